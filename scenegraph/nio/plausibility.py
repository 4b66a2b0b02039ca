"""How far a motion is from dynamically possible: its root residual with the best contact forces.

An independent measure of an *initial* motion (or any motion without solver forces): at every
frame of a uniform grid (``rate`` Hz) the six root generalized forces Q_0 of the equations of
motion (``residual.residual_kernel``, gravity included, springs and the gated heel shoe of
``style``) are minimised over the contact forces the footsteps allow at that frame — each
planted handle's force in the friction pyramid of :func:`scenegraph.model.dynamics.friction_basis`
(f = V c, c ≥ 0, μ = 0.8), zero for handles not planted.  What is left is the part of the
motion no admissible ground force can explain: a motion a physical body could perform has it
at 0.  Frames are independent (one 6-row NNLS each), so nothing is smoothed between them.

Units: the returned translational residual |Q_0[:3]| in body weights (m g), the rotational
|Q_0[3:]| in body weight × m; times s (world).  Unlike the audit's dense residual this needs no
solver forces, so the kinematic variant of ``compose evaluate-style`` and an initial motion can
be judged by it, and it is a lower bound of the audit's figure for the same motion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from scenegraph.model.body import G, N_ROOT, Character
from scenegraph.model.dense_audit import kernel_theta, shoe_forces
from scenegraph.model.dynamics import MU, friction_basis
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.ground import FLAT, Ground
from scenegraph.model.motion import Motion
from scenegraph.model.residual import FORCE_HANDLES, residual_kernel
from scenegraph.model.style import Style

__all__ = ["BestFit", "best_fit_root_residual"]

# the moment rows are weighted as forces at this lever arm (m) in the per-frame fit
MOMENT_ARM = 1.0


@dataclass(frozen=True)
class BestFit:
    """``times`` (T,) s; ``force_bw`` (T,) |Q_0[:3]| / m g and ``moment_bw_m`` (T,) |Q_0[3:]| / m g
    left with the best admissible contact forces."""

    times: np.ndarray
    force_bw: np.ndarray
    moment_bw_m: np.ndarray

    @property
    def force_rms_bw(self) -> float:
        return float(np.sqrt(np.mean(self.force_bw ** 2)))

    @property
    def force_max_bw(self) -> float:
        return float(self.force_bw.max())

    @property
    def moment_rms_bw_m(self) -> float:
        return float(np.sqrt(np.mean(self.moment_bw_m ** 2)))

    def worst_time(self) -> float:
        return float(self.times[int(np.argmax(self.force_bw))])

    def summary(self) -> dict:
        return {"force_rms_bw": self.force_rms_bw, "force_max_bw": self.force_max_bw,
                "moment_rms_bw_m": self.moment_rms_bw_m, "worst_time_s": self.worst_time()}


def best_fit_root_residual(ch: Character, style: Style, motion: Motion, footsteps: tuple[Footstep, ...],
                           rate: float = 120.0, ground: Ground = FLAT, times=None) -> BestFit:
    """The root residual of ``motion`` left at each frame by the best contact forces of the
    planted handles (see the module docstring).  ``times``: world times (s) instead of the
    uniform ``rate`` Hz grid over the motion."""
    if times is None:
        n = max(2, int(round(motion.duration * rate)) + 1)
        times = np.linspace(motion.start, motion.end, n)
    times = np.asarray(times, float)
    T = len(times)
    q, qd, qdd = motion.state_at_s(motion.to_canonical(times))
    kern = residual_kernel(ch).map(T)
    th = np.tile(kernel_theta(style, True)[:, None], (1, T))
    F0 = shoe_forces(ch, style, motion, footsteps, q, times, ground)
    Q0 = np.asarray(kern(q.T, qd.T, qdd.T, F0, th))[-N_ROOT:]  # (6, T) with no contact force
    planted = np.zeros((len(FORCE_HANDLES), T), bool)
    for step in footsteps:
        for handle, (ta, tb), _ in contact_points(ch, step, None, ground):
            planted[FORCE_HANDLES.index(handle)] |= (times >= ta - 1e-9) & (times <= tb + 1e-9)
    # Q_0 is affine in F: the columns of a unit force on each handle along x, y, z
    cols = np.zeros((len(FORCE_HANDLES), 3, N_ROOT, T))
    for i in np.flatnonzero(planted.any(axis=1)):
        for d in range(3):
            F = F0.copy()
            F[3 * i + d] += 1.0
            cols[i, d] = np.asarray(kern(q.T, qd.T, qdd.T, F, th))[-N_ROOT:] - Q0
    V = friction_basis(getattr(ground, "friction", None) or MU)
    w = np.r_[np.ones(3), np.full(3, 1.0 / MOMENT_ARM)]
    force, moment = np.zeros(T), np.zeros(T)
    for k in range(T):
        hs = np.flatnonzero(planted[:, k])
        r = Q0[:, k]
        if hs.size:
            A = np.concatenate([cols[i, :, :, k].T @ V for i in hs], axis=1)  # (6, 4·handles)
            c, _ = nnls(w[:, None] * A, -w * r, maxiter=200 * A.shape[1])
            r = r + A @ c
        force[k] = np.linalg.norm(r[:3])
        moment[k] = np.linalg.norm(r[3:])
    mg = ch.total_mass * G
    return BestFit(times, force / mg, moment / mg)
