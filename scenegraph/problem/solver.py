"""Solving a transcribed subproblem with IPOPT: options, iteration callbacks, nlpsol creation, solve.

:func:`solver_options` builds the CasADi ``nlpsol`` options of a :class:`~.subproblem.Subproblem`
(``max_iter``, ``tol``, the project's IPOPT defaults, then ``ipopt_options`` and
``nlpsol_options``; the environment variable ``COMPOSE_IPOPT_PRINT`` sets IPOPT's print level,
``COMPOSE_IPOPT_TIMING=1`` adds IPOPT's timing statistics).
:func:`make_solver` creates the IPOPT solver of an :class:`~.transcription.NLP` (with a
:class:`StallMonitor` when ``stall_iterations`` > 0) and returns a :class:`Built`;
:func:`solve` transcribes (unless given a :class:`Built`), solves and reads the
:class:`~.result.Result`, with its :class:`~.result.SolveTiming` (wall seconds).
"""
from __future__ import annotations

import os as _os
import time as _time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from scenegraph.problem.result import Result, SolveTiming, read_solution, violations
from scenegraph.problem.subproblem import Subproblem
from scenegraph.problem.transcription import NLP, transcribe

__all__ = ["Built", "IterationCallback", "StallMonitor", "STALL_RATE", "STALL_VIOL", "solver_options",
           "create_nlpsol", "make_solver", "build", "solve"]

STALL_RATE = 1e-3  # mean relative gain per feasible iterate, over the last `patience`, that counts as
# progress: Gauss–Newton creeps on large-residual windows (a walk_to_run window: −26 % of its
# objective over its last 270 of 300 iterations, 0.1 % per iterate); below this it stops
STALL_VIOL = 1e-5  # worst constraint violation (m, or the constraint's unit) of a stalled iterate


