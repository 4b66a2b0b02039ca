"""Physics audit of a synthesized motion, per character.

Everything is re-evaluated from the final motion, not read from the solver: kinematics at
``rate`` Hz (also between collocation points), the equations of motion at the times where
contact forces are known, and again at every ``rate`` Hz frame of the whole motion — between
those times and through every flight — with the forces read as the transcription represents
them (:mod:`.dense_audit`: piecewise linear within each planted interval, zero outside).
Units: N, m, m/s, rad.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from scenegraph.model.body import G, N_ROOT, Character
from scenegraph.model.dense_audit import dense_residual, kernel_theta, shoe_forces
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.ground import FLAT, Ground
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.motion import Motion
from scenegraph.model.residual import CONTACT_HANDLES, FORCE_HANDLES, residual_kernel
from scenegraph.model.style import Style

__all__ = ["Audit", "audit_motion"]


@dataclass(frozen=True)
class Audit:
    root_residual_rms: float  # N (translational and rotational generalized forces together)
    root_residual_max: float
    root_residual_rel: float  # rms / body weight
    footstep_error_max: float  # m, planted handle distance from its footprint
    penetration_max: float  # m, depth of the lowest foot handle below the ground (vertical, under the handle)
    friction_violation_max: float  # N, how far a contact force leaves the friction cone (about the ground normal)
    planted_speed_max: float  # m/s: the largest horizontal speed of a planted handle (a speed, not a slide distance; was foot_sliding_max)
    joint_limit_violation_max: float  # rad
    energy: float  # Σ α Q_m² dt over the audited times
    dense_residual_max: float = 0.0  # body weights: largest |Q_0 force| at any ``rate`` Hz frame (dense_audit)
    dense_residual_rms: float = 0.0  # body weights, RMS over those frames
    dense_flight_residual_max: float = 0.0  # body weights, the same over the frames with no handle planted
    dense_residual_time: float = 0.0  # s, world time of the largest

    def to_dict(self) -> dict:
        return asdict(self)

    def passes(self, footstep_tol=1e-3, penetration_tol=1e-3, friction_tol=1e-3 * 9.81,
               residual_rel_tol=0.05, dense_tol=None) -> bool:
        """Whether every figure is within its tolerance; ``dense_tol`` (body weights, None: not
        judged) bounds the dense residual — at every frame, flights included."""
        return (self.footstep_error_max <= footstep_tol and self.penetration_max <= penetration_tol
                and self.friction_violation_max <= friction_tol and self.root_residual_rel <= residual_rel_tol
                and (dense_tol is None or self.dense_residual_max <= dense_tol))


def audit_motion(ch: Character, style: Style, motion: Motion, footsteps: tuple[Footstep, ...] = (),
                 contact_forces: dict | None = None, rate: float = 120.0, ground: Ground = FLAT,
                 shoe_gate: bool = True) -> Audit:
    """Audit ``motion``; ``contact_forces`` maps handle → (times (n,), forces (n, 3)).

    ``ground``: heights, normals and μ come from it (default flat z = 0 with the solver's μ):
    penetration is measured below the ground height under each handle, footprints sit at
    the ground height, the friction cone is about the ground normal at the contact.
    ``shoe_gate``: the heel shoe springs act only in planned heel contact (the solver's default,
    ``scenegraph/model/shoe.py``) or everywhere (False: the round-8 semantics).
    """
    n = max(2, int(round(motion.duration * rate)) + 1)
    t = np.linspace(motion.start, motion.end, n)
    s = motion.to_canonical(t)
    q, qd, qdd = motion.state_at_s(s)
    names = tuple(CONTACT_HANDLES)
    hp = np.asarray(handle_positions_fn(ch, names).map(n)(q.T)).reshape(3, len(names), n, order="F")
    # hp[:, j, k]: handle j at time k
    above = hp[2] - (0.0 if ground.flat else ground.height(hp[0], hp[1]))  # (handles, times)
    pen = max(0.0, float(-np.min(above)))
    foot_err, planted_speed = 0.0, 0.0
    for step in footsteps:
        for handle, (ta, tb), xy in contact_points(ch, step, None, ground):
            j = names.index(handle)
            inside = (t >= ta - 1e-9) & (t <= tb + 1e-9)
            if not inside.any():
                continue
            target = np.array([xy[0], xy[1], ground.height(xy[0], xy[1])])
            err = np.linalg.norm(hp[:, j, inside].T - target, axis=1)
            foot_err = max(foot_err, float(err.max()))
            if inside.sum() > 1:
                v = np.gradient(hp[:2, j, inside], t[inside], axis=1)
                planted_speed = max(planted_speed, float(np.linalg.norm(v, axis=0).max()))
    lim = max(0.0, float(np.max(np.maximum(ch.lower - q, q - ch.upper)[:, N_ROOT:])))

    # equations of motion at the contact-force times (or the audit grid without contact)
    cf = contact_forces or {}
    times = sorted({round(float(x), 9) for v in cf.values() for x in v[0]}) or list(t)
    times = np.array(times)
    F = np.zeros((3 * len(FORCE_HANDLES), len(times)))
    fric = 0.0
    for h, (ht, hf) in cf.items():
        i = FORCE_HANDLES.index(h)
        where = None
        if not ground.flat and len(ht):  # the contact's (x, y): the handle's, when the force acts
            qh, _, _ = motion.state_at_s(motion.to_canonical(np.asarray(ht, float)))
            where = np.asarray(handle_positions_fn(ch, (h,)).map(len(ht))(np.atleast_2d(qh).T))[:2]
        for j, (tt, f) in enumerate(zip(ht, hf)):
            k = int(np.argmin(np.abs(times - tt)))
            F[3 * i:3 * i + 3, k] += f
            if h not in CONTACT_HANDLES:  # a coupling force at a hand: no friction cone
                continue
            if where is None:
                tang = np.hypot(f[0], f[1])
                fric = max(fric, tang - ground.friction * f[2], -f[2])
            else:
                fric = max(fric, ground.cone_violation(where[0, j], where[1, j], f))
    sq = motion.to_canonical(times)
    q2, qd2, qdd2 = motion.state_at_s(sq)
    if shoe_gate:
        F = F + shoe_forces(ch, style, motion, footsteps, q2, times, ground)
    th = np.tile(kernel_theta(style, shoe_gate)[:, None], (1, len(times)))
    Q = np.asarray(residual_kernel(ch).map(len(times))(q2.T, qd2.T, qdd2.T, F, th))
    root = Q[-N_ROOT:, :]
    rms = float(np.sqrt(np.mean(root ** 2)))
    dt = np.gradient(times) if len(times) > 1 else np.ones(1)
    energy = float(np.sum(np.asarray(style.alpha)[:, None] * Q[:-N_ROOT] ** 2 * dt))
    mg = ch.total_mass * G
    d = dense_residual(ch, style, motion, footsteps, cf, rate, ground, shoe_gate)
    return Audit(rms, float(np.abs(root).max()), rms / mg, foot_err, pen, max(0.0, fric), planted_speed, lim, energy,
                 d.force_max_bw, d.force_rms_bw, d.flight_force_max_bw, d.worst_time())
