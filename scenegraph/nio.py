"""Nonlinear Inverse Optimization (NIO, paper §6): learn a physical style θ from one motion.

Given an observed motion X_T with its footsteps C, NIO looks for the style under which X_T
is the energy-optimal motion (Eq. 16).  It minimises (Eq. 17–19)

    G(θ) + D(θ),   G(θ) = E(X_T; θ) − min_{X ∈ C} E(X; θ),
    D(θ) = w (Σ_j α_j − 1)² + w Σ_j min(α_j, 0)²,   w = 10⁴,

with the energy of the spacetime solver (Eq. 13, same collocation grid and normalisation):

    E(X; θ) = (OBJ_SCALE / m g)² Σ_k w_k T'_k [ Σ_j α_j Q_mj(s_k)² + w_r Σ_i Q_0i(s_k)² ].

Contact forces are part of a motion; for a *fixed* q the solver's objective is minimised over
the contact coefficients λ ≥ 0 point by point (a non-negative least-squares problem, because
the residuals are affine in the contact forces), and E includes the solver's small λ
regularisation (OBJ_SCALE·LAM_REG)² |λ|², so E is exactly the objective the spacetime solver
minimises with λ profiled out.  That is how X_T gets its forces, and it is also applied to
every counterexample, so E(X_T; θ) and E(X_S; θ) are measured alike.

Counterexamples: the spacetime solver warm-started at the best known motion (X_T or an
earlier counterexample) *with its NNLS λ*, IPOPT told to start there (``WARM_START``:
warm_start_init_point, tiny bound pushes; the default barrier start mu = 0.1, bound_push =
1e-2 throws a warm start far from the active bounds λ = 0 and the solve then ends above
E(X_T)), a limited number of IPOPT iterations, and the lowest-objective *feasible* iterate
kept (an iteration callback: IPOPT is not monotone, and its last iterate is often worse).
Infeasible counterexamples (constraint violation > ``feas_tol``) are rejected: X_S must
satisfy C.  X_S is the lowest-energy motion among X_T, the candidates and the solve, so G is
an honest lower bound of Eq. 17.

Optimiser (``run``, default ``method="bundle"``): every counterexample X_i found so far gives
G(θ) ≥ E(X_T; θ) − E(X_i; θ); linearised at the current θ with the Eq. 21 gradient (AD of the
residual kernel, motions and forces held fixed) they form a cutting-plane model of G, which
is minimised in a trust box (an LP, Σα = 1 held exactly so D = 0); each trial θ gets its own
counterexample, which joins the model; G of the current θ is re-read with every new
counterexample.  The paper's preconditioned gradient step with the halving line search of
footnote 3 is kept as ``method="gradient"``; with the noisy counterexamples of a 60-iteration
solve it stalled (G 0.0022 → 0.0016, then no decrease).  ``NIO(alpha_floor=a)`` bounds every α_j ≥ a in
the bundle step (an experiment, README "α floor": α = 0 makes a joint's torque free).

Local counterexamples (``NIO(local=True)``, the default of :func:`learn_style`): one
Gauss–Newton step from X_T within C (:meth:`NIO.local_counterexample`), i.e. G measured
against the local minimum next to X_T (the paper, §6: "consider the local minimum discovered
by [the optimizer]").  Why: IPOPT's Gauss–Newton solves creep along flat valleys of this
energy (a synthesis reported as converged at tol 1e-4 kept falling, E 146 → 35, over another
485 iterations and moved 12°), so a capped solve's G is mostly solver error (at θ* itself a
150-iteration counterexample beat a refined X_T by 10 %).  The local step costs ~0.3 s and is
smooth in θ.  Measured: synthetic G 9.0e-4 → 1.7e-5 (54×) with the springs recovered but not
α; 07_01 G 1.09 → 0.030 in 121 iterations (~200 s).  What it does not give: X_T as the
optimum of a long re-synthesis (README, Status).

X_T for a real clip: :func:`feasible_target` moves the reconstruction onto its footsteps.

Stop: G below ``g_abs`` × its initial value, no decrease in ``patience`` iterations, or
after ``max_iter`` iterations (a safety net, reported as such).
"""
from __future__ import annotations

import functools
import time as _time
from dataclasses import dataclass, replace
from typing import Callable

import casadi as ca
import numpy as np
from scipy.optimize import nnls

from .body import G, N_DOF, N_JOINT, N_ROOT, Character
from .dynamics import friction_basis
from .footsteps import Footstep
from .motion import Motion
from .problem import (NLP, OBJ_SCALE, Built, IterationCallback, PoseTarget, Result, Subproblem, build,
                      make_solver, solve, transcribe, violations)
from .residual import FORCE_HANDLES, W_ROOT, residual_kernel
from .style import ExamplePoses, Provenance, Style, default_style

__all__ = ["NIO", "NIOResult", "IterationRecord", "learn_style", "initial_style", "joint_rms_deg",
           "resynthesize_from_example", "example_of",
           "D_WEIGHT", "N_THETA_FULL"]

D_WEIGHT = 1.0e4  # paper: w in Eq. 18
N_THETA_FULL = 5 * N_JOINT + 2  # 147
LAM_REG = 1e-3  # the solver's λ regularisation (kept for a well-posed contact split)
# IPOPT options of a counterexample solve: start *at* the warm start (X_T or the previous
# counterexample, with its NNLS contact coefficients) instead of being pushed off the active
# bounds λ = 0 by the default barrier (mu_init = 0.1, bound_push = 1e-2).
WARM_START = (("warm_start_init_point", "yes"), ("mu_init", 1e-4),
              ("warm_start_bound_push", 1e-6), ("warm_start_bound_frac", 1e-6),
              ("warm_start_slack_bound_push", 1e-6), ("warm_start_slack_bound_frac", 1e-6),
              ("warm_start_mult_bound_push", 1e-6),
              # no "acceptable level" exit: on this flat energy IPOPT otherwise stops while
              # the energy is still falling fast (measured: E 146 → 35 when continued)
              ("acceptable_iter", 0))


