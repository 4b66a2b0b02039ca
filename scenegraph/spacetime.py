"""One spacetime subproblem (a Step's unit of work): problem, transcription, solve, result.

Transcription
-------------
Decision variables: the free DOF spline control points, the free timewarp control points,
contact coefficients λ ≥ 0 (four per planted handle per collocation point; the contact
force is m g V λ with V the friction-pyramid basis) and free footprint positions.
Collocation points are uniform in canonical time s; the energy (paper Eq. 13)

    E = Σ_k w_k T'(s_k) [ Σ_j α_j Q_mj(s_k)² + w_r Σ_i Q_0i(s_k)² ]

is a sum of squares of residuals computed by one per-point kernel (inverse dynamics plus
passive, contact and shoe terms) that is compiled to C with its first derivatives.
IPOPT gets a **Gauss–Newton Hessian** (2 JᵀJ of the residuals) plus the exact Hessian of
the kinematic constraints by default; ``Subproblem(hessian="exact")`` adds the residual
curvature 2 Σ r ∇²r (a compiled per-point kernel Hessian, :func:`kernel_hessian`, chained
through the splines; see README "Exact Hessian" for what it measured).  Style θ and all
fixed data are NLP parameters, so one built problem serves many solves (NIO).

Constraints: footsteps (planted handles at their footprint on the ground), ground
non-penetration of the foot handles, feet not crossing (thesis Eq. 6.3), joint limits
(bounds on control points: a B-spline stays in the hull of its control points), monotone
timewarp (Eq. 6.1), optional boundary states and avoid-spheres; soft springs toward
handle targets and poses (continuations).
"""
from __future__ import annotations

import functools
import os as _os
import time as _time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from .body import G, N_DOF, N_JOINT, N_ROOT, Character
from .dynamics import friction_basis, muscle_and_residual
from .footsteps import Footstep, contact_points
from .ground import FLAT, Ground
from .kinematics import frame_transforms, handle_position
from .motion import Motion, basis
from .style import Style

__all__ = ["read_solution", "Subproblem", "HandleTarget", "PoseTarget", "Avoid", "Spring", "Result", "solve", "build",
           "CONTACT_HANDLES", "residual_kernel", "W_ROOT"]

W_ROOT = 100.0  # paper: weight of the root residual
OBJ_SCALE = 30.0  # objective = (OBJ_SCALE / m g)² E: O(1–100) so IPOPT's tolerances mean something
KIN_WEIGHT = 3.0  # pull toward the initial motion in kinematic pre-solves
CONTACT_HANDLES = ("heel_l", "ball_l", "toe_l", "heel_r", "ball_r", "toe_r")
FORCE_HANDLES = CONTACT_HANDLES + ("palm_l", "palm_r")
N_THETA = 4 * N_JOINT + 2  # style numbers the kernel needs: ks1, ks2, kd, q_rest, k_shoe, h_rest


@dataclass(frozen=True)
class HandleTarget:
    """Soft spring pulling ``handle`` toward ``point`` (world, m) at world time ``t``.

    ``weight`` is in 1/m² of the normalised objective; ``hard`` makes it an equality.
    """

    handle: str
    t: float
    point: tuple[float, float, float]
    weight: float = 10.0
    hard: bool = False
    name: str = "target"


@dataclass(frozen=True)
class PoseTarget:
    """Soft spring toward a full pose ``q`` (35) at world time ``t`` (continuations, seams)."""

    t: float
    q: tuple[float, ...]
    weight: float = 1.0
    velocity: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Spring:
    """A physical spring on ``handle``: force stiffness · (anchor(t) − handle position) (N, world).

    ``times`` (s, world, increasing) and ``points`` (n × 3, m) sample the anchor's path — a
    partner's held handle in a rubber-band coupling (thesis §6.4.3); it is interpolated
    linearly at the collocation times, and the force acts only within [times[0], times[-1]].
    The force enters the equations of motion at the handle (one of FORCE_HANDLES).
    """

    handle: str
    times: tuple[float, ...]
    points: tuple[tuple[float, float, float], ...]
    stiffness: float  # N/m
    name: str = "spring"


