"""Hard root rows (Subproblem.root_tolerance): the six root residuals at every evaluation point
outside flights as constraints, kept MX beside the SX-expanded rows (scenegraph/problem/transcription.py)."""
from dataclasses import replace

import casadi as ca
import numpy as np

from scenegraph.model.body import G, N_DOF, make_character, standing_pose
from scenegraph.model.footsteps import Footstep
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.motion import Motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe

CH = make_character()
STYLE = default_style(CH.total_mass)


def _standing() -> Subproblem:
    q0 = np.asarray(standing_pose(CH), float)
    s = np.linspace(0, 1, 10)
    ctrl = np.array([q0 + 0.02 * np.sin(3 * v) * np.r_[np.zeros(6), np.ones(N_DOF - 6)] for v in s])
    m = Motion(ctrl, Motion.uniform_warp(0.0, 0.5, 6))
    P = np.asarray(handle_positions_fn(CH, ("ball_l", "ball_r"))(q0))
    steps = (Footstep("l", (P[0, 0], P[1, 0]), 0.0, 0.5, 0.0, heel=(0.0, 0.5), ball=(0.0, 0.5)),
             Footstep("r", (P[0, 1], P[1, 1]), 0.0, 0.5, 0.0, heel=(0.0, 0.5), ball=(0.0, 0.5)))
    return Subproblem(CH, STYLE, m, steps, free=frozenset({"q"}), collocation_hz=20.0, constraint_hz=20.0)


def test_root_rows_are_the_root_residual_with_its_jacobian():
    sp = _standing()
    base = transcribe(sp)
    nlp = transcribe(replace(sp, root_tolerance=(0.002, 0.1)))
    grp = {n: (sl, kind) for n, sl, kind in nlp.groups}
    assert "root_residual" not in {n for n, _, _ in base.groups}
    sl, kind = grp["root_residual"]
    assert kind == "ineq" and sl.stop - sl.start == 6 * len(nlp.s_eval)  # no flight: every point
    np.testing.assert_allclose(nlp.lbg[sl], -np.tile([0.002] * 3 + [0.1] * 3, len(nlp.s_eval)))
    # the rows: the residual kernel's root entries (force in body weights, moment in N m), as the
    # objective sees them: rho_dyn's root rows are (√w_root · quadrature weight · scale) times the same
    rows = np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()[sl].reshape(-1, 6)
    assert np.abs(rows).max() > 1e-3  # the start is not in equilibrium
    rho = np.asarray(nlp.rho_dyn_fn(nlp.x0, nlp.p0)).reshape(-1, N_DOF)[:, -6:]  # per point, root last
    ratio = rho / np.where(np.abs(rows) > 1e-9, rows, np.nan)
    mg = CH.total_mass * G
    for k in range(len(rows)):  # one factor (√w_root · quadrature · scale) per point, the moment's / m g
        r = ratio[k]
        np.testing.assert_allclose(np.r_[r[:3], r[3:] * mg][~np.isnan(np.r_[r[:3], r[3:]])],
                                   np.nanmean(r[:3]), rtol=1e-6)
    # the Jacobian handed to IPOPT (MX rows put back in g's order) equals CasADi's AD of g
    g_j, J = nlp.jac_g(nlp.x0, nlp.p0)
    np.testing.assert_allclose(np.asarray(g_j).ravel(), np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel(), atol=1e-12)
    J_ad = ca.Function("J", [nlp.x, nlp.p], [ca.jacobian(nlp.g, nlp.x)])(nlp.x0, nlp.p0)
    np.testing.assert_allclose(np.asarray(ca.DM(J)), np.asarray(ca.DM(J_ad)), atol=1e-9, rtol=1e-7)
    eq = transcribe(replace(sp, root_tolerance=(0.0, 0.0)), derivatives=False)
    assert {n: k for n, _, k in eq.groups}["root_residual"] == "eq"


def test_root_rows_only_with_full_dynamics():
    sp = replace(_standing(), root_tolerance=(0.0, 0.0))
    for dyn in ("relaxed", "kinematic"):
        assert "root_residual" not in {n for n, _, _ in transcribe(replace(sp, dynamics=dyn), derivatives=False).groups}