def joint_rms_deg(a: Motion, b: Motion, fps: float = 30.0) -> float:
    """RMS (degrees) of the joint angles (root excluded) of ``a`` vs ``b`` at ``fps`` frames
    over their common time span."""
    t0, t1 = max(a.start, b.start), min(a.end, b.end)
    n = int(np.floor((t1 - t0) * fps + 1e-9)) + 1
    t = t0 + np.arange(n) / fps
    qa = a.canonical(a.to_canonical(t))[:, N_ROOT:]
    qb = b.canonical(b.to_canonical(t))[:, N_ROOT:]
    return float(np.degrees(np.sqrt(np.mean((qa - qb) ** 2))))


def _theta_scales(style: Style) -> np.ndarray:
    """Typical magnitude of every θ component (the diagonal preconditioner)."""
    ref = default_style()
    ks = np.maximum(np.maximum(ref.ks1, np.asarray(style.ks1)), 1.0)
    return np.concatenate([np.full(N_JOINT, 1.0 / N_JOINT), ks, ks, 0.1 * ks, np.full(N_JOINT, 0.1),
                           [max(ref.k_shoe, style.k_shoe)], [0.005]])


def _project(th: np.ndarray) -> np.ndarray:
    """Bounds of a Style except α (soft constraints D)."""
    th = th.copy()
    M = N_JOINT
    th[M:4 * M] = np.clip(th[M:4 * M], 0.0, 1e5)
    th[4 * M:5 * M] = np.clip(th[4 * M:5 * M], -np.pi, np.pi)
    th[-2] = float(np.clip(th[-2], 0.0, 1e7))
    th[-1] = float(np.clip(th[-1], 0.0, 0.1))
    return th


def style_from_theta(th: np.ndarray, name: str = "learned", provenance: Provenance | None = None) -> Style:
    """A valid Style from θ: α clipped at 0 and normalised, everything else projected."""
    th = _project(np.asarray(th, float))
    a = np.maximum(th[:N_JOINT], 0.0)
    a = a / a.sum() if a.sum() > 0 else np.full(N_JOINT, 1.0 / N_JOINT)
    th[:N_JOINT] = a
    return Style.from_vector(th, name=name, provenance=provenance)


def d_penalty(th: np.ndarray) -> tuple[float, np.ndarray]:
    """D(θ) (Eq. 18) and its gradient."""
    a = th[:N_JOINT]
    s = a.sum() - 1.0
    neg = np.minimum(a, 0.0)
    g = np.zeros_like(th)
    g[:N_JOINT] = D_WEIGHT * (2 * s + 2 * neg)
    return float(D_WEIGHT * (s ** 2 + np.sum(neg ** 2))), g


@functools.lru_cache(maxsize=4)
def _force_jacobian(ch: Character) -> ca.Function:
    k = residual_kernel(ch)
    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    f = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("th", k.size1_in(4))
    Q = k(q, qd, qdd, f, th)
    return ca.Function("dQdf", [q, qd, qdd, f, th], [Q, ca.jacobian(Q, f)])


class _BestIterate(IterationCallback):
    """IPOPT iteration callback keeping the lowest-objective iterate that satisfies the
    constraints to ``tol``: IPOPT is not monotone in the objective, and a counterexample
    solve that stops at its iteration limit can end worse than it began."""

    def __init__(self, nx: int, ng: int, lbg: np.ndarray, ubg: np.ndarray, tol: float):
        self.tol = tol
        self.reset()
        super().__init__("nio_best_iterate", nx, ng, lbg, ubg)

    def reset(self):
        self.best_f, self.best_x = np.inf, None

    def on_iterate(self, arg):
        f = float(arg[1])
        if f < self.best_f and self.violation(arg[2]) <= self.tol:
            self.best_f, self.best_x = f, np.asarray(arg[0]).ravel().copy()
        return [0]


@dataclass
class IterationRecord:
    iteration: int
    G: float
    D: float
    E_target: float
    E_counter: float
    beta: float
    evaluations: int
    seconds: float


@dataclass
class NIOResult:
    style: Style  # α normalised
    theta: np.ndarray  # raw θ (147) at the end
    history: list[IterationRecord]
    g_initial: float
    g_final: float
    iterations: int
    evaluations: int
    seconds: float
    stop_reason: str
    counterexample: Motion | None = None


@dataclass
class _Eval:
    theta: np.ndarray
    G: float
    D: float
    E_T: float
    E_S: float
    grad: np.ndarray  # dG̃/dθ + dD/dθ
    motion_S: Motion
    FS: np.ndarray
    solve: Result | None