@dataclass(frozen=True)
class Avoid:
    """Keep ``handle`` outside a sphere (center world m, radius m) at world time ``t``."""

    handle: str
    t: float
    center: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Subproblem:
    """What one Step solves for one character.  Times are world times of ``motion``.

    ``window`` (t0, t1): control points whose support lies inside are free; the others are
    held, which gives the boundary conditions of a window.  ``free`` names the free blocks:
    "q" (spline control points), "warp", "footprints" (positions of footsteps with
    ``free=True``); λ is always free where a handle is planted.  ``dynamics`` is "full"
    (energy with w_r) or "relaxed" (root residual weight divided by 100: timing steps).
    ``cyclic`` makes the motion end in the state it began (velocities too), moved along
    the ground (root x, y free).  "kinematic" drops the dynamics and stays near the initial motion (a kinematic
    pre-solve that makes the initial guess satisfy the constraints).  ``style_end`` blends θ linearly over the window toward another style (transitions).
    """

    character: Character
    style: Style
    motion: Motion
    footsteps: tuple[Footstep, ...] = ()
    window: tuple[float, float] | None = None
    free: frozenset = frozenset({"q", "warp"})
    dynamics: str = "full"
    targets: tuple[HandleTarget, ...] = ()
    poses: tuple[PoseTarget, ...] = ()
    avoid: tuple[Avoid, ...] = ()
    springs: tuple[Spring, ...] = ()
    style_end: Style | None = None
    collocation_hz: float = 30.0  # dynamics (energy, contact forces)
    constraint_hz: float = 30.0  # footsteps and ground (if higher than collocation_hz)
    ground_hz: float = 0.0  # extra grid for non-penetration (0: the constraint grid; denser grids
    # were measured to stall IPOPT: 300 iterations without convergence at 90 Hz)
    soft_pin_hz: float = 0.0  # soft footprint springs between the hard points (0: off; see README)
    soft_pin_weight: float = 1e5  # total weight, shared by the soft points
    soft_ground_hz: float = 0.0  # one-sided ground penalty on a dense grid (0: off)
    soft_ground_weight: float = 1e6  # total weight, shared by the dense points
    fix_start_time: bool = True
    fix_end_time: bool = True
    cyclic: bool = False
    contact_guess: dict | None = field(default=None, compare=False, hash=False)  # warm start for λ
    min_foot_separation: float = 0.06
    ground: Ground = FLAT  # terrain: footprint heights, non-penetration, friction pyramids (ground.py)
    max_iter: int = 300
    tol: float = 1e-4
    label: str = "step"
    ipopt_options: tuple = ()  # extra IPOPT options as (name, value) pairs (e.g. warm starts in NIO)
    nlpsol_options: tuple = ()  # extra CasADi nlpsol options as (name, value) pairs (e.g. iteration_callback)
    stall_iterations: int = 0  # > 0: stop as "Stalled" (a success) when the best feasible objective has
    # improved by less than STALL_RATE per iterate over this many feasible iterates (see StallMonitor)
    hessian: str = "gauss_newton"  # Hessian of the objective given to IPOPT: "gauss_newton" (2 JᵀJ) or
    # "exact" (adds 2 Σ r ∇²r: the compiled kernel Hessian chained through the splines; see build);
    # "gauss_newton_objective" (an experiment: 2 JᵀJ without the constraints' curvature; README)


@dataclass
class Result:
    """Outcome of one solve."""

    motion: Motion
    footsteps: tuple[Footstep, ...]
    status: str
    success: bool
    iterations: int
    seconds: float
    energy: float
    objective: float
    violations: dict[str, float]
    contact_forces: dict = field(default_factory=dict)  # handle -> (times, forces (n,3))
    label: str = "step"

    def summary(self) -> str:
        worst = max(self.violations.items(), key=lambda kv: kv[1], default=("none", 0.0))
        return (f"{self.label}: {self.status} in {self.iterations} it, {self.seconds:.2f} s, "
                f"E={self.energy:.4g}, worst violation {worst[0]}={worst[1]:.2e}")


# --- the per-point kernel -------------------------------------------------------------------

def _kernel_expr(ch: Character, q, qd, qdd, fc, th):
    """[Q_m (29); Q_0 (6)] as SX of the kernel's symbols (see residual_kernel)."""
    class _S:  # the style numbers the dynamics need
        ks1, ks2, kd, q_rest = (th[i * N_JOINT:(i + 1) * N_JOINT] for i in range(4))
        k_shoe, h_rest = th[4 * N_JOINT], th[4 * N_JOINT + 1]

    ext = []
    for i, name in enumerate(FORCE_HANDLES):
        h = ch.handle(name)
        ext.append((ch.body(h.body).frame, h.point, fc[3 * i:3 * i + 3]))
    qm, q0 = muscle_and_residual(ch, q, qd, qdd, _S, ext)
    return ca.vertcat(qm, q0)


@functools.lru_cache(maxsize=8)
def residual_kernel(ch: Character) -> ca.Function:
    """(q, q̇, q̈ (35 each), forces at FORCE_HANDLES (3·8, world N), θ (118)) → [Q_m (29); Q_0 (6)]."""
    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    fc = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("theta", N_THETA)
    return ca.Function("compose_residual", [q, qd, qdd, fc, th], [_kernel_expr(ch, q, qd, qdd, fc, th)],
                       ["q", "qd", "qdd", "f", "theta"], ["Q"])


@functools.lru_cache(maxsize=8)
def compiled_kernel(ch: Character) -> ca.Function:
    from .codegen import compiled
    return compiled(residual_kernel(ch), with_jacobian=True)


