"""The scenario schema: what a scenario YAML file may say, with units and cross-field checks.

A scenario names its characters (body preset and edits, style, start), their goals
(footprints, walk_to, reach, tackle, avoid, style_change), the couplings between them
(hand_hold, carry) and, optionally, an explicit schedule that overrides the compiler.

Units: metres, kilograms, seconds; **angles in scenario files are degrees** (they are
converted to radians where the scene is built).  Positions on the ground are ``[x, y]``
(m, world frame, Z up); points in space are ``[x, y, z]``.

This module belongs to the language layer and does not import ``scenegraph``: the names
it checks (body presets, handles, joint DOFs) are listed here as strings, and a test
asserts that they agree with the character model.

Cross-field problems (a goal naming a missing character, a time outside the scenario, an
unknown style, …) are raised as :class:`FieldProblem`, a ``ValueError`` that carries the
field path *relative to the model that raised it*, so that the loader can point at the
offending field's line and column.  Checks that need to know where the scenario file lives
(style files) read ``base_dir`` and ``styles`` from the pydantic validation context; see
:func:`scenarios.loader.validation_context`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Union

from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, PrivateAttr, Strict, StringConstraints,
                      ValidationInfo, field_validator, model_validator)

from scenarios.bundled import resolve_style, style_problem
from scenarios.edit_block import EditBlock, edit_problems
from scenarios.names import is_style_path, suggest
from scenarios.weights import AVOID_WEIGHT, TARGET_WEIGHT

_EPS = 1e-9  # s


def _meets(iv, w) -> bool:
    """Closed intervals iv and w (s) share a point."""
    return iv[0] <= w[1] + _EPS and w[0] <= iv[1] + _EPS


class _AtTime:
    """Plan fact of a goal that holds at one instant ``time``: active in windows containing it."""

    def active(self, window: tuple[float, float]) -> bool:
        return _meets((self.time, self.time), window)

__all__ = [
    "Scenario", "CharacterSpec", "BodySpec", "ExtraMass", "LockedJoint", "RangeOfMotion", "StartSpec",
    "Environment", "Ground", "Slope", "Region",
    "Goal", "FootprintsGoal", "Footprint", "WalkToGoal", "ReachGoal", "TackleGoal", "AvoidGoal", "StyleChangeGoal",
    "JumpGoal", "HopGoal", "KeyframesGoal", "LeapEnd", "Keyframe", "leap_sequence",
    "Coupling", "HandHold", "Carry", "HandleRef", "ScheduleSpec", "SCHEDULE_KINDS",
    "EditBlock", "FieldProblem", "BODY_PRESETS", "HANDLE_NAMES", "JOINT_DOF_NAMES", "JOINT_NAMES", "ADVERSARIAL_GOALS",
    "joint_dofs", "is_style_path", "suggest",
]

# --- names shared with the character model (scenegraph asserts against these) ---------------

BODY_PRESETS: tuple[str, ...] = ("adult_male", "adult_female", "child")

_SIDED_HANDLES = ("heel", "ball", "toe", "palm", "shoulder", "knee", "ankle", "wrist", "elbow", "hip")
HANDLE_NAMES: tuple[str, ...] = ("pelvis", "chest", "head", "head_top") + tuple(
    f"{h}_{s}" for s in ("l", "r") for h in _SIDED_HANDLES)

JOINT_DOF_NAMES: tuple[str, ...] = (
    "waist_flex", "waist_lat", "waist_twist", "chest_flex", "neck_flex",
    *(f"{d}_{s}" for s in ("l", "r") for d in (
        "shoulder_flex", "shoulder_twist", "shoulder_abd", "elbow_flex", "wrist_flex",
        "hip_flex", "hip_abd", "hip_rot", "knee_flex", "ankle_flex", "ankle_inv", "toe_flex")),
)


def _joint_of(dof: str) -> str:
    base, side = (dof[:-2], dof[-2:]) if dof.endswith(("_l", "_r")) else (dof, "")
    return base.split("_")[0] + side


JOINT_NAMES: tuple[str, ...] = tuple(dict.fromkeys(_joint_of(d) for d in JOINT_DOF_NAMES))


def joint_dofs(name: str) -> tuple[str, ...]:
    """The joint DOFs named by a joint (``knee_l`` → ``knee_flex_l``) or by a DOF itself."""
    if name in JOINT_DOF_NAMES:
        return (name,)
    return tuple(d for d in JOINT_DOF_NAMES if _joint_of(d) == name)


ADVERSARIAL_GOALS = ("tackle", "avoid")
SCHEDULE_KINDS = ("auto", "timewarp", "time_layered", "coupled", "decreasing_horizon")

# --- small helpers --------------------------------------------------------------------------


class FieldProblem(ValueError):
    """A validation problem at ``path`` (relative to the model whose validator raised it)."""

    def __init__(self, path: tuple, message: str, more: list[tuple[tuple, str]] | None = None):
        self.path = tuple(path)
        self.message = message
        self.more = list(more or [])  # further problems (absolute paths) found by the same check
        super().__init__(message)


# Plausibility limits (checked at validation, before anything is built or solved):
MAX_COORD = 10_000.0  # m: every position lies within ±10 km of the origin (a scene, not a map)
MAX_SPEED = 12.0  # m/s: a walk_to's average speed, start (or the previous walk_to) to target along
# its waypoints; the fastest human sprinters peak at about 12.4 m/s (100 m world record pace)


# Resource limits (checked at validation, before anything is built; docs/reliability.md):
MAX_CHARACTER_SECONDS = 60.0  # s: duration × characters; building the initial motions and the
# transcription grows with it (a 9.6 s window of one character takes ~14 s to build)
MAX_FOOTPRINTS = 1000  # explicit footprints in all footprints goals together
MAX_GOALS = 200  # goals of one scenario
# The solver's collocation rate (scenegraph.problem.Subproblem.collocation_hz; a test asserts
# they agree): an interval shorter than 1/COLLOCATION_HZ may hold no collocation point
COLLOCATION_HZ = 30.0
# Body sizes the plausibility checks use (scenegraph.model.body.PRESETS; a test asserts they agree)
PRESET_HEIGHTS = {"adult_male": 1.75, "adult_female": 1.65, "child": 1.20}  # m, default statures
REACH_UP = 1.35  # highest point a handle reaches, × stature (overhead, on tiptoe: ~1.3)
REACH_OUT = 0.75  # horizontal reach of a hand from the pelvis, × stature (arm + shoulder + lean)
LEG_SPREAD = 0.75  # largest distance between two planted feet, × stature (a long lunge)


def format_field(path: tuple) -> str:
    """('goals', 0, 'steps', 2) -> 'goals[0].steps[2]'."""
    return "".join(f"[{p}]" if isinstance(p, int) else (f".{p}" if i else str(p)) for i, p in enumerate(path))


def _coord(v: float) -> float:
    if abs(v) > MAX_COORD:
        raise ValueError(f"{v:g} m is beyond the scene limit of ±{MAX_COORD:g} m from the origin "
                         "(positions are metres in the scene)")
    return v


Num = Annotated[float, Strict()]
Seconds = Annotated[float, Strict(), Field(ge=0.0, le=3600.0)]
Degrees = Annotated[float, Strict()]
Coord = Annotated[float, Strict(), AfterValidator(_coord)]
Point2 = tuple[Coord, Coord]
Point3 = tuple[Coord, Coord, Coord]
Name = Annotated[str, StringConstraints(pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")]


def _interval(v: tuple[float, float]) -> tuple[float, float]:
    t0, t1 = v
    if t0 < 0:
        raise ValueError(f"interval starts at {t0} s, before 0")
    if t1 <= t0:
        raise ValueError(f"interval end {t1} s must be after its start {t0} s")
    return v


Interval = Annotated[tuple[Num, Num], Field(description="[t_start, t_end] (s), t_end > t_start >= 0")]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, populate_by_name=True)


def _check_handle(v: str) -> str:
    if v not in HANDLE_NAMES:
        raise ValueError(suggest(v, HANDLE_NAMES, "handle"))
    return v


# --- environment ----------------------------------------------------------------------------


class Ground(_Model):
    """Flat ground at z = 0."""

    friction: Num = Field(0.8, gt=0.0, le=5.0, description="Coulomb friction coefficient μ of the contact "
                                                         "forces' friction pyramid (dimensionless)")


class Region(_Model):
    """An axis-aligned rectangle on the ground plane."""

    min: Point2 = Field(description="lower-left corner [x, y] (m)")
    max: Point2 = Field(description="upper-right corner [x, y] (m)")

    @model_validator(mode="after")
    def _ordered(self):
        for axis, a, b in (("x", self.min[0], self.max[0]), ("y", self.min[1], self.max[1])):
            if b <= a:
                raise FieldProblem(("max",), f"region max {axis} ({b} m) must exceed min {axis} ({a} m)")
        return self


class Slope(_Model):
    """A plane z = tan(angle) · ((p − origin) · (cos heading, sin heading)) over a region."""

    name: Name | None = Field(None, description="label for markers and errors")
    angle: Degrees = Field(ge=-45.0, le=45.0, description="inclination (deg); positive rises along heading")
    heading: Degrees = Field(0.0, ge=-360.0, le=360.0, description="direction of steepest ascent (deg, from +X)")
    region: Region = Field(description="where the slope replaces the flat ground")
    origin: Point2 | None = Field(None, description="a point [x, y] (m) where the plane has z = 0; default: region centre")
    friction: Num | None = Field(None, gt=0.0, le=5.0, description="μ on this slope; default: the ground's")


class Environment(_Model):
    ground: Ground = Field(default_factory=Ground, description="the flat ground z = 0")
    slopes: list[Slope] = Field(default_factory=list, max_length=64, description="inclined planes over regions")


# --- characters -----------------------------------------------------------------------------


class ExtraMass(_Model):
    """A point mass rigidly attached at a handle (e.g. a 3 kg suitcase in the right hand)."""

    handle: str = Field(description="handle name, e.g. palm_r")
    mass: Num = Field(gt=0.0, le=200.0, description="mass (kg)")
    label: str | None = Field(None, max_length=64, description="what it is (for reports)")

    check_handle = field_validator("handle")(_check_handle)


class LockedJoint(_Model):
    """A joint (all its DOFs) or a single DOF held at a fixed angle."""

    joint: str = Field(description="joint name (knee_l, waist, …) or joint DOF name (knee_flex_l)")
    angle: Degrees = Field(0.0, ge=-180.0, le=180.0, description="angle every locked DOF is held at (deg)")

    @field_validator("joint")
    @classmethod
    def _known(cls, v: str) -> str:
        if not joint_dofs(v):
            raise ValueError(suggest(v, JOINT_NAMES + JOINT_DOF_NAMES, "joint or joint DOF"))
        return v


class RangeOfMotion(_Model):
    """A reduced range of motion for one joint DOF."""

    dof: str = Field(description="joint DOF name, e.g. knee_flex_r")
    min: Degrees = Field(ge=-180.0, le=180.0, description="lower limit (deg)")
    max: Degrees = Field(ge=-180.0, le=180.0, description="upper limit (deg)")

    @field_validator("dof")
    @classmethod
    def _known(cls, v: str) -> str:
        if v not in JOINT_DOF_NAMES:
            raise ValueError(suggest(v, JOINT_DOF_NAMES, "joint DOF"))
        return v

    @model_validator(mode="after")
    def _ordered(self):
        if self.max <= self.min:
            raise FieldProblem(("max",), f"max {self.max} deg must exceed min {self.min} deg")
        return self


class BodySpec(_Model):
    """A body preset scaled to a height and mass, with edits."""

    preset: Literal["adult_male", "adult_female", "child"] = Field("adult_male", description="body preset")
    height: Num | None = Field(None, ge=0.5, le=2.5, description="stature (m); default: the preset's")
    mass: Num | None = Field(None, ge=5.0, le=300.0, description="body mass (kg); default: the preset's")
    extra_masses: list[ExtraMass] = Field(default_factory=list, max_length=16,
                                          description="point masses carried at handles")
    locked: list[LockedJoint] = Field(default_factory=list, max_length=29, description="locked joints or DOFs")
    range_of_motion: list[RangeOfMotion] = Field(default_factory=list, max_length=29,
                                                 description="reduced joint limits per DOF")
    shoe_stiffness_scale: Num = Field(1.0, gt=0.0, le=100.0,
                                      description="factor on the style's shoe stiffness k_shoe (dimensionless)")

    @model_validator(mode="after")
    def _no_conflicts(self):
        locked: dict[str, int] = {}
        for i, lk in enumerate(self.locked):
            for d in joint_dofs(lk.joint):
                if d in locked:
                    raise FieldProblem(("locked", i, "joint"), f"{d} is already locked by locked[{locked[d]}]")
                locked[d] = i
        seen: dict[str, int] = {}
        for i, r in enumerate(self.range_of_motion):
            if r.dof in seen:
                raise FieldProblem(("range_of_motion", i, "dof"),
                                   f"{r.dof} already has a range in range_of_motion[{seen[r.dof]}]")
            seen[r.dof] = i
            if r.dof in locked:
                raise FieldProblem(("range_of_motion", i, "dof"), f"{r.dof} is locked by locked[{locked[r.dof]}]")
        return self


class StartSpec(_Model):
    position: Point2 = Field((0.0, 0.0), description="pelvis position on the ground [x, y] (m) at t = 0")
    heading: Degrees = Field(0.0, ge=-360.0, le=360.0, description="facing direction at t = 0 (deg, from +X)")


class CharacterSpec(_Model):
    name: Name = Field(description="unique character name (letters, digits, _)")
    body: BodySpec = Field(default_factory=BodySpec, description="body preset and edits")
    style: str = Field("default", min_length=1, max_length=512,
                       description="bundled style name, or a style file path relative to the scenario file")
    start: StartSpec = Field(default_factory=StartSpec, description="start position and heading")
    initial_motion: Literal["generator", "example"] = Field(
        "generator", description="joint angles of the initial guess: 'generator' (built-in gait curves) or "
                                 "'example' (the poses of the clip the style was learned from, by leg phase, as "
                                 "the paper initialises; needs a learned style and no style change)")


# --- goals ----------------------------------------------------------------------------------


class Footprint(_Model):
    foot: Literal["l", "r"] = Field(description="which foot")
    position: Point2 = Field(description="where the foot is planted [x, y] (m): midpoint of its heel and ball")
    heading: Degrees | None = Field(None, ge=-360.0, le=360.0, description="foot direction (deg); default: free")
    time: Interval = Field(description="contact interval [heel strike, toe off] (s)")

    check_time = field_validator("time")(_interval)


class FootprintsGoal(_Model):
    """Explicit footprints: where and when each foot is on the ground."""

    type: Literal["footprints"]
    name: Name | None = Field(None, description="goal name; default <type>_<index>")
    character: str = Field(description="character name")
    steps: list[Footprint] = Field(min_length=1, max_length=1000, description="footprints in any order")

    @model_validator(mode="after")
    def _no_overlap(self):
        last: dict[str, tuple[int, tuple[float, float]]] = {}
        for i, fp in sorted(enumerate(self.steps), key=lambda x: (x[1].foot, x[1].time[0], x[0])):
            prev = last.get(fp.foot)
            if prev is not None and fp.time[0] < prev[1][1]:
                raise FieldProblem(("steps", i, "time"),
                                   f"foot {fp.foot} is already on the ground until {prev[1][1]} s (steps[{prev[0]}])")
            last[fp.foot] = (i, fp.time)
        return self

    # plan facts (the compiler, no CasADi): active in a window, and how it is enforced
    plan_weight: ClassVar[float | str | None] = "hard"  # footprints are hard constraints of every subproblem

    def active(self, window: tuple[float, float]) -> bool:
        """A footprint's contact interval meets the window (canonical s)."""
        return any(_meets(fp.time, window) for fp in self.steps)


