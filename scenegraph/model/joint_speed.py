"""How fast a human joint can turn: a ceiling per DOF (rad/s) and the linear rows that keep a
motion's B-splines under it.

Why.  Nothing in the energy stops a limb whose torques the style makes cheap from being flung
where nothing follows — at a motion's free end above all: the round-14 stages had elbows at
31.7 rad/s in the last frame of a walk, 65–91 rad/s at the end of the tackles, hips at
70 rad/s.  At such speeds the inverse dynamics is so non-linear within a knot interval that the
motion zeroes the residual at the evaluation points and leaves 2 body weights between them
(two_tacklers, docs/results.md round 15).

The ceilings are the fastest joint speeds reported for the fastest human movements, rounded
up, so that no real motion meets them: throwing (elbow extension ≈ 40–44 rad/s, shoulder
internal rotation ≈ 120 rad/s, trunk rotation ≈ 20 rad/s; Fleisig et al. 1995/1996), kicking
(knee extension ≈ 30–35 rad/s, hip flexion ≈ 15–17 rad/s; Lees & Nolan 1998) and sprinting
(hip ≈ 12–15, knee ≈ 20–25, ankle ≈ 15–20 rad/s).  Walking and running stay far below them
(walk: ≤ 15 rad/s in every joint).

The rows.  A clamped cubic B-spline's derivative is a quadratic B-spline with control points
d_i = 3 (c_{i+1} − c_i) / (u_{i+4} − u_{i+1}) (u the knot vector), and a B-spline lies in the
hull of its control points; so |d_i| ≤ v_max · min T' over d_i's support keeps |q̇| = |q'| / T'
under v_max everywhere (conservative: the hull bound, not the curve's maximum).  Linear in the
control points for a held timewarp.  The transcription makes them a one-sided least-squares term
(zero under the ceiling), not inequality rows: IPOPT's barrier terms of ~800 rows that never
bind pulled a walk toward standing still (E 169 → 6322 in tests/problem/test_spacetime.py).
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import DOF_NAMES, N_ROOT
from scenegraph.model.motion import basis, clamped_knots

__all__ = ["MAX_JOINT_SPEED", "SPEED_WEIGHT", "max_speed", "speed_rows"]

SPEED_WEIGHT = 1.0  # per (rad/s)² over a ceiling, per control-point pair, in the objective's units
# (residuals of body weight: 1 rad/s over costs as much as 1 bw of root residual at one point)

# rad/s, by the name's prefix (first match)
MAX_JOINT_SPEED: tuple[tuple[str, float], ...] = (
    ("shoulder_twist", 120.0),
    ("shoulder", 40.0),
    ("elbow", 50.0),
    ("wrist", 40.0),
    ("hip", 25.0),
    ("knee", 40.0),
    ("ankle", 30.0),
    ("toe", 40.0),
    ("waist", 25.0),
    ("chest", 25.0),
    ("neck", 25.0),
)


def max_speed() -> np.ndarray:
    """Ceiling (rad/s) of each joint DOF (N_DOF − N_ROOT,), in DOF_NAMES order."""
    out = []
    for name in DOF_NAMES[N_ROOT:]:
        out.append(next(v for p, v in MAX_JOINT_SPEED if name.startswith(p)))
    return np.array(out)


def speed_rows(n_ctrl: int, warp: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(scale (len(pairs),), bound (len(pairs), n_joint)) for the control-point differences
    c_{i+1} − c_i, i in ``pairs``: the row is scale_i · (c_{i+1} − c_i)[joints] within ± bound_i
    (rad), with ``warp`` the held timewarp's control points (s)."""
    kn = np.array(clamped_knots(n_ctrl))
    pairs = np.asarray(pairs, int)
    scale = 3.0 / (kn[pairs + 4] - kn[pairs + 1])
    n_w = len(warp)
    bound = np.empty((len(pairs), len(DOF_NAMES) - N_ROOT))
    v = max_speed()
    for r, i in enumerate(pairs):
        s = np.linspace(kn[i + 1], kn[i + 4], 9)
        t1 = float(np.min(basis(n_w, s, 1) @ np.asarray(warp, float)))
        bound[r] = v * t1
    return scale, bound
