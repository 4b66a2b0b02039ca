"""Planting feet by moving the legs only: a Gauss–Newton leg fit of sampled poses.

:func:`fit_legs` moves the 14 leg DOFs (LEG_DOFS) of each frame that has a planted foot
handle so that those handles reach their targets (100 per m of handle error, 1 per rad of
leg change from the frame's own pose; joint limits clipped); the root and the upper body
are held.  Used by the momentum-preserving edit of a captured jump
(``scenegraph.mocap.momentum_edit``); a model-layer module so that model-level initial
motions can use it too.

Units: m, s, rad; world frame z up.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import N_DOF, Character
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.residual import CONTACT_HANDLES

__all__ = ["LEG_DOFS", "leg_fit_fn", "fit_legs"]

LEG_DOFS = tuple(f"{d}_{s}" for s in ("l", "r") for d in ("hip_flex", "hip_abd", "hip_rot", "knee_flex",
                                                         "ankle_flex", "ankle_inv", "toe_flex"))


@functools.lru_cache(maxsize=8)
def leg_fit_fn(ch: Character):
    """Gauss–Newton residual of a pose: the planted handles at their targets (weight 100 per
    m) and the leg DOFs near the reference (1 per rad); root and upper body held."""
    q = ca.SX.sym("q", N_DOF)
    legs = [ch.dof_index(d) for d in LEG_DOFS]
    x = ca.SX.sym("x", len(legs))
    qq = ca.vertcat(*[x[legs.index(i)] if i in legs else q[i] for i in range(N_DOF)])
    targ = ca.SX.sym("targ", 3, len(CONTACT_HANDLES))
    mask = ca.SX.sym("mask", len(CONTACT_HANDLES))
    hp = handle_positions_fn(ch, tuple(CONTACT_HANDLES))(qq)
    r = ca.vertcat(ca.vec((hp - targ) * ca.repmat(mask.T, 3, 1)) * 100.0, x - ca.vertcat(*[q[i] for i in legs]))
    return ca.Function("leg_fit", [x, q, targ, mask], [r, ca.jacobian(r, x)]), legs


def fit_legs(ch: Character, q: np.ndarray, targets: np.ndarray, mask: np.ndarray, iters: int = 8) -> np.ndarray:
    """q (T, 35) with the leg DOFs of the frames with a planted handle moved so that those
    handles reach ``targets`` (T, 3, 6) (Gauss–Newton, joint limits clipped)."""
    fn, legs = leg_fit_fn(ch)
    out = q.copy()
    lo, hi = ch.lower[legs], ch.upper[legs]
    for k in np.flatnonzero(mask.any(axis=1)):
        x = out[k, legs].copy()
        for _ in range(iters):
            r, J = (np.asarray(v) for v in fn(x, q[k], targets[k], mask[k].astype(float)))
            step = np.linalg.lstsq(J, -r.ravel(), rcond=None)[0]
            x = np.clip(x + step, lo, hi)
            if np.abs(step).max() < 1e-6:
                break
        out[k, legs] = x
    return out
