"""Transcription of one subproblem into an NLP: :func:`transcribe` (``Subproblem`` → :class:`NLP`).

The NLP is handed to IPOPT by :mod:`.solver`; nothing here creates a solver.  Units: world
times in s, positions in m (z up), forces in N; the objective is normalised by
(OBJ_SCALE / m g)² (residuals in units of body weight).

Transcription
-------------
Decision variables: the free DOF spline control points, the free timewarp control points,
contact coefficients λ ≥ 0 (four per planted handle per node; the contact force is m g V λ
with V the friction-pyramid basis) and free footprint positions.  The energy (paper Eq. 13)

    E = Σ_k w_k T'(s_k) [ Σ_j α_j Q_mj(s_k)² + w_r Σ_i Q_0i(s_k)² ]

is a sum of squares of residuals computed by one per-point kernel (inverse dynamics plus
passive, contact and shoe terms) that is compiled to C with its first derivatives.

Dense dynamics (``Subproblem.dense_dynamics``, the default; issue #15 item 2).  The equations
of motion must hold between the points too, not only at them:

* **nodes** (:func:`_node_grid`): every knot interval of the motion's B-splines cut into
  ⌈collocation_hz / knot rate⌉ equal parts (the knots are nodes: q̈ is linear in s
  between knots and kinks at them), plus every contact handle's touch-down and lift-off and
  every flight's take-off and landing (never merged: each is where a force starts or ends);
* **forces between nodes**: a handle's contact force is piecewise linear in s between its
  nodes, and λ = 0 at a touch-down or lift-off inside the motion — the B-spline motion has a
  continuous q̈, so a force that jumped there could not be balanced on both sides of it (on
  the round-8 grid the force at a lift-off point was up to 1.3 body weights and nothing the
  instant after: 1.5 bw of dynamics residual in a walk, 4 bw in a run);
* **evaluation points**: the kernel is evaluated at every node and at the midpoint of every
  node interval (forces and per-point style interpolated linearly, spring anchors sampled), summed
  with Simpson's weights — the objective is the integral of the squared residual, exact
  for a quadratic one — so the residual between nodes is what the solver minimises, and in a
  flight (``flights``) every evaluation point carries W_FLIGHT.

Jerk penalty (``Subproblem.jerk_weight``, full steps; :mod:`.jerk`): the jump of every joint's
third derivative at each knot, as the generalised force it amounts to, is a least-squares row — a
cubic spline can otherwise zig-zag its acceleration from knot to knot (the arms flailing at 1000+
rad/s² where the style makes their torques almost free).  The knots next to a planned contact
change (a footstep's first touch-down and last lift-off, a flight's ends: :func:`.jerk.contact_events`)
carry no row: there the true motion's jerk jumps.

Joint-speed ceilings (``Subproblem.joint_speed_limit``, full dynamics with a held warp;
:mod:`scenegraph.model.joint_speed`): each joint's speed over the fastest human one, bounded
through its control-point differences, is a one-sided least-squares term (zero below).

``dense_dynamics=False`` gives the round-8 transcription (uniform points plus contact ends,
forces only at the points, trapezoid weights), kept for comparison (tests/problem/
test_dense_dynamics.py); the independent check is :mod:`scenegraph.model.dense_audit`.
IPOPT gets a **Gauss–Newton Hessian** (2 JᵀJ of the residuals; the dynamics' JᵀJ assembled
point by point, :mod:`.gram`, when the timewarp is held) plus the exact Hessian of
the kinematic constraints by default; ``Subproblem(hessian="exact")`` adds the residual
curvature 2 Σ r ∇²r (a compiled per-point kernel Hessian, :func:`~scenegraph.model.residual.kernel_hessian`, chained
through the splines; see README "Exact Hessian" for what it measured).  Style θ and all
fixed data are NLP parameters, so one built problem serves many solves (NIO).

Constraints: footsteps (planted handles at their footprint on the ground), ground
non-penetration of the foot handles, feet not crossing (thesis Eq. 6.3), joint limits
(bounds on control points: a B-spline stays in the hull of its control points), monotone
timewarp (Eq. 6.1), optional boundary states and avoid-spheres; soft springs toward
handle targets and poses (continuations).

Layout
------
x = [ctrl (free control points, row-major (K, 35) entries) | warp (free timewarp control
points, s) | footprints (x, y per free footstep, m) | lambda (4 per planted (handle, point))];
p = [ctrl_fixed (all K·35 control points) | warp_fixed (nW) | anchors (3 × N_e per spring, at s_eval,
column-major, m) | theta (N_THETA × N, column-major) | sqrt_alpha (29 × N, column-major)].
:attr:`NLP.x_layout` and :attr:`NLP.p_layout` name these slices, so callers (NIO, the joint
problem) substitute parameters by name instead of by offset arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from scenegraph.model.body import G, N_DOF, N_JOINT, N_ROOT, Character
from scenegraph.model.clearance import sphere_centers_fn
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.joint_speed import SPEED_WEIGHT, max_speed, speed_rows
from scenegraph.model.dynamics import shoe_force
from scenegraph.model.motion import basis
from scenegraph.model.shoe import SIDES, gate_breaks, shoe_gate
from scenegraph.model.residual import (CONTACT_HANDLES, FORCE_HANDLES, N_THETA, W_ROOT, compiled_kernel, handles_kernel,
                        kernel_hessian, theta_kernel_vector)
from scenegraph.problem.flight import flight_constraints, flight_groups, flight_hessian, flight_jacobian, momenta_fn
from scenegraph.problem.gram import dynamics_gauss_newton
from scenegraph.problem.jerk import contact_events, jerk_rows
from scenegraph.problem.no_slip import no_slip_residuals
from scenegraph.problem.stance_frame import stance_frame_residuals
from scenegraph.problem.subproblem import HESSIAN_MODES, Subproblem

__all__ = ["NLP", "transcribe", "window_mask", "flight_root_weights", "flight_points", "W_FLIGHT", "OBJ_SCALE", "KIN_WEIGHT",
           "FREE_WEIGHT_MIN"]

W_FLIGHT = 1e6  # root residual weight in flight stages (W_ROOT elsewhere): a jump's flight is ballistic
OBJ_SCALE = 30.0  # objective = (OBJ_SCALE / m g)² E: O(1–100) so IPOPT's tolerances mean something
KIN_WEIGHT = 3.0  # pull toward the initial motion in kinematic pre-solves
FREE_WEIGHT_MIN = 0.05  # B-spline weight of the free control points below which a point counts as held


@dataclass(frozen=True, kw_only=True)
class NLP:
    """A transcribed subproblem: min f(x, p) s.t. lbg ≤ g(x, p) ≤ ubg, lbx ≤ x ≤ ubx.

    Symbols and expressions (MX) for the solver, numeric data (bounds, start ``x0``, the
    parameter values ``p0`` of ``sp``), the named layout of x and p, and what is needed to
    read a solution (:func:`.result.read_solution`) or to combine several NLPs into one
    (``scenegraph/problem/joint.py``).
    """

    sp: Subproblem
    x: ca.MX  # decision variables (see x_layout)
    p: ca.MX  # parameters (see p_layout)
    f: ca.MX  # objective of (x, p) = |rho_dyn|² + |rho_extra|²
    g: ca.MX  # constraints of (x, p)
    x0: np.ndarray  # start (warm start from sp.motion)
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    p0: np.ndarray  # parameter values of sp (callers may solve with others, e.g. NIO's θ)
    x_layout: dict[str, slice]  # "ctrl", "warp", "footprints", "lambda" → slice into x
    p_layout: dict[str, slice]  # "ctrl_fixed", "warp_fixed", "anchors", "theta", "sqrt_alpha" → slice into p
    anchor_slices: tuple[slice, ...]  # slice into p of each spring's anchor (3 × N_e at s_eval, column-major)
    f_fn: ca.Function  # x, p -> objective (IPOPT's f)
    g_fn: ca.Function  # x, p -> constraints
    hess_lag: ca.Function | None  # x, p, lam_f, lam_g -> upper triangle of the Lagrangian Hessian given to
    # IPOPT (None: transcribed with derivatives=False)
    jac_g: ca.Function | None  # x, p -> (g, ∂g/∂x) given to IPOPT (SX; None without derivatives)
    unpack: ca.Function  # x, p -> ctrl, warp, foot xy, energy terms, spring forces
    groups: list  # (name, slice into g, kind)
    s_points: np.ndarray  # collocation points (canonical time s)
    contact_index: list  # (handle, k, slice into x) of each planted (handle, collocation point)
    s_eval: np.ndarray  # where the dynamics are evaluated: s_points, then (dense) every interval's midpoint
    free_steps: list  # indices into sp.footsteps of the free footprints, in x order
    contact_basis: tuple = ()  # friction pyramid V (3×4, world) per contact_index entry
    spring_handles: tuple = ()  # handle of each Subproblem.springs entry, in order
    # the transcription's pieces, for problems that combine several NLPs (scenegraph/problem/joint.py):
    rho_dyn_fn: ca.Function | None = None  # x, p -> dynamics residuals (objective = |rho_dyn|² + |rho_extra|²)
    rho_extra_fn: ca.Function | None = None  # x, p -> the other least-squares residuals (SX-expandable)
    ctrl_fn: ca.Function | None = None  # x, p -> control points (K × 35)


def _layout(*sizes: tuple[str, int]) -> dict[str, slice]:
    """Consecutive named slices of the given sizes."""
    out, n = {}, 0
    for name, size in sizes:
        out[name] = slice(n, n + int(size))
        n += int(size)
    return out


def _sparse(a: np.ndarray) -> ca.DM:
    """A constant matrix with its structural zeros dropped (keeps Jacobians sparse)."""
    a = np.asarray(a, float)
    a = np.where(np.abs(a) < 1e-14, 0.0, a)
    return ca.sparsify(ca.DM(a))


def sphere_pick(rows, col: dict, shape: tuple[int, int]) -> ca.DM:
    """Sparse 0/1 matrix picking, for each clearance row (its ``sphere`` at time column
    ``col[row.t]``), the sphere centre's 3 entries out of vec(SC) of an (3·n_spheres × n_times)
    centre matrix SC; one matrix product instead of one slice per row (8100 rows of a hand-hold
    step took a minute to build as slices)."""
    n = len(rows)
    ri = np.arange(3 * n)
    ci = np.array([col[c.t] * shape[0] + 3 * c.sphere + k for c in rows for k in range(3)])
    return ca.DM(ca.Sparsity.triplet(3 * n, shape[0] * shape[1], ri.tolist(), ci.tolist()), 1.0)


def _clearance_terms(sp: Subproblem, P, to_canonical, mask, warp_free):
    """Bodies apart (``sp.clearance``, :mod:`scenegraph.model.clearance`) at the clearance times
    the free control points reach: (one-sided depths inside the summed radii (m), or None;
    squared-distance rows ``‖c − center‖² − R²`` ≥ 0 (m²), or None) — the depths when
    ``sp.clearance_weight`` > 0 (a least-squares term), else the rows (hard)."""
    K = sp.motion.n_ctrl
    t_c = np.array(sorted({c.t for c in sp.clearance}))
    s_c = to_canonical(t_c)
    live_c = _depend_on_free(K, s_c, mask, warp_free)
    if not live_c.any():
        return None, None
    SC = sphere_centers_fn(sp.character).map(int(live_c.sum()))(ca.mtimes(_sparse(basis(K, s_c[live_c], 0)), P).T)
    col = {float(t): k for k, t in enumerate(t_c[live_c])}
    live = [c for c in sp.clearance if c.t in col]
    if not live:
        return None, None
    d = ca.reshape(sphere_pick(live, col, SC.shape) @ ca.vec(SC), 3, len(live)) - ca.DM(np.array([c.center for c in live]).T)
    r = ca.DM([c.radius for c in live])
    if sp.clearance_weight > 0:
        return ca.fmin(ca.sqrt(ca.sum1(d * d)).T - r, 0.0), None
    return None, ca.sum1(d * d).T - r ** 2


def window_mask(sp: Subproblem, n_ctrl: int) -> np.ndarray:
    """Control points free under the window: those whose support lies inside it, so a
    windowed solve never changes the motion (or invalidates contact forces) outside its
    window; the points straddling two windows are freed by the seam window between them.
    With ``open_end`` the points straddling the window's end are free too (a receding window
    leaves its end state to the next one)."""
    if sp.window is None:
        return np.ones(n_ctrl, bool)
    s0, s1 = sp.motion.to_canonical([sp.window[0], sp.window[1]])
    knots = np.linspace(0, 1, n_ctrl - 2)
    mask = np.zeros(n_ctrl, bool)
    for i in range(n_ctrl):
        lo = knots[max(0, i - 3)]
        hi = knots[min(len(knots) - 1, i + 1)] if i + 1 < len(knots) else 1.0
        mask[i] = (lo >= s0 - 1e-9) and (hi <= s1 + 1e-9 or (sp.open_end and lo < s1 - 1e-9))
    return mask


def flight_root_weights(sp: Subproblem, s: np.ndarray, w_r: float) -> np.ndarray:
    """Root residual weight per collocation point (canonical ``s``): W_FLIGHT strictly inside a
    flight stage of ``sp.flights`` (world s; thesis ch. 3: no contact force there, so a zero
    root residual leaves gravity alone to move the centre of mass and keeps the angular
    momentum about it constant), ``w_r`` elsewhere.  A stiff least-squares term rather than
    an equality: the kernel has no second derivatives for constraint curvature."""
    w = np.full(len(s), float(w_r))
    if sp.dynamics == "full" and sp.flight_mode == "penalty":  # "momentum": equalities instead (.flight)
        w[flight_points(sp, s)] = W_FLIGHT
    return w


def flight_points(sp: Subproblem, s: np.ndarray) -> np.ndarray:
    """Which canonical collocation times ``s`` lie in a flight of ``sp.flights``, its ends
    included: at the take-off and touch-down points the contact force is held at zero as well
    (``transcribe``), so the spline's acceleration, linear between points, is ballistic on both
    sides of the flight's first and last intervals — with the ends left out the push-off force
    leaked into the first 30 ms of flight and the landing force into the last (the stage audit
    measured up to 1.08 body weights of missing force there)."""
    out = np.zeros(len(s), bool)
    for fa, fb in sp.flights:
        sa, sb = sp.motion.to_canonical([fa, fb])
        out |= (s > sa - 1e-6) & (s < sb + 1e-6)
    return out


def _depend_on_free(n_ctrl: int, s: np.ndarray, mask: np.ndarray, other_free: bool) -> np.ndarray:
    """Whether a kinematic constraint at each canonical time in ``s`` is a constraint of this
    step: the free control points under it carry at least FREE_WEIGHT_MIN of its B-spline
    weight (or another block it depends on is free).  Constraints on held values are
    constants; ones at the very edge of a window, where a single free control point enters
    with a tiny weight, are nearly so — several of them on one control point make the
    constraint Jacobian nearly rank-deficient (IPOPT then stops with "Error in step
    computation").  One basis evaluation for all times (one per time took 10 s of a 26 s
    build for a window of a 9.6 s scene)."""
    s = np.asarray(s, float)
    if other_free or not len(s):
        return np.full(len(s), bool(other_free))
    return basis(n_ctrl, s)[:, mask].sum(axis=1) >= FREE_WEIGHT_MIN


def _lambda_guess(sp: Subproblem, planted: list, s: np.ndarray, mg: float) -> np.ndarray:
    """Initial contact coefficients: from ``sp.contact_guess`` (handle → (times, forces N),
    e.g. the previous result's) by non-negative least squares, else a constant share."""
    lam = np.full(4 * len(planted), 0.125)
    if not sp.contact_guess:
        return lam
    from scipy.optimize import nnls
    Vs = [mg * V for V in _contact_bases(sp, sp.character, planted)]
    t = sp.motion.time(s)
    for c, (handle, k, _, _) in enumerate(planted):
        if handle in sp.contact_guess:
            times, forces = sp.contact_guess[handle]
            times = np.asarray(times)
            if len(times) and np.min(np.abs(times - t[k])) < 0.02:
                f = np.asarray(forces).reshape(-1, 3)[int(np.argmin(np.abs(times - t[k])))]
                lam[4 * c:4 * c + 4] = nnls(Vs[c], f)[0]
    return lam


def _contact_bases(sp: Subproblem, ch: Character, planted: list) -> list:
    """The ground's friction pyramid V (3×4, world) at each planted (handle, k, xy, step) pair's
    footprint (a free footprint: at its current position); the flat-ground V off slopes."""
    out, cache = [], {}
    for handle, _, _, si in planted:
        if (si, handle) not in cache:
            xy = next(p for h, _, p in contact_points(ch, sp.footsteps[si], None, sp.ground) if h == handle)
            cache[si, handle] = sp.ground.friction_basis(float(xy[0]), float(xy[1]))
        out.append(cache[si, handle])
    return out


def _collocation_grid(sp: Subproblem, ch: Character, hz: float) -> np.ndarray:
    """Uniform points in s at ``hz`` plus every contact interval's ends (so a footprint holds
    exactly from touch-down to lift-off); uniform points too close to an end are dropped."""
    m = sp.motion
    n = max(8, int(round(m.duration * hz)) + 1)
    uniform = np.linspace(0.0, 1.0, n)
    ends = []
    for step in sp.footsteps:
        for _, (ta, tb), _ in contact_points(ch, step):
            ends += [t for t in (ta, tb) if m.start < t < m.end]
    ends = np.unique(np.round(m.to_canonical(ends), 9)) if ends else np.zeros(0)
    h = 1.0 / (n - 1)
    keep = [u for u in uniform if u in (0.0, 1.0) or not np.any(np.abs(ends - u) < 0.4 * h)]
    grid = np.unique(np.r_[keep, ends])
    # merge ends closer than 0.4 h to each other or to the window ends
    out = [grid[0]]
    for v in grid[1:]:
        if v - out[-1] >= 0.4 * h or v == 1.0:
            if v == 1.0 and 1.0 - out[-1] < 0.4 * h and len(out) > 1:
                out[-1] = 1.0
                continue
            out.append(v)
    return np.array(out)


def _node_grid(sp: Subproblem, ch: Character, hz: float) -> np.ndarray:
    """The dense-dynamics node grid (canonical s): every knot interval of the motion's spline cut
    into r = ⌈hz / knot rate⌉ equal parts (node spacing ≤ 1/hz: never fewer points than the
    collocation rate asks — with 24 Hz knots and 30 Hz, 48 Hz nodes; rounding to 24 Hz nodes
    left a run's landing unbalanced by 0.98 body weight, measured), plus every contact
    interval's and flight's ends.

    The knots are kept (the spline's q̈ is linear in s between knots and kinks at them, so a
    force piecewise linear between these nodes can balance it between nodes too); a uniform
    point closer than 0.3 of the spacing to a contact or flight end gives way to the end; ends
    are never merged (each handle's force is zero exactly at its own touch-down and lift-off)."""
    m = sp.motion
    n_int = m.n_ctrl - 3
    r = max(1, int(np.ceil(hz * m.duration / n_int - 1e-9)))
    base = np.linspace(0.0, 1.0, n_int * r + 1)
    is_knot = (np.arange(len(base)) % r) == 0
    ends = []
    for step in sp.footsteps:
        for _, (ta, tb), _ in contact_points(ch, step, None, sp.ground):
            ends += [t for t in (ta, tb) if m.start < t < m.end]
    ends += [t for fa, fb in sp.flights for t in (fa, fb) if m.start < t < m.end]
    if sp.shoe_gate:  # the shoe gate's ramps (scenegraph/model/shoe.py): nodes too
        ends += gate_breaks(ch, sp.footsteps, m.start, m.end, sp.ground)
    ends = np.unique(np.round(m.to_canonical(ends), 12)) if ends else np.zeros(0)
    h = 1.0 / (n_int * r)
    near = np.array([len(ends) > 0 and bool(np.any(np.abs(ends - u) < 0.3 * h)) for u in base])
    keep = base[is_knot | ~near]
    grid = np.unique(np.r_[keep, ends])
    out = [grid[0]]
    for v in grid[1:]:  # points within 1e-7 (a knot on an end): one node
        if v - out[-1] > 1e-7:
            out.append(v)
        elif v in ends:
            out[-1] = v
    return np.array(out)


def _dense_points(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(evaluation points, their quadrature weights, interpolation matrix M (N, N_e)) of the
    dense residual: the N nodes ``s`` first, then the midpoint of every node interval; weights
    of Simpson's rule (h/6 at each end of an interval, 2h/3 at its midpoint), so Σ w Q² is the
    integral of Q² for a quadratic Q; column j of M gives the piecewise-linear interpolant of
    node values at evaluation point j (1 at a node, ½ ½ at a midpoint)."""
    N = len(s)
    h = np.diff(s)
    s_ev = np.r_[s, 0.5 * (s[:-1] + s[1:])]
    w = np.zeros(len(s_ev))
    w[:N - 1] += h / 6
    w[1:N] += h / 6
    w[N:] = 2 * h / 3
    M = np.zeros((N, len(s_ev)))
    M[np.arange(N), np.arange(N)] = 1.0
    M[np.arange(N - 1), N + np.arange(N - 1)] = 0.5
    M[np.arange(1, N), N + np.arange(N - 1)] = 0.5
    return s_ev, w, M


def _touches_free(n_ctrl: int, s: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Which canonical times ``s`` have a position, velocity or acceleration that depends on a
    free control point (``mask``) at all: the dynamics at the other times are constants."""
    if not mask.any():
        return np.zeros(len(s), bool)
    dep = np.zeros(len(s), bool)
    for d in (0, 1, 2):
        dep |= np.any(np.abs(basis(n_ctrl, s, d)[:, mask]) > 0.0, axis=1)
    return dep


def _drop_cyclic_duplicates(pins: list) -> list:
    """Footstep pins of a cyclic motion without the ones the cycle already implies.

    A cyclic motion ends in its start pose moved along the ground (root x, y free).  For a
    handle pinned at both ends, the end pin's height and the placement of every other such
    handle follow from the start pins; only the shift (x, y) is new.  Keeping them all makes
    the constraint Jacobian rank-deficient (IPOPT stops with "Error in step computation"),
    so the first such end pin keeps only its (x, y) and the other such end pins are dropped.
    """
    at_start = {pn[0] for pn in pins if pn[1] < 1e-9}
    repeated = [pn for pn in pins if pn[1] > 1.0 - 1e-9 and pn[0] in at_start]
    if not repeated:
        return pins
    h, v, xy, _, si = repeated[0]
    return [pn for pn in pins if pn not in repeated] + [(h, v, xy, "xy", si)]


def _heel_implied_along_foot(pins: list, heading: dict) -> list:
    """A heel pinned at the same point in time as its foot's ball keeps only its height and its
    position across the foot (rows ``"zn"``).

    Heel and ball lie on one rigid foot at a fixed distance; with the ball's three coordinates and
    the heel's height and sideways offset given, the heel's position along the foot follows.  The
    third row is dependent: every planted point of a flat foot added one dependent row to the
    constraint Jacobian (a 1.3 s walk: 240 footstep rows of rank 215), its multipliers grew to
    ~1e14 and IPOPT's scaled convergence test stopped meaning anything (docs/learning.md).
    """
    balls = {(pn[0].replace("ball_", ""), round(pn[1], 9)) for pn in pins
             if pn[0].startswith("ball_") and pn[3] == "xyz"}
    out = []
    for pn in pins:
        h, v, xy, rows, si = pn
        if h.startswith("heel_") and rows == "xyz" and (h[len("heel_"):], round(v, 9)) in balls:
            pn = (h, v, xy, ("zn", float(heading[si])), si)
        out.append(pn)
    return out


def _pin_rows(d, rows):
    """The constrained components of a pinned handle's offset ``d`` (3-vector) from its target:
    ``"xyz"`` all, ``"xy"`` the horizontal ones (the height implied: a cyclic end), ``("zn",
    heading)`` the height and the horizontal component across a foot of that heading (rad)."""
    if rows == "xyz":
        return d
    if rows == "xy":
        return d[:2]
    c, s_ = np.cos(rows[1]), np.sin(rows[1])
    return ca.vertcat(d[2], -s_ * d[0] + c * d[1])


def transcribe(sp: Subproblem, *, derivatives: bool = True) -> NLP:
    """The NLP of ``sp`` (see the module docstring); the solver is created by ``solver.make_solver``.

    ``derivatives=False`` skips the Lagrangian Hessian and the constraint Jacobian (``hess_lag``
    and ``jac_g`` are then None; about 70 % of the build time): the variables, objective,
    constraints, bounds and layout are the same, which is what a smoke test of the lowering
    needs (tests/execution/test_bundled_build.py); such an NLP cannot be handed to IPOPT."""
    ch, m = sp.character, sp.motion
    K, nW = m.n_ctrl, len(m.warp)
    mg = ch.total_mass * G
    mask = window_mask(sp, K) if "q" in sp.free else np.zeros(K, bool)
    warp_free = "warp" in sp.free
    dense = sp.dense_dynamics and sp.dynamics != "kinematic"
    s = (_node_grid if dense else _collocation_grid)(sp, ch, sp.collocation_hz)
    # footsteps and ground on the round-8 grid either way (the dense nodes are the dynamics')
    s_con = _collocation_grid(sp, ch, max(sp.constraint_hz, sp.collocation_hz)) if dense or \
        sp.constraint_hz > sp.collocation_hz else s
    wq = np.zeros(len(s))  # trapezoid weights in s
    wq[1:] += np.diff(s) / 2
    wq[:-1] += np.diff(s) / 2
    if sp.window_only and not warp_free:
        # a window: the dynamics only at the points its free control points reach (the others
        # are constants), so a window's cost does not grow with the length of the scene
        live = _touches_free(K, s, mask)
        if sp.open_end and sp.window is not None:  # nothing past the window's end pulls on its end state
            live &= s <= float(m.to_canonical([sp.window[1]])[0]) + 1e-9
        if live.any():
            s, wq = s[live], wq[live]
    N = len(s)
    if dense and N > 1:  # the dynamics at the nodes and between them (module docstring)
        s_ev, wq, Mev = _dense_points(s)
    else:
        s_ev, Mev = s, np.eye(N)
    Ne = len(s_ev)
    B0, B1, B2 = (basis(K, s_ev, d) for d in (0, 1, 2))
    W1, W2 = basis(nW, s_ev, 1), basis(nW, s_ev, 2)
    t_init = m.time(s)
    t_ev = m.time(s_ev)

    # free / fixed control points
    free_idx = np.flatnonzero(np.repeat(mask[:, None], N_DOF, axis=1).ravel())
    xP = ca.MX.sym("P", len(free_idx))
    P_fixed = ca.MX.sym("P_fixed", K * N_DOF)  # parameter: current control points
    sel = ca.DM.triplet(free_idx.tolist(), list(range(len(free_idx))), [1.0] * len(free_idx),
                        K * N_DOF, len(free_idx))  # built sparse: dense it was 8155 × 2200 for a 9.6 s scene
    keep = np.ones(K * N_DOF)
    keep[free_idx] = 0.0
    P_flat = ca.sparsify(ca.DM(keep)) * P_fixed + ca.mtimes(sel, xP)
    P = ca.reshape(P_flat, N_DOF, K).T  # row-major flatten of (K, 35)

    xW = ca.MX.sym("W", nW if warp_free else 0)
    W_fixed = ca.MX.sym("W_fixed", nW)
    warp = xW if warp_free else W_fixed

    free_steps = [i for i, f in enumerate(sp.footsteps) if f.free and "footprints" in sp.free]
    xF = ca.MX.sym("F", 2 * len(free_steps))

    def planted_handles(si: int, step: Footstep):
        """contact_points of a footstep, its position the NLP variable when it is free."""
        pos = None
        if si in free_steps:
            j = free_steps.index(si)
            pos = (xF[2 * j], xF[2 * j + 1])
        return contact_points(ch, step, pos, sp.ground)

    # contacts: (handle, k) pairs planted by footsteps, λ per pair
    planted = []  # (handle, k, target xy expr, step index): contact force at grid point k
    pins = []  # (handle, s, target xy expr, rows, step index): footstep position constraints (rows: _pin_rows)
    zero_force = set()  # planted pairs at a touch-down or lift-off inside the motion (dense: λ = 0)
    seam = ({h for st in sp.footsteps for h, (ta, tb), _ in contact_points(ch, st) if ta <= m.start + 1e-9 <= tb + 2e-9},
            {h for st in sp.footsteps for h, (ta, tb), _ in contact_points(ch, st) if ta - 2e-9 <= m.end - 1e-9 <= tb})
    anchored = set()  # free footsteps already tied to a held point (one such pin each: more are redundant)
    for si, step in enumerate(sp.footsteps):
        for handle, (ta, tb), xy in planted_handles(si, step):
            sa, sb = m.to_canonical([ta, tb])
            ks = np.flatnonzero((s >= sa - 1e-9) & (s <= sb + 1e-9))
            # a touch-down (lift-off) inside the motion — or at a cyclic motion's seam, where the
            # handle is not planted at the other end — starts (ends) its force at 0
            down = ta > m.start + 1e-9 or (sp.cyclic and handle not in seam[1])
            up = tb < m.end - 1e-9 or (sp.cyclic and handle not in seam[0])
            for k in ks:
                if dense and ((abs(s[k] - sa) < 1e-7 and down) or (abs(s[k] - sb) < 1e-7 and up)):
                    zero_force.add(len(planted))  # touch-down or lift-off: the force starts or ends at 0
                planted.append((handle, int(k), xy, si))
            span = s_con[(s_con >= sa - 1e-9) & (s_con <= sb + 1e-9)]
            for v, dep in zip(span, _depend_on_free(K, span, mask, warp_free)):
                if dep:
                    pins.append((handle, float(v), xy, "xyz", si))
                elif si in free_steps and si not in anchored:
                    pins.append((handle, float(v), xy, "xyz", si))
                    anchored.add(si)
    if sp.cyclic:
        pins = _drop_cyclic_duplicates(pins)
    pins = _heel_implied_along_foot(pins, {si: st.heading for si, st in enumerate(sp.footsteps)})
    n_lam = 4 * len(planted) if sp.dynamics != "kinematic" else 0
    xL = ca.MX.sym("L", n_lam)
    Vc = _contact_bases(sp, ch, planted if n_lam else [])  # friction pyramid per planted pair
    force_rows = {h: i for i, h in enumerate(FORCE_HANDLES)}
    Fmap = np.zeros((3 * len(FORCE_HANDLES) * N, n_lam))  # column-major (3*8, N) flattened
    for c, (handle, k, _, _) in enumerate(planted if n_lam else []):
        r0 = k * 3 * len(FORCE_HANDLES) + 3 * force_rows[handle]
        Fmap[r0:r0 + 3, 4 * c:4 * c + 4] = mg * Vc[c]
    Fc = ca.reshape(ca.mtimes(_sparse(Fmap), xL), 3 * len(FORCE_HANDLES), N)
    Fc = ca.mtimes(Fc, _sparse(Mev))  # piecewise linear in s between the nodes: (24, Ne)

    # parameters: fixed data and per-point style
    TH = ca.MX.sym("theta", N_THETA, N)
    SA = ca.MX.sym("sqrt_alpha", N_JOINT, N)
    # spring anchors (3, Ne each, at the evaluation points) are parameters too, so a joint problem
    # can substitute them (scenegraph/problem/joint.py: anchor = own handle + F / k makes the force F)
    A_sym = [ca.MX.sym(f"anchor_{j}", 3, Ne) for j in range(len(sp.springs))]
    p = ca.vertcat(P_fixed, W_fixed, *[ca.vec(a) for a in A_sym], ca.vec(TH), ca.vec(SA))
    n_fixed = K * N_DOF + nW  # offset of the anchors in p

    Q, Q1, Q2 = (ca.mtimes(_sparse(Bd), P).T for Bd in (B0, B1, B2))  # (35, Ne): nodes first
    T1 = ca.mtimes(_sparse(W1), warp).T  # (1, Ne)
    T2 = ca.mtimes(_sparse(W2), warp).T
    Qd = Q1 / ca.repmat(T1, N_DOF, 1)
    Qdd = Q2 / ca.repmat(T1 ** 2, N_DOF, 1) - Q1 * ca.repmat(T2 / T1 ** 3, N_DOF, 1)

    hk_names = tuple(sorted({t.handle for t in sp.targets} | {a.handle for a in sp.avoid}
                            | {sg.handle for sg in sp.springs}
                            | set(CONTACT_HANDLES) | {"ankle_l", "ankle_r"}))
    hk = handles_kernel(ch, hk_names)
    HP = hk.map(Ne)(Q)  # (3*len, Ne)
    spring_force = []  # (3, N) world force of each spring at the collocation points
    anchor_values = []  # the anchors' numeric values (p)
    for sg in sp.springs:
        i = hk_names.index(sg.handle)
        pts = np.asarray(sg.points, float).reshape(-1, 3)
        anchor = np.stack([np.interp(t_ev, sg.times, pts[:, c]) for c in range(3)])
        on = ((t_ev >= sg.times[0] - 1e-9) & (t_ev <= sg.times[-1] + 1e-9)).astype(float)
        anchor_values.append(anchor.ravel(order="F"))
        f = sg.stiffness * (A_sym[len(anchor_values) - 1] - HP[3 * i:3 * i + 3, :]) * ca.repmat(ca.DM(on).T, 3, 1)
        place = np.zeros((3 * len(FORCE_HANDLES), 3))
        r0 = 3 * FORCE_HANDLES.index(sg.handle)
        place[r0:r0 + 3, :] = np.eye(3)
        Fc = Fc + ca.mtimes(_sparse(place), f)
        spring_force.append(f)  # (3, Ne): at every evaluation point

    TH_ev, SA_ev = ca.mtimes(TH, _sparse(Mev)), ca.mtimes(SA, _sparse(Mev))  # style linear between nodes
    TH_k = TH_ev
    if sp.shoe_gate and sp.dynamics != "kinematic":
        # the shoe springs only in planned heel contact (scenegraph/model/shoe.py): the kernel's own
        # (everywhere) is switched off and the gated one enters as a vertical force at each heel
        keep_rows = np.ones(N_THETA)
        keep_rows[4 * N_JOINT] = 0.0  # k_shoe
        TH_k = TH_ev * ca.repmat(ca.DM(keep_rows), 1, Ne)
        gate = shoe_gate(ch, sp.footsteps, t_ev, m.start, m.end, sp.ground)  # (2, Ne), world time of s_ev
        k_shoe, h_rest = TH_ev[4 * N_JOINT, :], TH_ev[4 * N_JOINT + 1, :]
        for i, side in enumerate(SIDES):
            if not gate[i].any():
                continue
            j = hk_names.index(f"heel_{side}")
            z = HP[3 * j + 2, :]
            if not sp.ground.flat:
                z = z - sp.ground.z(HP[3 * j, :], HP[3 * j + 1, :])
            fz = ca.DM(gate[i]).T * shoe_force(z, k_shoe, h_rest)
            place = np.zeros((3 * len(FORCE_HANDLES), 1))
            place[3 * FORCE_HANDLES.index(f"heel_{side}") + 2, 0] = 1.0
            Fc = Fc + ca.mtimes(_sparse(place), fz)
    kern = compiled_kernel(ch).map(Ne)
    QQ = kern(Q, Qd, Qdd, Fc, TH_k)  # (35, Ne)
    w_r = W_ROOT if sp.dynamics == "full" else W_ROOT / 100.0
    w_root = flight_root_weights(sp, s_ev, w_r)  # (Ne,): W_FLIGHT at evaluation points in flight
    scale = OBJ_SCALE / mg  # residuals in units of body weight, objective O(1–100)
    wt = ca.sqrt(ca.DM(wq).T * T1)  # (1, N)
    rho_m = SA_ev * QQ[:N_JOINT, :]
    rho_0 = ca.repmat(ca.DM(np.sqrt(w_root)).T, N_ROOT, 1) * QQ[N_JOINT:, :]
    rho_dyn = ca.vec(ca.vertcat(rho_m, rho_0) * ca.repmat(wt, N_DOF, 1)) * scale
    energy = ca.sumsqr(ca.vec(rho_m * ca.repmat(wt, N_JOINT, 1)))  # Σ w T' α Q_m²
    root_energy = ca.sumsqr(ca.vec(QQ[N_JOINT:, :] * ca.repmat(wt, N_ROOT, 1)))

    if sp.dynamics == "kinematic":  # stay close to the initial motion; no dynamics at all
        rho_dyn = ca.vec(P_flat - P_fixed) * KIN_WEIGHT
    rho_extra = [1e-3 * xL]  # tiny λ regularisation keeps the contact split well posed
    if sp.jerk_weight > 0 and sp.dynamics != "kinematic":  # no ringing between the points (.jerk)
        rj = jerk_rows(ch, m, P, mask, sp.jerk_weight, events=contact_events(sp.footsteps, sp.flights))
        if rj is not None:
            rho_extra.append(rj)

    def state_at(t):
        sk = float(m.to_canonical([t])[0])
        b0, b1 = _sparse(basis(K, [sk], 0)), _sparse(basis(K, [sk], 1))
        t1 = ca.mtimes(_sparse(basis(nW, [sk], 1)), warp)
        return ca.mtimes(b0, P).T, ca.mtimes(b1, P).T / t1, sk

    g, lbg, ubg, groups = [], [], [], []

    def add(name, expr, lo, hi, kind="eq"):
        expr = ca.vec(expr)
        n0 = sum(int(e.numel()) for e in g)
        g.append(expr)
        lbg.extend(np.broadcast_to(lo, expr.shape[0]).tolist())
        ubg.extend(np.broadcast_to(hi, expr.shape[0]).tolist())
        groups.append((name, slice(n0, n0 + expr.shape[0]), kind))

    for targ in sp.targets:
        q_t, _, sk = state_at(targ.t)
        pos = hk(q_t)
        i = hk_names.index(targ.handle)
        d = pos[3 * i:3 * i + 3] - ca.DM(targ.point)
        if targ.hard:
            add(f"{targ.name}:{targ.handle}", d, 0.0, 0.0)
        else:
            rho_extra.append(np.sqrt(targ.weight) * d)
    for pose in sp.poses:
        q_t, qd_t, _ = state_at(pose.t)
        if pose.dofs is not None:  # a partial pose (a keyframe's heading and joint angles)
            rho_extra.append(np.sqrt(pose.weight) * (q_t[list(pose.dofs)] - ca.DM(pose.q)[list(pose.dofs)]))
            continue
        rho_extra.append(np.sqrt(pose.weight) * (q_t - ca.DM(pose.q)))
        if pose.velocity is not None:
            rho_extra.append(0.1 * np.sqrt(pose.weight) * (qd_t - ca.DM(pose.velocity)))
    for vt in sp.velocities:  # centre-of-mass velocity P / M (flight.momenta_fn)
        q_t, qd_t, _ = state_at(vt.t)
        v_com = momenta_fn(ch)(q_t, qd_t)[1] / ch.total_mass
        rho_extra.append(np.sqrt(vt.weight) * (v_com - ca.DM(vt.velocity)))
    for a in sp.avoid:
        q_t, _, _ = state_at(a.t)
        i = hk_names.index(a.handle)
        d = hk(q_t)[3 * i:3 * i + 3] - ca.DM(a.center)
        add(f"avoid:{a.handle}", ca.sumsqr(d) - a.radius ** 2, 0.0, np.inf, "ineq")
    if sp.clearance:  # bodies apart: sphere i of this character off another's held point
        depth, rows = _clearance_terms(sp, P, m.to_canonical, mask, warp_free)
        if depth is not None:
            rho_extra.append(np.sqrt(sp.clearance_weight / depth.shape[0]) * depth)
        if rows is not None:
            add("clearance", rows, 0.0, np.inf, "ineq")

    if sp.dynamics != "relaxed" and sp.flight_mode == "momentum" and sp.flights:  # ballistic flight (.flight)
        # at every evaluation point in flight, nodes and midpoints: stated at the nodes alone, a run's
        # flights wiggled between them (0.05 body weight at 120 Hz, tackle, docs/results.md)
        dep = _depend_on_free(K, s_ev, mask, warp_free)  # a window: only points its free control points move
        fgroups = [k[dep[k]] for k in flight_groups(sp.flights, m, s_ev) if dep[k].sum() >= 2]
        T_s = ca.mtimes(_sparse(basis(nW, s_ev, 0)), warp).T
        fc = flight_constraints(ch, fgroups, Q, Qd, T_s)
        if fc is not None:
            add("flight_momentum", fc, 0.0, 0.0)
            flight_rows = fc
            flight_jac = (lambda fgroups=fgroups, T_s=T_s: flight_jacobian(ch, fgroups, Q, Qd, T_s, x))
            flight_hess = (lambda lam, fgroups=fgroups: flight_hessian(ch, fgroups, Q, Qd, lam, x))
    # footsteps: planted handles at their footprint on the ground
    if pins:
        s_pin = np.array([pn[1] for pn in pins])
        HPp = hk.map(len(pins))(ca.mtimes(_sparse(basis(K, s_pin, 0)), P).T)
        rows = []
        for c, pn in enumerate(pins):
            d = (HPp[3 * hk_names.index(pn[0]):3 * hk_names.index(pn[0]) + 3, c]
                 - ca.vertcat(pn[2][0], pn[2][1], sp.ground.z(pn[2][0], pn[2][1])))
            rows.append(_pin_rows(d, pn[3]))
        add("footstep", ca.vertcat(*rows), 0.0, 0.0)
    if sp.soft_pin_hz > 0 and pins:
        # soft footprints between the hard points: least squares (Gauss–Newton friendly),
        # keeps planted feet still between collocation points without degenerate constraints
        dense = np.linspace(0, 1, max(2, int(round(m.duration * sp.soft_pin_hz)) + 1))
        soft = []
        for si, step in enumerate(sp.footsteps):
            for handle, (ta, tb), xy in planted_handles(si, step):
                sa, sb = m.to_canonical([ta, tb])
                inside = dense[(dense > sa) & (dense < sb)]
                for v in (inside[_touches_free(K, inside, mask) | warp_free] if sp.window_only else inside):
                    soft.append((handle, float(v), xy))
        if soft:
            HPs = hk.map(len(soft))(ca.mtimes(_sparse(basis(K, [v for _, v, _ in soft], 0)), P).T)
            rows = [HPs[3 * hk_names.index(h):3 * hk_names.index(h) + 3, c]
                    - ca.vertcat(xy[0], xy[1], sp.ground.z(xy[0], xy[1]))
                    for c, (h, _, xy) in enumerate(soft)]
            rho_extra.append(np.sqrt(sp.soft_pin_weight / len(soft)) * ca.vertcat(*rows))
    if sp.soft_ground_hz > 0:
        # below-ground depth of every foot handle between the hard points, least squares
        dense = np.linspace(0, 1, max(2, int(round(m.duration * sp.soft_ground_hz)) + 1))
        dense = dense[_depend_on_free(K, dense, mask, warp_free)]
        if len(dense):
            HPg = hk.map(len(dense))(ca.mtimes(_sparse(basis(K, dense, 0)), P).T)
            depth = ca.vertcat(*[ca.fmin(HPg[3 * hk_names.index(h) + 2, :] - sp.ground.z(
                HPg[3 * hk_names.index(h), :], HPg[3 * hk_names.index(h) + 1, :]), 0.0) for h in CONTACT_HANDLES])
            rho_extra.append(np.sqrt(sp.soft_ground_weight / depth.shape[0]) * depth)
    if sp.dynamics == "full" and (sp.stance_frame_weight > 0 or sp.no_slip_weight > 0):
        # contact semantics between the points (stance_frame.py, no_slip.py): time integrals on a
        # dense grid, samples where a free control point (or the free warp) moves the pose or velocity
        n_d = max(2, int(round(m.duration * sp.contact_hz)) + 1)
        dense = np.linspace(0.0, 1.0, n_d)
        dense = dense[_touches_free(K, dense, mask) | warp_free]
        dt_d = m.duration / (n_d - 1)
        if sp.stance_frame_weight > 0 and len(dense):
            r = stance_frame_residuals(ch, sp.footsteps, sp.ground, m.time(dense), dense, dt_d, P, K,
                                       sp.stance_frame_weight)
            if r is not None:
                rho_extra.append(r)
        if sp.no_slip_weight > 0 and len(dense):
            rho_extra.append(no_slip_residuals(ch, sp.ground, dense, dt_d, P, warp, K, nW, sp.no_slip_weight))
    # ground non-penetration of every foot handle at every point
    s_gnd = s_con if sp.ground_hz <= 0 else \
        np.unique(np.r_[s_con, np.linspace(0, 1, max(2, int(round(m.duration * sp.ground_hz)) + 1))])
    s_gnd = s_gnd[_depend_on_free(K, s_gnd, mask, warp_free)
                  & ~(sp.cyclic & (s_gnd > 1.0 - 1e-9))]  # cyclic: the end repeats the start
    HPc = hk.map(len(s_gnd))(ca.mtimes(_sparse(basis(K, s_gnd, 0)), P).T)
    ground = ca.vertcat(*[HPc[3 * hk_names.index(h) + 2, :] for h in CONTACT_HANDLES])
    if not sp.ground.flat:  # height above the terrain under each handle
        ground = ground - ca.vertcat(*[sp.ground.z(HPc[3 * hk_names.index(h), :], HPc[3 * hk_names.index(h) + 1, :])
                                       for h in CONTACT_HANDLES])
    # a handle pinned to the ground at a point already has its height fixed there: a second,
    # identical (active) row would make the constraint Jacobian rank-deficient
    pinned_z = {(pn[0], round(pn[1], 9)) for pn in pins if pn[3] != "xy"}
    keep = [k * len(CONTACT_HANDLES) + i for k, v in enumerate(s_gnd) for i, h in enumerate(CONTACT_HANDLES)
            if (h, round(float(v), 9)) not in pinned_z]
    add("penetration", ca.vec(ground)[keep], 0.0, np.inf, "ineq")
    # feet not crossing: left ankle stays left of the right one, in the pelvis heading frame
    yaw = Q[3, :]
    dl = HP[3 * hk_names.index("ankle_l"):3 * hk_names.index("ankle_l") + 2, :] - \
        HP[3 * hk_names.index("ankle_r"):3 * hk_names.index("ankle_r") + 2, :]
    lateral = -ca.sin(yaw) * dl[0, :] + ca.cos(yaw) * dl[1, :]
    live = np.flatnonzero(_depend_on_free(K, s, mask, warp_free) & ~(sp.cyclic & (s > 1.0 - 1e-9))).tolist()
    add("feet_crossing", lateral[live], sp.min_foot_separation, np.inf, "ineq")
    if sp.joint_speed_limit and sp.dynamics == "full" and not warp_free:
        pairs = np.flatnonzero(mask[:-1] | mask[1:])
        if len(pairs):
            # one-sided least squares, zero under the ceiling: as rows, their barrier terms pulled a walk
            # that never comes near the ceilings toward standing still (E 169 -> 6322, docs/formulation.md)
            dscale, bound = speed_rows(K, np.asarray(m.warp, float), pairs)
            d = ca.vertcat(*[float(dscale[r]) * (P[i + 1, N_ROOT:] - P[i, N_ROOT:]) for r, i in enumerate(pairs)])
            over = ca.fmax(0, ca.fabs(d) - ca.DM(bound)) / ca.DM(bound / max_speed())  # rad/s over the ceiling
            rho_extra.append(np.sqrt(SPEED_WEIGHT) * over)
    if sp.cyclic:  # thesis §2.2.2: the cycle ends where it began, moved along the ground
        qs, qe = ca.mtimes(_sparse(basis(K, [0.0], 0)), P).T, ca.mtimes(_sparse(basis(K, [1.0], 0)), P).T
        vs = ca.mtimes(_sparse(basis(K, [0.0], 1)), P).T / ca.mtimes(_sparse(basis(nW, [0.0], 1)), warp)
        ve = ca.mtimes(_sparse(basis(K, [1.0], 1)), P).T / ca.mtimes(_sparse(basis(nW, [1.0], 1)), warp)
        add("cyclic", ca.vertcat(qe[2:] - qs[2:], ve - vs), 0.0, 0.0)
    # monotone warp with a minimum slope (world seconds per unit s)
    if warp_free:
        add("warp_monotone", xW[1:] - xW[:-1], 0.05 * m.duration / nW, np.inf, "ineq")
        if sp.fix_start_time:
            add("start_time", xW[0] - m.start, 0.0, 0.0)
        if sp.fix_end_time:
            add("end_time", xW[-1] - m.end, 0.0, 0.0)
        elif sp.end_time_bounds is not None:  # a free duration (timing: free)
            add("end_time", xW[-1], float(sp.end_time_bounds[0]), float(sp.end_time_bounds[1]), "ineq")

    # variable bounds: joint limits on control points, λ ≥ 0, footprints within 0.5 m
    lo, hi = ch.lower, ch.upper
    ctrl0 = np.asarray(m.ctrl, float)
    lbx = [np.tile(lo, K)[free_idx], np.full(xW.shape[0], -np.inf), [], np.zeros(n_lam)]
    ubx = [np.tile(hi, K)[free_idx], np.full(xW.shape[0], np.inf), [], np.full(n_lam, np.inf)]
    if n_lam and sp.flights:  # no contact force at a flight's take-off and touch-down points
        edge = flight_points(sp, s)
        for c, (_, k, _, _) in enumerate(planted):
            if edge[k]:
                ubx[3][4 * c:4 * c + 4] = 0.0
    for c in (zero_force if n_lam else ()):  # dense: forces continuous at touch-down and lift-off
        ubx[3][4 * c:4 * c + 4] = 0.0
    x0 = [ctrl0.ravel()[free_idx], np.asarray(m.warp, float) if warp_free else [], [],
          _lambda_guess(sp, planted if n_lam else [], s, mg)]
    for c in (zero_force if n_lam else ()):
        x0[3][4 * c:4 * c + 4] = 0.0
    fp0 = []
    for si in free_steps:
        fp0 += list(sp.footsteps[si].position)
    lbx[2] = np.asarray(fp0) - 0.5
    ubx[2] = np.asarray(fp0) + 0.5
    for j, si in enumerate(free_steps):  # a footstep with bounds (a jump's landing region) keeps in them
        b = sp.footsteps[si].bounds
        if b is not None:
            lbx[2][2 * j:2 * j + 2], ubx[2][2 * j:2 * j + 2] = b[0], b[1]
    x0[2] = np.asarray(fp0)

    x = ca.vertcat(xP, xW, xF, xL)
    rho = ca.vertcat(rho_dyn, *[OBJ_SCALE * ca.vec(r) for r in rho_extra])
    f = ca.sumsqr(rho)
    gg = ca.vertcat(*g)

    # Gauss–Newton Hessian of the objective + exact Hessian of the (kinematic) constraints
    if sp.hessian not in HESSIAN_MODES:
        raise ValueError(f"Subproblem.hessian must be one of {HESSIAN_MODES}, not {sp.hessian!r}")
    rho_x = ca.vertcat(*[OBJ_SCALE * ca.vec(r) for r in rho_extra])
    hess = jac_g = None
    if derivatives:
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", gg.shape[0])
        # Everything but the dynamics kernel is plain SX-expandable algebra: expanding those
        # parts makes their derivatives cheap scalar code instead of MX graph evaluation.
        # (expand the plain functions first, then differentiate in SX: much cheaper to build)
        xs, ps = ca.SX.sym("x", x.shape[0]), ca.SX.sym("p", p.shape[0])
        if sp.dynamics != "kinematic" and not warp_free:  # the same JᵀJ, point by point (.gram)
            D = scale * ca.vertcat(SA_ev, ca.repmat(ca.DM(np.sqrt(w_root)).T, N_ROOT, 1)) * ca.repmat(wt, N_DOF, 1)
            JtJ_dyn = dynamics_gauss_newton(ch, ca.vertcat(Q, Qd, Qdd, Fc), TH_k, D, x)
        else:
            J_dyn = ca.jacobian(rho_dyn, x)
            JtJ_dyn = ca.mtimes(J_dyn.T, J_dyn)
        rxs = ca.Function("rho_extra", [x, p], [rho_x]).expand()(xs, ps)
        J_x = ca.Function("J_extra", [xs, ps], [ca.jacobian(rxs, xs)])(x, p)
        # The flight momentum rows (.flight) stay MX, out of the SX expansion: expanded, the momenta's
        # forward kinematics at every flight point made the SX Jacobian of g 38 s of broad_jump's 75 s
        # build; CasADi differentiates the (SX) momenta function once and maps it instead.  They get
        # no curvature in the Hessian (Gauss–Newton in them, as before).
        is_fl = np.zeros(gg.shape[0], bool)
        for name, sl, _ in groups:
            if name == "flight_momentum":
                is_fl[sl] = True
        rest, frows = np.flatnonzero(~is_fl).tolist(), np.flatnonzero(is_fl).tolist()
        g_rest = gg[rest] if frows else gg
        gs = ca.Function("g_all", [x, p], [g_rest]).expand()(xs, ps)
        if gs.shape[0]:
            lam_s = ca.SX.sym("lam_s", gs.shape[0])
            Hc = ca.Function("H_con", [xs, ps, lam_s], [ca.hessian(ca.dot(lam_s, gs), xs)[0]])(
                x, p, lam_g[rest] if frows else lam_g)
        else:
            Hc = ca.MX(x.shape[0], x.shape[0])
        H = 2 * lam_f * (JtJ_dyn + ca.mtimes(J_x.T, J_x))
        if sp.hessian != "gauss_newton_objective":
            H = H + Hc
            if frows and sp.flight_curvature:  # the flight rows' curvature (.flight)
                H = H + flight_hess(lam_g[frows])
        if sp.hessian == "exact":
            # second-order term 2 Σ r ∇²r of Σ r² (times lam_f).  Dynamics: r = C ⊙ Q(z) per point with
            # z = (q, q̇, q̈, forces); with the timewarp held, C is constant and z linear in x, so the
            # term is exactly J_zᵀ blockdiag(∇²_z (w·Q)) J_z with w = 2 lam_f r ⊙ C (compiled kernel
            # Hessian).  A free timewarp (and a spring's force, nonlinear in q) also curves z and C:
            # those curvature terms are left out (Gauss–Newton in them).
            if sp.dynamics != "kinematic":
                C = scale * ca.vertcat(SA_ev, ca.repmat(ca.DM(np.sqrt(w_root)).T, N_ROOT, 1)) * ca.repmat(wt, N_DOF, 1)
                Wk = 2 * lam_f * ca.reshape(rho_dyn, N_DOF, Ne) * C
                nz = 3 * N_DOF + 3 * len(FORCE_HANDLES)
                Hk = kernel_hessian(ch).map(Ne)(Q, Qd, Qdd, Fc, TH_k, Wk)  # (nz, nz Ne)
                Hzz = ca.diagcat(*ca.horzsplit(Hk, nz)) if Ne > 1 else Hk
                Jz = ca.jacobian(ca.vec(ca.vertcat(Q, Qd, Qdd, Fc)), x)
                H = H + ca.mtimes(Jz.T, ca.mtimes(Hzz, Jz))
            if rho_x.shape[0]:  # the other least-squares terms are plain SX algebra: exact Hessian directly
                mu = ca.SX.sym("mu", rho_x.shape[0])
                H = H + ca.Function("H_extra", [xs, ps, mu], [ca.hessian(ca.dot(mu, rxs), xs)[0]])(
                    x, p, 2 * lam_f * rho_x)
        H = ca.triu(H)
        hess = ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])

        if frows:  # the SX rows and the MX flight rows, put back in g's order
            g_r, J_r = ca.Function("jac_g_rest", [xs, ps], [gs, ca.jacobian(gs, xs)])(x, p)
            back = ca.DM(ca.Sparsity.triplet(gg.shape[0], gg.shape[0], rest + frows, list(range(gg.shape[0]))), 1.0)
            jac_g = ca.Function("nlp_jac_g", [x, p], [ca.mtimes(back, ca.vertcat(g_r, flight_rows)),
                                                      ca.mtimes(back, ca.vertcat(J_r, flight_jac()))],
                                ["x", "p"], ["g", "jac_g_x"])
        else:
            jac_g = ca.Function("nlp_jac_g", [xs, ps], [gs, ca.jacobian(gs, xs)], ["x", "p"], ["g", "jac_g_x"])
    th = theta_kernel_vector(sp.style)
    sa = np.sqrt(np.asarray(sp.style.alpha, float))
    if sp.style_end is not None:
        wgt = np.clip((t_init - sp.window[0]) / (sp.window[1] - sp.window[0]), 0, 1) if sp.window else s
        th_end = theta_kernel_vector(sp.style_end)
        sa_end = np.sqrt(np.asarray(sp.style_end.alpha, float))
        TH0 = np.outer(th, 1 - wgt) + np.outer(th_end, wgt)
        SA0 = np.outer(sa, 1 - wgt) + np.outer(sa_end, wgt)
    else:
        TH0, SA0 = np.tile(th[:, None], (1, N)), np.tile(sa[:, None], (1, N))
    pv = np.concatenate([ctrl0.ravel(), np.asarray(m.warp, float), *anchor_values,
                         TH0.ravel(order="F"), SA0.ravel(order="F")])

    springs_out = ca.vertcat(*spring_force) if spring_force else ca.MX(0, Ne)
    unpack = ca.Function("unpack", [x, p], [P, warp, xF, energy, root_energy, springs_out])
    x_layout = _layout(("ctrl", xP.shape[0]), ("warp", xW.shape[0]), ("footprints", xF.shape[0]), ("lambda", n_lam))
    p_layout = _layout(("ctrl_fixed", K * N_DOF), ("warp_fixed", nW), ("anchors", 3 * Ne * len(sp.springs)),
                       ("theta", N_THETA * N), ("sqrt_alpha", N_JOINT * N))
    assert x_layout["lambda"].stop == x.shape[0] and p_layout["sqrt_alpha"].stop == p.shape[0] == pv.size
    lam0 = x_layout["lambda"].start
    return NLP(
        sp=sp, x=x, p=p, f=f, g=gg,
        x0=np.concatenate([np.ravel(a) for a in x0]),
        lbx=np.concatenate([np.ravel(a) for a in lbx]), ubx=np.concatenate([np.ravel(a) for a in ubx]),
        lbg=np.asarray(lbg, float), ubg=np.asarray(ubg, float), p0=pv,
        x_layout=x_layout, p_layout=p_layout,
        anchor_slices=tuple(slice(n_fixed + 3 * Ne * j, n_fixed + 3 * Ne * (j + 1)) for j in range(len(sp.springs))),
        f_fn=ca.Function("f", [x, p], [f]), g_fn=ca.Function("g", [x, p], [gg]), hess_lag=hess, jac_g=jac_g,
        unpack=unpack, groups=groups, s_points=s, s_eval=s_ev,
        contact_index=[(h, k, slice(lam0 + 4 * c, lam0 + 4 * c + 4))
                       for c, (h, k, _, _) in enumerate(planted if n_lam else [])],
        free_steps=free_steps, contact_basis=tuple(Vc), spring_handles=tuple(sg.handle for sg in sp.springs),
        rho_dyn_fn=ca.Function("rho_dyn", [x, p], [rho_dyn]), rho_extra_fn=ca.Function("rho_extra", [x, p], [rho_x]),
        ctrl_fn=ca.Function("ctrl", [x, p], [P]))