@functools.lru_cache(maxsize=8)
def kernel_hessian(ch: Character, compile: bool = True) -> ca.Function:
    """(q, q̇, q̈, forces, θ, w (35)) → ∇²_z (w · Q(z)) (129×129, z = (q, q̇, q̈, forces)).

    The second-order term of the exact Hessian of a weighted sum of squares Σ w_i Q_i, with
    one exception: the paper's smooth steps g(x) = (tanh(500 x) + 1)/2 that blend the passive
    springs (ks1/ks2) and switch the shoe spring are held at their values when differentiating
    twice (their first derivatives stay in the gradient).  Their own curvature is a spike of
    ~500² at the kink (a heel at its 5 mm rest height, a joint at q̄): with it IPOPT's inertia
    correction reached 1e10–1e17 and stopped with "Error in step computation" (measured).  Away
    from the kinks (|x| ≫ 2 mm) this is the exact Hessian.  The kernel is linear in q̈ and in
    the forces, so only (q, q̇) rows and columns are non-zero (3319 entries; ~140 k SX
    instructions, compiled at -O1 in ~20 s once)."""
    from . import dynamics as dyn

    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    fc = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("theta", N_THETA)
    w = ca.SX.sym("w", N_DOF)
    held, smooth_step = [], dyn.sigmoid

    def held_step(x):  # a symbol in place of g(x): differentiated as a constant
        g = ca.SX.sym(f"g{len(held)}", x.shape)
        held.append((g, smooth_step(x)))
        return g

    dyn.sigmoid = held_step
    try:
        Q = _kernel_expr(ch, q, qd, qdd, fc, th)
    finally:
        dyn.sigmoid = smooth_step
    z = ca.vertcat(q, qd, qdd, fc)
    H, _ = ca.hessian(ca.dot(w, Q), z)
    if held:
        H = ca.substitute(H, ca.vertcat(*[g for g, _ in held]), ca.vertcat(*[v for _, v in held]))
    f = ca.Function("compose_residual_hess", [q, qd, qdd, fc, th, w], [H],
                    ["q", "qd", "qdd", "f", "theta", "w"], ["H"])
    if not compile:
        return f
    from .codegen import compiled
    return compiled(f)


HESSIAN_MODES = ("gauss_newton", "exact", "gauss_newton_objective")


@functools.lru_cache(maxsize=8)
def handles_kernel(ch: Character, names: tuple[str, ...]) -> ca.Function:
    q = ca.SX.sym("q", N_DOF)
    tr = frame_transforms(ch, q)
    return ca.Function("handles", [q], [ca.vertcat(*[handle_position(ch, q, n, tr) for n in names])])


def theta_kernel_vector(style: Style) -> np.ndarray:
    return np.concatenate([style.ks1, style.ks2, style.kd, style.q_rest, [style.k_shoe, style.h_rest]])


def _sparse(a: np.ndarray) -> ca.DM:
    """A constant matrix with its structural zeros dropped (keeps Jacobians sparse)."""
    a = np.asarray(a, float)
    a = np.where(np.abs(a) < 1e-14, 0.0, a)
    return ca.sparsify(ca.DM(a))


# --- transcription --------------------------------------------------------------------------

@dataclass
class Built:
    """A transcribed problem: the IPOPT solver and what is needed to read its solution."""

    sp: Subproblem
    solver: ca.Function
    x0: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    p: np.ndarray
    unpack: ca.Function  # x, p -> ctrl, warp, foot xy, energy terms
    groups: list  # (name, slice into g, kind)
    s_points: np.ndarray
    contact_index: list  # (handle, k, slice into λ)
    lam_slice: slice
    free_steps: list
    g_fn: ca.Function
    contact_basis: tuple = ()  # friction pyramid V (3×4, world) per contact_index entry
    spring_handles: tuple = ()  # handle of each Subproblem.springs entry, in order
    monitor: object = None  # StallMonitor when Subproblem.stall_iterations > 0
    f_fn: ca.Function | None = None  # x, p -> objective (IPOPT's f)
    hess_fn: ca.Function | None = None  # x, p, lam_f, lam_g -> upper triangle of the Lagrangian Hessian given to IPOPT
    # the transcription's pieces, for problems that combine several Built (scenegraph/joint.py):
    rho_dyn_fn: ca.Function | None = None  # x, p -> dynamics residuals (objective = |rho_dyn|² + |rho_extra|²)
    rho_extra_fn: ca.Function | None = None  # x, p -> the other least-squares residuals (SX-expandable)
    ctrl_fn: ca.Function | None = None  # x, p -> control points (K × 35)
    anchor_slices: tuple = ()  # slice into p of each spring's anchor (3 × N at s_points, column-major)


STALL_RATE = 1e-3  # mean relative gain per feasible iterate, over the last `patience`, that counts as
# progress: Gauss–Newton creeps on large-residual windows (a walk_to_run window: −26 % of its
# objective over its last 270 of 300 iterations, 0.1 % per iterate); below this it stops
STALL_VIOL = 1e-5  # worst constraint violation (m, or the constraint's unit) of a stalled iterate


class IterationCallback(ca.Callback):
    """Base of IPOPT iteration callbacks: receives nlpsol's outputs (x, f, g, multipliers) of
    an NLP with ``nx`` variables and ``ng`` constraints; subclasses implement ``eval`` and
    read ``violation(g)`` (worst violation of [lbg, ubg])."""

    def __init__(self, name: str, nx: int, ng: int, lbg: np.ndarray, ubg: np.ndarray):
        ca.Callback.__init__(self)
        self.nx, self.ng, self.lbg, self.ubg = nx, ng, np.asarray(lbg, float), np.asarray(ubg, float)
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

    def eval(self, arg):
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


