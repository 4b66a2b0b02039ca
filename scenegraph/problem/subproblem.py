"""What one spacetime subproblem (a Step's unit of work for one character) solves: plain data.

Frozen dataclasses only, no CasADi: the character, style and motion to start from, the
footsteps, which blocks are free under which window, and the soft or hard terms (handle
targets, poses, avoid-spheres, springs).  Times are world times (s) of ``Subproblem.motion``;
positions are world coordinates (m, z up); forces are in N.  The transcription
(:mod:`.transcription`) turns a :class:`Subproblem` into an NLP.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.ground import FLAT, Ground
from scenegraph.model.motion import Motion
from scenegraph.model.style import Style

__all__ = ["Subproblem", "HandleTarget", "PoseTarget", "Spring", "Avoid", "HESSIAN_MODES"]

HESSIAN_MODES = ("gauss_newton", "exact", "gauss_newton_objective")


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
    dofs: tuple[int, ...] | None = None  # only these DOF indices (None: all 35)


@dataclass(frozen=True)
class VelocityTarget:
    """Soft spring toward the centre-of-mass velocity ``velocity`` (m/s, world frame) at world
    time ``t``; ``weight`` in (s/m)² of the normalised objective (E units).  A scene's start:
    the character enters with the momentum of its planned motion instead of whatever momentum
    the first contact forces could take out (the ground force is not part of the energy)."""

    t: float
    velocity: tuple[float, float, float]
    weight: float = 1.0


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
    flights: tuple[tuple[float, float], ...] = ()  # world s (take-off, landing): zero root residual inside
    flight_mode: str = "momentum"  # "momentum": ballistic momentum equalities at the flight's points
    # (scenegraph/problem/flight.py); "penalty": the root residual weighted W_FLIGHT in flight (round 8)
    flight_curvature: bool = False  # True: the momentum rows' curvature in the Lagrangian Hessian (flight.flight_hessian;
    # broad_jump A/B 2026-12-03: 212 it, E 1648 against 237–300 it, E 1136–1180 without); False: Gauss–Newton in them
    window: tuple[float, float] | None = None
    free: frozenset = frozenset({"q", "warp"})
    dynamics: str = "full"
    targets: tuple[HandleTarget, ...] = ()
    poses: tuple[PoseTarget, ...] = ()
    velocities: tuple[VelocityTarget, ...] = ()
    avoid: tuple[Avoid, ...] = ()
    springs: tuple[Spring, ...] = ()
    style_end: Style | None = None
    collocation_hz: float = 30.0  # dynamics (energy, contact forces)
    constraint_hz: float = 30.0  # footsteps and ground (if higher than collocation_hz)
    dense_dynamics: bool = True  # nodes on the spline's knots and every contact/flight end, contact forces
    # piecewise linear between nodes and zero at touch-down and lift-off, the residual also at every
    # node interval's midpoint (Simpson); False: the round-8 grid (forces at points only), for comparison
    shoe_gate: bool = True  # the heel shoe springs only in planned heel contact, ramped (scenegraph/model/shoe.py);
    # False: everywhere a heel is within ~5 mm of the floor (the round-8 kernel's)
    ground_hz: float = 0.0  # extra grid for non-penetration (0: the constraint grid; denser grids
    # were measured to stall IPOPT: 300 iterations without convergence at 90 Hz)
    soft_pin_hz: float = 0.0  # soft footprint springs between the hard points (0: off; see README)
    soft_pin_weight: float = 1e5  # total weight, shared by the soft points
    soft_ground_hz: float = 0.0  # one-sided ground penalty on a dense grid (0: off)
    soft_ground_weight: float = 1e6  # total weight, shared by the dense points
    stance_frame_weight: float = 0.0  # 1/(rad²·s): a planted foot keeps its footstep's yaw and roll
    # (scenegraph/problem/stance_frame.py; 0: off; full dynamics only)
    no_slip_weight: float = 0.0  # s/m²: foot handles near the floor do not move horizontally
    # (scenegraph/problem/no_slip.py; 0: off; full dynamics only)
    contact_hz: float = 120.0  # samples per second of those two terms (world s of the initial motion)
    jerk_weight: float = 0.0  # dimensionless: the knot-to-knot jump of the jerk as a generalised force,
    # integrated over time (scenegraph/problem/jerk.py; 0: off; full and relaxed dynamics)
    joint_speed_limit: bool = True  # joints under the human ceilings of scenegraph/model/joint_speed.py
    # (full dynamics, held timewarp)
    window_only: bool = False  # transcribe only the collocation points the window's free control
    # points reach (a window's cost independent of the scene's length); receding windows use it —
    # in walk_to_run's first window it ended "Error in step computation" where the whole-scene
    # transcription stalls feasibly, so the other windows keep the whole scene for now
    open_end: bool = False  # a receding window: the control points whose support begins inside the
    # window are free (the end state too), and the dynamics count only up to the window's end
    fix_start_time: bool = True
    fix_end_time: bool = True  # False (free duration): the end of the timewarp moves within end_time_bounds
    end_time_bounds: tuple[float, float] | None = None  # world s; with fix_end_time False and a free warp
    cyclic: bool = False
    contact_guess: dict | None = field(default=None, compare=False, hash=False)  # warm start for λ
    min_foot_separation: float = 0.06
    clearance: tuple = ()  # scenegraph.model.clearance.BodyClearance: this character's body spheres kept
    # off other characters' (held) bodies at given times
    clearance_weight: float = 0.0  # 0: clearance as hard rows; > 0: one-sided least squares of the depth
    # (m) inside the summed radii, this total weight shared by the rows
    ground: Ground = FLAT  # terrain: footprint heights, non-penetration, friction pyramids (ground.py)
    max_iter: int = 300
    tol: float = 1e-4
    label: str = "step"
    ipopt_options: tuple = ()  # extra IPOPT options as (name, value) pairs (e.g. warm starts in NIO)
    nlpsol_options: tuple = ()  # extra CasADi nlpsol options as (name, value) pairs (e.g. iteration_callback)
    stall_iterations: int = 0  # > 0: stop as "Stalled" (a success) when the best feasible objective has
    # improved by less than STALL_RATE per iterate over this many feasible iterates (see StallMonitor)
    hessian: str = "gauss_newton"  # Hessian of the objective given to IPOPT (HESSIAN_MODES): "gauss_newton"
    # (2 JᵀJ) or "exact" (adds 2 Σ r ∇²r: the compiled kernel Hessian chained through the splines; see
    # transcription); "gauss_newton_objective" (an experiment: 2 JᵀJ without the constraints' curvature; README)
