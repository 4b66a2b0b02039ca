"""The Scene: what a scenario describes, turned into the world model the solver works on.

``build_scene(scenario)`` gives, per character, its :class:`~scenegraph.body.Character`
(preset plus edits), its styles, its footsteps (explicit footprints, or free footsteps
generated for ``walk_to``, or both feet planted for a character without locomotion goals),
and an initial :class:`~scenegraph.motion.Motion` over [0, duration].  Goals that become
solver terms (reach, tackle, avoid, walk_to end point) are described by :class:`GoalSpec`;
their solver targets depend on the partners' *current* motions and are computed on demand
with :func:`goal_targets` / :func:`coupling_targets`.

Scenario files use degrees; everything here is in radians (SI units otherwise).
The Scene is immutable: ``scene.with_motion(name, motion, footsteps)`` returns a new one.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scenarios.schema import (AvoidGoal, Carry, FootprintsGoal, HandHold, ReachGoal, Scenario, StyleChangeGoal,
                              TackleGoal, WalkToGoal, joint_dofs)

from .body import Character, make_character
from .footsteps import RUN_BALL, WALK_BALL, WALK_HEEL, Footstep
from .gait import initial_motion
from .ground import FLAT, Ground, ground_from_environment
from .kinematics import handle_positions_fn
from .motion import Motion
from .spacetime import Avoid, HandleTarget, Spring
from .style import Style, default_style, load_style

__all__ = ["Scene", "CharacterState", "GoalSpec", "CouplingSpec", "build_scene", "goal_targets",
           "coupling_targets", "coupling_springs", "handle_track", "CADENCE", "STANCE_FRACTION", "FOOT_WIDTH"]

CADENCE = 1.85          # steps per second of generated walks
STANCE_FRACTION = 0.62  # stance / stride of generated walks (> 0.5: double support)
FOOT_WIDTH = 0.18       # m, lateral distance between the feet of generated footsteps
TARGET_WEIGHT = 300.0   # soft goal springs (1/m² of the normalised objective)


@dataclass(frozen=True)
class CharacterState:
    """One character in the Scene."""

    name: str
    character: Character
    styles: tuple[tuple[str, Style], ...]  # (style reference as written, Style), first = initial
    footsteps: tuple[Footstep, ...]
    motion: Motion
    start: tuple[float, float, float]  # x, y (m), heading (rad)

    @property
    def style(self) -> Style:
        return self.styles[0][1]

    def style_of(self, ref: str) -> Style:
        for r, s in self.styles:
            if r == ref:
                return s
        raise KeyError(ref)


@dataclass(frozen=True)
class GoalSpec:
    """A goal as the executor needs it: which character it binds, when, and its tolerance."""

    name: str
    type: str
    character: str            # the character whose motion must satisfy it
    partner: str | None       # the other character (tackle target, avoid's 'around')
    time: float | None        # s (None for footprints)
    tolerance: float          # m
    data: tuple = ()          # type-specific: (handle, point) for reach; (radius,) for avoid; ...


@dataclass(frozen=True)
class CouplingSpec:
    name: str
    type: str
    handles: tuple[tuple[str, str], ...]  # (character, handle)
    interval: tuple[float, float]
    mass: float = 0.0
    tolerance: float = 0.03  # m: hands within this distance count as holding


@dataclass(frozen=True)
class Scene:
    scenario: str
    duration: float
    characters: tuple[CharacterState, ...]
    goals: tuple[GoalSpec, ...] = ()
    couplings: tuple[CouplingSpec, ...] = ()
    friction: float = 1.0
    style_refs: tuple[tuple[str, str], ...] = field(default=())  # (ref, resolved file or "built-in")
    ground: Ground = FLAT  # terrain the solver and the audit use (flat unless the scenario has slopes)

    def character(self, name: str) -> CharacterState:
        for c in self.characters:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.characters)

    def goal(self, name: str) -> GoalSpec:
        for g in self.goals:
            if g.name == name:
                return g
        raise KeyError(name)

    def coupling(self, name: str) -> CouplingSpec:
        for c in self.couplings:
            if c.name == name:
                return c
        raise KeyError(name)

    def with_motion(self, name: str, motion: Motion, footsteps: tuple[Footstep, ...] | None = None) -> "Scene":
        chars = tuple(replace(c, motion=motion, footsteps=c.footsteps if footsteps is None else tuple(footsteps))
                      if c.name == name else c for c in self.characters)
        return replace(self, characters=chars)


# --- characters and styles -------------------------------------------------------------------

def _character(spec) -> Character:
    b = spec.body
    ch = make_character(b.preset, b.height, b.mass)
    for em in b.extra_masses:
        ch = ch.with_extra_mass(em.handle, em.mass)
    for lk in b.locked:
        a = math.radians(lk.angle)
        for d in joint_dofs(lk.joint):
            i = ch.dof_index(d)
            lo, hi = ch.lower[i], ch.upper[i]
            ch = ch.with_limits(d, float(np.clip(a, lo, hi)), float(np.clip(a, lo, hi)))
    for r in b.range_of_motion:
        ch = ch.with_limits(r.dof, math.radians(r.min), math.radians(r.max))
    return ch


def _style(scn: Scenario, ref: str, ch: Character, shoe_scale: float) -> tuple[Style, str]:
    f = scn.style_file(ref)
    if f is None:
        st, where = default_style(ch.total_mass), "built-in"
    else:
        st, where = load_style(f), str(f)
    if shoe_scale != 1.0:
        st = st.with_(k_shoe=float(st.k_shoe) * shoe_scale)
    return st, where


# --- footsteps -------------------------------------------------------------------------------

@functools.lru_cache(maxsize=16)
def _foot_length(ch: Character) -> float:
    return float(ch.handle("ball_l").point[0] - ch.handle("heel_l").point[0])


def _part(frac, a, b, c, d):
    """Fractions of the clipped stance [c, d] during which the part (fractions of [a, b]) is down."""
    if frac is None:
        return None
    lo, hi = max(a + frac[0] * (b - a), c), min(a + frac[1] * (b - a), d)
    if hi - lo < 0.02:
        return None
    return (float((lo - c) / (d - c)), float((hi - c) / (d - c)))


@dataclass(frozen=True)
class Gait:
    """Timing and size of generated steps: steps per second, stance / stride, step length (m)."""

    cadence: float
    stance_fraction: float
    step_length: float
    heel: tuple[float, float] | None
    ball: tuple[float, float] | None


GAITS = {"walk": Gait(CADENCE, STANCE_FRACTION, 0.7, WALK_HEEL, WALK_BALL),
         "run": Gait(2.8, 0.38, 1.1, None, RUN_BALL)}


def gait_footsteps(start_xy, target_xy, t0: float, t1: float, change: tuple[float, float, str] | None = None,
                   *, width: float = FOOT_WIDTH, foot_length: float = 0.2, first: str = "r",
                   before: str = "walk") -> tuple[Footstep, ...]:
    """Free footsteps along start → target over [t0, t1] (world m, s) through a gait change.

    ``change`` = (time, blend, gait after) (s, s, name in GAITS): cadence, stance fraction and
    step length move from ``before``'s to the new gait's over [time − blend/2, time + blend/2]
    (smoothstep).  Stance k is centred where the step phase ∫ cadence dt reaches k; the
    pelvis advances in proportion to ∫ cadence · step length dt, scaled to reach the target
    at t1; each foot lands under it (± width/2).  A stance is a walk's (heel, then ball) or
    a run's (ball only, flight between stances) by which gait dominates at its middle.
    Without ``change`` the whole path uses ``before``.
    """
    tc, blend, after = change or (t0, 0.0, before)
    g0, g1 = GAITS[before], GAITS[after]
    tt = np.linspace(t0, t1, 2001)
    w = np.clip((tt - (tc - blend / 2)) / max(blend, 1e-6), 0.0, 1.0)
    w = w * w * (3 - 2 * w)
    cad = g0.cadence + (g1.cadence - g0.cadence) * w
    sf = g0.stance_fraction + (g1.stance_fraction - g0.stance_fraction) * w
    speed = cad * (g0.step_length + (g1.step_length - g0.step_length) * w)
    dt = np.diff(tt)
    phase = np.r_[0.0, np.cumsum((cad[1:] + cad[:-1]) / 2 * dt)]
    dist_t = np.r_[0.0, np.cumsum((speed[1:] + speed[:-1]) / 2 * dt)]
    p0, p1 = np.asarray(start_xy, float), np.asarray(target_xy, float)
    d = p1 - p0
    u = d / max(float(np.linalg.norm(d)), 1e-9)
    lat = np.array([-u[1], u[0]])
    heading = math.atan2(u[1], u[0])
    steps = []
    for k in range(int(math.floor(phase[-1])) + 1):
        tm = float(np.interp(k, phase, tt))
        i = int(np.searchsorted(tt, tm).clip(0, len(tt) - 1))
        stance = 2 * sf[i] / cad[i]
        a, b = tm - stance / 2, tm + stance / 2
        c, e = max(a, t0), min(b, t1)
        this = first if k % 2 == 0 else ("l" if first == "r" else "r")
        pel = p0 + d * dist_t[i] / dist_t[-1]
        side = 1.0 if this == "l" else -1.0
        ball = pel + side * width / 2 * lat + u * foot_length / 2
        gg = g1 if w[i] >= 0.5 else g0
        heel, ballf = _part(gg.heel, a, b, c, e), _part(gg.ball, a, b, c, e)
        if e - c < 0.04 or (heel is None and ballf is None):
            continue
        steps.append(Footstep(this, (float(ball[0]), float(ball[1])), float(c), float(e), heading,
                              heel=heel, ball=ballf, free=True))
    return tuple(steps)


def walk_footsteps(start_xy, target_xy, t0: float, t1: float, *, cadence: float = CADENCE,
                   stance_fraction: float = STANCE_FRACTION, width: float = FOOT_WIDTH, foot_length: float = 0.2,
                   free: bool = True, first: str = "r") -> tuple[Footstep, ...]:
    """Free footsteps along the straight line start → target over [t0, t1] (world m, s).

    The pelvis is assumed to move uniformly; each foot lands under it (± width/2) at the
    middle of its stance.  Stances that begin before t0 or end after t1 are clipped, and
    their heel/ball parts clipped with them.
    """
    p0, p1 = np.asarray(start_xy, float), np.asarray(target_xy, float)
    T = t1 - t0
    d = p1 - p0
    dist = float(np.linalg.norm(d))
    u = d / dist if dist > 1e-6 else np.array([1.0, 0.0])
    lat = np.array([-u[1], u[0]])
    heading = math.atan2(u[1], u[0])
    n = max(2, int(round(T * cadence)))
    period = T / n
    stance = 2 * period * stance_fraction
    steps = []
    for k in range(n + 1):  # stance k is centred at t0 + k * period; feet alternate
        this = first if k % 2 == 0 else ("l" if first == "r" else "r")
        tm = t0 + k * period
        a, b = tm - stance / 2, tm + stance / 2
        c, e = max(a, t0), min(b, t1)
        pel = p0 + d * (tm - t0) / T
        side = 1.0 if this == "l" else -1.0
        ball = pel + side * width / 2 * lat + u * foot_length / 2
        heel = _part(WALK_HEEL, a, b, c, e)
        ballf = _part(WALK_BALL, a, b, c, e)
        if e - c < 0.04 or (heel is None and ballf is None):
            continue
        steps.append(Footstep(this, (float(ball[0]), float(ball[1])), float(c), float(e), heading,
                              heel=heel, ball=ballf, free=free))
    return tuple(steps)


def standing_footsteps(start, t0: float, t1: float, foot_length: float, width: float = FOOT_WIDTH):
    x, y, h = start
    u, lat = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
    out = []
    for foot, side in (("l", 1.0), ("r", -1.0)):
        ball = np.array([x, y]) + side * width / 2 * lat + u * foot_length / 2
        out.append(Footstep(foot, (float(ball[0]), float(ball[1])), t0, t1, h, heel=(0.0, 1.0), ball=(0.0, 1.0)))
    return tuple(out)


def _explicit_footsteps(g: FootprintsGoal, default_heading: float, foot_length: float) -> list[Footstep]:
    out = []
    for fp in g.steps:
        h = math.radians(fp.heading) if fp.heading is not None else default_heading
        # the file gives the midpoint of heel and ball; Footstep.position is the ball
        ball = (fp.position[0] + foot_length / 2 * math.cos(h), fp.position[1] + foot_length / 2 * math.sin(h))
        out.append(Footstep(fp.foot, (float(ball[0]), float(ball[1])), float(fp.time[0]), float(fp.time[1]), h))
    return out


# --- build -----------------------------------------------------------------------------------

def build_scene(scn: Scenario) -> Scene:
    """The initial Scene of a scenario (see the module docstring)."""
    T = float(scn.duration)
    chars, refs = [], {}
    goals: list[GoalSpec] = []
    for name, g in scn.named_goals():
        if isinstance(g, ReachGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, g.tolerance, (g.handle, tuple(g.target))))
        elif isinstance(g, WalkToGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, g.tolerance,
                                  (tuple(g.target), None if g.heading is None else math.radians(g.heading))))
        elif isinstance(g, TackleGoal):
            goals.append(GoalSpec(name, g.type, g.attacker, g.target, g.time, 0.15,
                                  (g.min_speed, g.hands_around_torso)))
        elif isinstance(g, AvoidGoal):
            goals.append(GoalSpec(name, g.type, g.character, g.around, g.time, 1e-3, (g.radius,)))
        elif isinstance(g, FootprintsGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, None, 2e-3))
        elif isinstance(g, StyleChangeGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, 0.0, (g.style,)))
    couplings = []
    for name, c in scn.named_couplings():
        if isinstance(c, HandHold):
            couplings.append(CouplingSpec(name, c.type, tuple((r.character, r.handle) for r in c.between),
                                          tuple(c.interval)))
        elif isinstance(c, Carry):
            couplings.append(CouplingSpec(name, c.type, tuple((r.character, r.handle) for r in c.holders),
                                          tuple(c.interval), mass=c.mass, tolerance=0.05))

    ground = ground_from_environment(scn.environment)
    attackers = {g.attacker for g in scn.goals if isinstance(g, TackleGoal)}
    order = sorted(scn.characters, key=lambda c: c.name in attackers)
    for spec in order:
        ch = _character(spec)
        for cpl in couplings:  # a carried object's weight is shared by its holders (static share)
            if cpl.type == "carry":
                for who, handle in cpl.handles:
                    if who == spec.name:
                        ch = ch.with_extra_mass(handle, cpl.mass / len(cpl.handles))
        styles = []
        for _, ref, _ in scn.style_timeline(spec.name):
            if ref not in dict(styles):
                st, where = _style(scn, ref, ch, spec.body.shoe_stiffness_scale)
                styles.append((ref, st))
                refs[ref] = where
        start = (float(spec.start.position[0]), float(spec.start.position[1]), math.radians(spec.start.heading))
        fl = _foot_length(ch)
        steps: list[Footstep] = []
        for _, g in scn.named_goals():
            if isinstance(g, FootprintsGoal) and g.character == spec.name:
                steps += _explicit_footsteps(g, start[2], fl)
        walk = [g for g in scn.goals if isinstance(g, WalkToGoal) and g.character == spec.name]
        gaits = [g for g in scn.goals if isinstance(g, StyleChangeGoal) and g.character == spec.name and g.gait]
        change = None
        if gaits:  # the (first) gait change shapes the generated footsteps; blend default 0.6 s
            c = min(gaits, key=lambda g: g.time)
            change = (float(c.time), float(c.blend or 0.6), c.gait)
        if walk and not steps:
            p, t = start[:2], 0.0
            for g in sorted(walk, key=lambda g: g.time):
                pts = list(g.waypoints) + [g.target]
                legs = [(np.asarray(a, float), np.asarray(b, float)) for a, b in zip([p] + pts[:-1], pts)]
                lens = np.array([np.linalg.norm(b - a) for a, b in legs])
                total = max(float(lens.sum()), 1e-9)
                for (a, b), ln in zip(legs, lens):
                    dt = (g.time - t) * ln / total if total > 1e-6 else (g.time - t) / len(legs)
                    if dt <= 1e-6:
                        continue
                    first = "r" if not steps else ("l" if steps[-1].foot == "r" else "r")
                    if change is not None and t - 1e-6 <= change[0] <= t + dt + 1e-6:
                        steps += list(gait_footsteps(a, b, t, t + dt, change, foot_length=fl, first=first))
                    else:
                        steps += list(walk_footsteps(a, b, t, t + dt, foot_length=fl, first=first))
                    t += dt
                p = g.target
            if t < T - 1e-6:  # stand at the target for the rest of the scenario
                h = math.atan2(*(np.asarray(p) - np.asarray(start[:2]))[::-1]) if walk else start[2]
                steps += list(standing_footsteps((p[0], p[1], h), t, T, fl))
        tackles = [g for g in scn.goals if isinstance(g, TackleGoal) and g.attacker == spec.name]
        if tackles and not steps:  # run at where the target is at impact (its initial plan), then stand
            g = min(tackles, key=lambda g: g.time)
            other = next((c for c in chars if c.name == g.target), None)
            if other is not None:
                aim = handle_track(other, "chest", [g.time])[0][:2]
            else:
                aim = np.asarray(scn.character(g.target).start.position, float)
            d = aim - np.asarray(start[:2])
            stop = aim - d / max(np.linalg.norm(d), 1e-6) * 0.35
            steps += list(gait_footsteps(start[:2], stop, 0.0, g.time, foot_length=fl, before="run"))
            if g.time < T - 1e-6:
                steps += list(standing_footsteps((stop[0], stop[1], math.atan2(d[1], d[0])), g.time, T, fl))
        if not steps:
            steps = list(standing_footsteps(start, 0.0, T, fl))
        steps.sort(key=lambda f: (f.t0, f.foot))
        run_from = change[0] if change is not None and change[2] == "run" else False
        motion = initial_motion(ch, tuple(steps), 0.0, T, ground=ground, run=run_from)
        chars.append(CharacterState(spec.name, ch, tuple(styles), tuple(steps), motion, start))
    chars.sort(key=lambda c: scn.character_names.index(c.name))
    return Scene(scn.name, T, tuple(chars), tuple(goals), tuple(couplings),
                 float(scn.environment.ground.friction), tuple(sorted(refs.items())), ground)


# --- targets from the current scene ------------------------------------------------------------

@functools.lru_cache(maxsize=64)
def _hfn(ch: Character, names: tuple[str, ...]):
    return handle_positions_fn(ch, names)


def handle_track(state: CharacterState, handle: str, times) -> np.ndarray:
    """World positions (len(times), 3) of a handle along the character's current motion."""
    fn = _hfn(state.character, (handle,))
    q, _, _ = state.motion.at(np.clip(np.asarray(times, float), state.motion.start, state.motion.end))
    q = np.atleast_2d(q)
    return np.array([np.asarray(fn(qi)).ravel() for qi in q])


