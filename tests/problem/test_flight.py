"""Ballistic flight as momentum equalities (scenegraph/problem/flight.py, issue 20).

The momenta the NLP constrains (CasADi, from the symbolic forward kinematics and its time
derivative) are checked against an independent computation: the numeric forward kinematics
of sampled poses and central differences (``scenegraph.mocap.momentum_edit.body_momenta``).  The
equalities vanish on a motion that is ballistic by construction and not on one that is not.
No IPOPT (fast).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from scenegraph.mocap.momentum_edit import body_momenta
from scenegraph.model.body import G, N_DOF, default_character, make_character, standing_pose
from scenegraph.problem.flight import flight_constraints, momenta_fn


def _motion(ch, t):
    """A smooth whole-body motion: every joint and the root swing (rad, m) at its own rate."""
    rng = np.random.default_rng(3)
    amp, w, ph = rng.uniform(0.05, 0.3, N_DOF), rng.uniform(2.0, 6.0, N_DOF), rng.uniform(0, 6, N_DOF)
    q = standing_pose(ch)[None, :] + amp * np.sin(np.outer(t, w) + ph)
    qd = amp * w * np.cos(np.outer(t, w) + ph)
    return q, qd


def test_momenta_agree_with_finite_differences_of_the_numeric_kinematics():
    ch = default_character()
    dt = 1e-4
    t = np.arange(0.0, 0.3, dt)
    q, qd = _motion(ch, t)
    c_n, P_n, H_n, _ = body_momenta(ch, q, 1.0 / dt)
    fn = momenta_fn(ch)
    for k in (100, 1500, 2800):
        c, P, H = (np.asarray(v).ravel() for v in fn(q[k], qd[k]))
        assert np.allclose(c, c_n[k], atol=1e-9)
        assert np.allclose(P, P_n[k], rtol=1e-5, atol=1e-4), (P, P_n[k])
        assert np.allclose(H, H_n[k], rtol=1e-4, atol=1e-3), (H, H_n[k])
        assert np.linalg.norm(H) > 1.0  # a real test: the swinging body has angular momentum


def test_the_equalities_vanish_on_a_ballistic_motion_only():
    ch = default_character()
    t = np.linspace(0.0, 0.4, 13)
    q = np.tile(standing_pose(ch), (len(t), 1))
    v0 = np.array([2.0, 0.5, 2.0])
    q[:, :3] += np.outer(t, v0) - np.outer(t ** 2 / 2, [0.0, 0.0, G])  # a rigid pose thrown: a parabola
    qd = np.zeros_like(q)
    qd[:, :3] = v0 - np.outer(t, [0.0, 0.0, G])
    groups = [np.arange(len(t))]
    g = flight_constraints(ch, groups, ca.DM(q.T), ca.DM(qd.T), ca.DM(t[None, :]))
    g = np.asarray(ca.evalf(g)).ravel()
    assert g.shape == (6 * (len(t) - 1),) and np.abs(g).max() < 1e-9
    qd[:, 2] = v0[2]  # the same speed without gravity: the linear momentum rows are violated by M g t
    g = np.asarray(ca.evalf(flight_constraints(ch, groups, ca.DM(q.T), ca.DM(qd.T), ca.DM(t[None, :])))).ravel()
    assert abs(np.abs(g).max() - ch.total_mass * G * t[-1]) < 1e-6


def _rows(ch, q, qd, t):
    g = flight_constraints(ch, [np.arange(len(t))], ca.DM(q.T), ca.DM(qd.T), ca.DM(t[None, :]))
    g = np.asarray(ca.evalf(g)).ravel()
    n = len(t) - 1
    return np.c_[g[:3 * n].reshape(n, 3), g[3 * n:].reshape(n, 3)]  # per point: 3 linear, 3 angular rows


def test_rows_for_a_heavy_and_a_light_character():
    """The rows are momentum changes (kg·m/s, kg·m²/s): for a 70 kg adult and a 30 kg child the
    linear rows are M × the centre of mass's velocity change plus g t (an independent
    finite-difference measure); the same motion of the same body at another mass gives linear
    rows in proportion to the mass; a ballistic throw satisfies them at either mass."""
    t = np.linspace(0.0, 0.4, 9)
    rows = {}
    for preset, mass in (("adult_male", 70.0), ("child", 30.0), ("adult_male", 30.0)):
        ch = make_character(preset, mass=mass)
        assert abs(ch.total_mass - mass) < 1e-6
        q, qd = _motion(ch, t)  # not ballistic: every joint swings, the root does not fall
        r = _rows(ch, q, qd, t)
        c_n, P_n, H_n, _ = body_momenta(ch, *_motion(ch, np.arange(0.0, 0.4 + 1e-9, 1e-4))[:1], 1e4)
        k = np.round(t / 1e-4).astype(int)
        v = P_n[k] / mass
        expect = mass * (v[1:] - v[0] + np.outer(t[1:] - t[0], [0.0, 0.0, G]))
        assert np.allclose(r[:, :3], expect, atol=2e-3 * mass), (r[:, :3], expect)
        assert np.abs(r[:, 3:]).max() > 1e-3 * mass  # the swinging body's angular momentum changes
        rows[preset, mass] = r
    a, b = rows["adult_male", 70.0], rows["adult_male", 30.0]
    assert np.allclose(a[:, :3] / 70.0, b[:, :3] / 30.0, atol=1e-9)
    for preset, mass in (("adult_male", 70.0), ("child", 30.0)):
        ch = make_character(preset, mass=mass)
        q = np.tile(standing_pose(ch), (len(t), 1))
        v0 = np.array([1.5, 0.0, 2.5])
        q[:, :3] += np.outer(t, v0) - np.outer(t ** 2 / 2, [0.0, 0.0, G])
        qd = np.zeros_like(q)
        qd[:, :3] = v0 - np.outer(t, [0.0, 0.0, G])
        assert np.abs(_rows(ch, q, qd, t)).max() < 1e-9


def _random_flight_map(seed: int, nx: int, n: int = 7):
    """A random B-spline-like linear map from x (nx) to n poses and velocities around standing,
    a time map moving with x (a free warp), and two overlapping flight groups."""
    ch = default_character()
    rng = np.random.default_rng(seed)
    x = ca.MX.sym("x", nx)
    A, B = rng.standard_normal((N_DOF * n, nx)) * 0.05, rng.standard_normal((N_DOF * n, nx)) * 0.3
    Q = ca.reshape(ca.DM(np.tile(standing_pose(ch), n)) + ca.mtimes(ca.DM(A), x), N_DOF, n)
    Qd = ca.reshape(ca.mtimes(ca.DM(B), x), N_DOF, n)
    T = ca.reshape(ca.DM(np.linspace(0.0, 0.3, n)) + 0.01 * ca.mtimes(ca.DM(rng.standard_normal((n, nx))), x), 1, n)
    return ch, rng, x, Q, Qd, T, [np.arange(0, 4), np.arange(3, 7)]


def test_the_chain_rule_jacobian_equals_casadis_ad_jacobian_with_a_free_warp():
    """flight_jacobian (per-point momenta Jacobian × ∂(q, q̇)/∂x, plus the gravity term's time
    derivative) against CasADi's AD Jacobian of the same rows, on a random B-spline-like linear
    map from x to poses and velocities and a free time map (the warp)."""
    from scenegraph.problem.flight import flight_jacobian
    nx = 40
    ch, rng, x, Q, Qd, T, groups = _random_flight_map(seed=5, nx=nx)
    rows = flight_constraints(ch, groups, Q, Qd, T)
    f = ca.Function("f", [x], [flight_jacobian(ch, groups, Q, Qd, T, x), ca.jacobian(rows, x)])
    J, J_ad = (np.array(ca.densify(v)) for v in f(rng.standard_normal(nx)))
    np.testing.assert_allclose(J, J_ad, rtol=0, atol=1e-9 * np.abs(J_ad).max())
    assert np.abs(J_ad).max() > 1.0


def test_the_rows_curvature_equals_casadis_ad_hessian():
    """flight_hessian (per-point momenta curvature, weighted by the rows' multipliers) against
    CasADi's AD Hessian of λ · rows, (q, q̇) linear in x and the times moving with x."""
    from scenegraph.problem.flight import flight_hessian
    nx = 30
    ch, rng, x, Q, Qd, T, groups = _random_flight_map(seed=7, nx=nx)
    rows = flight_constraints(ch, groups, Q, Qd, T)
    lam = ca.MX.sym("lam", rows.shape[0])
    f = ca.Function("f", [x, lam], [flight_hessian(ch, groups, Q, Qd, lam, x), ca.hessian(ca.dot(lam, rows), x)[0]])
    H, H_ad = (np.array(ca.densify(v)) for v in f(rng.standard_normal(nx), rng.standard_normal(rows.shape[0])))
    assert np.abs(H_ad).max() > 1.0
    np.testing.assert_allclose(H, H_ad, rtol=0, atol=1e-9 * np.abs(H_ad).max())