def test_cop_bound_rows_hold_the_moment_within_d_times_the_vertical_force():
    sp = _standing()
    nlp = transcribe(replace(sp, cop_bound=(0.005, 0.1)))
    sl = {n: sl for n, sl, _ in nlp.groups}["root_moment"]
    rows = np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()[sl].reshape(-1, 2, 3)  # per point: slack − M, slack + M
    slack, M = (rows[:, 0] + rows[:, 1]) / 2, (rows[:, 1] - rows[:, 0]) / 2
    assert np.allclose(slack, slack[:, :1]) and slack.min() >= 0.1 - 1e-9  # F_z ≥ 0 (λ ≥ 0, friction pyramid)
    assert np.abs(M).max() > 0.1
    g_j, J = nlp.jac_g(nlp.x0, nlp.p0)
    J_ad = ca.Function("J", [nlp.x, nlp.p], [ca.jacobian(nlp.g, nlp.x)])(nlp.x0, nlp.p0)
    np.testing.assert_allclose(np.asarray(ca.DM(J)), np.asarray(ca.DM(J_ad)), atol=1e-9, rtol=1e-7)


def test_cop_bound_between_points_matches_the_independent_dense_residual():
    """With ``cop_hz`` the bound also holds at 240 Hz points within 30 ms of each contact end (here
    the left heel's lift-off and the other handles'); those rows equal d·F_z + m0 ∓ M with F_z and M computed
    independently (scenegraph.model.dense_audit: node forces interpolated in s, the gated shoe, the
    residual kernel) from the start's motion and contact forces."""
    from scenegraph.model.dense_audit import force_at, kernel_theta, shoe_forces
    from scenegraph.model.residual import FORCE_HANDLES, residual_kernel
    sp = _standing()
    l, r = sp.footsteps
    sp = replace(sp, footsteps=(replace(l, heel=(0.0, 0.25)), r), cop_bound=(0.005, 0.1), cop_hz=240.0)
    nlp = transcribe(sp, derivatives=False)
    base = transcribe(replace(sp, cop_hz=0.0), derivatives=False)
    sl, sl0 = ({n: g for n, g, _ in b.groups}["root_moment"] for b in (nlp, base))
    n_x = ((sl.stop - sl.start) - (sl0.stop - sl0.start)) // 6
    t = np.arange(0.0, 0.5, 1 / 240)[1:]
    from scenegraph.model.footsteps import contact_points
    ends = np.array([e for st in sp.footsteps for _, iv, _ in contact_points(CH, st) for e in iv if 0 < e < 0.5])
    assert len(ends)
    t = t[np.min(np.abs(t[:, None] - ends[None, :]), axis=1) <= 0.03]
    s_ev = np.r_[nlp.s_points, 0.5 * (nlp.s_points[:-1] + nlp.s_points[1:])]
    t = t[np.min(np.abs(sp.motion.to_canonical(t)[:, None] - s_ev[None, :]), axis=1) > 1e-6]
    assert n_x == len(t) > 0
    g = np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()[sl][-6 * n_x:].reshape(n_x, 2, 3)
    # the start's contact forces as the solver's samples: per planted (handle, node)
    forces: dict = {}
    tn = sp.motion.time(nlp.s_points)
    for (h, k, xs), V in zip(nlp.contact_index, nlp.contact_basis):
        f = CH.total_mass * G * V @ nlp.x0[xs]
        forces.setdefault(h, ([], []))
        forces[h][0].append(tn[k])
        forces[h][1].append(f)
    m = sp.motion
    q, qd, qdd = m.state_at_s(m.to_canonical(t))
    F = force_at(CH, m, sp.footsteps, forces, t) + shoe_forces(CH, STYLE, m, sp.footsteps, q, t)
    th = np.tile(kernel_theta(STYLE, True)[:, None], (1, len(t)))
    M = np.asarray(residual_kernel(CH).map(len(t))(q.T, qd.T, qdd.T, F, th))[-3:].T
    fz = F.reshape(len(FORCE_HANDLES), 3, len(t))[:, 2, :].sum(0)
    slack = 0.005 * fz + 0.1
    np.testing.assert_allclose(g[:, 0], slack[:, None] - M, atol=1e-6 * max(1.0, np.abs(M).max()))
    np.testing.assert_allclose(g[:, 1], slack[:, None] + M, atol=1e-6 * max(1.0, np.abs(M).max()))
