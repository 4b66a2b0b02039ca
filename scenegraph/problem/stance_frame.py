"""A planted foot keeps its footstep's frame: no swivel (yaw) and no roll in stance (issue #15 item 3).

The footstep pins hold the heel and ball handles at the collocation points.  Both lie on the
foot's long axis, so the pins leave the foot free to **roll** about that axis, and while only
one of them is planted (heel strike, heel-off) free to **swivel** (yaw) about it — a real
foot is wide and flat and does neither; on the stage the sole's outer vertices slide.

The term: during each footstep's planted interval (from its first handle's touch-down to
its last handle's lift-off, world s of the initial motion) the foot body's lateral axis
y_foot (world, unit; the foot frame's y axis, across the foot) stays at the footstep's
lateral axis ℓ = n × d / |n × d| (d the footstep's heading (cos ψ, sin ψ, 0), n the ground
normal under the footstep).  A rotation about y_foot — pitch: heel-off and toe-off roll over
the ball — leaves y_foot where it is and costs nothing; yaw turns y_foot within the ground
plane, roll tilts it out of it.  With Δ = y_foot − ℓ (|Δ| ≈ the angle, rad), yaw ≈ −Δ·(ℓ × n)
and roll ≈ Δ·n.

The term is a time integral, evaluated at every sample of a dense grid (``hz``, 120 Hz by
default) inside a planted interval, not only at the collocation points:

    E_frame = w_frame ∫_planted |y_foot(t) − ℓ|² dt        (w_frame in 1/(rad²·s))

entered as least-squares residuals sqrt(w_frame Δt_i) Δ(t_i) (Δt_i = the sample spacing in
world s), which the transcription scales by OBJ_SCALE like its other terms: the objective
gains OBJ_SCALE² E_frame next to the energy (OBJ_SCALE / m g)² ∫ Σ α Q_m² dt.  Both are
integrals over time, so their ratio does not change with the scene's length, the sampling
rate or the character's mass (the energy is in body weights, the angle is mass-free).
Why :data:`STANCE_FRAME_WEIGHT`: see its comment.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import N_DOF, Character
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.kinematics import frame_transforms
from scenegraph.model.motion import basis

__all__ = ["STANCE_FRAME_WEIGHT", "foot_lateral_fn", "planted_frames", "stance_frame_residuals",
           "stance_frame_deviation"]

# w_frame, 1/(rad²·s).  A planted foot turned by θ for τ seconds costs OBJ_SCALE² w θ² τ: 1°
# (0.0175 rad) held through a 0.6 s stance costs 900 · 100 · 3.0e-4 · 0.6 ≈ 16.5.  The styles'
# energies differ by two orders of magnitude (objective per second of motion: the learned run
# ≈ 20, the learned walk ≈ 370, the default style ≈ 3000), so one number must hold a walker's
# feet without swamping a runner's energy.  Measured (docs/results.md, "Contact semantics"):
# at 1e3 (with NO_SLIP_WEIGHT 100) the walk passed the stage audit but springy_run's objective went
# 23 → 259, capped at 300 iterations, its 120 Hz root residual 0.018 → 0.24 bw (the run's audit
# failed); at 100 (and 10) the walk still passes (slide 1.37 mm, 60 iterations) and the run keeps
# its dynamics (0.019 bw, objective 42).  The same number for every gait, body and scene length
# (the term and the energy are both integrals over time, see the module docstring).
STANCE_FRAME_WEIGHT = 100.0


@functools.lru_cache(maxsize=16)
def foot_lateral_fn(ch: Character) -> ca.Function:
    """casadi.Function q (35) → (3, 2): the world lateral (y) axis of foot_l and foot_r."""
    q = ca.SX.sym("q", N_DOF)
    R, _ = frame_transforms(ch, q)
    cols = [R[ch.body(f"foot_{side}").frame][:, 1] for side in ("l", "r")]
    return ca.Function("foot_lateral", [q], [ca.horzcat(*cols)])


def planted_frames(ch: Character, footsteps, ground) -> list[tuple[str, float, float, np.ndarray, np.ndarray]]:
    """[(side, t_a, t_b, ℓ, n)] per footstep: its planted interval (world s: the first of its
    handles down to the last one up), the lateral axis ℓ (3, world, unit) its foot keeps and
    the ground normal n under the footstep."""
    out = []
    for step in footsteps:
        spans = [iv for _, iv, _ in contact_points(ch, step, None, ground)]
        if not spans:
            continue
        ta, tb = min(a for a, _ in spans), max(b for _, b in spans)
        d = np.array([np.cos(step.heading), np.sin(step.heading), 0.0])
        n = np.array([0.0, 0.0, 1.0]) if ground is None or ground.flat else \
            np.asarray(ground.normal(*step.position), float).reshape(3)
        ell = np.cross(n, d)
        out.append((step.foot, float(ta), float(tb), ell / np.linalg.norm(ell), n))
    return out


def _planted_samples(ch, footsteps, ground, times):
    """[(foot column 0/1, sample index, ℓ, n)] of the samples strictly inside a planted interval."""
    out = []
    for side, ta, tb, ell, n in planted_frames(ch, footsteps, ground):
        for k in np.flatnonzero((times > ta + 1e-9) & (times < tb - 1e-9)):
            out.append((0 if side == "l" else 1, int(k), ell, n))
    return out


def stance_frame_residuals(ch: Character, footsteps: tuple[Footstep, ...], ground, times: np.ndarray,
                           s: np.ndarray, dt: float, P, n_ctrl: int, weight: float):
    """Least-squares residuals sqrt(weight · dt) (y_foot − ℓ) (3 per planted sample) of the
    samples ``s`` (canonical; ``times`` their world s) that lie strictly inside a footstep's
    planted interval; ``P`` (n_ctrl × 35, CasADi) the control points.  None without any."""
    rows = _planted_samples(ch, footsteps, ground, np.asarray(times, float))
    if not rows:
        return None
    ks = sorted({k for _, k, _, _ in rows})
    col = {k: j for j, k in enumerate(ks)}
    B = ca.sparsify(ca.DM(basis(n_ctrl, np.asarray(s, float)[ks], 0)))
    Y = foot_lateral_fn(ch).map(len(ks))(ca.mtimes(B, P).T)  # (3, 2·len(ks)): foot_l, foot_r per sample
    pick = [2 * col[k] + c for c, k, _, _ in rows]
    dev = Y[:, pick] - ca.DM(np.array([r[2] for r in rows]).T)
    return np.sqrt(weight * dt) * ca.vec(dev)


def stance_frame_deviation(ch: Character, footsteps, ground, times: np.ndarray, q: np.ndarray):
    """Numeric check of a motion sampled at world ``times`` (poses ``q`` (T, 35)): per planted
    sample, (side "l"/"r", sample index, yaw rad, roll rad) of the foot against its footstep's
    frame; yaw about the ground normal n, roll about the footstep's forward axis ℓ × n (both
    right-handed)."""
    times = np.asarray(times, float)
    Y = np.asarray(foot_lateral_fn(ch).map(len(times))(np.asarray(q, float).reshape(len(times), N_DOF).T))
    out = []
    for c, k, ell, n in _planted_samples(ch, footsteps, ground, times):
        y = Y[:, 2 * k + c]
        fwd = np.cross(ell, n)
        out.append(("lr"[c], k, float(np.arcsin(np.clip(-y @ fwd, -1, 1))), float(np.arcsin(np.clip(y @ n, -1, 1)))))
    return out