class WalkToGoal(_Model):
    """Walk to a point by a time, footprints chosen by the optimisation."""

    type: Literal["walk_to"]
    name: Name | None = None
    character: str = Field(description="character name")
    target: Point2 = Field(description="where the pelvis ends [x, y] (m)")
    time: Seconds = Field(description="arrival time (s)")
    waypoints: list[Point2] = Field(default_factory=list, max_length=100,
                                    description="optional path [x, y] points (m) passed in order")
    heading: Degrees | None = Field(None, ge=-360.0, le=360.0,
                                   description="final facing (deg, from +X): the feet the character stands on after "
                                               "arriving point this way; needs time left after `time` and generated "
                                               "footsteps; default: the direction of the walk")
    tolerance: Num = Field(0.05, gt=0.0, le=10.0, description="allowed distance from the target (m)")

    plan_weight: ClassVar[float | str | None] = TARGET_WEIGHT  # a soft pelvis spring (scenarios/weights.py)

    def active(self, window: tuple[float, float]) -> bool:
        """The walk (and its waypoints) happens over [0, time]."""
        return window[0] <= self.time + _EPS


class ReachGoal(_AtTime, _Model):
    """Bring a handle to a point at a time."""

    type: Literal["reach"]
    name: Name | None = None
    character: str
    handle: str = Field(description="handle name, e.g. palm_r")
    target: Point3 = Field(description="target point [x, y, z] (m)")
    time: Seconds = Field(description="when the handle is at the target (s)")
    tolerance: Num = Field(0.02, gt=0.0, le=10.0, description="allowed distance (m)")

    check_handle = field_validator("handle")(_check_handle)

    plan_weight: ClassVar[float | str | None] = TARGET_WEIGHT