def goal_targets(scene: Scene, character: str, goal_names) -> tuple[tuple[HandleTarget, ...], tuple[Avoid, ...]]:
    """Solver terms for the named goals that bind ``character``, from the current Scene."""
    targets, avoid = [], []
    me = scene.character(character)
    for gname in goal_names:
        try:
            g = scene.goal(gname)
        except KeyError:
            continue
        if g.type == "walk_to" and g.character == character:
            (x, y), _ = g.data
            z = float(handle_track(me, "pelvis", [g.time])[0][2])
            targets.append(HandleTarget("pelvis", g.time, (float(x), float(y), z), TARGET_WEIGHT,
                                        name=f"goal:{g.name}"))
        elif g.type == "reach" and g.character == character:
            handle, point = g.data
            targets.append(HandleTarget(handle, g.time, tuple(point), TARGET_WEIGHT, name=f"goal:{g.name}"))
        elif g.type == "tackle" and g.character == character:
            other = scene.character(g.partner)
            chest = handle_track(other, "chest", [g.time])[0]
            my_chest = handle_track(me, "chest", [g.time])[0]
            d = chest[:2] - my_chest[:2]
            u = d / max(np.linalg.norm(d), 1e-6)
            lat = np.array([-u[1], u[0]])
            r = 0.14  # m: half the torso depth
            contact = chest - np.r_[u * r, 0.0]
            targets.append(HandleTarget("chest", g.time, tuple(contact - np.r_[u * 0.12, 0.0]), TARGET_WEIGHT,
                                        name=f"goal:{g.name}"))
            if g.data[1]:  # hands around the torso: palms beside / behind it
                for side, s in (("l", 1.0), ("r", -1.0)):
                    p = chest + np.r_[s * lat * 0.17 + u * 0.05, 0.0]
                    targets.append(HandleTarget(f"palm_{side}", g.time, tuple(p), TARGET_WEIGHT / 3,
                                                name=f"goal:{g.name}"))
        elif g.type == "avoid" and g.character == character:
            other = scene.character(g.partner)
            center = tuple(handle_track(other, "chest", [g.time])[0])
            for h in ("pelvis", "chest"):
                avoid.append(Avoid(h, g.time, center, g.data[0]))
    return tuple(targets), tuple(avoid)