def _window_mask(sp: Subproblem, n_ctrl: int) -> np.ndarray:
    """Control points free under the window: those whose support lies inside it, so a
    windowed solve never changes the motion (or invalidates contact forces) outside its
    window; the points straddling two windows are freed by the seam window between them."""
    if sp.window is None:
        return np.ones(n_ctrl, bool)
    s0, s1 = sp.motion.to_canonical([sp.window[0], sp.window[1]])
    knots = np.linspace(0, 1, n_ctrl - 2)
    mask = np.zeros(n_ctrl, bool)
    for i in range(n_ctrl):
        lo = knots[max(0, i - 3)]
        hi = knots[min(len(knots) - 1, i + 1)] if i + 1 < len(knots) else 1.0
        mask[i] = (lo >= s0 - 1e-9) and (hi <= s1 + 1e-9)
    return mask


FREE_WEIGHT_MIN = 0.05  # B-spline weight of the free control points below which a point counts as held


def _depends_on_free(n_ctrl: int, s: float, mask: np.ndarray, other_free: bool) -> bool:
    """Whether a kinematic constraint at canonical time s is a constraint of this step: the
    free control points under s carry at least FREE_WEIGHT_MIN of its B-spline weight (or
    another block it depends on is free).  Constraints on held values are constants; ones
    at the very edge of a window, where a single free control point enters with a tiny
    weight, are nearly so — several of them on one control point make the constraint
    Jacobian nearly rank-deficient (IPOPT then stops with "Error in step computation")."""
    return other_free or float(np.sum(basis(n_ctrl, [s])[0][mask])) >= FREE_WEIGHT_MIN


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


def _drop_cyclic_duplicates(pins: list) -> list:
    """Footstep pins of a cyclic motion without the ones the cycle already implies.

    A cyclic motion ends in its start pose moved along the ground (root x, y free).  For a
    handle pinned at both ends, the end pin's height and the placement of every other such
    handle follow from the start pins; only the shift (x, y) is new.  Keeping them all makes
    the constraint Jacobian rank-deficient (IPOPT stops with "Error in step computation"),
    so the first such end pin keeps only its (x, y) (marked by a fourth entry "xy") and the
    other such end pins are dropped.
    """
    at_start = {pn[0] for pn in pins if pn[1] < 1e-9}
    repeated = [pn for pn in pins if pn[1] > 1.0 - 1e-9 and pn[0] in at_start]
    if not repeated:
        return pins
    h, v, xy = repeated[0]
    return [pn for pn in pins if pn not in repeated] + [(h, v, xy, "xy")]


