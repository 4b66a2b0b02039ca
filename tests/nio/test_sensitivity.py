"""dX*/dθ by the implicit-function theorem (scenegraph/nio/sensitivity.py): coordinates, the
report's arithmetic, and the derivative against finite differences of re-solves."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import N_DOF, N_JOINT
from scenegraph.model.style import THETA_LAYOUT, default_style
from scenegraph.nio import sensitivity as S
from scenegraph.nio.heldout import group_indices


def _fake_nlp(N=3):
    """Just what perturbed_params reads: p0, p_layout, s_points."""
    from types import SimpleNamespace

    from scenegraph.model.residual import N_THETA

    size = N_THETA * N + N_JOINT * N
    lay = {"theta": slice(0, N_THETA * N), "sqrt_alpha": slice(N_THETA * N, size)}
    return SimpleNamespace(p0=np.zeros(size), p_layout=lay, s_points=np.linspace(0, 1, N))


def test_perturbed_params_moves_ln_alpha_and_one_kernel_component():
    nlp, st = _fake_nlp(), default_style()
    th = st.vector()
    p0 = S.perturbed_params(nlp, th, 0, 0.0)
    p1 = S.perturbed_params(nlp, th, 3, 0.2)  # ln α_3 + 0.2
    sa0 = p0[nlp.p_layout["sqrt_alpha"]].reshape(-1, N_JOINT).T  # column-major (29, N)
    sa1 = p1[nlp.p_layout["sqrt_alpha"]].reshape(-1, N_JOINT).T
    assert np.allclose(sa1[3], sa0[3] * np.exp(0.1)) and np.allclose(np.delete(sa1, 3, 0), np.delete(sa0, 3, 0))
    assert np.array_equal(p1[nlp.p_layout["theta"]], p0[nlp.p_layout["theta"]])
    i = THETA_LAYOUT["ks1"].start + 5
    p2 = S.perturbed_params(nlp, th, i, 7.0)
    d = (p2 - p0)[nlp.p_layout["theta"]].reshape(3, -1)  # (N, N_THETA): row k = point k
    assert np.allclose(d[:, 5], 7.0) and np.count_nonzero(d) == 3


def test_theta_difference_uses_log_alpha():
    a = default_style()
    b = a.with_(alpha=a.alpha * np.r_[2.0, np.ones(N_JOINT - 1)] / (1 + a.alpha[0]), ks1=a.ks1 + 1.0)
    d = S.theta_difference(b, a)
    assert d[0] == pytest.approx(np.log(2.0 / (1 + a.alpha[0])))
    assert np.allclose(d[THETA_LAYOUT["ks1"]], 1.0)


def test_group_report_sums_components_in_quadrature():
    th = default_style().vector()
    T = 10
    dq = np.zeros((T, N_DOF, len(th)))
    j = group_indices("arms")[0]
    dq[:, j, THETA_LAYOUT["ks1"].start] = 0.01  # rad per unit ks1_0
    dq[:, j, THETA_LAYOUT["ks1"].start + 1] = 0.02
    sens = S.Sensitivity(np.zeros((1, len(th))), dq, np.linspace(0, 1, T), 0, 0, 0.0, 0.0, None)
    rep = S.group_sensitivity(sens, th)
    tc = S.typical_change(th)
    n_arms = len(group_indices("arms"))
    one = lambda v: np.degrees(np.sqrt(v ** 2 / n_arms))  # noqa: E731
    want = np.hypot(one(0.01 * tc[THETA_LAYOUT["ks1"].start]), one(0.02 * tc[THETA_LAYOUT["ks1"].start + 1]))
    assert rep["ks1"]["arms"] == pytest.approx(want)
    assert rep["ks1"]["legs"] == 0.0 and rep["alpha"]["arms"] == 0.0
    lin = S.linear_response_deg(sens, np.eye(len(th))[THETA_LAYOUT["ks1"].start] * 2.0)
    assert lin["arms"] == pytest.approx(np.degrees(np.sqrt((0.02) ** 2 / n_arms)))


@pytest.fixture(scope="module")
def tiny():
    """A 1.3 s three-step walk (default style) transcribed with the exact Hessian, free q."""
    from scenegraph.model.body import make_character
    from scenegraph.model.footsteps import footsteps_for_walk
    from scenegraph.model.gait import initial_motion
    from scenegraph.problem import Subproblem, transcribe
    from scenegraph.problem.result import read_solution

    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3)
    st = default_style(ch.total_mass)
    m0 = initial_motion(ch, fs, 0.0, 1.3)
    nlp = transcribe(Subproblem(ch, st, m0, fs, free=frozenset({"q"}), hessian="exact"))
    x = nlp.x0.copy()
    pt = S.KKTPoint(x, nlp.p0, np.zeros(nlp.lbg.size), np.zeros(x.size), "x0", 0,
                    read_solution(nlp, x, nlp.p0)[0], 0.0)
    return nlp, pt, st.vector()


def _pieces(tiny, col):
    import casadi as ca
    import scipy.sparse as sps
    import scipy.sparse.linalg as spla

    nlp, pt, th = tiny
    sens = S.kkt_sensitivity(nlp, pt, th, np.linspace(0.0, 1.3, 20), columns=[col])
    grad = ca.Function("g", [nlp.x, nlp.p], [ca.gradient(nlp.f, nlp.x)])
    _, Jg = nlp.jac_g(pt.x, pt.p)
    Jg = sps.csr_matrix(Jg.sparse())
    fx, rows = sens.fixed_x, sens.active_rows
    pin = sps.csr_matrix((np.ones(fx.size), (np.arange(fx.size), fx)), shape=(fx.size, pt.x.size))
    A = sps.vstack([Jg[rows], pin]).tocsc()
    g0 = np.asarray(grad(pt.x, pt.p)).ravel()
    mu = spla.lsqr(A.T, -g0, atol=1e-14, btol=1e-14, iter_lim=50000)[0][:rows.size]
    lam_g = np.zeros(nlp.lbg.size)
    lam_g[rows] = mu

    def grad_lagrangian(x, p):  # ∇f + J_activeᵀ μ with the least-squares μ held (bound rows: constant J)
        _, J = nlp.jac_g(x, p)
        return np.asarray(grad(x, p)).ravel() + sps.csr_matrix(J.sparse())[rows].T @ mu

    Hu = sps.csc_matrix(nlp.hess_lag(pt.x, pt.p, 1.0, lam_g).sparse())
    H = Hu + Hu.T - sps.diags(Hu.diagonal())
    return sens, A, H, grad_lagrangian


def test_sensitivity_solves_the_linearised_kkt_system(tiny):
    """dx/dθ_i keeps the active constraints (A dx = 0) and H dx + ∂(∇L)/∂θ_i lies in the span of
    their normals (H: the NLP's Lagrangian Hessian; the θ derivative recomputed here with another
    step), at a point that need not be optimal (the initial motion)."""
    import scipy.sparse.linalg as spla

    nlp, pt, th = tiny
    from scenegraph.model.body import JOINT_DOF_NAMES

    for col in (THETA_LAYOUT["ks1"].start + 10, THETA_LAYOUT["alpha"].start + JOINT_DOF_NAMES.index("knee_flex_l")):
        sens, A, H, gl = _pieces(tiny, col)
        assert sens.kkt_residual < 1e-6
        dx = sens.dx[:, col]
        assert np.abs(dx).max() > 0 and np.abs(sens.dq[:, 6:, col]).max() > 0
        assert np.linalg.norm(A @ dx) <= 1e-5 * max(1.0, np.linalg.norm(dx))  # A is rank-deficient (redundant
        # footstep pins): a least-squares solve; 1.4e-6 on the dense-dynamics transcription
        h = 1e-3 * S.typical_change(th)[col]
        B = (gl(pt.x, S.perturbed_params(nlp, th, col, h)) - gl(pt.x, S.perturbed_params(nlp, th, col, -h))) / (2 * h)
        r = H @ dx + B
        off = np.linalg.norm(r - A.T @ spla.lsqr(A.T, r, atol=1e-14, btol=1e-14, iter_lim=50000)[0])
        assert off <= 1e-4 * np.linalg.norm(H @ dx), (col, off, np.linalg.norm(H @ dx))


@pytest.mark.xfail(strict=True, reason="measured 2026-12-02: along dx/dθ at the initial motion of this walk the "
                   "transcription's exact Lagrangian Hessian differs from finite differences of the AD gradient "
                   "by 21-29 % (random directions at a converged point: 3e-8), so the IFT derivative is off by "
                   "as much; not diagnosed (transcription.py belongs to issue #15)")
def test_exact_hessian_along_the_sensitivity_direction(tiny):
    nlp, pt, th = tiny
    col = THETA_LAYOUT["ks1"].start + 10
    sens, A, H, gl = _pieces(tiny, col)
    dx = sens.dx[:, col]
    eps = 1e-6 / np.abs(dx).max()
    fd = (gl(pt.x + eps * dx, pt.p) - gl(pt.x - eps * dx, pt.p)) / (2 * eps)
    assert np.linalg.norm(H @ dx - fd) <= 0.02 * np.linalg.norm(fd)
