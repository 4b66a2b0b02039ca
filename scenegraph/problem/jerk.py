"""Knot-to-knot jerk penalty: the motion's splines do not ring between evaluation points.

A cubic B-spline's third derivative q⃛ is constant on each knot interval and jumps at every
knot; a motion whose acceleration zig-zags from knot to knot (the "ringing" measured on
``springy_run`` and ``handhold``: joint accelerations changing sign at every knot, 32 ms, at
1000+ rad/s²) has large jumps, a smooth one small jumps.  Because the dense transcription
evaluates the residual only at nodes and node-interval midpoints, the solver can zero it there
while the ringing leaves ±3–4 N·m of root moment between the points (docs/results.md).

The term, per DOF j and interior knot i (world time t, world knot spacing h_i = T'(s_i)/n_int):

    kink force   F_ij = M_j · Δq⃛_j(t_i) · h_i         (N·m; j one of the 29 joint DOFs)
    energy       E_jerk = w Σ_i h_i Σ_j F_ij²           (N²·m²·s, like the style energy Σ w_k T' α Q²)

i.e. the generalised force the jump of the jerk amounts to over one knot interval (the
acceleration one interval's worth of that jump adds, times the DOF's inertia M_j: the norm of
the mass matrix's entries that couple it to itself and to the root, at a reference pose — the
generalised force that acceleration needs at the joint and leaks into the root residual, which
is what the ringing does between evaluation points), integrated over time like the energy with a
dimensionless weight ``w`` (the style weights α are 0–0.24, W_ROOT is 100).  Only the joints
(the muscles' DOFs): the root has no actuator, its acceleration is what the external forces make
it, and those legitimately kink at every touch-down (a run's root: kinks of 20–70 m/s² per knot).  The residual rows
returned are sqrt(w h_i) F_ij / (m g) (body weights·√s, the normalisation of the transcription's
other least-squares rows, which multiplies them by OBJ_SCALE).  They are linear in the control
points; the warp slope T' is taken from the motion as given (held during the solve: a free
timewarp changes the world jerk only through it).

Contact changes are exempt (:func:`contact_events`, ``jerk_rows(events=...)``): where a foot
touches down or lifts off (or a flight starts or ends) the contact force starts or ends with a
kink, so the true motion's jerk jumps there — the legs absorb a landing.  A spline can only kink
at its knots, so the knots bounding the knot interval that holds a planned contact change (every
interior knot closer than one knot spacing to it) carry no jerk row.  Without the exemption
(round 13) the penalty smoothed ``springy_run``'s touch-downs and its stage CoP 11 ms after a
touch-down grew 2.28 → 3.91 cm.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from scenegraph.model.body import G, N_DOF, N_ROOT, Character
from scenegraph.model.dynamics import mass_matrix
from scenegraph.model.motion import Motion, basis

__all__ = ["JERK_WEIGHT", "knot_jump_matrix", "dof_inertia", "contact_events", "exempt_knots", "jerk_rows",
           "jerk_energy"]

JERK_WEIGHT = 1e-3  # w of E_jerk in full steps (lowering): handhold's flailing arms gone, overlap 0.56 -> 0.29 cm,
# walk and walk_to_run measured (docs/results.md, round 13); 1e-4 with the joint's own inertia left the ringing


def knot_jump_matrix(n_ctrl: int) -> tuple[np.ndarray, np.ndarray]:
    """(J, s_knots): J (n_int − 1, n_ctrl) with (J @ ctrl)[i] the jump of d³q/ds³ at interior knot
    ``s_knots[i]`` (canonical s; right interval's value minus left's) of a clamped uniform cubic
    spline with ``n_ctrl`` control points (n_int = n_ctrl − 3 knot intervals)."""
    n_int = n_ctrl - 3
    if n_int < 2:
        return np.zeros((0, n_ctrl)), np.zeros(0)
    edges = np.linspace(0.0, 1.0, n_int + 1)
    mid = 0.5 * (edges[:-1] + edges[1:])
    B3 = basis(n_ctrl, mid, 3)  # q⃛ in s: constant on each interval
    return B3[1:] - B3[:-1], edges[1:-1]


def dof_inertia(ch: Character, q: np.ndarray) -> np.ndarray:
    """Per DOF j, the generalised force a unit acceleration of j alone needs on itself and on
    the root: ‖(M_jj, M_rj for the 6 root DOFs r)‖ of the joint-space mass matrix M(q) at pose
    ``q`` (35, rad / m) — kg·m² (kg·m for the root forces) per DOF; the root DOFs' own entries
    too (kg and kg·m²), though the penalty leaves the root out."""
    M = np.asarray(ca.evalf(mass_matrix(ch, ca.DM(np.asarray(q, float)))))
    cols = np.sqrt(np.diag(M) ** 2 + np.sum(M[:N_ROOT, :] ** 2, axis=0) - np.r_[np.diag(M)[:N_ROOT] ** 2, np.zeros(N_DOF - N_ROOT)])
    return np.maximum(cols, 1e-6)


def contact_events(footsteps, flights=()) -> tuple[float, ...]:
    """World times (s, of the initial motion, as the footsteps') at which a planned contact starts
    or ends: every footstep's first touch-down and last lift-off (any handle) and every flight's
    take-off and landing, sorted, duplicates once."""
    from scenegraph.model.footsteps import planted_interval
    ev = [t for f in footsteps for t in planted_interval(f)] + [t for fl in flights for t in fl]
    return tuple(sorted(set(round(float(t), 12) for t in ev)))


def exempt_knots(motion: Motion, events) -> np.ndarray:
    """Bools over the interior knots of ``motion`` (those of :func:`knot_jump_matrix`): True for a
    knot closer than one knot spacing (canonical) to a contact change in ``events`` (world s,
    :func:`contact_events`) inside the motion — the two knots bounding the interval that holds it
    (one, when the change falls on a knot)."""
    _, s_k = knot_jump_matrix(motion.n_ctrl)
    ev = [t for t in events if motion.start < t < motion.end]
    if not len(s_k) or not ev:
        return np.zeros(len(s_k), bool)
    s_ev = np.asarray(motion.to_canonical(ev), float)
    spacing = 1.0 / (motion.n_ctrl - 3)
    return np.any(np.abs(s_k[:, None] - s_ev[None, :]) < spacing - 1e-9, axis=1)


def _knot_scales(ch: Character, motion: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(J, T', h, M_j) at the interior knots of ``motion``: the jump matrix (:func:`knot_jump_matrix`),
    the warp slope T' (world s per unit s), the world knot spacing h (s) and the per-DOF inertias
    (:func:`dof_inertia`) at the reference pose, the motion's at s = 0.5."""
    K = motion.n_ctrl
    J, s_k = knot_jump_matrix(K)
    t1 = basis(len(motion.warp), s_k, 1) @ np.asarray(motion.warp, float) if len(s_k) else np.zeros(0)
    q_ref = np.asarray(motion.state_at_s(np.array([0.5]))[0], float).reshape(-1)[:N_DOF]
    return J, t1, t1 / max(K - 3, 1), dof_inertia(ch, q_ref)


def jerk_rows(ch: Character, motion: Motion, P, mask: np.ndarray, weight: float, events=()):
    """Residual rows (MX column) of E_jerk (module docstring) for the control points ``P`` (K × 35,
    MX) at the interior knots whose jump a free control point (``mask``, K bools) moves and that
    are not next to a contact change in ``events`` (world s, :func:`exempt_knots`); None when
    ``weight`` ≤ 0 or no such knot.  The reference pose of M_j is the motion's at s = 0.5."""
    if weight <= 0 or not np.any(mask):
        return None
    J, t1, h, m_j = _knot_scales(ch, motion)
    live = (np.abs(J[:, mask]).sum(axis=1) > 0) & ~exempt_knots(motion, events)
    if not live.any():
        return None
    J, t1, h = J[live], t1[live], h[live]
    # F_ij = M_jj Δ(d³q/ds³)/T'³ h; row = sqrt(w h) F / (m g)
    row_scale = np.sqrt(weight * h) * h / t1 ** 3 / (ch.total_mass * G)  # (n_live,)
    Jw = J * row_scale[:, None]
    jumps = ca.mtimes(ca.DM(Jw), P[:, N_ROOT:])  # (n_live, 29): the joints' jumps in s, scaled per knot
    return ca.vec(jumps * ca.repmat(ca.DM(m_j[N_ROOT:]).T, Jw.shape[0], 1))


def jerk_energy(ch: Character, motion: Motion, weight: float = 1.0, events=()) -> float:
    """E_jerk (N²·s, module docstring) of a numeric ``motion`` over its interior knots not exempt
    by ``events`` (:func:`exempt_knots`): the unnormalised value of the rows of :func:`jerk_rows`
    (a diagnostic, and the tests' check)."""
    J, t1, h, m_j = _knot_scales(ch, motion)
    keep = ~exempt_knots(motion, events)
    J, t1, h = J[keep], t1[keep], h[keep]
    if not len(t1):
        return 0.0
    F = (J @ np.asarray(motion.ctrl, float)[:, N_ROOT:]) / (t1 ** 3)[:, None] * h[:, None] * m_j[None, N_ROOT:]
    return float(weight * np.sum(h[:, None] * F ** 2))