def build(sp: Subproblem) -> Built:
    ch, m = sp.character, sp.motion
    K, nW = m.n_ctrl, len(m.warp)
    mg = ch.total_mass * G
    s = _collocation_grid(sp, ch, sp.collocation_hz)
    s_con = _collocation_grid(sp, ch, sp.constraint_hz) if sp.constraint_hz > sp.collocation_hz else s
    N = len(s)
    wq = np.zeros(N)  # trapezoid weights in s
    wq[1:] += np.diff(s) / 2
    wq[:-1] += np.diff(s) / 2
    B0, B1, B2 = (basis(K, s, d) for d in (0, 1, 2))
    W1, W2 = basis(nW, s, 1), basis(nW, s, 2)
    t_init = m.time(s)

    # free / fixed control points
    mask = _window_mask(sp, K) if "q" in sp.free else np.zeros(K, bool)
    free_idx = np.flatnonzero(np.repeat(mask[:, None], N_DOF, axis=1).ravel())
    xP = ca.MX.sym("P", len(free_idx))
    P_fixed = ca.MX.sym("P_fixed", K * N_DOF)  # parameter: current control points
    sel = np.zeros((K * N_DOF, len(free_idx)))
    sel[free_idx, np.arange(len(free_idx))] = 1.0
    keep = np.ones(K * N_DOF)
    keep[free_idx] = 0.0
    P_flat = ca.sparsify(ca.DM(keep)) * P_fixed + ca.mtimes(_sparse(sel), xP)
    P = ca.reshape(P_flat, N_DOF, K).T  # row-major flatten of (K, 35)

    warp_free = "warp" in sp.free
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
    pins = []  # (handle, s, target xy expr[, "xy"]): footstep position constraints
    anchored = set()  # free footsteps already tied to a held point (one such pin each: more are redundant)
    for si, step in enumerate(sp.footsteps):
        for handle, (ta, tb), xy in planted_handles(si, step):
            sa, sb = m.to_canonical([ta, tb])
            ks = np.flatnonzero((s >= sa - 1e-9) & (s <= sb + 1e-9))
            for k in ks:
                planted.append((handle, int(k), xy, si))
            for v in s_con[(s_con >= sa - 1e-9) & (s_con <= sb + 1e-9)]:
                if _depends_on_free(K, v, mask, warp_free):
                    pins.append((handle, float(v), xy))
                elif si in free_steps and si not in anchored:
                    pins.append((handle, float(v), xy))
                    anchored.add(si)
    if sp.cyclic:
        pins = _drop_cyclic_duplicates(pins)
    n_lam = 4 * len(planted) if sp.dynamics != "kinematic" else 0
    xL = ca.MX.sym("L", n_lam)
    Vc = _contact_bases(sp, ch, planted if n_lam else [])  # friction pyramid per planted pair
    force_rows = {h: i for i, h in enumerate(FORCE_HANDLES)}
    Fmap = np.zeros((3 * len(FORCE_HANDLES) * N, n_lam))  # column-major (3*8, N) flattened
    for c, (handle, k, _, _) in enumerate(planted if n_lam else []):
        r0 = k * 3 * len(FORCE_HANDLES) + 3 * force_rows[handle]
        Fmap[r0:r0 + 3, 4 * c:4 * c + 4] = mg * Vc[c]
    Fc = ca.reshape(ca.mtimes(_sparse(Fmap), xL), 3 * len(FORCE_HANDLES), N)

    # parameters: fixed data and per-point style
    TH = ca.MX.sym("theta", N_THETA, N)
    SA = ca.MX.sym("sqrt_alpha", N_JOINT, N)
    # spring anchors (3, N each, at the collocation points) are parameters too, so a joint problem
    # can substitute them (scenegraph/joint.py: anchor = own handle + F / k makes the force F)
    A_sym = [ca.MX.sym(f"anchor_{j}", 3, N) for j in range(len(sp.springs))]
    p = ca.vertcat(P_fixed, W_fixed, *[ca.vec(a) for a in A_sym], ca.vec(TH), ca.vec(SA))
    n_fixed = K * N_DOF + nW  # offset of the anchors in p

    Q, Q1, Q2 = (ca.mtimes(_sparse(Bd), P).T for Bd in (B0, B1, B2))  # (35, N)
    T1 = ca.mtimes(_sparse(W1), warp).T  # (1, N)
    T2 = ca.mtimes(_sparse(W2), warp).T
    Qd = Q1 / ca.repmat(T1, N_DOF, 1)
    Qdd = Q2 / ca.repmat(T1 ** 2, N_DOF, 1) - Q1 * ca.repmat(T2 / T1 ** 3, N_DOF, 1)

    hk_names = tuple(sorted({t.handle for t in sp.targets} | {a.handle for a in sp.avoid}
                            | {sg.handle for sg in sp.springs}
                            | set(CONTACT_HANDLES) | {"ankle_l", "ankle_r"}))
    hk = handles_kernel(ch, hk_names)
    HP = hk.map(N)(Q)  # (3*len, N)
    spring_force = []  # (3, N) world force of each spring at the collocation points
    anchor_values = []  # the anchors' numeric values (p)
    for sg in sp.springs:
        i = hk_names.index(sg.handle)
        pts = np.asarray(sg.points, float).reshape(-1, 3)
        anchor = np.stack([np.interp(t_init, sg.times, pts[:, c]) for c in range(3)])
        on = ((t_init >= sg.times[0] - 1e-9) & (t_init <= sg.times[-1] + 1e-9)).astype(float)
        anchor_values.append(anchor.ravel(order="F"))
        f = sg.stiffness * (A_sym[len(anchor_values) - 1] - HP[3 * i:3 * i + 3, :]) * ca.repmat(ca.DM(on).T, 3, 1)
        place = np.zeros((3 * len(FORCE_HANDLES), 3))
        r0 = 3 * FORCE_HANDLES.index(sg.handle)
        place[r0:r0 + 3, :] = np.eye(3)
        Fc = Fc + ca.mtimes(_sparse(place), f)
        spring_force.append(f)

    kern = compiled_kernel(ch).map(N)
    QQ = kern(Q, Qd, Qdd, Fc, TH)  # (35, N)
    w_r = W_ROOT if sp.dynamics == "full" else W_ROOT / 100.0
    scale = OBJ_SCALE / mg  # residuals in units of body weight, objective O(1–100)
    wt = ca.sqrt(ca.DM(wq).T * T1)  # (1, N)
    rho_m = SA * QQ[:N_JOINT, :]
    rho_0 = np.sqrt(w_r) * QQ[N_JOINT:, :]
    rho_dyn = ca.vec(ca.vertcat(rho_m, rho_0) * ca.repmat(wt, N_DOF, 1)) * scale
    energy = ca.sumsqr(ca.vec(rho_m * ca.repmat(wt, N_JOINT, 1)))  # Σ w T' α Q_m²
    root_energy = ca.sumsqr(ca.vec(QQ[N_JOINT:, :] * ca.repmat(wt, N_ROOT, 1)))

    if sp.dynamics == "kinematic":  # stay close to the initial motion; no dynamics at all
        rho_dyn = ca.vec(P_flat - P_fixed) * KIN_WEIGHT
    rho_extra = [1e-3 * xL]  # tiny λ regularisation keeps the contact split well posed

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
        rho_extra.append(np.sqrt(pose.weight) * (q_t - ca.DM(pose.q)))
        if pose.velocity is not None:
            rho_extra.append(0.1 * np.sqrt(pose.weight) * (qd_t - ca.DM(pose.velocity)))
    for a in sp.avoid:
        q_t, _, _ = state_at(a.t)
        i = hk_names.index(a.handle)
        d = hk(q_t)[3 * i:3 * i + 3] - ca.DM(a.center)
        add(f"avoid:{a.handle}", ca.sumsqr(d) - a.radius ** 2, 0.0, np.inf, "ineq")

    # footsteps: planted handles at their footprint on the ground
    if pins:
        s_pin = np.array([pn[1] for pn in pins])
        HPp = hk.map(len(pins))(ca.mtimes(_sparse(basis(K, s_pin, 0)), P).T)
        rows = []
        for c, pn in enumerate(pins):
            d = (HPp[3 * hk_names.index(pn[0]):3 * hk_names.index(pn[0]) + 3, c]
                 - ca.vertcat(pn[2][0], pn[2][1], sp.ground.z(pn[2][0], pn[2][1])))
            rows.append(d[:2] if len(pn) > 3 else d)  # "xy": the height is implied (cyclic end)
        add("footstep", ca.vertcat(*rows), 0.0, 0.0)
    # ground non-penetration of every foot handle at every point
    if sp.soft_pin_hz > 0 and pins:
        # soft footprints between the hard points: least squares (Gauss–Newton friendly),
        # keeps planted feet still between collocation points without degenerate constraints
        dense = np.linspace(0, 1, max(2, int(round(m.duration * sp.soft_pin_hz)) + 1))
        soft = []
        for si, step in enumerate(sp.footsteps):
            for handle, (ta, tb), xy in planted_handles(si, step):
                sa, sb = m.to_canonical([ta, tb])
                for v in dense[(dense > sa) & (dense < sb)]:
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
        dense = np.array([v for v in dense if _depends_on_free(K, v, mask, warp_free)])
        if len(dense):
            HPg = hk.map(len(dense))(ca.mtimes(_sparse(basis(K, dense, 0)), P).T)
            depth = ca.vertcat(*[ca.fmin(HPg[3 * hk_names.index(h) + 2, :] - sp.ground.z(
                HPg[3 * hk_names.index(h), :], HPg[3 * hk_names.index(h) + 1, :]), 0.0) for h in CONTACT_HANDLES])
            rho_extra.append(np.sqrt(sp.soft_ground_weight / depth.shape[0]) * depth)
    s_gnd = s_con if sp.ground_hz <= 0 else \
        np.unique(np.r_[s_con, np.linspace(0, 1, max(2, int(round(m.duration * sp.ground_hz)) + 1))])
    s_gnd = np.array([v for v in s_gnd if _depends_on_free(K, v, mask, warp_free)
                      and not (sp.cyclic and v > 1.0 - 1e-9)])  # cyclic: the end repeats the start
    HPc = hk.map(len(s_gnd))(ca.mtimes(_sparse(basis(K, s_gnd, 0)), P).T)
    ground = ca.vertcat(*[HPc[3 * hk_names.index(h) + 2, :] for h in CONTACT_HANDLES])
    if not sp.ground.flat:  # height above the terrain under each handle
        ground = ground - ca.vertcat(*[sp.ground.z(HPc[3 * hk_names.index(h), :], HPc[3 * hk_names.index(h) + 1, :])
                                       for h in CONTACT_HANDLES])
    # a handle pinned to the ground at a point already has its height fixed there: a second,
    # identical (active) row would make the constraint Jacobian rank-deficient
    pinned_z = {(pn[0], round(pn[1], 9)) for pn in pins if len(pn) == 3}
    keep = [k * len(CONTACT_HANDLES) + i for k, v in enumerate(s_gnd) for i, h in enumerate(CONTACT_HANDLES)
            if (h, round(float(v), 9)) not in pinned_z]
    add("penetration", ca.vec(ground)[keep], 0.0, np.inf, "ineq")
    # feet not crossing: left ankle stays left of the right one, in the pelvis heading frame
    yaw = Q[3, :]
    dl = HP[3 * hk_names.index("ankle_l"):3 * hk_names.index("ankle_l") + 2, :] - \
        HP[3 * hk_names.index("ankle_r"):3 * hk_names.index("ankle_r") + 2, :]
    lateral = -ca.sin(yaw) * dl[0, :] + ca.cos(yaw) * dl[1, :]
    live = [k for k in range(N) if _depends_on_free(K, s[k], mask, warp_free)
            and not (sp.cyclic and s[k] > 1.0 - 1e-9)]
    add("feet_crossing", lateral[live], sp.min_foot_separation, np.inf, "ineq")
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

    # variable bounds: joint limits on control points, λ ≥ 0, footprints within 0.5 m
    lo, hi = ch.lower, ch.upper
    ctrl0 = np.asarray(m.ctrl, float)
    lbx = [np.tile(lo, K)[free_idx], np.full(xW.shape[0], -np.inf), [], np.zeros(n_lam)]
    ubx = [np.tile(hi, K)[free_idx], np.full(xW.shape[0], np.inf), [], np.full(n_lam, np.inf)]
    x0 = [ctrl0.ravel()[free_idx], np.asarray(m.warp, float) if warp_free else [], [],
          _lambda_guess(sp, planted if n_lam else [], s, mg)]
    fp0 = []
    for si in free_steps:
        fp0 += list(sp.footsteps[si].position)
    lbx[2] = np.asarray(fp0) - 0.5
    ubx[2] = np.asarray(fp0) + 0.5
    x0[2] = np.asarray(fp0)

    x = ca.vertcat(xP, xW, xF, xL)
    rho = ca.vertcat(rho_dyn, *[OBJ_SCALE * ca.vec(r) for r in rho_extra])
    f = ca.sumsqr(rho)
    gg = ca.vertcat(*g)

    # Gauss–Newton Hessian of the objective + exact Hessian of the (kinematic) constraints
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", gg.shape[0])
    # Everything but the dynamics kernel is plain SX-expandable algebra: expanding those
    # parts makes their derivatives cheap scalar code instead of MX graph evaluation.
    # (expand the plain functions first, then differentiate in SX: much cheaper to build)
    rho_x = ca.vertcat(*[OBJ_SCALE * ca.vec(r) for r in rho_extra])
    xs, ps = ca.SX.sym("x", x.shape[0]), ca.SX.sym("p", p.shape[0])
    J_dyn = ca.jacobian(rho_dyn, x)
    rxs = ca.Function("rho_extra", [x, p], [rho_x]).expand()(xs, ps)
    J_x = ca.Function("J_extra", [xs, ps], [ca.jacobian(rxs, xs)])(x, p)
    gs = ca.Function("g_all", [x, p], [gg]).expand()(xs, ps)
    if gg.shape[0]:
        lam_s = ca.SX.sym("lam_s", gg.shape[0])
        Hc = ca.Function("H_con", [xs, ps, lam_s], [ca.hessian(ca.dot(lam_s, gs), xs)[0]])(x, p, lam_g)
    else:
        Hc = ca.MX(x.shape[0], x.shape[0])
    H = 2 * lam_f * (ca.mtimes(J_dyn.T, J_dyn) + ca.mtimes(J_x.T, J_x))
    if sp.hessian != "gauss_newton_objective":
        H = H + Hc
    if sp.hessian not in HESSIAN_MODES:
        raise ValueError(f"Subproblem.hessian must be one of {HESSIAN_MODES}, not {sp.hessian!r}")
    if sp.hessian == "exact":
        # second-order term 2 Σ r ∇²r of Σ r² (times lam_f).  Dynamics: r = C ⊙ Q(z) per point with
        # z = (q, q̇, q̈, forces); with the timewarp held, C is constant and z linear in x, so the
        # term is exactly J_zᵀ blockdiag(∇²_z (w·Q)) J_z with w = 2 lam_f r ⊙ C (compiled kernel
        # Hessian).  A free timewarp (and a spring's force, nonlinear in q) also curves z and C:
        # those curvature terms are left out (Gauss–Newton in them).
        if sp.dynamics != "kinematic":
            C = scale * ca.vertcat(SA, np.sqrt(w_r) * ca.DM.ones(N_ROOT, N)) * ca.repmat(wt, N_DOF, 1)
            Wk = 2 * lam_f * ca.reshape(rho_dyn, N_DOF, N) * C
            nz = 3 * N_DOF + 3 * len(FORCE_HANDLES)
            Hk = kernel_hessian(ch).map(N)(Q, Qd, Qdd, Fc, TH, Wk)  # (nz, nz N)
            Hzz = ca.diagcat(*ca.horzsplit(Hk, nz)) if N > 1 else Hk
            Jz = ca.jacobian(ca.vec(ca.vertcat(Q, Qd, Qdd, Fc)), x)
            H = H + ca.mtimes(Jz.T, ca.mtimes(Hzz, Jz))
        if rho_x.shape[0]:  # the other least-squares terms are plain SX algebra: exact Hessian directly
            mu = ca.SX.sym("mu", rho_x.shape[0])
            H = H + ca.Function("H_extra", [xs, ps, mu], [ca.hessian(ca.dot(mu, rxs), xs)[0]])(
                x, p, 2 * lam_f * rho_x)
    H = ca.triu(H)
    hess = ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])

    jac_g = ca.Function("nlp_jac_g", [xs, ps], [gs, ca.jacobian(gs, xs)], ["x", "p"], ["g", "jac_g_x"])
    opts = {
        "hess_lag": hess, "jac_g": jac_g, "print_time": False,
        "ipopt": {"print_level": int(_os.environ.get("COMPOSE_IPOPT_PRINT", "0")), "max_iter": sp.max_iter, "tol": sp.tol, "acceptable_tol": 1e-4,
                  "acceptable_iter": 5, "mu_strategy": "adaptive", "linear_solver": "mumps", "sb": "yes"},
    }
    opts["ipopt"].update(dict(sp.ipopt_options))
    opts.update(dict(sp.nlpsol_options))
    monitor = None
    if sp.stall_iterations > 0:
        monitor = StallMonitor(x.shape[0], gg.shape[0], np.asarray(lbg, float), np.asarray(ubg, float),
                               sp.stall_iterations)
        opts["iteration_callback"] = monitor
    solver = ca.nlpsol("spacetime", "ipopt", {"x": x, "p": p, "f": f, "g": gg}, opts)

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

    springs_out = ca.vertcat(*spring_force) if spring_force else ca.MX(0, N)
    unpack = ca.Function("unpack", [x, p], [P, warp, xF, energy, root_energy, springs_out])
    return Built(sp, solver, np.concatenate([np.ravel(a) for a in x0]),
                 np.concatenate([np.ravel(a) for a in lbx]), np.concatenate([np.ravel(a) for a in ubx]),
                 np.asarray(lbg, float), np.asarray(ubg, float), pv, unpack, groups, s,
                 [(h, k, slice(xP.shape[0] + xW.shape[0] + xF.shape[0] + 4 * c,
                               xP.shape[0] + xW.shape[0] + xF.shape[0] + 4 * c + 4))
                  for c, (h, k, _, _) in enumerate(planted if n_lam else [])],
                 slice(xP.shape[0] + xW.shape[0] + xF.shape[0], x.shape[0]), free_steps,
                 ca.Function("g", [x, p], [gg]), tuple(Vc), tuple(sg.handle for sg in sp.springs), monitor,
                 ca.Function("f", [x, p], [f]), hess,
                 ca.Function("rho_dyn", [x, p], [rho_dyn]), ca.Function("rho_extra", [x, p], [rho_x]),
                 ca.Function("ctrl", [x, p], [P]),
                 tuple(slice(n_fixed + 3 * N * j, n_fixed + 3 * N * (j + 1)) for j in range(len(sp.springs))))


