"""Counterexamples X_S: motions within the footstep constraints C with less energy than X_T.

Two kinds:

* a spacetime solve (:meth:`Counterexamples.solve`) for style θ warm-started at the best
  known motion *with its NNLS λ*, IPOPT told to start there (:data:`WARM_START`), a limited
  number of iterations, and the lowest-objective *feasible* iterate kept (an iteration
  callback: IPOPT is not monotone, and its last iterate is often worse);
* a local one (:meth:`Counterexamples.local`): one Gauss–Newton step from X_T within C, i.e.
  G measured against the local minimum next to X_T (the paper, §6: "the local minimum
  discovered by the optimizer").  IPOPT's Gauss–Newton solves creep along flat valleys of
  this energy, so a capped solve's G is mostly solver error; the local step costs ~0.3 s and
  is smooth in θ.

Both substitute θ into the NLP's parameters by name (``NLP.p_layout["theta"]`` and
``["sqrt_alpha"]``) and set the start by name (``NLP.x_layout["ctrl"]``, ``["lambda"]``).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from scenegraph.model.motion import Motion
from scenegraph.problem import NLP, Built, IterationCallback, Result, Subproblem, make_solver, solve, transcribe, violations
from scenegraph.nio.energy import nlp_params
from scenegraph.nio.theta import ALPHA, KERNEL

__all__ = ["WARM_START", "BestIterate", "Counterexamples", "nlp_params"]

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
LOCAL_STEPS = (1.0, 0.5, 0.25, 0.1, 0.05, 0.02, 0.01)  # fractions of the Gauss–Newton step tried


class BestIterate(IterationCallback):
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


@dataclass(frozen=True)
class Counterexamples:
    """The counterexample solvers of one NIO problem: the q-only subproblem ``sp`` (with the
    :class:`BestIterate` callback ``best`` in its nlpsol options), its NLP and IPOPT solver."""

    sp: Subproblem
    nlp: NLP
    built: Built
    best: BestIterate
    feas_tol: float  # m: a counterexample must satisfy C to this tolerance

    @classmethod
    def build(cls, sp: Subproblem, feas_tol: float) -> "Counterexamples":
        """Transcribe ``sp`` and create its solver with the best-feasible-iterate callback
        (iterates count as feasible within half of ``feas_tol``)."""
        nlp = transcribe(sp)
        best = BestIterate(nlp.x0.size, nlp.lbg.size, nlp.lbg, nlp.ubg, 0.5 * feas_tol)
        sp = replace(sp, nlpsol_options=(("iteration_callback", best),))
        return cls(sp, nlp, make_solver(nlp, sp), best, feas_tol)

    @functools.cached_property
    def _derivatives(self):
        """The solver's objective gradient, Lagrangian Hessian and constraint Jacobian."""
        sv = self.built.solver
        return tuple(sv.get_function(n) for n in ("nlp_grad_f", "nlp_hess_l", "nlp_jac_g"))

    def _start(self, start: Motion | None, lam0: np.ndarray | None) -> np.ndarray:
        x0 = self.nlp.x0.copy()
        if start is not None:
            x0[self.nlp.x_layout["ctrl"]] = np.asarray(start.ctrl, float).ravel()  # NIO frees every control point
        if lam0 is not None:
            x0[self.nlp.x_layout["lambda"]] = lam0
        return x0

    def solve(self, theta: np.ndarray, start: Motion | None = None, lam0: np.ndarray | None = None) -> Result:
        """X_S: the spacetime solve for style θ warm-started at ``start`` (default X_T) with
        contact coefficients ``lam0``; the best feasible iterate if IPOPT ended above it."""
        b = self.nlp
        p = nlp_params(b, theta)
        x0 = self._start(start, lam0)
        self.best.reset()
        res = solve(self.sp, self.built, x0=x0, p=p)
        if self.best.best_x is not None and self.best.best_f < res.objective:
            # IPOPT ended above its best feasible iterate: use that one
            x = self.best.best_x
            P, W = (np.asarray(v, float) for v in b.unpack(x, p)[:2])
            res = replace(res, motion=Motion(P, W.ravel()), objective=float(self.best.best_f),
                          violations=violations(b, x, p), status=res.status + "+best_iterate")
        return res

    def local(self, theta: np.ndarray, start: Motion, lam0: np.ndarray,
              energy: Callable[[np.ndarray, Motion], float],
              steps: tuple[float, ...] = LOCAL_STEPS) -> tuple[Motion, float]:
        """A *local* counterexample: the Gauss–Newton step from ``start`` (X_T) within C,

            min_d  ∇f·d + ½ dᵀ H d   s.t.  the active constraints' linearisation A d = 0,
                   contact coefficients at 0 stay at 0,

        (H: the solver's Gauss–Newton Hessian, f its objective under θ), one sparse KKT solve;
        the step is shortened (``steps``) to the lowest ``energy(θ, motion)`` that keeps C to
        ``feas_tol``.  Its energy drop predicts E(X_T) − (the local minimum next to X_T): it
        vanishes exactly when X_T is stationary under θ, which is what a re-synthesis started
        at X_T needs.  Returns (motion, worst constraint violation)."""
        import scipy.sparse as sps
        import scipy.sparse.linalg as spla

        b = self.nlp
        fgrad, fhess, fjac = self._derivatives
        p = nlp_params(b, theta)
        x = self._start(start, lam0)
        lam_slice = b.x_layout["lambda"]
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
            pin = sps.csr_matrix((np.ones(fixed.size), (np.arange(fixed.size), fixed)), shape=(fixed.size, n))
            A = sps.vstack([A, pin])
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
            E = energy(theta, m_a)
            if E < best_E:
                best, best_E, best_v = m_a, E, v
        return best, best_v