class TackleGoal(_AtTime, _Model):
    """Hit the target's torso at a time and speed, hands around it."""

    type: Literal["tackle"]
    name: Name | None = None
    attacker: str = Field(description="character who tackles")
    target: str = Field(description="character who is tackled")
    time: Seconds = Field(description="impact time (s)")
    min_speed: Num = Field(2.0, ge=0.0, le=15.0, description="lower bound of the closing speed at impact (m/s); "
                                                           "used when `speed` is not given")
    speed: Num | None = Field(None, gt=0.0, le=15.0,
                              description="closing speed at impact (m/s): the attacker's chest front toward the "
                                          "target's torso, relative to it; holds within ±10 %")
    hands_around_torso: Annotated[bool, Strict()] = Field(True, description="wrap both palms around the target's torso")
    plans_last: str | None = Field(None, description="who optimises last in the decreasing-horizon schedule "
                                                     "(attacker or target name); default: the attacker")

    plan_weight: ClassVar[float | str | None] = TARGET_WEIGHT

    @property
    def opponents(self) -> tuple[str, str]:
        """(who acts, the other); by default the first plans last."""
        return (self.attacker, self.target)


class AvoidGoal(_AtTime, _Model):
    """Stay outside a sphere around another character at a time."""

    type: Literal["avoid"]
    name: Name | None = None
    character: str = Field(description="character who avoids")
    around: str = Field(description="the character to keep away from")
    radius: Num = Field(gt=0.0, le=20.0, description="sphere radius around the other's chest (m)")
    time: Seconds = Field(description="when the distance must exceed the radius (s)")
    plans_last: str | None = Field(None, description="who optimises last (one of the pair); default: the attacker")

    plan_weight: ClassVar[float | str | None] = AVOID_WEIGHT

    @property
    def opponents(self) -> tuple[str, str]:
        """(the one avoided, who avoids); by default the first (the attacker) plans last."""
        return (self.around, self.character)


class StyleChangeGoal(_Model):
    """Switch a character's style at a time (θ interpolated across the transition)."""

    type: Literal["style_change"]
    name: Name | None = None
    character: str
    time: Seconds = Field(description="middle of the transition (s)")
    style: str = Field(min_length=1, max_length=512, description="new style: bundled name or file path")
    blend: Num | None = Field(None, gt=0.0, le=60.0,
                              description="transition length (s); default: the seam window of the time-layered schedule")
    gait: Literal["walk", "run"] | None = Field(
        None, description="gait of generated footsteps after the change (run: flight phases, longer and "
                          "quicker steps); default: unchanged")

    plan_weight: ClassVar[float | str | None] = None  # no solver term: the compiler's style timeline carries it

    def active(self, window: tuple[float, float]) -> bool:
        return False


# --- dynamic motion (issue 20): jumps, hops, a rough keyframe sketch -------------------------

G_ACC = 9.81  # m/s², the plan's nominal flight time of a jump with free timing
LEAP_TAKEOFF_DEFAULT = 0.7  # s: take-off of a first leap without a time (a countermovement from standing)
LEAP_FLIGHT_RANGE = (0.25, 0.8)  # s: nominal flight times are clipped to this