def violations(b: Built, x: np.ndarray, p: np.ndarray | None = None) -> dict[str, float]:
    """Worst violation per constraint group (m for positions; 0 when satisfied)."""
    gv = np.asarray(b.g_fn(x, b.p if p is None else p)).ravel()
    out = {}
    for name, sl, _ in b.groups:
        lo, hi, v = b.lbg[sl], b.ubg[sl], gv[sl]
        viol = np.maximum(np.maximum(lo - v, v - hi), 0.0)
        key = name.split(":")[0] if name.startswith("target") else name
        out[key] = max(out.get(key, 0.0), float(viol.max()) if viol.size else 0.0)
    return out


def read_solution(b: Built, x: np.ndarray, p: np.ndarray) -> tuple[Motion, tuple, float, dict]:
    """(motion, footsteps, energy, forces) of a solution vector ``x`` of ``b`` with parameters
    ``p``; forces: handle → (world times s, forces N (n, 3)), contact forces from λ plus each
    spring's force over its interval (external forces at their handle, for the audit)."""
    sp = b.sp
    P, W, F, E, _, FS = (np.asarray(v) for v in b.unpack(x, p))
    F = F.ravel()
    motion = Motion(np.asarray(P, float), np.asarray(W, float).ravel())
    steps = list(sp.footsteps)
    for j, si in enumerate(b.free_steps):
        steps[si] = replace(steps[si], position=(float(F[2 * j]), float(F[2 * j + 1])))
    mg = sp.character.total_mass * G
    forces: dict = {}
    for c, (h, k, sl) in enumerate(b.contact_index):
        V = b.contact_basis[c] if b.contact_basis else friction_basis()
        forces.setdefault(h, []).append((float(motion.time([b.s_points[k]])[0]), mg * V @ x[sl]))
    contact = {h: (np.array([t for t, _ in v]), np.array([f for _, f in v])) for h, v in forces.items()}
    t_pts = motion.time(b.s_points)
    for j, h in enumerate(b.spring_handles):
        fj = FS[3 * j:3 * j + 3, :].T
        on = (t_pts >= sp.springs[j].times[0] - 1e-9) & (t_pts <= sp.springs[j].times[-1] + 1e-9)
        if h in contact:
            t_old, f_old = contact[h]
            t_all = np.unique(np.r_[t_old, t_pts[on]])
            f_all = np.zeros((len(t_all), 3))
            for tt, ff in zip(t_old, f_old):
                f_all[np.argmin(np.abs(t_all - tt))] += ff
            for tt, ff in zip(t_pts[on], fj[on]):
                f_all[np.argmin(np.abs(t_all - tt))] += ff
            contact[h] = (t_all, f_all)
        elif on.any():
            contact[h] = (t_pts[on], fj[on])
    return motion, tuple(steps), float(np.ravel(E)[0]), contact


