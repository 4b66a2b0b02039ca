"""dX*/dθ at a converged synthesis by the implicit-function theorem (issue #18, item 2).

Which style parameters can move a synthesised motion at all?  At a local minimum x* of the
spacetime NLP  min f(x; θ) s.t. g(x) ∈ [lbg, ubg], x ∈ [lbx, ubx]  (θ enters the objective
only: the constraints are kinematic) with the active constraints and bounds A(x) = const,
KKT stationarity ∇f + Jᵀμ = 0 holds; differentiating it in θ with the active set fixed,

    [ H   Aᵀ ] [ dx/dθ ]     [ ∂(∇_x f)/∂θ ]
    [ A   0  ] [ dμ/dθ ] = − [      0      ]

with H the Hessian of the Lagrangian from the transcription's ``hessian="exact"`` mode (the
compiled kernel Hessian; along dx/dθ at a walk's initial motion it was measured 21–29 % off
finite differences of the gradient — the strict xfail in tests/nio/test_sensitivity.py), A the
Jacobian of the active constraints (by the primal point, :func:`_active`) plus one row per
active bound, and least-squares multipliers.  ∂(∇_x f)/∂θ is taken by central differences of
the AD gradient (the compiled kernel has first derivatives only).  At a point that is not a KKT
point (what IPOPT returns here, see docs/results.md) the same system gives the derivative of
the stationary point of the local model; ``Sensitivity.stationarity`` says how far off it is.

Coordinates of θ (:data:`COORDS`): α by ln α_j (one e-fold of one muscle weight; the √α
parameter of the NLP is exp(u/2)), every other component in its own unit (``THETA_LAYOUT``:
N·m/rad, N·m·s/rad, rad, N/m, m).  :func:`group_sensitivity` scales each column by a *typical
change* (:func:`typical_change`) and reports, per θ field and joint group
(``heldout.JOINT_GROUPS``), the RMS (deg) of the joint-angle change that moving each
component of the field by its typical change produces, summed in quadrature over the field.

Units: joint angles rad inside, deg in reports; time in s (world).  Nothing here writes files.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scenegraph.model.body import N_DOF, N_JOINT
from scenegraph.model.motion import Motion, basis
from scenegraph.model.style import THETA_LAYOUT, Style
from scenegraph.problem import NLP, Built, Subproblem, build
from scenegraph.problem.result import read_solution, violations
from scenegraph.nio.counterexamples import WARM_START, nlp_params
from scenegraph.nio.heldout import JOINT_GROUPS, group_indices
from scenegraph.nio.theta import ALPHA, N_THETA_FULL

__all__ = ["KKTPoint", "solve_kkt", "perturbed_params", "theta_difference", "kkt_sensitivity", "Sensitivity", "typical_change", "group_sensitivity",
           "THETA_FIELDS", "linear_response_deg", "sensitivity_report"]

THETA_FIELDS = ("alpha", "ks1", "ks2", "kd", "q_rest", "k_shoe", "h_rest")
COORDS = "α: d/d ln α_j; ks1 N·m/rad, ks2, kd N·m·s/rad, q_rest rad, k_shoe N/m, h_rest m"


@dataclass(frozen=True)
class KKTPoint:
    """A solve's primal-dual point: x, parameters p, multipliers of g and of the bounds of x
    (CasADi's sign convention: ∇f + Jᵀ lam_g + lam_x = 0), IPOPT's status and iterations."""

    x: np.ndarray
    p: np.ndarray
    lam_g: np.ndarray
    lam_x: np.ndarray
    status: str
    iterations: int
    motion: Motion
    violation: float  # worst constraint violation (m)


def solve_kkt(sp: Subproblem, built: Built | None = None, *, x0: np.ndarray | None = None,
              p: np.ndarray | None = None, warm: bool = False, lam_g0: np.ndarray | None = None,
              lam_x0: np.ndarray | None = None) -> tuple[KKTPoint, Built]:
    """Solve ``sp`` with IPOPT keeping the multipliers (``problem.solve`` drops them).  ``warm``:
    IPOPT's warm-start options (:data:`.counterexamples.WARM_START`), e.g. to re-solve a
    perturbed θ from a converged point with its multipliers ``lam_g0``/``lam_x0``."""
    if warm:
        sp = replace(sp, ipopt_options=tuple(sp.ipopt_options) + WARM_START)
    b = built if built is not None else build(sp)
    nlp = b.nlp
    x0 = nlp.x0 if x0 is None else np.asarray(x0, float)
    p = nlp.p0 if p is None else np.asarray(p, float)
    kw = {}
    if lam_g0 is not None:
        kw["lam_g0"] = lam_g0
    if lam_x0 is not None:
        kw["lam_x0"] = lam_x0
    sol = b.solver(x0=x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg, p=p, **kw)
    st = b.solver.stats()
    x = np.asarray(sol["x"], float).ravel()
    motion = read_solution(nlp, x, p)[0]
    viol = max(violations(nlp, x, p).values(), default=0.0)
    return KKTPoint(x, p, np.asarray(sol["lam_g"], float).ravel(), np.asarray(sol["lam_x"], float).ravel(),
                    str(st.get("return_status", "unknown")), int(st.get("iter_count", -1)), motion, viol), b


def _theta_params(nlp: NLP, theta: np.ndarray, alpha_log_shift: np.ndarray | None = None) -> np.ndarray:
    """NLP parameters with style θ; ``alpha_log_shift`` (29,): α_j → α_j exp(u_j) (unnormalised,
    the objective's own scale)."""
    p = nlp_params(nlp, theta)
    if alpha_log_shift is not None:
        N = len(nlp.s_points)
        sa = np.sqrt(np.maximum(theta[ALPHA], 0.0)) * np.exp(0.5 * np.asarray(alpha_log_shift, float))
        p[nlp.p_layout["sqrt_alpha"]] = np.tile(sa[:, None], (1, N)).ravel(order="F")
    return p


def perturbed_params(nlp: NLP, theta: np.ndarray, i: int, h: float) -> np.ndarray:
    """Parameters with θ coordinate ``i`` (:data:`COORDS`: ln α for α) moved by ``h``."""
    theta = np.asarray(theta, float)
    if ALPHA.start <= i < ALPHA.stop:
        u = np.zeros(N_JOINT)
        u[i - ALPHA.start] = h
        return _theta_params(nlp, theta, u)
    th = theta.copy()
    th[i] += h
    return _theta_params(nlp, th)


def _steps(theta: np.ndarray) -> np.ndarray:
    """Difference steps per θ coordinate for ∂(∇f)/∂θ (ln α: 1e-4; others 1e-4 of their typical change)."""
    return 1e-4 * typical_change(theta)


def typical_change(theta: np.ndarray) -> np.ndarray:
    """A typical change of each θ coordinate (:data:`COORDS`): ln α 1 (an e-fold); ks1, ks2 the
    larger of the component and 10 N·m/rad, kd the larger of it and 1 N·m·s/rad; q_rest 0.1 rad;
    k_shoe the larger of it and 1e4 N/m; h_rest 5 mm.  (Springs by their own size: a spring of 0
    is moved by the floor.)"""
    th = np.asarray(theta, float)
    out = np.ones(N_THETA_FULL)
    for f, floor in (("ks1", 10.0), ("ks2", 10.0), ("kd", 1.0)):
        sl = THETA_LAYOUT[f]
        out[sl] = np.maximum(np.abs(th[sl]), floor)
    out[THETA_LAYOUT["q_rest"]] = 0.1
    out[THETA_LAYOUT["k_shoe"]] = max(abs(float(th[THETA_LAYOUT["k_shoe"]][0])), 1e4)
    out[THETA_LAYOUT["h_rest"]] = 0.005
    return out


@dataclass(frozen=True)
class Sensitivity:
    """dx*/dθ at a KKT point: ``dx`` (n_x, 147) in :data:`COORDS`, ``dq`` (T, 35, 147) the joint
    angles (rad) at ``times`` (s) per unit θ coordinate, and what the linear algebra showed."""

    dx: np.ndarray
    dq: np.ndarray
    times: np.ndarray
    n_active_g: int
    n_active_x: int
    kkt_residual: float  # relative residual of the KKT solve
    stationarity: float  # |∇f + Jᵀλ_g + λ_x|_∞ at the point (how converged it is)
    reduced_hessian: dict | None  # eigenvalues of Zᵀ H Z (flatness), when asked for
    active_rows: np.ndarray | None = None  # indices into g of the active constraints
    fixed_x: np.ndarray | None = None  # indices into x of the active bounds


def _active(nlp: NLP, x: np.ndarray, gv: np.ndarray, act_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Active constraint rows and bounds, by the primal point: equalities always; an inequality
    or a bound when it lies within ``act_tol`` (its own unit: m, rad, contact coefficient) of a
    finite limit.  (IPOPT's multipliers do not tell: the footstep pins over-determine a planted
    foot's spline, the constraint Jacobian is rank-deficient and IPOPT's footstep multipliers
    grow to ~1e14, measured.)"""
    eq = nlp.lbg == nlp.ubg
    near = (np.abs(gv - nlp.lbg) <= act_tol) | (np.abs(gv - nlp.ubg) <= act_tol)
    fixed = (nlp.lbx == nlp.ubx) | (np.abs(x - nlp.lbx) <= act_tol) | (np.abs(x - nlp.ubx) <= act_tol)
    return np.flatnonzero(eq | near), np.flatnonzero(fixed)


def kkt_sensitivity(nlp: NLP, pt: KKTPoint, theta: np.ndarray, times: np.ndarray, *, act_tol: float = 1e-4,
                    columns=None, reduced_hessian: bool = False) -> Sensitivity:
    """dx*/dθ and the joint angles' dq/dθ at ``times`` (world s) by the implicit-function theorem at
    the point ``pt.x`` of ``nlp`` (see the module docstring).  ``nlp`` must carry the exact
    Hessian (``Subproblem(hessian="exact")``) for the answer to be the true derivative; its free
    variables must be the control points (and λ) only: the warp is held.  ``columns``: θ
    coordinates to compute (default all 147).

    The multipliers are not IPOPT's (degenerate, see :func:`_active`) but the least-squares ones
    of the active set, min |∇f + Aᵀμ|; ``stationarity`` is that residual (the reduced gradient,
    independent of the degeneracy), which says how far ``pt.x`` is from a KKT point."""
    import casadi as ca
    import scipy.sparse as sps
    import scipy.sparse.linalg as spla

    if nlp.hess_lag is None:
        raise ValueError("kkt_sensitivity needs an NLP transcribed with derivatives")
    theta = np.asarray(theta, float)
    cols = np.arange(N_THETA_FULL) if columns is None else np.asarray(columns, int)
    x, n = pt.x, pt.x.size
    grad = ca.Function("grad_f", [nlp.x, nlp.p], [ca.gradient(nlp.f, nlp.x)])
    gv, Jg = nlp.jac_g(x, pt.p)
    gv = np.asarray(gv, float).ravel()
    Jg = sps.csr_matrix(Jg.sparse())
    gf = np.asarray(grad(x, pt.p), float).ravel()
    rows_g, fixed = _active(nlp, x, gv, act_tol)
    pin = sps.csr_matrix((np.ones(fixed.size), (np.arange(fixed.size), fixed)), shape=(fixed.size, n))
    A = sps.vstack([Jg[rows_g], pin]).tocsc()
    m = A.shape[0]
    mu = spla.lsqr(A.T, -gf, atol=1e-14, btol=1e-14, iter_lim=20 * (n + m))[0]
    stat = float(np.abs(gf + A.T @ mu).max(initial=0.0))
    lam_g = np.zeros(nlp.lbg.size)
    lam_g[rows_g] = mu[:rows_g.size]
    Hu = sps.csc_matrix(nlp.hess_lag(x, pt.p, 1.0, lam_g).sparse())
    H = (Hu + Hu.T - sps.diags(Hu.diagonal())).tocsc()
    # ∂(∇f)/∂θ by central differences of the AD gradient
    h = _steps(theta)
    B = np.zeros((n, len(cols)))
    for c, i in enumerate(cols):
        gp = np.asarray(grad(x, perturbed_params(nlp, theta, int(i), h[i])), float).ravel()
        gm = np.asarray(grad(x, perturbed_params(nlp, theta, int(i), -h[i])), float).ravel()
        B[:, c] = (gp - gm) / (2 * h[i])
    scale = max(1.0, float(np.abs(H.diagonal()).max(initial=0.0)))
    K = sps.bmat([[H + 1e-12 * scale * sps.identity(n), A.T], [A, -1e-10 * sps.identity(m)]], format="csc")
    rhs = np.vstack([-B, np.zeros((m, len(cols)))])
    sol = spla.splu(K).solve(rhs)
    res = float(np.linalg.norm(K @ sol - rhs) / max(np.linalg.norm(rhs), 1e-300))
    dx = np.zeros((n, N_THETA_FULL))
    dx[:, cols] = sol[:n]
    # joint angles: q(s) = B(s) P with P (K, 35) linear in x (the warp is held)
    motion = pt.motion
    s = motion.to_canonical(np.asarray(times, float))
    Bs = basis(motion.n_ctrl, s)
    P0 = np.asarray(nlp.ctrl_fn(x, pt.p), float)
    dq = np.zeros((len(s), N_DOF, N_THETA_FULL))
    for i in cols:
        dP = np.asarray(nlp.ctrl_fn(x + dx[:, i], pt.p), float) - P0
        dq[:, :, i] = Bs @ dP
    rh = _reduced_hessian(H, A) if reduced_hessian else None
    return Sensitivity(dx, dq, np.asarray(times, float), int(rows_g.size), int(fixed.size), res, stat, rh, rows_g, fixed)


def _reduced_hessian(H, A) -> dict:
    """Eigenvalues of Zᵀ H Z, Z an orthonormal basis of the null space of the active constraints A
    (dense; for problems of a few thousand variables): the curvature of the energy along the
    constraint surface.  Reports the smallest, the number of negative ones and the 1st/50th/99th
    percentiles (objective units per unit x², x in rad / m / λ)."""
    Ad = A.toarray()
    _, sv, Vt = np.linalg.svd(Ad, full_matrices=True)
    rank = int(np.sum(sv > 1e-9 * max(sv.max(initial=0.0), 1e-300)))
    Z = Vt[rank:].T
    Hd = H.toarray()
    ev = np.linalg.eigvalsh(Z.T @ Hd @ Z)
    return {"dimension": int(Z.shape[1]), "min": float(ev[0]), "max": float(ev[-1]),
            "negative": int(np.sum(ev < 0)), "p01": float(np.percentile(ev, 1)),
            "p50": float(np.percentile(ev, 50)), "p99": float(np.percentile(ev, 99))}


def _rms_deg(dq: np.ndarray, group: str) -> float:
    """RMS (deg) over frames and a group's DOFs of joint-angle changes dq (T, 35)."""
    return float(np.degrees(np.sqrt(np.mean(dq[:, group_indices(group)] ** 2))))


def group_sensitivity(sens: Sensitivity, theta: np.ndarray) -> dict[str, dict[str, float]]:
    """Per θ field (:data:`THETA_FIELDS`) and joint group: the RMS (deg) of the joint-angle change
    when each component of the field moves by its :func:`typical_change`, summed in quadrature
    over the field's components (the expected response to independent typical changes)."""
    tc = typical_change(theta)
    out = {}
    for f in THETA_FIELDS:
        sl = THETA_LAYOUT[f]
        out[f] = {g: float(np.sqrt(sum(_rms_deg(sens.dq[:, :, i] * tc[i], g) ** 2
                                       for i in range(sl.start, sl.stop))))
                  for g in JOINT_GROUPS}
    return out


def linear_response_deg(sens: Sensitivity, dtheta: np.ndarray) -> dict[str, float]:
    """Group RMS (deg) of the first-order change of the joint angles for a θ change ``dtheta``
    (in :data:`COORDS`: ln α differences for α)."""
    dq = np.tensordot(sens.dq, np.asarray(dtheta, float), axes=([2], [0]))
    return {g: _rms_deg(dq, g) for g in JOINT_GROUPS}


def theta_difference(a: Style, b: Style, alpha_min: float = 1e-4 / N_JOINT) -> np.ndarray:
    """θ(a) − θ(b) in :data:`COORDS` (α by ln, each clipped at ``alpha_min``)."""
    va, vb = a.vector(), b.vector()
    d = va - vb
    d[ALPHA] = np.log(np.maximum(va[ALPHA], alpha_min)) - np.log(np.maximum(vb[ALPHA], alpha_min))
    return d


def sensitivity_report(sens: Sensitivity, theta: np.ndarray, others: dict[str, Style] | None = None,
                       style: Style | None = None, top: int = 8) -> dict:
    """A JSON-ready summary: per-field group responses, the singular values of the scaled
    sensitivity (all joints, deg per typical change), the components that move the motion most,
    and, for ``others`` (name → Style) against ``style``, the first-order predicted change."""
    from scenegraph.model.body import JOINT_DOF_NAMES

    tc = typical_change(theta)
    idx = group_indices("all")
    S = (sens.dq[:, idx, :] * tc[None, None, :]).reshape(-1, N_THETA_FULL)
    S = np.degrees(S) / np.sqrt(S.shape[0])  # so that |S v| is the RMS (deg) of the response to v
    sv = np.linalg.svd(S, compute_uv=False)
    names = [f"{f}:{JOINT_DOF_NAMES[j]}" for f in ("alpha", "ks1", "ks2", "kd", "q_rest")
             for j in range(N_JOINT)] + ["k_shoe", "h_rest"]
    col = np.linalg.norm(S, axis=0)
    order = np.argsort(-col)[:top]
    out = {
        "coordinates": COORDS,
        "typical_change": "ln α 1; ks1/ks2 max(|k|, 10 N·m/rad); kd max(|k|, 1 N·m·s/rad); q_rest 0.1 rad; "
                          "k_shoe max(k, 1e4 N/m); h_rest 5 mm",
        "by_field_deg": group_sensitivity(sens, theta),
        "singular_values_deg": [float(v) for v in sv[:12]],
        "directions_over_1deg": int(np.sum(sv > 1.0)),
        "top_components_deg": {names[i]: float(col[i]) for i in order},
        "kkt": {"active_constraints": sens.n_active_g, "active_bounds": sens.n_active_x,
                "solve_relative_residual": sens.kkt_residual, "stationarity_inf": sens.stationarity,
                "reduced_hessian": sens.reduced_hessian},
    }
    if others and style is not None:
        out["first_order_change_deg"] = {name: linear_response_deg(sens, theta_difference(o, style))
                                         for name, o in others.items()}
    return out