class LeapEnd(_Model):
    """Where (and optionally when) a jump or hop leaves or meets the ground."""

    position: Point2 | None = Field(None, description="[x, y] (m): the midpoint of the feet it stands on (after "
                                                      "a hop's landing: the foot's heel-ball midpoint); default "
                                                      "for a take-off: where the character stands")
    region: Region | None = Field(None, description="instead of position: the feet land (or take off) anywhere "
                                                    "in this rectangle; the optimisation places them")
    time: Seconds | None = Field(None, description="when (s): the last moment on the ground (take-off) or the "
                                                   "first (landing); default free: a nominal time from the "
                                                   "distance, which the timing step may move")

    @model_validator(mode="after")
    def _one_place(self):
        if self.position is not None and self.region is not None:
            raise FieldProblem(("region",), "give position or region, not both")
        return self

    def centre(self) -> tuple[float, float] | None:
        """The position, or the region's centre (m); None when neither is given."""
        if self.position is not None:
            return (float(self.position[0]), float(self.position[1]))
        if self.region is not None:
            return ((self.region.min[0] + self.region.max[0]) / 2, (self.region.min[1] + self.region.max[1]) / 2)
        return None


class _LeapGoal(_Model):
    """Fields and plan facts shared by jump and hop (a ground stage, a flight stage, a ground stage)."""

    name: Name | None = None
    character: str = Field(description="character name")
    takeoff: LeapEnd = Field(default_factory=LeapEnd, description="take-off: position/region and time; "
                                                                  "default: from where the character stands")
    landing: LeapEnd = Field(description="landing: position or region (required), time (optional)")
    turn_deg: Degrees = Field(0.0, ge=-720.0, le=720.0, description="turn in the air (deg, counter-clockwise "
                                                                  "seen from above): the landing feet face this "
                                                                  "much further round than the take-off feet")
    obstacle_height: Num | None = Field(None, gt=0.0, le=1.2, description="an obstacle midway between take-off "
                                                                        "and landing (m): the feet pass above it")
    tolerance: Num = Field(0.05, gt=0.0, le=10.0, description="allowed landing distance from the position (m)")

    @property
    def plan_weight(self) -> float | None:
        """The obstacle springs' weight (scenarios/weights.py); None without an obstacle (no
        goal term: the leap acts through its footprints and its flight term)."""
        return TARGET_WEIGHT if self.obstacle_height is not None else None

    @model_validator(mode="after")
    def _landing_place(self):
        if self.landing.centre() is None:
            raise FieldProblem(("landing",), "a landing needs a position or a region")
        t0, t1 = self.takeoff.time, self.landing.time
        if t0 is not None and t1 is not None and t1 <= t0 + 1e-9:
            raise FieldProblem(("landing", "time"), f"landing at {t1} s must come after the take-off at {t0} s")
        return self

    def flight_time(self, start: tuple[float, float]) -> float:
        """Nominal flight (s): the times given, else √(2 d / g) (the range of a 45° launch over
        d m from ``start`` or the take-off), clipped to LEAP_FLIGHT_RANGE, and at least the
        time to rise over the obstacle and back (2 √(2 h / g))."""
        if self.takeoff.time is not None and self.landing.time is not None:
            return float(self.landing.time - self.takeoff.time)
        a = self.takeoff.centre() or start
        b = self.landing.centre()
        d = ((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2) ** 0.5
        t = min(max((2 * d / G_ACC) ** 0.5, LEAP_FLIGHT_RANGE[0]), LEAP_FLIGHT_RANGE[1])
        if self.obstacle_height is not None:
            t = max(t, 2 * (2 * self.obstacle_height / G_ACC) ** 0.5)
        return t

    def times(self, start: tuple[float, float] = (0.0, 0.0), after: float = 0.0) -> tuple[float, float]:
        """(take-off, landing) s: the given times, else a take-off LEAP_TAKEOFF_DEFAULT after
        ``after`` (the previous landing, or 0) and the nominal flight."""
        tf = self.flight_time(start)
        t0 = self.takeoff.time
        if t0 is None:
            t0 = self.landing.time - tf if self.landing.time is not None else after + LEAP_TAKEOFF_DEFAULT
        return float(t0), float(t0 + tf)

    def active(self, window: tuple[float, float]) -> bool:
        """The flight meets the window (canonical s; nominal times when free)."""
        return _meets(self.times(), window)


class JumpGoal(_LeapGoal):
    """A two-footed jump: both feet leave the ground together and land together (a broad jump, a twist jump)."""

    type: Literal["jump"]


class HopGoal(_LeapGoal):
    """A hop: one foot takes off and the same foot lands."""

    type: Literal["hop"]
    foot: Literal["l", "r"] = Field(description="the foot that takes off and lands")


class Keyframe(_Model):
    """One key of a rough sketch: the pelvis position, the heading and some joint angles at a time."""

    time: Seconds = Field(description="when (s)")
    position: Point3 | None = Field(None, description="pelvis [x, y, z] (m)")
    heading: Degrees | None = Field(None, ge=-720.0, le=720.0, description="pelvis heading (deg, from +X)")
    joints: dict[str, Degrees] = Field(default_factory=dict, max_length=29,
                                       description="joint DOF angles (deg), e.g. {knee_flex_l: 60}")
    weight: Num = Field(1.0, gt=0.0, le=1000.0, description="multiplies the sketch's spring weight")

    @field_validator("joints")
    @classmethod
    def _dofs(cls, v):
        for k in v:
            if k not in JOINT_DOF_NAMES:
                raise ValueError(suggest(k, JOINT_DOF_NAMES, "joint DOF"))
        return v

    @model_validator(mode="after")
    def _something(self):
        if self.position is None and self.heading is None and not self.joints:
            raise FieldProblem(("time",), "a key needs a position, a heading or joints")
        return self


LEAP_TAKEOFF_SLACK = 0.3  # m: a given take-off position lies this close to where the character stands


LEAP_LAND_HOLD = 0.15  # s: after a landing both feet stay down this long before a walk or run goes on
LEAP_PUSH_MIN = 0.3  # s: the least time on the ground before a take-off (a countermovement, a gather)


def leap_sequence(c, leaps: list, walks: list = ()) -> list:
    """[((j, goal), (take-off s, landing s), where the character stands before it [x, y] m,
    facing rad or None)] of one character's jumps and hops ``leaps`` = [(j, goal)], in time
    order (nominal times for free timing; each free take-off LEAP_TAKEOFF_DEFAULT after the
    previous landing or walk).  ``walks`` = [(j, walk_to goal)] of the same character: a walk
    arriving after the previous landing and by the leap's take-off (or landing) time moves
    where it stands to the walk's target and its facing to the walk's last leg (its
    ``heading`` when given); facing None: no walk since the start or the last landing."""
    here = (float(c.start.position[0]), float(c.start.position[1]))
    after, out = 0.0, []
    given = sorted(leaps, key=lambda jg: (jg[1].takeoff.time if jg[1].takeoff.time is not None else
                                          jg[1].landing.time if jg[1].landing.time is not None else float("inf"),
                                          jg[0]))
    ws = sorted(walks, key=lambda jw: jw[1].time)
    for j, g in given:
        t_ref = g.takeoff.time if g.takeoff.time is not None else g.landing.time
        facing = None
        for _, w in ws:
            if w.time > after + 1e-9 and (t_ref is None or w.time <= t_ref + 1e-9):
                pts = [here] + [tuple(p) for p in w.waypoints] + [tuple(w.target)]
                a, b = pts[-2], pts[-1]
                facing = math.radians(w.heading) if w.heading is not None else \
                    math.atan2(b[1] - a[1], b[0] - a[0])
                here, after = (float(w.target[0]), float(w.target[1])), float(w.time)
        t = g.times(here, after)
        out.append(((j, g), t, here, facing))
        here, after = g.landing.centre(), t[1]
    return out


class KeyframesGoal(_Model):
    """A rough animation: soft springs toward a few keys (thesis ch. 3's sketch)."""

    type: Literal["keyframes"]
    name: Name | None = None
    character: str = Field(description="character name")
    keys: list[Keyframe] = Field(min_length=1, max_length=200, description="the keys, in any order")
    tolerance: Num = Field(0.1, gt=0.0, le=10.0, description="report bound: largest pelvis distance from a "
                                                            "key's position (m)")
    stages: Literal["detect", "none"] = Field(
        "detect", description="detect: flights the keys imply (out of the legs' reach, or the pelvis in free fall) "
                              "become jump goals (scenarios/sketch_stages.py); none: no flight is added")

    plan_weight: ClassVar[float | str | None] = TARGET_WEIGHT

    def active(self, window: tuple[float, float]) -> bool:
        return any(_meets((k.time, k.time), window) for k in self.keys)


Goal = Annotated[Union[FootprintsGoal, WalkToGoal, ReachGoal, TackleGoal, AvoidGoal, StyleChangeGoal, JumpGoal,
                       HopGoal, KeyframesGoal],
                 Field(discriminator="type")]

# --- couplings ------------------------------------------------------------------------------


class HandleRef(_Model):
    character: str
    handle: str = Field(description="handle name, e.g. palm_l")

    check_handle = field_validator("handle")(_check_handle)


class HandHold(_Model):
    """Two characters hold hands (handles coincide) over an interval."""

    type: Literal["hand_hold"]
    name: Name | None = None
    between: tuple[HandleRef, HandleRef] = Field(description="the two held handles")
    interval: Interval

    check_interval = field_validator("interval")(_interval)


class Carry(_Model):
    """Characters carry an object together: its weight is shared at their handles."""

    type: Literal["carry"]
    name: Name | None = None
    mass: Num = Field(gt=0.0, le=500.0, description="object mass (kg)")
    holders: list[HandleRef] = Field(min_length=2, max_length=8, description="the handles that hold the object")
    interval: Interval

    check_interval = field_validator("interval")(_interval)


Coupling = Annotated[Union[HandHold, Carry], Field(discriminator="type")]

# --- schedule -------------------------------------------------------------------------------


class ScheduleSpec(_Model):
    """Override or tune the schedule the compiler would choose (thesis §6.4)."""

    kind: Literal["auto", "timewarp", "time_layered", "coupled", "decreasing_horizon"] = Field(
        "auto", description="auto: derived from the scenario; otherwise forced for all characters")
    cycles: int | None = Field(None, ge=1, le=50, description="schedule cycles; default per kind "
                                                              "(time_layered 2, coupled 4, decreasing_horizon 3)")
    timewarp: Annotated[bool, Strict()] | None = Field(
        None, description="a timing step (relaxed dynamics, free timewarp) before each whole-scene full solve: "
                          "null (default) only where the duration is free (timing: free), true always, "
                          "false never (the full step then frees the timewarp)")
    max_window: Num = Field(2.5, gt=0.1, le=600.0, description="longest window of one subproblem (s)")
    seam: Num | None = Field(None, gt=0.0, le=600.0, description="width of the seam window C (s); default: "
                                                                 "half of the shorter neighbour on each side")
    stiffness_start: Num = Field(100.0, gt=0.0, le=1e9, description="rubber-band stiffness in cycle 1 (N/m)")
    stiffness_increase: Num = Field(100.0, ge=0.0, le=1e9, description="added to the stiffness every cycle (N/m)")
    stiffness_factor: Num = Field(1.0, ge=1.0, le=100.0, description="multiplies the stiffness every cycle")
    solves_per_cycle: dict[str, Annotated[int, Strict(), Field(ge=1, le=10)]] = Field(
        default_factory=dict, description="how often each character is solved per coupled cycle (who adapts more)")

    def stiffness(self, cycle: int) -> float:
        """Rubber-band stiffness (N/m) in cycle ``cycle`` (1-based); rises monotonically."""
        c = cycle - 1
        return (self.stiffness_start + self.stiffness_increase * c) * self.stiffness_factor ** c


# --- the scenario ---------------------------------------------------------------------------


def _goal_refs(g) -> list[tuple[str, str]]:
    """(field, character name) pairs a goal refers to."""
    if isinstance(g, TackleGoal):
        return [("attacker", g.attacker), ("target", g.target)]
    if isinstance(g, AvoidGoal):
        return [("character", g.character), ("around", g.around)]
    return [("character", g.character)]


def _goal_times(g) -> list[tuple[tuple, float]]:
    if isinstance(g, (JumpGoal, HopGoal)):
        return [((end, "time"), t) for end, t in (("takeoff", g.takeoff.time), ("landing", g.landing.time))
                if t is not None]
    if isinstance(g, KeyframesGoal):
        return [(("keys", i, "time"), k.time) for i, k in enumerate(g.keys)]
    if isinstance(g, FootprintsGoal):
        out = []
        for i, fp in enumerate(g.steps):
            out += [(("steps", i, "time"), fp.time[0]), (("steps", i, "time"), fp.time[1])]
        return out
    return [(("time",), g.time)]


class Scenario(_Model):
    """A scenario: characters, their goals and couplings, in an environment, over a duration."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False,
                              title="compose scenario")

    version: Literal[1] = Field(1, description="scenario format version")
    name: Name = Field(description="scenario name")
    description: str = Field("", max_length=200, description="one line shown by `compose list`")
    duration: Num | None = Field(None, gt=0.0, le=600.0, description="length of the scenario (s); with free timing "
                                                                  "the initial guess (required, except with `edit`)")
    timing: Literal["fixed", "free"] = Field(
        "fixed", description="free: the timewarp may stretch the whole scenario within duration_bounds; "
                             "goal times are then canonical (they move with the motion)")
    duration_bounds: tuple[Num, Num] | None = Field(None, description="[min, max] total duration (s) with free timing; "
                                                                      "default [0.5, 2] × duration")
    environment: Environment = Field(default_factory=Environment)
    characters: list[CharacterSpec] = Field(default_factory=list, max_length=16,
                                            description="at least one (required, except with `edit`)")
    goals: list[Goal] = Field(default_factory=list, max_length=MAX_GOALS)
    couplings: list[Coupling] = Field(default_factory=list, max_length=100)
    schedule: ScheduleSpec | None = Field(None, description="explicit schedule; default: compiled from the scenario")
    edit: EditBlock | None = Field(None, description="edit a captured jump instead (scenarios/edit_block.py): "
                                                     "no characters, goals, couplings, schedule or duration then")

    _base_dir: Path | None = PrivateAttr(None)
    _source: str | None = PrivateAttr(None)
    _positions: dict = PrivateAttr(default_factory=dict)
    _sketch_stages: list = PrivateAttr(default_factory=list)

    # -- accessors -----------------------------------------------------------------------
    @property
    def source(self) -> str | None:
        """The file this scenario was loaded from, if any."""
        return self._source

    def location(self, path: tuple):
        """Where a field path (``("characters", 1, "style")``) sits in the source file."""
        from scenarios.yamlio import error_location  # local: keeps the schema importable on its own
        return error_location(self._source, self._positions, tuple(path))

    @property
    def base_dir(self) -> Path | None:
        """The folder style paths are resolved against (the scenario file's folder)."""
        return self._base_dir

    def character(self, name: str) -> CharacterSpec:
        for c in self.characters:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def sketch_stages(self) -> list[dict]:
        """Flights detected in keyframe sketches (scenarios/sketch_stages.py), each added as a jump goal."""
        return list(self._sketch_stages)

    @property
    def is_edit(self) -> bool:
        """An edit of a captured clip (``edit:`` block), not a synthesis of characters."""
        return self.edit is not None

    @property
    def character_names(self) -> list[str]:
        return [c.name for c in self.characters]

    def goal_name(self, index: int) -> str:
        g = self.goals[index]
        return g.name or f"{g.type}_{index}"

    def coupling_name(self, index: int) -> str:
        c = self.couplings[index]
        return c.name or f"{c.type}_{index}"

    def named_goals(self) -> list[tuple[str, Any]]:
        return [(self.goal_name(i), g) for i, g in enumerate(self.goals)]

    def named_couplings(self) -> list[tuple[str, Any]]:
        return [(self.coupling_name(i), c) for i, c in enumerate(self.couplings)]

    def coupling_characters(self, index: int) -> list[str]:
        c = self.couplings[index]
        refs = c.between if isinstance(c, HandHold) else c.holders
        return list(dict.fromkeys(r.character for r in refs))

    def style_timeline(self, character: str) -> list[tuple[float, str, float | None]]:
        """[(time s, style ref, blend s or None)], starting with (0, initial style, None), sorted by time."""
        out = [(0.0, self.character(character).style, None)]
        changes = sorted((g.time, g.style, g.blend) for g in self.goals
                         if isinstance(g, StyleChangeGoal) and g.character == character)
        return out + changes

    def style_file(self, ref: str) -> Path | None:
        """The YAML file of a style reference; None for the built-in ``default`` style."""
        return resolve_style(ref, self._base_dir)

    # -- cross-field checks ----------------------------------------------------------------
    @field_validator("duration_bounds")
    @classmethod
    def _bounds(cls, v):
        if v is not None and not (0 < v[0] < v[1]):
            raise ValueError(f"expected 0 < min < max, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _cross_check(self, info: ValidationInfo):
        problems = self.problems(info.context)
        if problems:
            path, msg = problems[0]
            raise FieldProblem(path, msg, more=problems[1:])
        ctx = info.context or {}
        if ctx.get("base_dir") is not None:
            self._base_dir = Path(ctx["base_dir"])
        if ctx.get("file") is not None:
            self._source = str(ctx["file"])
        return self

    def ground_height(self, x: float, y: float) -> float:
        """Height (m) of the ground at (x, y): 0 on the flat ground, the last slope covering
        the point otherwise (as scenegraph.model.ground builds it)."""
        import math
        z = 0.0
        for sl in self.environment.slopes:
            (x0, y0), (x1, y1) = sl.region.min, sl.region.max
            if x0 <= x <= x1 and y0 <= y <= y1:
                ox, oy = sl.origin if sl.origin is not None else ((x0 + x1) / 2, (y0 + y1) / 2)
                h = math.radians(sl.heading)
                z = math.tan(math.radians(sl.angle)) * ((x - ox) * math.cos(h) + (y - oy) * math.sin(h))
        return z

    def _plausibility(self, names: dict[str, int]) -> list[tuple[tuple, str]]:
        """Goals a human body cannot meet: a walk_to faster than MAX_SPEED, a reach target under
        the ground."""
        import math
        out: list[tuple[tuple, str]] = []
        last: dict[str, tuple[float, tuple[float, float], str]] = {
            c.name: (0.0, tuple(c.start.position), f"the start position of {c.name}") for c in self.characters}
        walks = sorted((g.time, j, g) for j, g in enumerate(self.goals) if isinstance(g, WalkToGoal))
        for t, j, g in walks:
            if g.character not in last:
                continue
            t0, p0, where = last[g.character]
            pts = [p0, *g.waypoints, g.target]
            dist = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(pts, pts[1:]))
            dist = max(0.0, dist - g.tolerance)
            dt = t - t0
            if dist > 0 and (dt <= 0 or dist / dt > MAX_SPEED):
                need = f"{dist / dt:.3g} m/s" if dt > 0 else "an infinite speed"
                out.append((("goals", j, "target"),
                            f"walking {dist:.4g} m from {where} to {list(g.target)} in {max(dt, 0.0):g} s needs "
                            f"{need}, above the limit of {MAX_SPEED:g} m/s (about the peak speed of the fastest "
                            "human sprinters); move the target closer or the time later"))
            last[g.character] = (t, tuple(g.target), f"goals[{j}]'s target")
        for j, g in enumerate(self.goals):
            if isinstance(g, ReachGoal) and g.character in names:
                x, y, z = g.target
                floor = self.ground_height(x, y)
                if z < floor - 1e-9:
                    out.append((("goals", j, "target"),
                                f"target z = {z:g} m is {floor - z:.3g} m below the ground (z = {floor:.3g} m there): "
                                f"the {g.handle} cannot go through the floor"))
                    continue
                out += self._reach_problems(j, g)
            elif isinstance(g, TackleGoal) and g.attacker in names and g.target in names and g.attacker != g.target:
                a, b = self.character(g.attacker), self.character(g.target)
                gap = math.dist(a.start.position, b.start.position) - REACH_OUT * (self._stature(a) + self._stature(b))
                if gap > 2 * MAX_SPEED * g.time:
                    out.append((("goals", j, "time"),
                                f"{g.attacker} and {g.target} start {math.dist(a.start.position, b.start.position):.4g} m "
                                f"apart: meeting at {g.time:g} s needs {gap / max(g.time, 1e-9):.3g} m/s of closing "
                                f"speed, above two sprinters' {2 * MAX_SPEED:g} m/s; make the time later"))
        out += self._footprint_problems()
        out += self._leap_problems(names)
        return out

    def _leap_problems(self, names: dict[str, int]) -> list[tuple[tuple, str]]:
        """Jumps and hops of a character form one sequence from where it stands, in time order
        with walk_to goals of the same character (a run-up, a leap, a run on: thesis ch. 3's
        compositions): no footprints besides them; a take-off within LEAP_TAKEOFF_SLACK of where
        it stands (after a walk: the walk's target); at least LEAP_PUSH_MIN s on the ground
        before a take-off; no walk arriving during a leap's push-off, flight or landing hold
        (LEAP_LAND_HOLD), nor leaps without times among walks; all inside the scenario."""
        out: list[tuple[tuple, str]] = []
        for c in self.characters:
            leaps = [(j, g) for j, g in enumerate(self.goals) if isinstance(g, (JumpGoal, HopGoal))
                     and g.character == c.name]
            if not leaps:
                continue
            other = next((j for j, g in enumerate(self.goals) if isinstance(g, FootprintsGoal)
                          and g.character == c.name), None)
            if other is not None:
                out.append((("goals", other, "type"), f"{c.name} jumps or hops (goals[{leaps[0][0]}]); footprints "
                            "cannot be combined with jump/hop goals of the same character (walk_to can: "
                            "docs/dynamic-motion.md)"))
                continue
            walks = [(j, g) for j, g in enumerate(self.goals) if isinstance(g, WalkToGoal) and g.character == c.name]
            if walks:
                untimed = [j for j, g in leaps if g.takeoff.time is None and g.landing.time is None]
                if untimed:
                    out.append((("goals", untimed[0], "takeoff", "time"), f"{c.name} walks (goals[{walks[0][0]}]) "
                                "and leaps: give each leap a take-off or landing time, so the sequence's order "
                                "is known"))
                    continue
            seq = leap_sequence(c, leaps, walks)
            for k, ((j, g), (t0, t1), here, _) in enumerate(seq):
                if g.takeoff.region is not None:
                    out.append((("goals", j, "takeoff", "region"), "a take-off is where the character stands: give "
                                "its position (or nothing); a region is for landings"))
                if g.takeoff.position is not None:
                    d = ((g.takeoff.position[0] - here[0]) ** 2 + (g.takeoff.position[1] - here[1]) ** 2) ** 0.5
                    if d > LEAP_TAKEOFF_SLACK:
                        out.append((("goals", j, "takeoff", "position"),
                                    f"take-off {list(g.takeoff.position)} is {d:.3g} m from where {c.name} stands "
                                    f"then ({here[0]:.3g}, {here[1]:.3g}); a leap starts where the character "
                                    f"stands (within {LEAP_TAKEOFF_SLACK:g} m)"))
                if t1 > self.duration + 1e-9:
                    out.append((("goals", j, "landing"), f"the landing at {t1:.3g} s is after the end of the "
                                f"scenario ({self.duration:g} s)"))
                ground_from = max([0.0] + [seq[k - 1][1][1] if k else 0.0]
                                  + [w.time for _, w in walks if w.time <= t0 + 1e-9])
                if t0 - ground_from < LEAP_PUSH_MIN - 1e-9:
                    out.append((("goals", j, "takeoff"), f"take-off at {t0:.3g} s leaves under {LEAP_PUSH_MIN:g} s "
                                f"on the ground to push off (on the ground from {ground_from:.3g} s)"))
            for jw, w in walks:  # a walk arrives outside every leap's push-off, flight and landing hold
                for (j, g), (t0, t1), _, _ in seq:
                    lo, hi = t0 - LEAP_PUSH_MIN, t1 + LEAP_LAND_HOLD
                    if lo + 1e-9 < w.time < hi - 1e-9:
                        out.append((("goals", jw, "time"), f"{c.name} arrives at {w.time:g} s, during goals[{j}]'s "
                                    f"take-off, flight or landing ({lo:.3g}–{hi:.3g} s: {LEAP_PUSH_MIN:g} s on the "
                                    f"ground before the take-off at {t0:.3g} s, {LEAP_LAND_HOLD:g} s after the "
                                    f"landing at {t1:.3g} s); move the arrival out of it"))
        return out

    def _stature(self, c: "CharacterSpec") -> float:
        """The character's standing height (m): body.height or its preset's."""
        return c.body.height if c.body.height is not None else PRESET_HEIGHTS[c.body.preset]

    def _anchors(self, name: str) -> list[tuple[float, tuple[float, float], float, str]]:
        """Where the pelvis of character ``name`` is known to be: (time s, [x, y] m, slack m,
        what): the start, every walk_to target (within its tolerance), every footprint (within
        a leg's reach of the foot, for the whole contact)."""
        c = self.character(name)
        H = self._stature(c)
        out = [(0.0, tuple(c.start.position), 0.0, "its start position")]
        for j, g in enumerate(self.goals):
            if isinstance(g, WalkToGoal) and g.character == name:
                out.append((g.time, tuple(g.target), g.tolerance, f"goals[{j}]'s target"))
            elif isinstance(g, FootprintsGoal) and g.character == name:
                for i, fp in enumerate(g.steps):
                    for t in fp.time:
                        out.append((t, tuple(fp.position), 0.5 * LEG_SPREAD * H, f"goals[{j}].steps[{i}]"))
        return out

    def _reach_problems(self, j: int, g: "ReachGoal") -> list[tuple[tuple, str]]:
        """A reach target above the highest point the handle reaches, or too far from every
        place the character's path can bring its pelvis by the goal's time."""
        import math
        c = self.character(g.character)
        H = self._stature(c)
        x, y, z = g.target
        top = self.ground_height(x, y) + REACH_UP * H
        if z > top + g.tolerance:
            return [(("goals", j, "target"),
                     f"target z = {z:g} m is above the {top:.3g} m a {H:g} m tall character reaches "
                     f"({REACH_UP:g} × its stature over the ground there): the {g.handle} cannot get there")]
        for t, p, slack, what in self._anchors(g.character):
            d = math.dist((x, y), p) - slack - REACH_OUT * H - g.tolerance
            dt = abs(g.time - t)
            if d > MAX_SPEED * dt + 1e-9:
                return [(("goals", j, "target"),
                         f"target {list(g.target)} is out of reach of {g.character}'s path: {math.dist((x, y), p):.4g} m "
                         f"from {what} ({t:g} s), {dt:g} s from the reach at {g.time:g} s; an arm reaches "
                         f"{REACH_OUT * H:.2g} m from the pelvis and a sprint covers {MAX_SPEED:g} m/s")]
        return []

    def _footprint_problems(self) -> list[tuple[tuple, str]]:
        """Consecutive footprints of a character (both feet, by heel strike) farther apart than
        a sprint between them plus the widest stance, and a first footprint out of reach of the
        start."""
        import math
        out: list[tuple[tuple, str]] = []
        for c in self.characters:
            H = self._stature(c)
            spread = LEG_SPREAD * H
            prints = sorted(((fp.time[0], fp.time[1], tuple(fp.position), ("goals", j, "steps", i))
                             for j, g in enumerate(self.goals) if isinstance(g, FootprintsGoal) and g.character == c.name
                             for i, fp in enumerate(g.steps)), key=lambda f: (f[0], f[3]))
            prev = (0.0, 0.0, tuple(c.start.position), None)
            for f in prints:
                t0p, t1p, pp, where = prev
                gap_t = max(f[0] - t1p, 0.0)
                d = math.dist(f[2], pp)
                reach = MAX_SPEED * gap_t + (spread if where is not None else 0.5 * spread)
                if d > reach + 1e-9:
                    frm = format_field(where) if where is not None else f"the start position of {c.name}"
                    out.append((f[3] + ("position",),
                                f"this footprint is {d:.4g} m from {frm}, with {gap_t:g} s between the two contacts: "
                                f"more than a sprint at {MAX_SPEED:g} m/s plus the widest stance ({spread:.2g} m) "
                                "covers"))
                    break
                prev = f
        return out

    def problems(self, context: dict | None = None) -> list[tuple[tuple, str]]:
        """Every cross-field problem as (field path, message), in file order."""
        ctx = context or {}
        if self.edit is not None:  # an edit scenario: the clip gives everything else
            return edit_problems(self.edit, set(self.model_fields_set), ctx)
        out: list[tuple[tuple, str]] = []
        if self.duration is None:
            return [(("duration",), "missing required field 'duration'")]
        if "characters" not in self.model_fields_set:
            return [(("characters",), "missing required field 'characters'")]
        if not self.characters:
            return [(("characters",), "List should have at least 1 item (a scenario needs a character)")]
        T = self.duration
        if self.duration_bounds is not None:
            lo, hi = self.duration_bounds
            if self.timing != "free":
                out.append((("duration_bounds",), "duration_bounds needs timing: free"))
            elif not (lo <= T <= hi):
                out.append((("duration",), f"duration {T} s lies outside duration_bounds [{lo}, {hi}] s"))

        # resource limits: the size of what would be built
        load = T * len(self.characters)
        if load > MAX_CHARACTER_SECONDS:
            out.append((("duration",), f"{len(self.characters)} character(s) × {T:g} s = {load:g} character-seconds, "
                        f"above the limit of {MAX_CHARACTER_SECONDS:g} (building and solving grow with it; "
                        "split the scene into shorter scenarios)"))
        n_prints = 0
        for j, g in enumerate(self.goals):
            if isinstance(g, FootprintsGoal):
                n_prints += len(g.steps)
                if n_prints > MAX_FOOTPRINTS:
                    out.append((("goals", j, "steps"), f"more than {MAX_FOOTPRINTS} footprints in all footprints goals"))
                    break
        # intervals narrower than one collocation interval hold no collocation point to enforce them
        dt = 1.0 / COLLOCATION_HZ
        for j, g in enumerate(self.goals):
            spans = [(("steps", i, "time"), fp.time[1] - fp.time[0], "contact")
                     for i, fp in enumerate(g.steps)] if isinstance(g, FootprintsGoal) else []
            if isinstance(g, StyleChangeGoal) and g.blend is not None:
                spans.append((("blend",), g.blend, "blend"))
            for path, w, what in spans:
                if w < dt - 1e-9:
                    out.append((("goals", j) + path, f"a {w:.3g} s {what} is shorter than one collocation interval "
                                f"(1/{COLLOCATION_HZ:g} s = {dt:.3g} s): no collocation point may lie inside it"))
        for j, c in enumerate(self.couplings):
            w = c.interval[1] - c.interval[0]
            if w < dt - 1e-9:
                out.append((("couplings", j, "interval"), f"a {w:.3g} s coupling is shorter than one collocation "
                            f"interval (1/{COLLOCATION_HZ:g} s = {dt:.3g} s): no collocation point may lie inside it"))

        names: dict[str, int] = {}
        for i, c in enumerate(self.characters):
            if c.name in names:
                out.append((("characters", i, "name"),
                            f"duplicate character name {c.name!r} (also characters[{names[c.name]}])"))
            names.setdefault(c.name, i)
            msg = style_problem(c.style, ctx)
            if msg:
                out.append((("characters", i, "style"), msg))

        def ref(path: tuple, name: str):
            if name not in names:
                out.append((path, suggest(name, list(names), "character")))
                return False
            return True

        def in_time(path: tuple, t: float):
            if not (0.0 <= t <= T):
                out.append((path, f"time {t} s is outside the scenario [0, {T}] s"))

        item_names: dict[str, str] = {}

        def unique(path: tuple, name: str | None, where: str):
            if name is None:
                return
            if name in item_names:
                out.append((path, f"duplicate name {name!r} (also {item_names[name]})"))
            item_names.setdefault(name, where)

        pairs: dict[frozenset, tuple[str, str]] = {}
        changes: dict[tuple[str, float], int] = {}
        for j, g in enumerate(self.goals):
            base = ("goals", j)
            unique(base + ("name",), g.name, f"goals[{j}]")
            ok = all([ref(base + (f,), n) for f, n in _goal_refs(g)])
            for p, t in _goal_times(g):
                in_time(base + p, t)
            if isinstance(g, (TackleGoal, AvoidGoal)):
                a, b = (g.attacker, g.target) if isinstance(g, TackleGoal) else (g.around, g.character)
                if a == b:
                    field = "target" if isinstance(g, TackleGoal) else "around"
                    out.append((base + (field,), f"{g.type} needs two different characters, got {a!r} twice"))
                    continue
                if g.plans_last is not None:
                    if g.plans_last not in (a, b):
                        out.append((base + ("plans_last",),
                                    f"plans_last must be {a!r} or {b!r}, got {g.plans_last!r}"))
                        continue
                    key = frozenset((a, b))
                    if key in pairs and pairs[key][0] != g.plans_last:
                        out.append((base + ("plans_last",), f"plans_last {g.plans_last!r} contradicts "
                                    f"{pairs[key][1]} which says {pairs[key][0]!r}"))
                    pairs.setdefault(key, (g.plans_last, f"goals[{j}]"))
            if isinstance(g, StyleChangeGoal):
                msg = style_problem(g.style, ctx)
                if msg:
                    out.append((base + ("style",), msg))
                if ok:
                    k = (g.character, g.time)
                    if k in changes:
                        out.append((base + ("time",), f"{g.character} already changes style at {g.time} s "
                                    f"(goals[{changes[k]}])"))
                    changes.setdefault(k, j)
                    if g.time <= 0.0 or g.time >= T:
                        out.append((base + ("time",), f"a style change must lie strictly inside (0, {T}) s"))

        out += self._plausibility(names)

        for j, c in enumerate(self.couplings):
            base = ("couplings", j)
            unique(base + ("name",), c.name, f"couplings[{j}]")
            refs = c.between if isinstance(c, HandHold) else c.holders
            field = "between" if isinstance(c, HandHold) else "holders"
            seen: dict[tuple[str, str], int] = {}
            for k, r in enumerate(refs):
                ref(base + (field, k, "character"), r.character)
                key = (r.character, r.handle)
                if key in seen:
                    out.append((base + (field, k, "handle"), f"{r.character}.{r.handle} is listed twice"))
                seen.setdefault(key, k)
            if isinstance(c, HandHold) and c.between[0].character == c.between[1].character:
                out.append((base + (field, 1, "character"), "hand_hold needs two different characters"))
            in_time(base + ("interval",), c.interval[0])
            in_time(base + ("interval",), c.interval[1])

        if self.schedule is not None:
            for who in self.schedule.solves_per_cycle:
                ref(("schedule", "solves_per_cycle", who), who)
        return out
