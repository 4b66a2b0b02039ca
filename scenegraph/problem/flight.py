"""Ballistic flight as momentum constraints (thesis ch. 3, formulation (b) in flight).

In flight only gravity acts on the body: its linear momentum P changes by −M g per second
and its angular momentum H about the centre of mass is constant.  :func:`flight_constraints`
states exactly that at the evaluation points of each flight — the dense transcription's nodes
and the midpoints between them (its take-off and touch-down nodes included, where the contact
force is held at zero too): for every point k other than the flight's first node k0

    P(k) − P(k0) + M g (t_k − t_k0) e_z = 0,     H(k) − H(k0) = 0      (6 equalities per point)

in kg·m/s and kg·m²/s.  Stated per kilogram instead (divided by M, so O(1) whatever the body's
mass) they were measured worse on hopscotch and kept out (docs/dynamic-motion.md, round 11):
twist_jump unchanged (300-iteration cap, E 593 vs 595, flight drift 0.33 vs 0.75 %), hopscotch
stalled early (172 vs 600 iterations) at a higher energy (4172 vs 3873) with its stage's feet
worse (penetration 12.5 vs 5.0 mm, stance slide 32 vs 10 mm).

with P, H functions of the pose q and velocity q̇ only (:func:`momenta_fn`, plain CasADi SX
algebra of the forward kinematics: exact first derivatives).  The transcription keeps these rows
MX and gives IPOPT their Jacobian by the chain rule (:func:`flight_jacobian`: the per-point
momenta Jacobian, differentiated once, times ∂(q, q̇)/∂x); their curvature
(:func:`flight_hessian`) is left out of the Lagrangian Hessian by default
(``Subproblem.flight_curvature``: with it broad_jump took 212 iterations to E 1648 against
237–300 to E 1136–1180, docs/dynamic-motion.md).  This
replaces the stiff least-squares term (root residual weighted W_FLIGHT = 1e6 in flight,
formulation (a)) whose ill-conditioning made IPOPT spend most of a jump's iterations on it;
the root residual keeps its ordinary weight W_ROOT in flight (it still counts in the energy,
and between the points it keeps P and H from wiggling).

Units: m, s, kg; world frame z up; q̇ in world seconds.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import G, N_DOF, Character
from scenegraph.model.kinematics import body_transforms

__all__ = ["momenta_fn", "momenta_jacobian_fn", "flight_groups", "flight_constraints", "flight_jacobian",
           "momenta_hessian_fn", "flight_hessian", "FLIGHT_MODES"]

FLIGHT_MODES = ("penalty", "momentum")  # Subproblem.flight_mode: W_FLIGHT least squares, or these equalities


@functools.lru_cache(maxsize=16)
def momenta_fn(ch: Character) -> ca.Function:
    """CasADi Function (q (35), q̇ (35)) → (c (3) m, P (3) kg·m/s, H (3) kg·m²/s about c),
    world frame: the centre of mass, linear momentum and angular momentum of the body."""
    q, qd = ca.SX.sym("q", N_DOF), ca.SX.sym("qd", N_DOF)
    M = ch.total_mass
    xs, vs, Iws, ws, ms = [], [], [], [], []
    for b, (R, p) in zip(ch.bodies, body_transforms(ch, q)):
        x = p + ca.mtimes(R, ca.DM(b.center))
        v = ca.jtimes(x, q, qd)
        Rd = ca.reshape(ca.jtimes(ca.vec(R), q, qd), 3, 3)
        W = ca.mtimes(Rd, R.T)  # ω^ = Ṙ Rᵀ
        ws.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
        Iws.append(ca.mtimes(ca.mtimes(R, ca.DM(b.inertia)), R.T))
        xs.append(x)
        vs.append(v)
        ms.append(float(b.mass))
    c = sum(m * x for m, x in zip(ms, xs)) / M
    P = sum(m * v for m, v in zip(ms, vs))
    vc = P / M
    H = sum(m * ca.cross(x - c, v - vc) + ca.mtimes(I, w) for m, x, v, I, w in zip(ms, xs, vs, Iws, ws))
    return ca.Function("momenta", [q, qd], [c, P, H], ["q", "qd"], ["c", "P", "H"])


@functools.lru_cache(maxsize=16)
def momenta_jacobian_fn(ch: Character) -> ca.Function:
    """CasADi Function (q (35), q̇ (35)) → ∂(P, H)/∂(q, q̇) (6 × 70): the momenta's Jacobian at one
    point, differentiated once symbolically (SX) and mapped over points by :func:`flight_jacobian`."""
    q, qd = ca.SX.sym("q", N_DOF), ca.SX.sym("qd", N_DOF)
    _, P, H = momenta_fn(ch)(q, qd)
    return ca.Function("momenta_jac", [q, qd], [ca.jacobian(ca.vertcat(P, H), ca.vertcat(q, qd))], ["q", "qd"], ["J"])


def flight_groups(flights, motion, s: np.ndarray) -> list[np.ndarray]:
    """Indices into the canonical collocation times ``s`` of each flight (world s (take-off,
    landing) in ``flights`` of ``motion``), its ends included."""
    out = []
    for fa, fb in flights:
        sa, sb = motion.to_canonical([fa, fb])
        k = np.flatnonzero((s > sa - 1e-6) & (s < sb + 1e-6))
        if len(k) >= 2:
            out.append(k)
    return out


def flight_constraints(ch: Character, groups: list[np.ndarray], Q, Qd, T) -> ca.MX | None:
    """The equalities of the module docstring (6 per flight point after each flight's first),
    stacked; ``Q``, ``Qd`` (35, N) poses and world-time velocities at the evaluation points,
    ``T`` (1, N) their world times; each group's first index is its reference point (MX: the timewarp may be free).  None without flights."""
    if not groups:
        return None
    fn = momenta_fn(ch)
    M, rows = ch.total_mass, []
    for k in groups:
        idx = [int(i) for i in k]
        _, P, H = fn.map(len(idx))(Q[:, idx], Qd[:, idx])
        dt = T[:, idx[1:]] - T[:, idx[0]]
        grav = ca.vertcat(ca.DM.zeros(2, len(idx) - 1), M * G * dt)
        rows.append(ca.vec(P[:, 1:] - ca.repmat(P[:, 0], 1, len(idx) - 1) + grav))
        rows.append(ca.vec(H[:, 1:] - ca.repmat(H[:, 0], 1, len(idx) - 1)))
    return ca.vertcat(*rows)


def flight_jacobian(ch: Character, groups: list[np.ndarray], Q, Qd, T, x) -> ca.MX | None:
    """∂/∂x of :func:`flight_constraints` (same rows), by the chain rule through the per-point
    momenta Jacobian (:func:`momenta_jacobian_fn`, mapped) and ∂(q, q̇)/∂x: CasADi's MX Jacobian
    of the rows took 1.1 s per evaluation on broad_jump (its SX expansion 38 s to build)."""
    if not groups:
        return None
    jfn = momenta_jacobian_fn(ch)
    M, blocks = ch.total_mass, []
    for k in groups:
        idx = [int(i) for i in k]
        n = len(idx)
        Jm = jfn.map(n)(Q[:, idx], Qd[:, idx])  # (6, 70 n): point j's columns 70 j … 70 j + 69
        Jp = [Jm[0:3, 70 * j:70 * (j + 1)] for j in range(n)]
        Jh = [Jm[3:6, 70 * j:70 * (j + 1)] for j in range(n)]
        d_y = ca.vertcat(ca.horzcat(-ca.repmat(Jp[0], n - 1, 1), ca.diagcat(*Jp[1:])),
                         ca.horzcat(-ca.repmat(Jh[0], n - 1, 1), ca.diagcat(*Jh[1:])))
        y = ca.vec(ca.vertcat(Q[:, idx], Qd[:, idx]))  # (q_j, q̇_j) point by point
        # ∂(t_j − t_0)/∂x of the vertical rows (a free warp moves the times), as an explicit
        # difference matrix: the Jacobian of the broadcast ``T[:, idx[1:]] - T[:, idx[0]]`` came out
        # wrong (tests/problem/test_flight.py)
        diff = np.hstack([-np.ones((n - 1, 1)), np.eye(n - 1)])  # (n − 1, n)
        dT = M * G * ca.mtimes(ca.DM(diff), ca.jacobian(ca.vec(T[:, idx]), x))  # (n − 1, nx)
        pick = np.zeros((6 * (n - 1), n - 1))
        pick[3 * np.arange(n - 1) + 2, np.arange(n - 1)] = 1.0  # the P_z row of each point
        blocks.append(ca.mtimes(d_y, ca.jacobian(y, x)) + ca.mtimes(ca.sparsify(ca.DM(pick)), dT))
    return ca.vertcat(*blocks)


@functools.lru_cache(maxsize=16)
def momenta_hessian_fn(ch: Character) -> ca.Function:
    """CasADi Function (q (35), q̇ (35), w (6)) → ∇²_(q, q̇) (w · (P, H)) (70 × 70): the curvature of
    a weighted sum of one point's momenta (SX, built once in ~0.6 s, ~3 ms per point evaluated)."""
    q, qd, w = ca.SX.sym("q", N_DOF), ca.SX.sym("qd", N_DOF), ca.SX.sym("w", 6)
    _, P, H = momenta_fn(ch)(q, qd)
    Hs = ca.hessian(ca.dot(w, ca.vertcat(P, H)), ca.vertcat(q, qd))[0]
    return ca.Function("momenta_hess", [q, qd, w], [Hs], ["q", "qd", "w"], ["H"])


def flight_hessian(ch: Character, groups: list[np.ndarray], Q, Qd, lam, x) -> ca.MX | None:
    """Σ_i λ_i ∇²_x row_i of :func:`flight_constraints` (nx × nx), ``lam`` the rows' multipliers
    (MX, in the rows' order): per point the momenta's curvature weighted by its rows' multipliers
    (the first point of a flight by minus their sum), chained through ∂(q, q̇)/∂x.  Exact when
    (q, q̇) are linear in x (the timewarp held); with a free warp the curvature of q̇ = q′/T′ is
    left out.  The gravity term is linear in the times: no curvature."""
    if not groups:
        return None
    hfn = momenta_hessian_fn(ch)
    out, r0 = 0, 0
    for k in groups:
        idx = [int(i) for i in k]
        n = len(idx)
        lp = ca.reshape(lam[r0:r0 + 3 * (n - 1)], 3, n - 1)  # P rows, point by point
        lh = ca.reshape(lam[r0 + 3 * (n - 1):r0 + 6 * (n - 1)], 3, n - 1)
        r0 += 6 * (n - 1)
        W = ca.vertcat(lp, lh)  # (6, n − 1)
        W = ca.horzcat(-ca.sum2(W), W)  # the flight's first point: minus the others'
        Hk = hfn.map(n)(Q[:, idx], Qd[:, idx], W)  # (70, 70 n)
        Hyy = ca.diagcat(*ca.horzsplit(Hk, 70)) if n > 1 else Hk
        Jy = ca.jacobian(ca.vec(ca.vertcat(Q[:, idx], Qd[:, idx])), x)
        out = out + ca.mtimes(Jy.T, ca.mtimes(Hyy, Jy))
    return out