class NIO:
    """An NIO problem for one target motion (fixed footsteps and timing).

    ``target``: the observed motion X_T (a Motion on the character); ``footsteps`` its
    footstep constraints C.  ``solve_iter``: IPOPT iterations per counterexample.
    """

    def __init__(self, ch: Character, target: Motion, footsteps: tuple[Footstep, ...], *,
                 solve_iter: int = 80, collocation_hz: float = 30.0, tol: float = 1e-4,
                 ipopt_options: tuple = WARM_START, feas_tol: float = 1e-3, rounds: int = 1,
                 cyclic: bool = False, soft_pin_hz: float = 0.0, local: bool = False,
                 hessian: str = "gauss_newton", alpha_floor: float = 0.0):
        self.ch, self.target, self.footsteps = ch, target, tuple(footsteps)
        self.alpha_floor = alpha_floor  # lower bound of every α_j in the bundle's LP
        self.local = local  # counterexamples by one Gauss–Newton step from X_T (local_counterexample)
        self.verbose = False
        self.rounds = rounds  # a counterexample = `rounds` solves of solve_iter iterations, each
        # restarted from the best feasible motion so far (IPOPT's last iterate can be worse)
        self.feas_tol = feas_tol  # m: a counterexample must satisfy C to this tolerance
        self.sp = Subproblem(ch, default_style(ch.total_mass), target, self.footsteps, free=frozenset({"q"}),
                             collocation_hz=collocation_hz, max_iter=solve_iter, tol=tol, label="nio",
                             ipopt_options=tuple(ipopt_options), cyclic=cyclic, soft_pin_hz=soft_pin_hz,
                             hessian="gauss_newton" if local else hessian)
        # ``hessian``: Subproblem.hessian of the IPOPT solves (counterexamples with local=False,
        # resynthesize).  The local counterexample always takes the Gauss–Newton step: with the
        # exact Hessian (indefinite at X_T) its KKT step goes to a saddle and found nothing
        # below E(X_T) on 07_01 (G = 0 at the first iteration, measured).
        self.hessian = hessian
        t = _time.perf_counter()
        self.nlp: NLP = transcribe(self.sp)
        # the solver's iteration callback keeps the best feasible iterate
        b = self.nlp
        self._best = _BestIterate(b.x0.size, b.lbg.size, b.lbg, b.ubg, 0.5 * feas_tol)
        self.sp = replace(self.sp, nlpsol_options=(("iteration_callback", self._best),))
        self.built: Built = make_solver(self.nlp, self.sp)
        self.build_seconds = _time.perf_counter() - t
        s = b.s_points
        self.N = N = len(s)
        wq = np.zeros(N)
        wq[1:] += np.diff(s) / 2
        wq[:-1] += np.diff(s) / 2
        self.mg = ch.total_mass * G
        T1 = target.time(s, 1)  # warp is fixed (free = q): the same for every counterexample
        self.wT = wq * T1
        self.c = self.wT * (OBJ_SCALE / self.mg) ** 2
        # contact structure: per point the planted handles and their λ slices
        self.planted: list[list[tuple[int, slice]]] = [[] for _ in range(N)]
        for h, k, sl in b.contact_index:
            self.planted[k].append((FORCE_HANDLES.index(h), sl))
        self.V = friction_basis()
        self._energy_fn = self._make_energy_fn()
        self.n_solves = 0
        self.solve_seconds = 0.0

    # --- energy ---------------------------------------------------------------------------
    def _make_energy_fn(self) -> ca.Function:
        N = self.N
        th = ca.MX.sym("theta", N_THETA_FULL)
        q, qd, qdd = (ca.MX.sym(n, N_DOF, N) for n in ("q", "qd", "qdd"))
        F = ca.MX.sym("F", 3 * len(FORCE_HANDLES), N)
        alpha = th[:N_JOINT]
        thk = th[N_JOINT:]
        QQ = residual_kernel(self.ch).map(N)(q, qd, qdd, F, ca.repmat(thk, 1, N))
        per = ca.mtimes(alpha.T, QQ[:N_JOINT, :] ** 2) + W_ROOT * ca.sum1(QQ[N_JOINT:, :] ** 2)
        E = ca.mtimes(per, ca.DM(self.c))
        return ca.Function("nio_E", [th, q, qd, qdd, F], [E, ca.gradient(E, th)])

    def states(self, motion: Motion):
        q, qd, qdd = motion.state_at_s(self.nlp.s_points)
        return q.T, qd.T, qdd.T

    def forces(self, motion: Motion, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact forces (24, N) minimising E for the fixed q of ``motion`` (NNLS per point),
        and λ in the solver's layout."""
        q, qd, qdd = self.states(motion)
        fn = _force_jacobian(self.ch).map(self.N)
        nf = 3 * len(FORCE_HANDLES)
        thk = np.tile(theta[N_JOINT:, None], (1, self.N))
        Q0, J = fn(q, qd, qdd, np.zeros((nf, self.N)), thk)
        Q0, J = np.asarray(Q0), np.asarray(J)  # J: (35, 24 N)
        wsq = np.sqrt(np.r_[np.maximum(theta[:N_JOINT], 0.0), np.full(N_ROOT, W_ROOT)])
        F = np.zeros((nf, self.N))
        lam_slice = self.nlp.x_layout["lambda"]
        lam = np.zeros(lam_slice.stop - lam_slice.start)
        off = lam_slice.start
        for k, pl in enumerate(self.planted):
            if not pl:
                continue
            Jk = J[:, k * nf:(k + 1) * nf]
            A = np.hstack([Jk[:, 3 * i:3 * i + 3] @ (self.mg * self.V) for i, _ in pl])
            reg = LAM_REG * self.mg / np.sqrt(max(self.wT[k], 1e-12))
            AA = np.vstack([wsq[:, None] * A, reg * np.eye(A.shape[1])])
            bb = np.r_[-wsq * Q0[:, k], np.zeros(A.shape[1])]
            x, _ = nnls(AA, bb, maxiter=50 * A.shape[1])
            for c, (i, sl) in enumerate(pl):
                lk = x[4 * c:4 * c + 4]
                F[3 * i:3 * i + 3, k] += self.mg * self.V @ lk
                lam[sl.start - off:sl.stop - off] = lk
        return F, lam

    def energy(self, theta: np.ndarray, motion: Motion, F: np.ndarray,
               lam: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """E(X; θ) for motion q and forces F, and ∂E/∂θ.  With ``lam`` (the contact
        coefficients of F) the solver's λ regularisation (OBJ_SCALE·LAM_REG)² |λ|² is added:
        that is the objective the spacetime solver minimises, so X_T is a minimum of this
        measure under θ* (without it, E(X_T; θ*) is not minimal and G(θ*) > 0)."""
        E, g = self._energy_fn(theta, *self.states(motion), F)
        E = float(E)
        if lam is not None:
            E += float((OBJ_SCALE * LAM_REG) ** 2 * np.sum(np.asarray(lam) ** 2))
        return E, np.asarray(g).ravel()

    def measure(self, theta: np.ndarray, motion: Motion):
        """(E, ∂E/∂θ, F, λ) of ``motion`` under θ with its energy-optimal contact forces."""
        F, lam = self.forces(motion, theta)
        E, g = self.energy(theta, motion, F, lam)
        return E, g, F, lam

    # --- counterexample -------------------------------------------------------------------
    def counterexample(self, theta: np.ndarray, start: Motion | None = None,
                       lam0: np.ndarray | None = None) -> Result:
        """X_S: the spacetime solve for style θ warm-started at ``start`` (default X_T)."""
        b = self.nlp
        p = self._params(theta)
        x0 = b.x0.copy()
        if start is not None:
            x0[b.x_layout["ctrl"]] = np.asarray(start.ctrl, float).ravel()  # NIO frees every control point
        if lam0 is not None:
            x0[b.x_layout["lambda"]] = lam0
        t = _time.perf_counter()
        self._best.reset()
        res = solve(self.sp, self.built, x0=x0, p=p)
        if self._best.best_x is not None and self._best.best_f < res.objective:
            # IPOPT ended above its best feasible iterate: use that one
            x = self._best.best_x
            P, W = (np.asarray(v, float) for v in b.unpack(x, p)[:2])
            res = replace(res, motion=Motion(P, W.ravel()), objective=float(self._best.best_f),
                          violations=violations(b, x, p), status=res.status + "+best_iterate")
        self.solve_seconds += _time.perf_counter() - t
        self.n_solves += 1
        return res

    def _params(self, theta: np.ndarray) -> np.ndarray:
        """The NLP's parameters with style θ (147) at every collocation point."""
        b, N = self.nlp, self.N
        TH = np.tile(theta[N_JOINT:, None], (1, N))
        SA = np.tile(np.sqrt(np.maximum(theta[:N_JOINT], 0.0))[:, None], (1, N))
        p = b.p0.copy()
        p[b.p_layout["theta"]] = TH.ravel(order="F")
        p[b.p_layout["sqrt_alpha"]] = SA.ravel(order="F")
        return p

    def local_counterexample(self, theta: np.ndarray, start: Motion, lam0: np.ndarray,
                             steps: tuple[float, ...] = (1.0, 0.5, 0.25, 0.1, 0.05, 0.02, 0.01)) -> tuple[Motion, float]:
        """A *local* counterexample: the Gauss–Newton step from ``start`` (X_T) within C,

            min_d  ∇f·d + ½ dᵀ H d   s.t.  the active constraints' linearisation A d = 0,
                   contact coefficients at 0 stay at 0,

        (H: the solver's Gauss–Newton Hessian, f its objective under θ), one sparse KKT solve;
        the step is shortened (``steps``) to the lowest measured energy that keeps C to
        ``feas_tol``.  Its energy drop predicts E(X_T) − (the local minimum next to X_T): it
        vanishes exactly when X_T is stationary under θ, which is what a re-synthesis started
        at X_T needs.  The paper allows this view of G ("the local minimum discovered by the
        optimizer", §6).  Returns (motion, worst constraint violation)."""
        import scipy.sparse as sps
        import scipy.sparse.linalg as spla

        b = self.nlp
        if not hasattr(self, "_fns"):
            sv = self.built.solver
            self._fns = (sv.get_function("nlp_grad_f"), sv.get_function("nlp_hess_l"), sv.get_function("nlp_jac_g"))
        fgrad, fhess, fjac = self._fns
        p = self._params(theta)
        x = b.x0.copy()
        x[b.x_layout["ctrl"]] = np.asarray(start.ctrl, float).ravel()  # NIO frees every control point
        lam_slice = b.x_layout["lambda"]
        x[lam_slice] = lam0
        _, gf = fgrad(x, p)
        gf = np.asarray(gf, float).ravel()
        Hu = sps.csc_matrix(fhess(x, p, 1.0, np.zeros(b.lbg.size)).sparse())  # upper triangle
        H = Hu + Hu.T - sps.diags(Hu.diagonal())
        gv, Jg = fjac(x, p)
        gv = np.asarray(gv, float).ravel()
        Jg = sps.csr_matrix(Jg.sparse())
        tol = 1e-7
        active = (np.abs(gv - b.lbg) <= tol) | (np.abs(gv - b.ubg) <= tol)
        A = Jg[np.flatnonzero(active)]
        n = x.size
        lam_idx = np.arange(lam_slice.start, lam_slice.stop)
        fixed = lam_idx[x[lam_idx] <= 1e-12]
        if fixed.size:
            A = sps.vstack([A, sps.csr_matrix((np.ones(fixed.size), (np.arange(fixed.size), fixed)), shape=(fixed.size, n))])
        m = A.shape[0]
        ridge = 1e-8 * max(1.0, float(abs(H.diagonal()).max()))
        K = sps.bmat([[H + ridge * sps.identity(n), A.T], [A, -1e-12 * sps.identity(m)]], format="csc")
        sol = spla.spsolve(K, np.r_[-gf, np.zeros(m)])
        d = sol[:n]
        best, best_E, best_v = start, np.inf, 0.0
        for a in steps:
            xa = x + a * d
            xa[lam_slice] = np.maximum(xa[lam_slice], 0.0)
            P = np.asarray(b.unpack(xa, p)[0], float)
            m_a = Motion(P, np.asarray(start.warp, float))
            v = max(violations(b, xa, p).values(), default=0.0)
            if v > self.feas_tol:
                continue
            E = self.measure(theta, m_a)[0]
            if E < best_E:
                best, best_E, best_v = m_a, E, v
        self.n_solves += 1
        return best, best_v

    def evaluate(self, theta: np.ndarray, candidates: tuple[Motion, ...] = ()) -> _Eval:
        """G(θ), D(θ) and the approximate gradient (Eq. 21) of G + D.

        ``candidates`` (earlier counterexamples) are motions that also satisfy C: the solve
        starts from the best of X_T and them, and X_S is the best motion seen, so G is an
        honest lower bound of Eq. 17 even when IPOPT stops early or wanders off.
        """
        theta = np.asarray(theta, float)
        ET, gT, FT, lamT = self.measure(theta, self.target)
        best = (ET, gT, self.target, FT, lamT)
        for m in candidates:
            E, g, F, lam = self.measure(theta, m)
            if np.isfinite(E) and E < best[0]:
                best = (E, g, m, F, lam)
        res = None
        if self.local:
            XS, _ = self.local_counterexample(theta, self.target, lamT)
            ES, gS, FS, lamS = self.measure(theta, XS)
            if np.isfinite(ES) and ES < best[0]:
                best = (ES, gS, XS, FS, lamS)
        for _ in range(0 if self.local else self.rounds):  # short solves chained from the best motion so far
            res = self.counterexample(theta, best[2], best[4])
            XS = res.motion
            ES, gS, FS, lamS = self.measure(theta, XS)
            feasible = max(res.violations.values(), default=0.0) <= self.feas_tol
            if feasible and np.isfinite(ES) and ES < best[0]:
                best = (ES, gS, XS, FS, lamS)
        ES, gS, XS, FS, _ = best
        D, gD = d_penalty(theta)
        return _Eval(theta, ET - ES, D, ET, ES, gT - gS + gD, XS, FS, res)

    def resynthesize(self, style: Style, max_iter: int = 300, warm: bool = False) -> Result:
        """Re-synthesis for the real-clip check (paper §7, "Estimating style parameters"): the
        spacetime solve with ``style`` and X_T's own footsteps, started from X_T, the same
        budget for every style (``max_iter`` iterations, tol 1e-6, no "acceptable" exit).

        ``warm`` False: the project's ordinary solve (as ``synthesize`` runs it: IPOPT's default
        barrier start, contact coefficients from the constant guess).  ``warm`` True: X_T's
        energy-optimal contact forces under ``style`` and IPOPT's warm-start options, which lets
        the solve continue straight down from X_T (measured: it travels further, ~22° on 07_01
        for the learned and the default style alike)."""
        sp = replace(self.sp, style=style, max_iter=max_iter, tol=1e-6, nlpsol_options=(), hessian=self.hessian,
                     label=f"resynth{'-warm' if warm else ''}:{style.name}",
                     ipopt_options=WARM_START if warm else (("acceptable_iter", 0),))
        b = build(sp)
        x0 = None
        if warm:
            x0 = b.nlp.x0.copy()
            x0[b.nlp.x_layout["lambda"]] = self.forces(self.target, style.vector())[1]
        return solve(sp, b, x0=x0)

    # --- the learning loop ----------------------------------------------------------------
    def run(self, theta0: np.ndarray, *, method: str = "bundle", **kw) -> NIOResult:
        """Minimise G + D from θ0.  ``method``: "bundle" (default; trust-region cutting planes
        built from the Eq. 21 gradients of every counterexample found so far) or "gradient"
        (the paper's preconditioned gradient step with the halving line search)."""
        if method == "gradient":
            return self.run_gradient(theta0, **kw)
        if method != "bundle":
            raise ValueError(f"unknown NIO method {method!r}")
        return self.run_bundle(theta0, **kw)

    def _cut(self, theta: np.ndarray, motion: Motion, ET: float, gT: np.ndarray):
        E, g, _, _ = self.measure(theta, motion)
        return ET - E, gT - g

    def _model_step(self, theta: np.ndarray, cuts: list, radius: float, scales: np.ndarray):
        """argmin over δ of max(0, max_i L_i + g_i·δ) + μ Σ|δ/s| subject to Σα = 1, the Style
        bounds and the trust box |δ_j| ≤ radius·s_j (an LP).  Returns (θ + δ, model value)."""
        from scipy.optimize import linprog

        n = len(theta)
        M = N_JOINT
        lo = np.full(n, -np.inf)
        hi = np.full(n, np.inf)
        lo[:4 * M] = 0.0
        lo[:M] = self.alpha_floor
        hi[M:4 * M] = 1e5
        lo[4 * M:5 * M], hi[4 * M:5 * M] = -np.pi, np.pi
        lo[-2], hi[-2] = 0.0, 1e7
        lo[-1], hi[-1] = 0.0, 0.1
        dlo = np.maximum(lo - theta, -radius * scales)
        dhi = np.minimum(hi - theta, radius * scales)
        dlo = np.minimum(dlo, 0.0)
        dhi = np.maximum(dhi, 0.0)
        Lmax = max(c[0] for c in cuts)
        mu = 1e-3 * max(Lmax, 1e-12) / max(radius, 1e-12) / n
        # variables: δ (n), u (n) ≥ |δ/s|, t ≥ 0
        cvec = np.r_[np.zeros(n), np.full(n, mu), 1.0]
        rows, rhs = [], []
        for L, g in cuts:
            rows.append(np.r_[g, np.zeros(n), -1.0])
            rhs.append(-L)
        A1 = np.hstack([np.diag(1 / scales), -np.eye(n), np.zeros((n, 1))])
        A2 = np.hstack([-np.diag(1 / scales), -np.eye(n), np.zeros((n, 1))])
        A_ub = np.vstack([np.array(rows), A1, A2])
        b_ub = np.r_[rhs, np.zeros(2 * n)]
        A_eq = np.r_[np.ones(M), np.zeros(2 * n - M), 0.0][None, :]
        b_eq = [1.0 - theta[:M].sum()]
        bounds = list(zip(dlo, dhi)) + [(0, None)] * n + [(0, None)]
        r = linprog(cvec, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
        if r.status != 0:
            return theta.copy(), Lmax
        d = r.x[:n]
        return theta + d, float(r.x[-1])

    def run_bundle(self, theta0: np.ndarray, *, max_iter: int = 30, rtol: float = 0.02, patience: int = 3,
                   g_abs: float = 1e-3, trust: float = 0.03, min_trust: float = 1e-3, max_trust: float = 4.0,
                   max_cuts: int = 40, max_tries: int = 4, callback: Callable[[IterationRecord], None] | None = None,
                   seeds: tuple[Motion, ...] = ()) -> NIOResult:
        """A trust-region cutting-plane (bundle) method on G + D.

        Every counterexample X_i ever found is a motion satisfying C, so for every θ
        G(θ) ≥ E(X_T; θ) − E(X_i; θ) =: L_i(θ) (and ≥ 0).  At the current θ_c each L_i is
        linearised with its Eq. 21 gradient (AD, forces re-fitted by NNLS under θ_c); the
        step minimises the model max(0, max_i L_i + g_i·δ) in the box |δ_j| ≤ r s_j (s: the
        typical magnitudes), with Σα = 1 held exactly (so D = 0) — an LP.  The trial θ gets
        its own counterexample (a spacetime solve warm-started from the best known motion),
        which is added to the bundle.  G(θ_c) itself is re-read with every new counterexample
        (a later solve can show that the current G was underestimated), and the trial is
        accepted when G + D is below that; r doubles when the decrease was ≥ half the model's
        prediction, else r halves (the halving of footnote 3) and the enriched model is
        re-solved (at most ``max_tries`` trials per iteration).  The returned g_initial and
        g_final are G at θ0 and at the result re-read with all counterexamples found.
        ``seeds``: motions known to satisfy C (e.g. syntheses from a neutral initial motion
        under θ0) that start the bundle as counterexamples.
        """
        t_start = _time.perf_counter()
        th = _project(np.asarray(theta0, float))
        a = np.maximum(th[:N_JOINT], 0)
        th[:N_JOINT] = a / a.sum()
        scales = _theta_scales(style_from_theta(th))
        cur = self.evaluate(th, tuple(seeds))
        bundle: list[Motion] = list(seeds) + ([cur.motion_S] if cur.G > 0 else [])
        n_eval = 1
        hist = [IterationRecord(0, cur.G, cur.D, cur.E_T, cur.E_S, 0.0, 1, _time.perf_counter() - t_start)]
        if callback:
            callback(hist[-1])
        g0 = cur.G + cur.D
        slow, fails, reason, r = 0, 0, "max_iter", trust
        it = 0
        for it in range(1, max_iter + 1):
            if cur.G + cur.D <= g_abs * max(g0, 1e-300):
                reason = f"G below {g_abs:g} x G_initial"
                it -= 1
                break
            if not bundle:
                reason = "no counterexample: the solver found no motion below E(X_T)"
                it -= 1
                break
            ET, gT, _, _ = self.measure(cur.theta, self.target)
            cuts = [self._cut(cur.theta, m, ET, gT) for m in bundle]
            # G(θ_c) with everything known now (later counterexamples can reveal a larger G)
            prev = max(0.0, max(c[0] for c in cuts)) + cur.D
            tries = 0
            accepted = False
            while r >= min_trust and tries < max_tries:
                th_new, model = self._model_step(cur.theta, cuts, r, scales)
                pred = prev - model
                if pred <= 1e-12 * max(prev, 1e-300):
                    r *= 0.5
                    continue
                new = self.evaluate(th_new, tuple(bundle))
                tries += 1
                n_eval += 1
                if new.G > 0:
                    bundle.append(new.motion_S)
                    bundle = bundle[-max_cuts:]
                c_new = self._cut(cur.theta, new.motion_S, ET, gT)
                prev = max(prev, c_new[0] + cur.D)
                actual = prev - (new.G + new.D)
                if self.verbose:
                    print(f"    trial r={r:.3g}: G(θ_c)={prev:.5g} model={model:.5g} G(trial)={new.G + new.D:.5g}",
                          flush=True)
                if actual > 0:
                    cur = new
                    accepted = True
                    r_used = r
                    if actual >= 0.5 * pred:
                        r = min(max_trust, 2 * r)
                    break
                r *= 0.5
                cuts.append(c_new)
            if not accepted:
                rec = IterationRecord(it, prev - cur.D, cur.D, cur.E_T, cur.E_S, 0.0, tries, _time.perf_counter() - t_start)
                hist.append(rec)
                if callback:
                    callback(rec)
                fails += 1
                r = max(r, 4 * min_trust)
                if fails >= patience:
                    reason = f"no decrease of G + D found in {patience} iterations"
                    break
                continue
            fails = 0
            rec = IterationRecord(it, cur.G, cur.D, cur.E_T, cur.E_S, r_used, tries, _time.perf_counter() - t_start)
            hist.append(rec)
            if callback:
                callback(rec)
            rel = (prev - (cur.G + cur.D)) / max(prev, 1e-300)
            slow = slow + 1 if rel < rtol else 0
            if slow >= patience:
                reason = f"relative decrease < {rtol} for {patience} iterations"
                break
        # G(θ0) re-read with every counterexample found: the first solve alone can underestimate it
        ET0, gT0, _, _ = self.measure(th, self.target)
        g_init = max([hist[0].G] + [self._cut(th, m, ET0, gT0)[0] for m in bundle])
        ET1, gT1, _, _ = self.measure(cur.theta, self.target)
        g_fin = max([0.0] + [self._cut(cur.theta, m, ET1, gT1)[0] for m in bundle])
        return NIOResult(style_from_theta(cur.theta), cur.theta, hist, g_init, g_fin,
                         sum(1 for h in hist[1:] if h.beta > 0), n_eval, _time.perf_counter() - t_start,
                         reason, cur.motion_S)

    def run_gradient(self, theta0: np.ndarray, *, max_iter: int = 30, rtol: float = 0.02, patience: int = 2,
                     g_abs: float = 1e-4, trust: float = 0.1, min_beta: float = 1e-6,
                     callback: Callable[[IterationRecord], None] | None = None) -> NIOResult:
        t_start = _time.perf_counter()
        scales = _theta_scales(style_from_theta(theta0))
        cur = self.evaluate(_project(np.asarray(theta0, float)))
        n_eval = 1
        hist = [IterationRecord(0, cur.G, cur.D, cur.E_T, cur.E_S, 0.0, 1, _time.perf_counter() - t_start)]
        if callback:
            callback(hist[-1])
        g0 = cur.G + cur.D
        slow, reason, it = 0, "max_iter", 0
        cache: dict[float, _Eval] = {}
        if cur.G <= 0.0:
            reason = "no counterexample: the solver found no motion below E(X_T) (raise solve_iter)"
            max_iter = 0
        for it in range(1, max_iter + 1):
            if cur.G + cur.D <= g_abs * max(g0, 1e-300):
                reason = "G below tolerance"
                it -= 1
                break
            d = scales ** 2 * cur.grad  # preconditioned gradient
            nrm = np.max(np.abs(d / scales))
            if not np.isfinite(nrm) or nrm == 0:
                reason = "zero gradient"
                it -= 1
                break
            delta = d * (trust / nrm)
            cache = {}

            def at(beta):
                if beta not in cache:
                    cache[beta] = self.evaluate(_project(cur.theta - beta * delta), (cur.motion_S,))
                return cache[beta]

            beta = 1.0  # footnote 3
            while beta > min_beta and at(beta).G + at(beta).D > at(beta / 2).G + at(beta / 2).D:
                beta /= 2
            new = at(beta)
            n_eval += len(cache)
            prev = cur.G + cur.D
            if new.G + new.D >= prev:
                # no decrease along this direction: try shorter steps once, then stop
                trust *= 0.25
                rec = IterationRecord(it, cur.G, cur.D, cur.E_T, cur.E_S, 0.0, len(cache),
                                      _time.perf_counter() - t_start)
                hist.append(rec)
                if callback:
                    callback(rec)
                if trust < 1e-3:
                    reason = "line search found no decrease"
                    break
                slow += 1
                if slow >= patience + 1:
                    reason = "line search found no decrease"
                    break
                continue
            cur = new
            trust = min(4.0, trust * (2.0 if beta == 1.0 else max(beta, 1e-3) * 2))
            rec = IterationRecord(it, cur.G, cur.D, cur.E_T, cur.E_S, beta, len(cache),
                                  _time.perf_counter() - t_start)
            hist.append(rec)
            if callback:
                callback(rec)
            rel = (prev - (cur.G + cur.D)) / max(prev, 1e-300)
            slow = slow + 1 if rel < rtol else 0
            if slow >= patience:
                reason = f"relative decrease < {rtol} for {patience} iterations"
                break
        return NIOResult(style_from_theta(cur.theta), cur.theta, hist, hist[0].G, cur.G,
                         sum(1 for h in hist[1:] if h.beta > 0), n_eval, _time.perf_counter() - t_start,
                         reason, cur.motion_S)

    # --- initialisation (§6.1) ------------------------------------------------------------
    def initial_theta(self, base: Style | None = None, rest_from_target: bool = True,
                      springs_from_target: bool = True) -> np.ndarray:
        """α = 1/M, q̄ = mean pose of X_T, springs by Eq. 22 (least squares of the inferred
        muscle forces, stiffnesses ≥ 0); shoe from ``base``."""
        base = base or default_style(self.ch.total_mass)
        th = base.vector().copy()
        th[:N_JOINT] = 1.0 / N_JOINT
        M = N_JOINT
        q, qd, _ = self.states(self.target)
        if rest_from_target:
            th[4 * M:5 * M] = np.clip(q[N_ROOT:, :] @ (self.wT / self.wT.sum()), -np.pi, np.pi)
        if springs_from_target:
            th = self._fit_springs(th)
        return _project(th)

    def _fit_springs(self, th: np.ndarray) -> np.ndarray:
        """Eq. 22: per joint DOF, min Σ_t Q_mj² over (ks1, ks2, kd) ≥ 0.  Q_mj is affine in its
        own DOF's spring and damper (generalized passive forces act on their DOF only), so
        each DOF is a 3-unknown NNLS; contact forces are re-inferred once with the springs."""
        M = N_JOINT
        q, qd, qdd = self.states(self.target)
        for _ in range(2):
            F, _ = self.forces(self.target, th)
            th0 = th.copy()
            th0[M:4 * M] = 0.0
            Q0 = np.asarray(residual_kernel(self.ch).map(self.N)(q, qd, qdd, F,
                                                                 np.tile(th0[M:, None], (1, self.N))))
            # passive generalized force is linear in (ks1, ks2, kd): get its columns by probing
            cols = []
            for blk in range(3):
                thp = th0.copy()
                thp[(1 + blk) * M:(2 + blk) * M] = 1.0
                Qp = np.asarray(residual_kernel(self.ch).map(self.N)(q, qd, qdd, F,
                                                                     np.tile(thp[M:, None], (1, self.N))))
                cols.append(Qp[:M] - Q0[:M])
            w = np.sqrt(self.wT)
            for j in range(M):
                A = np.stack([c[j] * w for c in cols], axis=1)
                b = -Q0[j] * w
                # a small ridge keeps unobservable springs near zero
                ridge = 1e-3 * np.linalg.norm(A) + 1e-9
                x, _ = nnls(np.vstack([A, ridge * np.eye(3)]), np.r_[b, np.zeros(3)])
                th[M + j], th[2 * M + j], th[3 * M + j] = x
        return th


def initial_style(ch: Character, target: Motion, footsteps, **kw) -> Style:
    nio = NIO(ch, target, footsteps, **kw)
    return style_from_theta(nio.initial_theta(), name="nio-initial")


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version
    out = {}
    for pkg in ("compose-motion", "casadi", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "src" if pkg == "compose-motion" else "unknown"
    return out


def learn_style(ch: Character, target: Motion, footsteps: tuple[Footstep, ...], *, init: Style | str = "paper",
                name: str = "learned", clip: str | None = None, frames: str | None = None,
                body: str | None = None, callback=None, solve_iter: int = 100, cyclic: bool = False,
                local: bool = True, hessian: str = "gauss_newton", alpha_floor: float = 0.0, **run_kw) -> NIOResult:
    """Learn a style from ``target``.  ``init``: "paper" (α = 1/M, q̄ = mean pose, springs by
    Eq. 22) or a Style to start from.  The returned style carries its provenance."""
    nio = NIO(ch, target, footsteps, solve_iter=solve_iter, cyclic=cyclic, local=local, hessian=hessian,
              alpha_floor=alpha_floor)
    th0 = nio.initial_theta() if isinstance(init, str) else init.vector().copy()
    if local:  # cheap iterations (~1 s): a stricter relative-decrease stop
        run_kw.setdefault("rtol", 0.005)
        run_kw.setdefault("patience", 5)
    out = nio.run(th0, callback=callback, **run_kw)
    prov = Provenance(clip=clip, frames=frames, body=body or ch.preset, versions=_versions(), g_final=float(out.g_final),
                      g_initial=float(out.g_initial), iterations=out.iterations, stop=out.stop_reason,
                      counterexamples="local (one Gauss-Newton step from X_T)" if local else
                      f"spacetime solves of {solve_iter} IPOPT iterations",
                      **({"hessian": hessian} if hessian != "gauss_newton" else {}),
                      **({"alpha_floor": float(alpha_floor)} if alpha_floor > 0 else {}))
    out.style = style_from_theta(out.theta, name=name, provenance=prov).with_(
        example=example_of(target, footsteps))
    out.nio = nio  # type: ignore[attr-defined]
    return out


def resample(motion: Motion, ctrl_per_second: float = 24.0, fps: float = 120.0) -> Motion:
    """The same motion on a denser spline (the synthesis resolution): a reconstruction at
    10–12 control points per second cannot hold a foot on its footprint at 30 Hz."""
    t, q = motion.sample(fps)
    return Motion.from_samples(t, q, max(6, int(round(motion.duration * ctrl_per_second)) + 3))


def feasible_target(ch: Character, motion: Motion, footsteps: tuple[Footstep, ...], *, cyclic: bool = False,
                    weight: float = 1.0, hz: float = 30.0, max_iter: int = 1500, tol: float = 1e-6) -> Result:
    """X_T for NIO from a reconstructed clip: the motion closest to ``motion`` that satisfies
    the footstep constraints C exactly, with the root residual softly zero (Appendix A):

        min  w_r Σ_k Q_0(s_k)² (normalised as the energy) + weight Σ_f |q(t_f) − q_clip(t_f)|²   s.t. C

    (a spacetime solve with every muscle weight α set to 0 and pose springs toward the clip at
    ``hz``).  Q_0 depends on no part of θ but the shoe spring, which is the default one (the
    one NIO starts from; with the shoe off, the target's heels would sit compressed at the
    ground and every θ with a shoe would see a root residual there), so the target is not
    biased toward a style.  A reconstruction that misses its footprints by a centimetre is
    otherwise beaten by every counterexample for the wrong
    reason (it is outside C).
    """
    n = max(2, int(round(motion.duration * hz)) + 1)
    t = motion.start + np.arange(n) * (motion.duration / (n - 1))
    q = motion.canonical(motion.to_canonical(t))
    poses = tuple(PoseTarget(float(ti), tuple(map(float, qi)), weight=weight / n) for ti, qi in zip(t, q))
    st = default_style(ch.total_mass)
    sp = Subproblem(ch, st, motion, tuple(footsteps), free=frozenset({"q"}), poses=poses, cyclic=cyclic,
                    max_iter=max_iter, tol=tol, label="nio-target",
                    ipopt_options=(("acceptable_iter", 0),))
    b = build(sp)
    p = b.nlp.p0.copy()
    p[b.nlp.p_layout["sqrt_alpha"]] = 0.0  # sqrt(α) = 0: no muscle energy
    return solve(sp, b, p=p)


def example_of(target: Motion, footsteps: tuple[Footstep, ...], fps: float = 60.0) -> ExamplePoses:
    """The example poses a learned style carries: X_T's joint angles at ``fps`` keyed by leg
    phase under its footsteps (the paper's initial motions for new footsteps, §7).  The poses
    are copied, not interpolated, so the rate matters: the initial motion for 07_01's own
    footprints is 1.11° from X_T at 60 fps, 1.80° at 30 fps."""
    from .gait import example_poses

    t, q = target.sample(fps)
    return ExamplePoses.from_arrays(*example_poses(tuple(footsteps), t, q[:, N_ROOT:]))


def resynthesize_from_example(ch: Character, target: Motion, footsteps: tuple[Footstep, ...], style: Style, *,
                              max_iter: int = 300, hessian: str = "gauss_newton") -> Result:
    """The paper's re-synthesis check (§7, "Estimating style parameters"), with the paper's
    initialisation: for each time the joint angles of the pose of the example ``target`` (X_T)
    with the most similar footstep constraints (leg phases; ``gait.initial_motion(example=…)``),
    the root from the footprints; then the ordinary synthesis (kinematic pre-solve, spacetime
    solve of ``max_iter`` iterations) with ``style`` and the same ``footsteps``.  For X_T's own
    footprints the initial motion is close to X_T up to its root (0.42–1.11° joint RMS on the
    four shipped clips).  The poses are those a learned style carries (:func:`example_of`)."""
    from .synthesis import synthesize

    return synthesize(ch, style, tuple(footsteps), target.start, target.end,
                      example=example_of(target, footsteps).arrays(), max_iter=max_iter, hessian=hessian).result