class IterationCallback(ca.Callback):
    """Base of IPOPT iteration callbacks: receives nlpsol's outputs (x, f, g, multipliers) of
    an NLP with ``nx`` variables and ``ng`` constraints; subclasses implement ``on_iterate``
    (returning [0] to continue, [1] to stop) and read ``violation(g)`` (worst violation of
    [lbg, ubg]).  ``seconds`` accumulates the wall time spent in ``on_iterate`` (SolveTiming)."""

    def __init__(self, name: str, nx: int, ng: int, lbg: np.ndarray, ubg: np.ndarray):
        ca.Callback.__init__(self)
        self.nx, self.ng, self.lbg, self.ubg = nx, ng, np.asarray(lbg, float), np.asarray(ubg, float)
        self.seconds = 0.0
        self.construct(name, {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        size = {"f": (1, 1), "g": (self.ng, 1), "lam_g": (self.ng, 1), "p": (0, 0), "lam_p": (0, 0)}
        return ca.Sparsity.dense(*size.get(ca.nlpsol_out(i), (self.nx, 1)))

    def violation(self, g) -> float:
        g = np.asarray(g).ravel()
        return float(np.max(np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0), initial=0.0))

    def eval(self, arg):
        t = _time.perf_counter()
        try:
            return self.on_iterate(arg)
        finally:
            self.seconds += _time.perf_counter() - t

    def on_iterate(self, arg):
        raise NotImplementedError


class StallMonitor(IterationCallback):
    """IPOPT iteration callback: stop once the best feasible objective (every constraint held
    to STALL_VIOL) has improved by less than STALL_RATE (relative) per iterate on average over
    the last ``patience`` feasible iterates (infeasible iterates are not counted).

    Windows whose held boundary leaves residuals that cannot vanish are large-residual least
    squares; there the Gauss–Newton Hessian converges only linearly, and IPOPT can spend
    hundreds of iterations on the last digits of a flat objective.  ``stalled`` records why
    the solve stopped; ``best_x`` is the best feasible iterate, which :func:`solve` returns
    when IPOPT ends somewhere worse (warm-started from a good motion, IPOPT's first barrier
    iterations can leave it and stall at a higher energy: a seam window started at E ≈ 1.4e3
    stalled at 1.1e4).
    """

    def __init__(self, nx: int, ng: int, lbg: np.ndarray, ubg: np.ndarray, patience: int):
        self.patience = patience
        self.reset()
        super().__init__("stall_monitor", nx, ng, lbg, ubg)

    def reset(self) -> None:
        self.best, self.stalled, self.best_x = np.inf, False, None
        self.trace: list[float] = []  # best feasible objective after each feasible iterate

    def on_iterate(self, arg):
        f = float(arg[ca.nlpsol_out().index("f")])
        if self.violation(arg[ca.nlpsol_out().index("g")]) > STALL_VIOL:
            return [0]  # not counted (restarting the count let a blip every ~25 iterates run a solve to its cap)
        if f < self.best:
            self.best, self.best_x = f, np.array(arg[ca.nlpsol_out().index("x")], float).ravel()
        self.trace.append(self.best)
        if len(self.trace) > self.patience:
            gained = self.trace[-1 - self.patience] - self.best
            if gained <= STALL_RATE * self.patience * max(1e-9, abs(self.best)):
                self.stalled = True
                return [1]
        return [0]


def solver_options(sp: Subproblem, *, max_iter: int | None = None, tol: float | None = None) -> dict:
    """CasADi nlpsol options (IPOPT's under "ipopt") of ``sp``, without the derivative functions:
    the project's IPOPT settings, then ``sp.ipopt_options`` and ``sp.nlpsol_options`` on top.
    ``max_iter`` / ``tol`` replace the subproblem's (the joint problem combines two)."""
    opts = {
        "print_time": False,
        "ipopt": {"print_level": int(_os.environ.get("COMPOSE_IPOPT_PRINT", "0")),
                  "max_iter": sp.max_iter if max_iter is None else max_iter, "tol": sp.tol if tol is None else tol,
                  "acceptable_tol": 1e-4, "acceptable_iter": 5, "mu_strategy": "adaptive",
                  "linear_solver": "mumps", "sb": "yes"},
    }
    if _os.environ.get("COMPOSE_IPOPT_TIMING"):  # profiling: IPOPT's timing statistics at the end
        opts["ipopt"]["print_timing_statistics"] = "yes"
    opts["ipopt"].update(dict(sp.ipopt_options))
    opts.update(dict(sp.nlpsol_options))
    return opts


def create_nlpsol(name: str, problem: dict, options: dict, lbg: np.ndarray, ubg: np.ndarray,
                  patience: int) -> tuple[ca.Function, StallMonitor | None, ca.Callback | None]:
    """``ca.nlpsol(name, "ipopt", problem, options)`` with a StallMonitor of ``patience`` as the
    iteration callback when ``patience`` > 0 (it replaces one given in ``options``); returns
    (solver, monitor or None, the iteration callback in use or None)."""
    monitor = None
    options = dict(options)
    if patience > 0:
        monitor = StallMonitor(problem["x"].shape[0], problem["g"].shape[0], np.asarray(lbg, float),
                               np.asarray(ubg, float), patience)
        options["iteration_callback"] = monitor
    return ca.nlpsol(name, "ipopt", problem, options), monitor, options.get("iteration_callback")


@dataclass(frozen=True)
class Built:
    """An NLP with the IPOPT solver created for it (reusable: one Built serves many solves)."""

    nlp: NLP
    solver: ca.Function  # casadi nlpsol (IPOPT)
    monitor: StallMonitor | None = None  # when Subproblem.stall_iterations > 0
    callback: ca.Callback | None = None  # the iteration callback in use (the monitor, or one from nlpsol_options)
    seconds: float = 0.0  # wall time of the transcription and the nlpsol creation


def make_solver(nlp: NLP, sp: Subproblem | None = None) -> Built:
    """The IPOPT solver of ``nlp`` with the options of ``sp`` (default ``nlp.sp``): the NLP's own
    Lagrangian Hessian and constraint Jacobian (see the transcription), ``solver_options(sp)``."""
    sp = nlp.sp if sp is None else sp
    t = _time.perf_counter()
    options = {"hess_lag": nlp.hess_lag, "jac_g": nlp.jac_g, **solver_options(sp)}
    solver, monitor, callback = create_nlpsol("spacetime", {"x": nlp.x, "p": nlp.p, "f": nlp.f, "g": nlp.g},
                                              options, nlp.lbg, nlp.ubg, sp.stall_iterations)
    return Built(nlp, solver, monitor, callback, _time.perf_counter() - t)


def build(sp: Subproblem) -> Built:
    """Transcribe ``sp`` and create its IPOPT solver."""
    t = _time.perf_counter()
    return replace(make_solver(transcribe(sp), sp), seconds=_time.perf_counter() - t)


def solve(sp: Subproblem, built: Built | None = None, *, x0: np.ndarray | None = None,
          p: np.ndarray | None = None) -> Result:
    """Build (unless given) and solve a subproblem with IPOPT, warm-started from sp.motion
    (the NLP's ``x0``) or from ``x0``, with the NLP's parameters ``p0`` or ``p``."""
    t_start = _time.perf_counter()
    b = built if built is not None else build(sp)
    t_built = _time.perf_counter()
    nlp = b.nlp
    x0 = nlp.x0 if x0 is None else x0
    p = nlp.p0 if p is None else p
    if b.monitor is not None:
        b.monitor.reset()
    cb_before = getattr(b.callback, "seconds", 0.0)
    t_call = _time.perf_counter()
    sol = b.solver(x0=x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg, p=p)
    solver_wall = _time.perf_counter() - t_call
    stats = b.solver.stats()
    x = np.asarray(sol["x"]).ravel()
    f_final = float(sol["f"])
    m_ = b.monitor
    if m_ is not None and m_.best_x is not None and m_.best < f_final - 1e-9 * max(1.0, abs(f_final)):
        x, f_final = m_.best_x, m_.best  # IPOPT ended worse than a feasible iterate it passed
    motion, steps, energy, contact = read_solution(nlp, x, p)
    viol = violations(nlp, x, p)
    status = stats.get("return_status", "unknown")
    ok = bool(stats.get("success", False)) or status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    if b.monitor is not None and b.monitor.stalled and status == "User_Requested_Stop":
        status, ok = "Stalled", True
    seconds = _time.perf_counter() - t_start
    timing = SolveTiming.from_stats(stats, build=t_built - t_start if built is None else 0.0,
                                    callbacks=getattr(b.callback, "seconds", 0.0) - cb_before,
                                    solver_wall=solver_wall, total=seconds)
    return Result(motion, tuple(steps), status, ok, int(stats.get("iter_count", -1)),
                  seconds, energy, f_final, viol, contact, sp.label, timing)
