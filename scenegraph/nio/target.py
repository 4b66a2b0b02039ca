"""X_T for NIO from a reconstructed clip, and the joint-angle distance between motions."""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import N_ROOT, Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.problem import PoseTarget, Result, Subproblem, build, solve
from scenegraph.model.style import default_style

__all__ = ["feasible_target", "resample", "joint_rms_deg"]


def joint_rms_deg(a: Motion, b: Motion, fps: float = 30.0) -> float:
    """RMS (degrees) of the joint angles (root excluded) of ``a`` vs ``b`` at ``fps`` frames
    over their common time span."""
    t0, t1 = max(a.start, b.start), min(a.end, b.end)
    n = int(np.floor((t1 - t0) * fps + 1e-9)) + 1
    t = t0 + np.arange(n) / fps
    qa = a.canonical(a.to_canonical(t))[:, N_ROOT:]
    qb = b.canonical(b.to_canonical(t))[:, N_ROOT:]
    return float(np.degrees(np.sqrt(np.mean((qa - qb) ** 2))))


def resample(motion: Motion, ctrl_per_second: float = 24.0, fps: float = 120.0) -> Motion:
    """The same motion on a denser spline (the synthesis resolution): a reconstruction at
    10–12 control points per second cannot hold a foot on its footprint at 30 Hz."""
    t, q = motion.sample(fps)
    return Motion.from_samples(t, q, max(6, int(round(motion.duration * ctrl_per_second)) + 3))


def feasible_target(ch: Character, motion: Motion, footsteps: tuple[Footstep, ...], *, cyclic: bool = False,
                    weight: float = 1.0, hz: float = 30.0, max_iter: int = 1500, tol: float = 1e-6) -> Result:
    """X_T for NIO from a reconstructed clip: the motion closest to ``motion`` that satisfies
    the footstep constraints C exactly, with the root residual softly zero (Appendix A):

        min  w_r Σ_k Q_0(s_k)² (normalised as the energy) + weight Σ_f |q(t_f) − q_clip(t_f)|²   s.t. C

    (a spacetime solve with every muscle weight α set to 0, through the NLP's
    ``p_layout["sqrt_alpha"]``, and pose springs toward the clip at ``hz``).  Q_0 depends on
    no part of θ but the shoe spring, which is the default one (the one NIO starts from;
    with the shoe off, the target's heels would sit compressed at the ground and every θ
    with a shoe would see a root residual there), so the target is not biased toward a
    style.  A reconstruction that misses its footprints by a centimetre is otherwise beaten
    by every counterexample for the wrong reason (it is outside C).
    """
    n = max(2, int(round(motion.duration * hz)) + 1)
    t = motion.start + np.arange(n) * (motion.duration / (n - 1))
    q = motion.canonical(motion.to_canonical(t))
    poses = tuple(PoseTarget(float(ti), tuple(map(float, qi)), weight=weight / n) for ti, qi in zip(t, q))
    st = default_style(ch.total_mass)
    sp = Subproblem(ch, st, motion, tuple(footsteps), free=frozenset({"q"}), poses=poses, cyclic=cyclic,
                    max_iter=max_iter, tol=tol, label="nio-target",
                    ipopt_options=(("acceptable_iter", 0),))
    b = build(sp)
    p = b.nlp.p0.copy()
    p[b.nlp.p_layout["sqrt_alpha"]] = 0.0  # sqrt(α) = 0: no muscle energy
    return solve(sp, b, p=p)