def coupling_targets(scene: Scene, character: str, coupling: str, stiffness: float,
                     window: tuple[float, float], rate: float = 10.0) -> tuple[HandleTarget, ...]:
    """Rubber-band springs of a coupling for ``character``: its handle toward the partners' held
    handles (their current motion) at ~``rate`` Hz inside the coupling interval ∩ window.

    The weight grows with the stiffness (N/m): w = stiffness / (m g) · 10 per point.
    """
    c = scene.coupling(coupling)
    mine = [h for who, h in c.handles if who == character]
    others = [(who, h) for who, h in c.handles if who != character]
    if not mine or not others:
        return ()
    a, b = max(c.interval[0], window[0]), min(c.interval[1], window[1])
    if b <= a:
        return ()
    n = max(2, int(math.ceil((b - a) * rate)) + 1)
    times = np.linspace(a, b, n)
    me = scene.character(character)
    w = float(stiffness) / (me.character.total_mass * 9.81) * 10.0
    out = []
    for who, h in others:
        track = handle_track(scene.character(who), h, times)
        for t, p in zip(times, track):
            out.append(HandleTarget(mine[0], float(t), tuple(float(v) for v in p), w, name=f"coupling:{c.name}"))
    return tuple(out)


def coupling_springs(scene: Scene, character: str, coupling: str, stiffness: float,
                     window: tuple[float, float], rate: float = 60.0) -> tuple[Spring, ...]:
    """The physical rubber band of a hand-hold for ``character``: a spring of ``stiffness``
    (N/m) from its handle to each partner's held handle (their current motion), sampled at
    ``rate`` Hz over the coupling interval ∩ window.  Solved in turn, each partner feels the
    equal and opposite force k (p_other − p_own) (thesis §6.4.3)."""
    c = scene.coupling(coupling)
    mine = [h for who, h in c.handles if who == character]
    others = [(who, h) for who, h in c.handles if who != character]
    a, b = max(c.interval[0], window[0]), min(c.interval[1], window[1])
    if c.type != "hand_hold" or not mine or not others or b <= a:
        return ()
    times = np.linspace(a, b, max(2, int(math.ceil((b - a) * rate)) + 1))
    return tuple(Spring(mine[0], tuple(float(t) for t in times),
                        tuple(tuple(float(v) for v in p) for p in handle_track(scene.character(who), h, times)),
                        float(stiffness), name=f"coupling:{c.name}")
                 for who, h in others)


def _resolve(path) -> Path:
    return Path(path).resolve()
