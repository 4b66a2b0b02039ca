"""Whole-body momenta of sampled poses, and making a sampled flight ballistic (thesis ch. 3).

In flight no force but gravity acts: the centre of mass follows a parabola with g and the
angular momentum about it is constant.  :func:`ballistic_flight` bends a sampled motion so
that its flight frames obey both (to the accuracy of the finite differences):

1. **angular momentum** — the flight frames are turned about their centre of mass by a
   whole-body angular velocity ω_c = I⁻¹(H̄ − H) (I the pose's inertia about the centre of
   mass, H its angular momentum there), H̄ the I⁻¹-weighted mean of H so that ∫ω_c dt = 0 and
   the touch-down pose is unchanged to first order;
2. **centre of mass** — the root is moved so that the centre of mass follows the parabola
   through its take-off and touch-down positions (g fixed, flight time given).

The jump synthesis starts from such a flight (``scenegraph.model.leaps.leap_motion``): with a
flight whose limbs swing and tuck while the pelvis alone flies a parabola, the root residual
in flight (weighted W_FLIGHT) made the initial objective ~1e10 and IPOPT spent most of its
iterations removing it.  The momentum-preserving edit of a captured jump
(``scenegraph.mocap.momentum_edit``) uses the same momenta.

Units: m, s, kg; world frame z up; poses q (T, 35) with the root (x, y, z, yaw, pitch, roll)
first, R = Rz(yaw) Ry(pitch) Rx(roll).
"""
from __future__ import annotations

import math

import numpy as np

from scenegraph.model.body import Character
from scenegraph.model.kinematics import numeric_fk

__all__ = ["body_momenta", "inertia_about_com", "rotate_about_com", "hold_angular_momentum", "ballistic_flight", "quintic", "G"]

G = 9.81


def _bodies(ch: Character, q: np.ndarray):
    """(R (T, nb, 3, 3), body centres of mass x (T, nb, 3), masses (nb,), inertias (nb, 3, 3))."""
    R, p = numeric_fk(ch, q)
    m = np.array([b.mass for b in ch.bodies])
    x = p + np.einsum("tbij,bj->tbi", R, np.array([b.center for b in ch.bodies]))
    return R, x, m, np.array([b.inertia for b in ch.bodies])


def body_momenta(ch: Character, q: np.ndarray, dt: float):
    """(com (T,3) m, P (T,3) kg·m/s, H (T,3) kg·m²/s about the com, Izz (T,) kg·m² about the
    vertical through the com) of poses ``q`` (T, 35) sampled every ``dt`` s (central differences)."""
    R, x, m, Ib = _bodies(ch, q)
    M = m.sum()
    com = np.einsum("b,tbi->ti", m, x) / M
    v = np.gradient(x, dt, axis=0)
    vc = np.gradient(com, dt, axis=0)
    Rd = np.gradient(R, dt, axis=0)
    W = np.einsum("tbij,tbkj->tbik", Rd, R)  # ω^ = Ṙ Rᵀ
    w = np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)
    Iw = np.einsum("tbij,bjk,tblk->tbil", R, Ib, R)  # world inertia per body
    r = x - com[:, None]
    H = np.einsum("b,tbi->ti", m, np.cross(r, v - vc[:, None])) + np.einsum("tbij,tbj->ti", Iw, w)
    Izz = np.einsum("b,tb->t", m, r[..., 0] ** 2 + r[..., 1] ** 2) + Iw[..., 2, 2].sum(axis=1)
    return com, M * vc, H, Izz


def inertia_about_com(ch: Character, q: np.ndarray) -> np.ndarray:
    """(T, 3, 3) inertia tensors (kg·m²) of poses q about their centres of mass, world axes."""
    R, x, m, Ib = _bodies(ch, q)
    r = x - (np.einsum("b,tbi->ti", m, x) / m.sum())[:, None]
    Iw = np.einsum("tbij,bjk,tblk->til", R, Ib, R)
    rr = np.einsum("tbi,tbi->tb", r, r)
    return Iw + np.einsum("b,tb->t", m, rr)[:, None, None] * np.eye(3) - np.einsum("b,tbi,tbj->tij", m, r, r)


def rotate_about_com(q: np.ndarray, c: np.ndarray, Rc: np.ndarray) -> np.ndarray:
    """Poses q (T, 35) rotated by Rc (T, 3, 3) about their centres of mass c (T, 3): the root
    (Rz(yaw) Ry(pitch) Rx(roll)) and its position; yaw kept continuous with q's."""
    out = q.copy()
    cy, sy, cp, sp, cr, sr = (f(q[:, k]) for k in (3, 4, 5) for f in (np.cos, np.sin))
    Rr = np.empty((len(q), 3, 3))
    Rr[:, 0] = np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], 1)
    Rr[:, 1] = np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], 1)
    Rr[:, 2] = np.stack([-sp, cp * sr, cp * cr], 1)
    Rn = np.einsum("tij,tjk->tik", Rc, Rr)
    yaw = np.arctan2(Rn[:, 1, 0], Rn[:, 0, 0])
    out[:, 3] = yaw + 2 * np.pi * np.round((q[:, 3] - yaw) / (2 * np.pi))
    out[:, 4] = np.arcsin(np.clip(-Rn[:, 2, 0], -1.0, 1.0))
    out[:, 5] = np.arctan2(Rn[:, 2, 1], Rn[:, 2, 2])
    out[:, :3] = c + np.einsum("tij,tj->ti", Rc, q[:, :3] - c)
    return out