def solve(sp: Subproblem, built: Built | None = None, theta_override=None) -> Result:
    """Build (unless given) and solve a subproblem with IPOPT, warm-started from sp.motion."""
    t_start = _time.perf_counter()
    b = built or build(sp)
    if b.monitor is not None:
        b.monitor.reset()
    sol = b.solver(x0=b.x0, lbx=b.lbx, ubx=b.ubx, lbg=b.lbg, ubg=b.ubg, p=b.p)
    stats = b.solver.stats()
    x = np.asarray(sol["x"]).ravel()
    f_final = float(sol["f"])
    m_ = b.monitor
    if m_ is not None and m_.best_x is not None and m_.best < f_final - 1e-9 * max(1.0, abs(f_final)):
        x, f_final = m_.best_x, m_.best  # IPOPT ended worse than a feasible iterate it passed
    motion, steps, energy, contact = read_solution(b, x, b.p)
    viol = violations(b, x)
    status = stats.get("return_status", "unknown")
    ok = bool(stats.get("success", False)) or status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    if b.monitor is not None and b.monitor.stalled and status == "User_Requested_Stop":
        status, ok = "Stalled", True
    return Result(motion, tuple(steps), status, ok, int(stats.get("iter_count", -1)),
                  _time.perf_counter() - t_start, energy, f_final, viol, contact, sp.label)
