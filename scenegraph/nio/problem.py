"""The NIO problem of one target motion: its q-only subproblem, energy model, counterexamples,
G(θ) with its Eq. 21 gradient, the optimiser entry point and the re-synthesis check."""
from __future__ import annotations

import time as _time
from dataclasses import replace

import numpy as np

from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.problem import Result, Subproblem, build, solve
from scenegraph.model.style import Style, default_style
from scenegraph.nio.bundle import run_bundle
from scenegraph.nio.counterexamples import LOCAL_STEPS, WARM_START, Counterexamples
from scenegraph.nio.energy import EnergyModel
from scenegraph.nio.gradient import run_gradient
from scenegraph.nio.initial import initial_theta
from scenegraph.nio.records import Evaluation, NIOResult
from scenegraph.nio.theta import d_penalty

__all__ = ["NIO"]


class NIO:
    """An NIO problem for one target motion (fixed footsteps and timing).

    ``target``: the observed motion X_T (a Motion on the character); ``footsteps`` its
    footstep constraints C.  ``solve_iter``: IPOPT iterations per counterexample;
    ``rounds``: a counterexample is ``rounds`` solves, each restarted from the best feasible
    motion so far; ``feas_tol`` (m): a counterexample must satisfy C to this tolerance;
    ``local``: counterexamples by one Gauss–Newton step from X_T (:meth:`local_counterexample`);
    ``hessian``: Subproblem.hessian of the IPOPT solves (counterexamples with local=False,
    :meth:`resynthesize`); ``alpha_floor``: lower bound of every α_j in the bundle's LP.

    The energy (:class:`.energy.EnergyModel`) is exposed as ``states``, ``forces``,
    ``energy`` and ``measure``.
    """

    def __init__(self, ch: Character, target: Motion, footsteps: tuple[Footstep, ...], *,
                 solve_iter: int = 80, collocation_hz: float = 30.0, tol: float = 1e-4,
                 ipopt_options: tuple = WARM_START, feas_tol: float = 1e-3, rounds: int = 1,
                 cyclic: bool = False, soft_pin_hz: float = 0.0, local: bool = False,
                 hessian: str = "gauss_newton", alpha_floor: float = 0.0):
        self.ch, self.target, self.footsteps = ch, target, tuple(footsteps)
        self.alpha_floor = alpha_floor
        self.local = local
        self.verbose = False
        self.rounds = rounds
        self.feas_tol = feas_tol
        # The local counterexample always takes the Gauss–Newton step: with the exact Hessian
        # (indefinite at X_T) its KKT step goes to a saddle and found nothing below E(X_T) on
        # 07_01 (G = 0 at the first iteration, measured).
        self.hessian = hessian
        sp = Subproblem(ch, default_style(ch.total_mass), target, self.footsteps, free=frozenset({"q"}),
                        collocation_hz=collocation_hz, max_iter=solve_iter, tol=tol, label="nio",
                        ipopt_options=tuple(ipopt_options), cyclic=cyclic, soft_pin_hz=soft_pin_hz,
                        hessian="gauss_newton" if local else hessian)
        t = _time.perf_counter()
        self.cx = Counterexamples.build(sp, feas_tol)
        self.sp, self.nlp, self.built = self.cx.sp, self.cx.nlp, self.cx.built
        self.build_seconds = _time.perf_counter() - t
        self.model = EnergyModel(ch, self.nlp, target)
        self.N = self.model.N
        self.states, self.forces = self.model.states, self.model.forces
        self.energy, self.measure = self.model.energy, self.model.measure
        self.n_solves = 0
        self.solve_seconds = 0.0

    # --- counterexamples ---------------------------------------------------------------------
    def counterexample(self, theta: np.ndarray, start: Motion | None = None,
                       lam0: np.ndarray | None = None) -> Result:
        """X_S: the spacetime solve for style θ warm-started at ``start`` (default X_T)."""
        t = _time.perf_counter()
        res = self.cx.solve(theta, start, lam0)
        self.solve_seconds += _time.perf_counter() - t
        self.n_solves += 1
        return res

    def local_counterexample(self, theta: np.ndarray, start: Motion, lam0: np.ndarray,
                             steps: tuple[float, ...] = LOCAL_STEPS) -> tuple[Motion, float]:
        """The Gauss–Newton counterexample from ``start`` (:meth:`.Counterexamples.local`);
        returns (motion, worst constraint violation)."""
        out = self.cx.local(theta, start, lam0, lambda th, m: self.measure(th, m)[0], steps)
        self.n_solves += 1
        return out

    # --- G(θ) --------------------------------------------------------------------------------
    def evaluate(self, theta: np.ndarray, candidates: tuple[Motion, ...] = ()) -> Evaluation:
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
        return Evaluation(theta, ET - ES, D, ET, ES, gT - gS + gD, XS, FS, res)

    # --- the learning loop -------------------------------------------------------------------
    def initial_theta(self, base: Style | None = None, rest_from_target: bool = True,
                      springs_from_target: bool = True) -> np.ndarray:
        """The paper's initial θ for X_T (:func:`.initial.initial_theta`)."""
        return initial_theta(self.model, self.target, base, rest_from_target, springs_from_target)

    def run(self, theta0: np.ndarray, *, method: str = "bundle", **kw) -> NIOResult:
        """Minimise G + D from θ0.  ``method``: "bundle" (default; :func:`.bundle.run_bundle`)
        or "gradient" (the paper's step, :func:`.gradient.run_gradient`)."""
        if method == "gradient":
            return self.run_gradient(theta0, **kw)
        if method != "bundle":
            raise ValueError(f"unknown NIO method {method!r}")
        return self.run_bundle(theta0, **kw)

    def run_bundle(self, theta0: np.ndarray, **kw) -> NIOResult:
        return run_bundle(self, theta0, **kw)

    def run_gradient(self, theta0: np.ndarray, **kw) -> NIOResult:
        return run_gradient(self, theta0, **kw)

    # --- re-synthesis ------------------------------------------------------------------------
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