def _exp_integrate(w: np.ndarray, dt: float) -> np.ndarray:
    """Rotations (T, 3, 3) integrating angular velocities w (T, 3) rad/s from the identity."""
    Rc = np.empty((len(w), 3, 3))
    R = np.eye(3)
    for k in range(len(w)):  # exp(ω dt) by Rodrigues
        th = float(np.linalg.norm(w[k])) * dt
        if th > 1e-12:
            u = w[k] / np.linalg.norm(w[k])
            K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
            R = (np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K) @ R
        Rc[k] = R
    return Rc


def hold_angular_momentum(ch: Character, q: np.ndarray, a: int, b: int, dt: float, rounds: int = 2) -> np.ndarray:
    """q (T, 35, sampled every ``dt`` s) with the flight frames [a, b) turned about their centre
    of mass so that the angular momentum about it is constant (step 1 of the module docstring);
    ``rounds`` passes."""
    out = q.copy()
    for _ in range(rounds):
        c, _, H, _ = body_momenta(ch, out, dt)
        Iinv = np.linalg.inv(inertia_about_com(ch, out[a:b]))
        Hf = H[a:b]
        Hbar = np.linalg.solve(Iinv.sum(axis=0), np.einsum("tij,tj->i", Iinv, Hf))
        w = np.einsum("tij,tj->ti", Iinv, Hbar - Hf)
        out[a:b] = rotate_about_com(out[a:b], c[a:b], _exp_integrate(w, dt))
    return out


def quintic(tau: np.ndarray, h: float, y0, v0, a0, y1, v1, a1) -> np.ndarray:
    """Quintic Hermite on [0, h] (tau (n,) s) matching value, slope and curvature at both ends
    (each (d,) arrays); returns (n, d)."""
    x = (np.asarray(tau, float) / h)[:, None]
    h0 = 1 - 10 * x ** 3 + 15 * x ** 4 - 6 * x ** 5
    h1 = x - 6 * x ** 3 + 8 * x ** 4 - 3 * x ** 5
    h2 = (x ** 2 - 3 * x ** 3 + 3 * x ** 4 - x ** 5) / 2
    h5 = 10 * x ** 3 - 15 * x ** 4 + 6 * x ** 5
    h4 = -4 * x ** 3 + 7 * x ** 4 - 3 * x ** 5
    h3 = (x ** 3 - 2 * x ** 4 + x ** 5) / 2
    return (h0 * y0 + h1 * h * v0 + h2 * h * h * a0 + h5 * y1 + h4 * h * v1 + h3 * h * h * a1)


def ballistic_flight(ch: Character, t: np.ndarray, q: np.ndarray, t_off: float, t_land: float,
                     push: float = 0.25, absorb: float = 0.2, rounds: int = 2) -> np.ndarray:
    """Poses ``q`` (T, 35) at uniform times ``t`` (s) with the frames in [t_off, t_land] made
    ballistic (module docstring): angular momentum about the centre of mass held constant,
    then the root shifted so that the centre of mass follows the parabola with g through its
    take-off and touch-down positions.  The ``push`` s before the take-off and the ``absorb`` s
    after the touch-down are shifted too, so that the centre of mass reaches the flight with
    its velocity and acceleration (−g): a quintic from the frame's own position, velocity and
    acceleration at the window's start to the parabola's at the take-off (and back after the
    landing).  Without them the B-spline of the motion, twice continuously differentiable,
    spread the push-off acceleration into the flight (4–6 body weights of root force at the
    flight's first and last points).  ``rounds`` passes; frames outside the windows unchanged."""
    t = np.asarray(t, float)
    dt = float(t[1] - t[0])
    inside = np.flatnonzero((t >= t_off - 1e-9) & (t <= t_land + 1e-9))
    if len(inside) < 4:
        return np.asarray(q, float).copy()
    a, b = int(inside[0]), int(inside[-1]) + 1
    out = np.asarray(q, float).copy()
    for _ in range(rounds):
        out = hold_angular_momentum(ch, out, a, b, dt, rounds=1)
        c = body_momenta(ch, out, dt)[0]
        cd = np.gradient(c, dt, axis=0)
        cdd = np.gradient(cd, dt, axis=0)
        tau = t[a:b] - t[a]
        T = tau[-1]
        v0 = (c[b - 1] - c[a]) / T
        v0[2] += G * T / 2
        gv = np.array([0.0, 0.0, -G])
        target = c.copy()
        target[a:b] = c[a] + np.outer(tau, v0) + np.outer(tau ** 2 / 2, gv)
        v1 = v0 + gv * T
        pa = max(0, a - int(round(push / dt)))
        if pa < a:
            target[pa:a + 1] = quintic(t[pa:a + 1] - t[pa], t[a] - t[pa], c[pa], cd[pa], cdd[pa], c[a], v0, gv)
        pb = min(len(t) - 1, b - 1 + int(round(absorb / dt)))
        if pb > b - 1:
            target[b - 1:pb + 1] = quintic(t[b - 1:pb + 1] - t[b - 1], t[pb] - t[b - 1], c[b - 1], v1, gv,
                                           c[pb], cd[pb], cdd[pb])
        out[:, :3] += target - c
    return out
