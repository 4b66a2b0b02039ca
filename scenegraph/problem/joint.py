"""Two characters in one NLP: a hard hand-hold solved simultaneously (the monolithic problem).

The schedules of thesis §6.4 solve coupled characters one at a time with a rubber band.  This
module solves the problem they approximate, for comparison (issue #7's ``monolithic_ratio``):
both characters' full-dynamics spacetime subproblems as **one** IPOPT NLP,

    min  E_a(x_a) + E_b(x_b)
    s.t. each character's own constraints (footsteps, ground, feet, bounds ...)
         palm_a(t_c) = palm_b(t_c)          at every coupling time t_c (hard hand-hold)

with decision variables x_a, x_b (each character's own transcription, :func:`problem.transcribe`)
and the hand force F(t_c) (N, world, 3 per coupling time).  F acts +F on character a's handle
and −F on character b's (equal and opposite); between coupling times it is interpolated
linearly, so each character's inverse dynamics sees F at its own collocation points.

How the force enters: each character gets a :class:`~scenegraph.problem.Spring` on its
coupled handle whose anchor is an NLP parameter (``NLP.anchor_slices``); here the anchor is
replaced by ``own handle(x) + σ F / k`` (σ = ±1), so the spring force k (anchor − handle) is
exactly σ F — through the very code path (kernel input at the handle, reported as an external
force at the handle) that the schedules' rubber band uses.

The Hessian given to IPOPT is built as :func:`problem.transcribe` builds it (Gauss–Newton 2 JᵀJ
of the stacked residuals of both characters, plus the exact Hessian of every kinematic
constraint, the coupling included), with the same IPOPT options and the same stall rule, so
timings compare like with like.  The timewarps are held (as in the schedules' full steps).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from scenegraph.model.clearance import sphere_centers_fn
from scenegraph.model.motion import basis
from scenegraph.problem import (NLP, Result, SolveTiming, Spring, Subproblem, create_nlpsol, read_solution, solver_options,
                      transcribe, violations)
from scenegraph.model.residual import handles_kernel
from scenegraph.problem.transcription import sphere_pick

__all__ = ["JointCoupling", "JointResult", "build_joint", "solve_joint", "coupling_times", "F_SCALE",
           "JOINT_SPRING_K"]

F_SCALE = 100.0  # N per unit of the force variables (keeps them O(1) like the other variables)
JOINT_SPRING_K = 1000.0  # N/m: stiffness of the stand-in spring (any value: the anchor cancels it)


@dataclass(frozen=True)
class JointCoupling:
    """A hard hold between ``handle_a`` of character a and ``handle_b`` of character b at the
    world times ``times`` (increasing; both characters' timewarps are held, so these are fixed
    canonical times of each).  The force F(t) acts +F on a and −F on b."""

    handle_a: str
    handle_b: str
    times: tuple[float, ...]
    name: str = "hold"


def coupling_times(interval: tuple[float, float], hz: float = 30.0) -> tuple[float, ...]:
    """Uniform coupling times over ``interval`` at ``hz`` (both ends included)."""
    a, b = float(interval[0]), float(interval[1])
    n = max(2, int(round((b - a) * hz)) + 1)
    return tuple(float(t) for t in np.linspace(a, b, n))


@dataclass
class JointBuilt:
    nlps: tuple[NLP, NLP]  # each character's transcription (with its stand-in spring)
    coupling: JointCoupling
    solver: ca.Function
    x0: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    slices: tuple[slice, slice, slice]  # x_a, x_b, force variables in the joint x
    g_slices: tuple[slice, slice, slice]  # g_a, g_b, coupling rows in the joint g
    p_of: ca.Function  # joint x -> (p_a, p_b) with the anchors substituted
    palms: ca.Function  # joint x -> (handle_a, handle_b) at the coupling times (3 × n each)
    monitor: object
    seconds_build: float
    callback: object = None  # the iteration callback in use (the monitor, or one from nlpsol_options)
    clear_fn: object = None  # joint x -> the bodies-apart rows between the two (≥ 0 when met), or None


@dataclass
class JointResult:
    results: tuple[Result, Result]  # per character (contact_forces include the coupling force)
    force_times: np.ndarray  # coupling times (s)
    force: np.ndarray  # (n, 3) N, acting on character a (b feels −force)
    status: str
    success: bool
    iterations: int
    seconds: float  # build + solve (wall)
    seconds_build: float
    seconds_solve: float
    objective: float
    gap_max: float  # m, max |handle_a − handle_b| at the coupling times
    violations: dict
    timing: SolveTiming | None = None  # of the joint solve (each character's Result carries the same)

    def summary(self) -> str:
        return (f"joint: {self.status} in {self.iterations} it, {self.seconds:.1f} s "
                f"(build {self.seconds_build:.1f} s), objective {self.objective:.4g}, "
                f"E = {self.results[0].energy:.4g} + {self.results[1].energy:.4g}, "
                f"hand gap {self.gap_max * 100:.3g} cm at the coupling times")


def _with_stand_in_spring(sp: Subproblem, handle: str, times) -> Subproblem:
    if "warp" in sp.free:
        raise ValueError("build_joint: the timewarp must be held (coupling times are fixed world times)")
    if sp.dynamics != "full":
        raise ValueError("build_joint: both subproblems must have full dynamics")
    zeros = tuple((0.0, 0.0, 0.0) for _ in times)
    return replace(sp, springs=(Spring(handle, tuple(times), zeros, JOINT_SPRING_K, name="joint"),))


def _interp_matrix(t_from: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """M (len(t_to), len(t_from)): linear interpolation of nodal values at t_from onto t_to
    (rows outside [t_from[0], t_from[-1]] are zero)."""
    M = np.zeros((len(t_to), len(t_from)))
    eye = np.eye(len(t_from))
    for i, t in enumerate(t_to):
        if t_from[0] - 1e-9 <= t <= t_from[-1] + 1e-9:
            M[i] = [np.interp(t, t_from, eye[:, j]) for j in range(len(t_from))]
    return M


def _handle_fn(b: NLP, handle: str, s: np.ndarray) -> ca.Function:
    """x -> handle position (3 × len(s)) at canonical times s (SX, expandable)."""
    sp = b.sp
    xs = ca.SX.sym("x", b.x0.size)
    P = b.ctrl_fn(xs, b.p0)  # (K, 35)
    Q = ca.mtimes(ca.DM(basis(sp.motion.n_ctrl, s, 0)), P).T  # (35, n)
    hk = handles_kernel(sp.character, (handle,))
    return ca.Function("handle", [xs], [hk.map(len(s))(Q)])


def _split_clearance(sp_a: Subproblem, sp_b: Subproblem, names: tuple[str, str] | None):
    """(sp_a, sp_b, cross): each subproblem without its clearance rows against the other (held
    at the other's start-of-step motion, which moves in a joint solve), and a's such rows, to be
    enforced between the two moving characters (:mod:`scenegraph.model.clearance`)."""
    if names is None:
        return sp_a, sp_b, ()

    def against(c, who: str) -> bool:
        return c.other.split("/", 1)[0] == who

    cross = tuple(c for c in sp_a.clearance if against(c, names[1]) and c.other_sphere >= 0)
    return (replace(sp_a, clearance=tuple(c for c in sp_a.clearance if not against(c, names[1]))),
            replace(sp_b, clearance=tuple(c for c in sp_b.clearance if not against(c, names[0]))), cross)


def _spheres_fn(b: NLP, s: np.ndarray) -> ca.Function:
    """x -> body sphere centres (3·n_spheres × len(s), world m) at canonical times s (SX)."""
    sp = b.sp
    xs = ca.SX.sym("x", b.x0.size)
    Q = ca.mtimes(ca.DM(basis(sp.motion.n_ctrl, s, 0)), b.ctrl_fn(xs, b.p0)).T  # (35, n)
    return ca.Function("spheres", [xs], [sphere_centers_fn(sp.character).map(len(s))(Q)])


def build_joint(sp_a: Subproblem, sp_b: Subproblem, coupling: JointCoupling,
                names: tuple[str, str] | None = None) -> JointBuilt:
    """Transcribe both subproblems (each with a stand-in spring on its coupled handle) and
    combine them into one IPOPT NLP with the hard coupling; see the module docstring.

    ``names`` (the characters' names): a's clearance rows against b become rows between the two
    moving characters, ‖c_i^a(t) − c_j^b(t)‖² ≥ (R_i + R_j)² (m²), and b's against a are dropped
    (the same pairs); without it each keeps its rows against the other's start-of-step motion."""
    t0 = _time.perf_counter()
    sp_a, sp_b, cross = _split_clearance(sp_a, sp_b, names)
    tc = np.asarray(coupling.times, float)
    nc = len(tc)
    bs = (transcribe(_with_stand_in_spring(sp_a, coupling.handle_a, tc)),
          transcribe(_with_stand_in_spring(sp_b, coupling.handle_b, tc)))
    na, nb, nf = bs[0].x0.size, bs[1].x0.size, 3 * nc
    X = ca.MX.sym("X", na + nb + nf)
    xa, xb, u = X[:na], X[na:na + nb], X[na + nb:]
    Xs = ca.SX.sym("Xs", na + nb + nf)
    xas, xbs = Xs[:na], Xs[na:na + nb]
    Fn = F_SCALE * ca.reshape(u, 3, nc)  # force on a at the coupling times (3, nc)

    # each character's p with its anchor replaced by own handle + σ F / k
    p_exprs, handle_c = [], []
    for b, x, xsym, handle, sign in ((bs[0], xa, xas, coupling.handle_a, 1.0),
                                     (bs[1], xb, xbs, coupling.handle_b, -1.0)):
        sl = b.anchor_slices[0]
        t_pts = b.sp.motion.time(b.s_eval)  # the anchors are sampled at the evaluation points
        M = _interp_matrix(tc, t_pts)  # (N, nc)
        own = _handle_fn(b, handle, b.s_eval)(x)  # (3, Ne)
        anchor = own + sign * ca.mtimes(Fn, ca.DM(M.T)) / JOINT_SPRING_K
        p_exprs.append(ca.vertcat(ca.DM(b.p0[:sl.start]), ca.vec(anchor), ca.DM(b.p0[sl.stop:])))
        handle_c.append(_handle_fn(b, handle, b.sp.motion.to_canonical(tc))(xsym))
    pa, pb = p_exprs

    # objective: the stacked residuals of both characters
    rho_dyn = ca.vertcat(bs[0].rho_dyn_fn(xa, pa), bs[1].rho_dyn_fn(xb, pb))
    rho_xs = ca.vertcat(bs[0].rho_extra_fn(xas, bs[0].p0), bs[1].rho_extra_fn(xbs, bs[1].p0))
    rho_x = ca.Function("rho_x", [Xs], [rho_xs])(X)
    f = ca.sumsqr(rho_dyn) + ca.sumsqr(rho_x)

    # constraints: each character's own, then the coupling (handle_a − handle_b at tc)
    gap = ca.vec(handle_c[0] - handle_c[1])
    ga, gb = bs[0].g_fn(xas, bs[0].p0), bs[1].g_fn(xbs, bs[1].p0)
    rows = []
    if cross:  # bodies apart, both moving
        tcl = np.array(sorted({c.t for c in cross}))
        col = {float(t): k for k, t in enumerate(tcl)}
        Ca = _spheres_fn(bs[0], bs[0].sp.motion.to_canonical(tcl))(xas)
        Cb = _spheres_fn(bs[1], bs[1].sp.motion.to_canonical(tcl))(xbs)
        mine = sphere_pick(cross, col, Ca.shape) @ ca.vec(Ca)
        theirs = sphere_pick([replace(c, sphere=c.other_sphere) for c in cross], col, Cb.shape) @ ca.vec(Cb)
        d = ca.reshape(mine - theirs, 3, len(cross))
        rows = [ca.sum1(d * d).T - ca.DM([c.radius ** 2 for c in cross])]
    gs = ca.vertcat(ga, gb, gap, *rows)
    ng_a, ng_b = bs[0].lbg.size, bs[1].lbg.size
    lbg = np.concatenate([bs[0].lbg, bs[1].lbg, np.zeros(nf), np.zeros(len(cross))])
    ubg = np.concatenate([bs[0].ubg, bs[1].ubg, np.zeros(nf), np.full(len(cross), np.inf)])
    g = ca.Function("g_joint", [Xs], [gs])(X)

    # Hessian as in problem.transcribe: Gauss–Newton objective + exact constraint Hessian
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", gs.shape[0])
    J_dyn = ca.jacobian(rho_dyn, X)
    J_x = ca.Function("J_x", [Xs], [ca.jacobian(rho_xs, Xs)])(X)
    lam_s = ca.SX.sym("lam_s", gs.shape[0])
    Hc = ca.Function("H_con", [Xs, lam_s], [ca.hessian(ca.dot(lam_s, gs), Xs)[0]])(X, lam_g)
    H = ca.triu(2 * lam_f * (ca.mtimes(J_dyn.T, J_dyn) + ca.mtimes(J_x.T, J_x)) + Hc)
    empty = ca.MX.sym("p", 0)
    hess = ca.Function("nlp_hess_l", [X, empty, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"],
                       ["hess_gamma_x_x"])
    ps = ca.SX.sym("p", 0)
    jac_g = ca.Function("nlp_jac_g", [Xs, ps], [gs, ca.jacobian(gs, Xs)], ["x", "p"], ["g", "jac_g_x"])
    # sp_a's options (ipopt_options, nlpsol_options), the larger iteration cap and the tighter tol
    opts = {"hess_lag": hess, "jac_g": jac_g,
            **solver_options(sp_a, max_iter=max(sp_a.max_iter, sp_b.max_iter), tol=min(sp_a.tol, sp_b.tol))}
    solver, monitor, callback = create_nlpsol("joint", {"x": X, "p": empty, "f": f, "g": g}, opts, lbg, ubg,
                                              max(sp_a.stall_iterations, sp_b.stall_iterations))

    x0 = np.concatenate([bs[0].x0, bs[1].x0, np.zeros(nf)])
    lbx = np.concatenate([bs[0].lbx, bs[1].lbx, np.full(nf, -np.inf)])
    ubx = np.concatenate([bs[0].ubx, bs[1].ubx, np.full(nf, np.inf)])
    return JointBuilt(bs, coupling, solver, x0, lbx, ubx, lbg, ubg,
                      (slice(0, na), slice(na, na + nb), slice(na + nb, na + nb + nf)),
                      (slice(0, ng_a), slice(ng_a, ng_a + ng_b), slice(ng_a + ng_b, ng_a + ng_b + nf)),
                      ca.Function("p_of", [X], [pa, pb]),
                      ca.Function("palms", [Xs], handle_c), monitor, _time.perf_counter() - t0, callback,
                      ca.Function("clear", [Xs], [ca.vertcat(*rows)]) if rows else None)


def _character_result(b: NLP, x: np.ndarray, p: np.ndarray, status: str, ok: bool, iterations: int,
                      seconds: float, objective: float, timing: SolveTiming) -> Result:
    """A per-character Result read off the joint solution (as problem.solve reads its own)."""
    motion, steps, energy, contact = read_solution(b, x, p)
    return Result(motion, steps, status, ok, iterations, seconds, energy, objective,
                  violations(b, x, p), contact, b.sp.label, timing)


def solve_joint(sp_a: Subproblem, sp_b: Subproblem, coupling: JointCoupling,
                built: JointBuilt | None = None, names: tuple[str, str] | None = None) -> JointResult:
    """Build (unless given) and solve the joint NLP, warm-started from both subproblems' motions
    (``names``: see :func:`build_joint`)."""
    t0 = _time.perf_counter()
    jb = built or build_joint(sp_a, sp_b, coupling, names)
    t1 = _time.perf_counter()
    if jb.monitor is not None and hasattr(jb.monitor, "reset"):
        jb.monitor.reset()
    cb_before = getattr(jb.callback, "seconds", 0.0)
    t_call = _time.perf_counter()
    sol = jb.solver(x0=jb.x0, lbx=jb.lbx, ubx=jb.ubx, lbg=jb.lbg, ubg=jb.ubg)
    t2 = _time.perf_counter()
    stats = jb.solver.stats()
    x = np.asarray(sol["x"]).ravel()
    f_final = float(sol["f"])
    m_ = jb.monitor  # as problem.solve: IPOPT ending worse than a feasible iterate it passed
    if m_ is not None and getattr(m_, "best_x", None) is not None and m_.best < f_final - 1e-9 * max(1.0, abs(f_final)):
        x, f_final = m_.best_x, m_.best
    status = stats.get("return_status", "unknown")
    ok = bool(stats.get("success", False)) or status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    if jb.monitor is not None and jb.monitor.stalled and status == "User_Requested_Stop":
        status, ok = "Stalled", True
    iters = int(stats.get("iter_count", -1))
    pa, pb = (np.asarray(v).ravel() for v in jb.p_of(x))
    seconds = t2 - t0  # build (unless given) + solve
    timing = SolveTiming.from_stats(stats, build=t1 - t0 if built is None else 0.0,
                                    callbacks=getattr(jb.callback, "seconds", 0.0) - cb_before,
                                    solver_wall=t2 - t_call, total=seconds)
    res = tuple(_character_result(b, x[sl], p, status, ok, iters, seconds, f_final, timing)
                for b, sl, p in zip(jb.nlps, jb.slices[:2], (pa, pb)))
    ha, hb = (np.asarray(v) for v in jb.palms(x))
    gap = float(np.linalg.norm(ha - hb, axis=0).max())
    viol = {}
    for r in res:
        for k, v in r.violations.items():
            viol[k] = max(viol.get(k, 0.0), v)
    viol["coupling"] = float(np.abs(ha - hb).max())
    if jb.clear_fn is not None:  # squared-distance rows (m²): how far inside the summed radii
        viol["clearance"] = max(viol.get("clearance", 0.0), float(max(0.0, -np.min(np.asarray(jb.clear_fn(x))))))
    force = F_SCALE * x[jb.slices[2]].reshape(-1, 3)  # column-major (3, nc) -> rows per time
    return JointResult(res, np.asarray(coupling.times, float), force, status, ok, iters, seconds,
                       jb.seconds_build if built is None else 0.0, t2 - t1, f_final, gap, viol, timing)
