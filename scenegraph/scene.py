"""The Scene: what a scenario describes, turned into the world model the solver works on.

``build_scene(scenario)`` gives, per character, its :class:`~scenegraph.body.Character`
(preset plus edits), its styles, its footsteps (explicit footprints, or free footsteps
generated for ``walk_to``, a run through the impact point for a tackler, a walk straight
ahead for a tackle/avoid target without a walk of its own, or both feet planted for a
character without locomotion goals), and an initial :class:`~scenegraph.motion.Motion` over
[0, duration] (running poses for a tackler).  Goals that become
solver terms (reach, tackle, avoid, walk_to end point) are described by :class:`GoalSpec`;
their solver targets depend on the partners' *current* motions and are computed on demand
with :func:`goal_targets` / :func:`coupling_targets`.  Tackle and avoid are soft springs
(never hard spheres) limited by the reaction time left in the optimised window
(:func:`reach_budget`); :func:`tackle_measure` / :func:`avoid_measure` measure them for the
report.

Scenario files use degrees; everything here is in radians (SI units otherwise).
The Scene is immutable: ``scene.with_motion(name, motion, footsteps)`` returns a new one.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from scenarios.errors import InputError
from scenarios.schema import (AvoidGoal, Carry, FootprintsGoal, HandHold, ReachGoal, Scenario, StyleChangeGoal,
                              TackleGoal, WalkToGoal, joint_dofs)
from scenarios.weights import AVOID_WEIGHT, START_WEIGHT, TARGET_WEIGHT  # re-exported: goal/start spring weights

from .body import PRESETS, Character, make_character
from .footsteps import (CADENCE, FOOT_WIDTH, GAITS, STANCE_FRACTION, Footstep, Gait, foot_length, gait_footsteps,
                        standing_footsteps, walk_footsteps)
from .gait import initial_motion, style_gait
from .ground import FLAT, Ground, ground_from_environment
from .kinematics import handle_positions_fn, numeric_fk
from .motion import Motion
from .problem import Avoid, HandleTarget, Spring
from .style import Style, default_style, load_style

__all__ = ["Scene", "CharacterState", "GoalSpec", "CouplingSpec", "build_scene", "goal_targets", "goal_weight",
           "coupling_targets", "coupling_springs", "handle_track", "CADENCE", "STANCE_FRACTION", "FOOT_WIDTH",
           "adversarial_plans_last", "tackle_measure", "avoid_measure", "scale_style_to_body",
           "TACKLE_CONTACT_TOL", "TACKLE_SPEED_TOL", "TARGET_WEIGHT", "AVOID_WEIGHT", "START_WEIGHT"]

TACKLE_CONTACT_TOL = 0.05  # m: the tackler's chest front within this of the target's torso surface
TACKLE_SPEED_TOL = 0.10    # relative: closing speed within ±10 % of the goal speed
TACKLE_SPEED_LEAD = 0.1    # s: the speed is asked for as a chest position this long before the impact
AVOID_MARGIN = 0.25        # m: the escape target lies this far outside the avoided sphere (0.08 left
#                            tackle_dodge's learned-style target 0.34-0.45 m from a `run` tackler)
REACH_ACCEL = 1.0          # m/s²: a tackle/avoid target asks for at most ½ a τ² of displacement, τ the
#                            time from the start of the optimised window to the goal (reaction time)
TORSO_BODIES = ("thorax", "abdomen")
FREE_DURATION_RANGE = (0.5, 2.0)  # timing: free without duration_bounds: the motion lasts 0.5–2 × duration


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
    plans_last: str | None = None  # tackle / avoid: who plans last in the pair (decides the outcome)

    @property
    def expected_to_hold(self) -> bool | None:
        """Adversarial goals (tackle, avoid): True for the side that plans last (it wins by
        design of the decreasing-horizon schedule), False for the other; None otherwise."""
        if self.type == "tackle":
            return self.plans_last == self.character
        if self.type == "avoid":
            return self.plans_last == self.character
        return None


@dataclass(frozen=True)
class CouplingSpec:
    name: str
    type: str
    handles: tuple[tuple[str, str], ...]  # (character, handle)
    interval: tuple[float, float]
    mass: float = 0.0
    tolerance: float = 0.01  # m: hands within this distance count as holding (issue #7: ≤ 1 cm)


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
    duration_bounds: tuple[float, float] | None = None  # s, [min, max] of the whole motion with timing: free

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
        st, where = scale_style_to_body(load_style(f), ch), str(f)
    if shoe_scale != 1.0:
        st = st.with_(k_shoe=float(st.k_shoe) * shoe_scale)
    return st, where


def scale_style_to_body(style: Style, ch: Character) -> Style:
    """A learned style on another body: the passive springs, their damping and the shoe spring
    (N·m/rad, N·m·s/rad, N/m) scale with the body mass ``ch.mass`` (kg, without carried
    loads) over the mass of the body it was learned on (``provenance.body``), as the default
    style's do; α, q̄ and h̄ carry over.  A style without a known learning body is unchanged."""
    body = style.provenance.body if style.provenance is not None else None
    if body is None or body not in PRESETS:
        return style
    r = float(ch.mass) / float(PRESETS[body].mass)
    if abs(r - 1.0) < 1e-12:
        return style
    return style.with_(ks1=np.asarray(style.ks1) * r, ks2=np.asarray(style.ks2) * r, kd=np.asarray(style.kd) * r,
                       k_shoe=float(style.k_shoe) * r)


def _example(scn: Scenario, spec, styles: list[tuple[str, Style]]):
    """The example poses of a character's initial motion (``initial_motion: example``), or None."""
    if spec.initial_motion != "example":
        return None
    i = scn.character_names.index(spec.name)
    ref, st = styles[0]
    why = ("it changes style" if len(scn.style_timeline(spec.name)) > 1 else
           f"style {ref!r} carries no example poses (styles learned by compose learn do)" if st.example is None
           else None)
    if why:
        raise InputError(f"initial_motion: example needs one learned style, but {why}",
                         scn.location(("characters", i, "initial_motion")))
    return st.example.arrays()


# --- footsteps (generated by scenegraph.footsteps) -------------------------------------------

_foot_length = foot_length  # the name tests used


def _explicit_footsteps(g: FootprintsGoal, default_heading: float, foot_length: float) -> list[Footstep]:
    out = []
    for fp in g.steps:
        h = math.radians(fp.heading) if fp.heading is not None else default_heading
        # the file gives the midpoint of heel and ball; Footstep.position is the ball
        ball = (fp.position[0] + foot_length / 2 * math.cos(h), fp.position[1] + foot_length / 2 * math.sin(h))
        out.append(Footstep(fp.foot, (float(ball[0]), float(ball[1])), float(fp.time[0]), float(fp.time[1]), h))
    return out


def _check_walk_heading(scn: Scenario, who: str, explicit_steps: bool, T: float) -> None:
    """A walk_to ``heading`` turns the feet the character stands on after arriving; it needs
    generated footsteps and time left after the arrival, and only the character's last
    walk_to stands: otherwise an InputError at ``goals[j].heading``."""
    walks = sorted((g.time, j) for j, g in enumerate(scn.goals) if isinstance(g, WalkToGoal) and g.character == who)
    for k, (t, j) in enumerate(walks):
        g = scn.goals[j]
        if g.heading is None:
            continue
        why = ("the character has explicit footprints (no footsteps are generated)" if explicit_steps else
               "a later walk_to follows it (only the last walk_to ends standing)" if k < len(walks) - 1 else
               f"it arrives at the end of the scenario ({T:g} s): no time is left to stand facing it"
               if t >= T - 1e-6 else None)
        if why:
            raise InputError(f"walk_to heading: the final facing turns the feet the character stands on after "
                             f"arriving, but {why}", scn.location(("goals", j, "heading")))


# --- adversarial pairs -----------------------------------------------------------------------

def adversarial_plans_last(scn: Scenario) -> dict[frozenset, str]:
    """Per adversarial pair (frozenset of two names): who plans last — the explicit
    ``plans_last`` of any of the pair's goals (the schema keeps them consistent), else the
    attacker (tackle) or the one avoided (avoid); the schedule compiler makes the same choice."""
    choices: dict[frozenset, list[tuple[str | None, str]]] = {}
    for g in scn.goals:
        if isinstance(g, TackleGoal):
            choices.setdefault(frozenset((g.attacker, g.target)), []).append((g.plans_last, g.attacker))
        elif isinstance(g, AvoidGoal):
            choices.setdefault(frozenset((g.character, g.around)), []).append((g.plans_last, g.around))
    out = {}
    for pair, cs in choices.items():
        explicit = sorted({c for c, _ in cs if c is not None})
        out[pair] = explicit[0] if explicit else sorted(d for _, d in cs)[0]
    return out


# --- build -----------------------------------------------------------------------------------

def build_scene(scn: Scenario) -> Scene:
    """The initial Scene of a scenario (see the module docstring)."""
    T = float(scn.duration)
    chars, refs = [], {}
    goals: list[GoalSpec] = []
    last = adversarial_plans_last(scn)
    for name, g in scn.named_goals():
        if isinstance(g, ReachGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, g.tolerance, (g.handle, tuple(g.target))))
        elif isinstance(g, WalkToGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, g.tolerance,
                                  (tuple(g.target), None if g.heading is None else math.radians(g.heading))))
        elif isinstance(g, TackleGoal):
            goals.append(GoalSpec(name, g.type, g.attacker, g.target, g.time, TACKLE_CONTACT_TOL,
                                  (g.min_speed, g.hands_around_torso, g.speed),
                                  plans_last=last[frozenset((g.attacker, g.target))]))
        elif isinstance(g, AvoidGoal):
            goals.append(GoalSpec(name, g.type, g.character, g.around, g.time, 1e-3, (g.radius,),
                                  plans_last=last[frozenset((g.character, g.around))]))
        elif isinstance(g, FootprintsGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, None, 2e-3))
        elif isinstance(g, StyleChangeGoal):
            goals.append(GoalSpec(name, g.type, g.character, None, g.time, 0.0, (g.style, g.gait, g.blend)))
    couplings = []
    for name, c in scn.named_couplings():
        if isinstance(c, HandHold):
            couplings.append(CouplingSpec(name, c.type, tuple((r.character, r.handle) for r in c.between),
                                          tuple(c.interval)))
        elif isinstance(c, Carry):
            couplings.append(CouplingSpec(name, c.type, tuple((r.character, r.handle) for r in c.holders),
                                          tuple(c.interval), mass=c.mass, tolerance=0.05))

    ground = ground_from_environment(scn.environment, friction=scn.environment.ground.friction)
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
        fl = foot_length(ch)
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
        before = style_gait(styles[0][1])  # the initial style's gait: a run style runs to its target
        _check_walk_heading(scn, spec.name, bool(steps), T)
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
                        steps += list(gait_footsteps(a, b, t, t + dt, change, foot_length=fl, first=first,
                                                     before=before))
                    elif before == "run":
                        steps += list(gait_footsteps(a, b, t, t + dt, foot_length=fl, first=first, before="run"))
                    else:
                        steps += list(walk_footsteps(a, b, t, t + dt, foot_length=fl, first=first))
                    t += dt
                p = g.target
            if t < T - 1e-6:  # stand at the target for the rest of the scenario, facing the last
                last = max(walk, key=lambda g: g.time)  # walk_to's heading if it has one
                h = math.atan2(*(np.asarray(p) - np.asarray(start[:2]))[::-1]) if last.heading is None \
                    else math.radians(last.heading)
                steps += list(standing_footsteps((p[0], p[1], h), t, T, fl))
        tackles = [g for g in scn.goals if isinstance(g, TackleGoal) and g.attacker == spec.name]
        runner = False
        if tackles and not steps:  # run at where the target is at impact (its initial plan), then stand
            g = min(tackles, key=lambda g: g.time)
            other = next((c for c in chars if c.name == g.target), None)
            if other is not None:
                aim = handle_track(other, "chest", [g.time])[0][:2]
            else:
                aim = np.asarray(scn.character(g.target).start.position, float)
            d = aim - np.asarray(start[:2])
            stop = aim - d / max(np.linalg.norm(d), 1e-6) * 0.35
            # one run at constant speed through the impact point; a tackle before the end of
            # the scenario keeps running on past it (a missed tackle does not stop dead)
            end = np.asarray(start[:2]) + (stop - np.asarray(start[:2])) * T / max(g.time, 1e-6)
            steps += list(gait_footsteps(start[:2], end, 0.0, T, foot_length=fl, before="run"))
            runner = True
        dodges = [g for g in scn.goals if (isinstance(g, AvoidGoal) and g.character == spec.name)
                  or (isinstance(g, TackleGoal) and g.target == spec.name)]
        if dodges and not steps:  # a target without a walk of its own: walks straight ahead (its initial plan)
            u = np.array([math.cos(start[2]), math.sin(start[2])])
            end = np.asarray(start[:2]) + u * GAITS["walk"].cadence * GAITS["walk"].step_length * T
            steps += list(walk_footsteps(start[:2], end, 0.0, T, foot_length=fl))
        if not steps:
            steps = list(standing_footsteps(start, 0.0, T, fl))
        steps.sort(key=lambda f: (f.t0, f.foot))
        run_from = change[0] if change is not None and change[2] == "run" else \
            runner or (bool(walk) and before == "run" and change is None)
        motion = initial_motion(ch, tuple(steps), 0.0, T, ground=ground, run=run_from,
                                example=_example(scn, spec, styles))
        chars.append(CharacterState(spec.name, ch, tuple(styles), tuple(steps), motion, start))
    chars.sort(key=lambda c: scn.character_names.index(c.name))
    bounds = None
    if scn.timing == "free":
        bounds = tuple(float(b) for b in scn.duration_bounds) if scn.duration_bounds else \
            (FREE_DURATION_RANGE[0] * T, FREE_DURATION_RANGE[1] * T)
    return Scene(scn.name, T, tuple(chars), tuple(goals), tuple(couplings),
                 float(ground.friction), tuple(sorted(refs.items())), ground, bounds)


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


def _body_index(ch: Character, name: str) -> int:
    return [b.name for b in ch.bodies].index(name)


def body_frames(state: CharacterState, body: str, times) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (n, 3, 3) and ellipsoid centres (n, 3) of one body along the motion."""
    ch = state.character
    q, _, _ = state.motion.at(np.clip(np.asarray(times, float), state.motion.start, state.motion.end))
    R, p = numeric_fk(ch, np.atleast_2d(q))
    i = _body_index(ch, body)
    b = ch.bodies[i]
    return R[:, i], p[:, i] + np.einsum("nij,j->ni", R[:, i], np.asarray(b.center))


def chest_front(state: CharacterState, times) -> np.ndarray:
    """(n, 3) the front of the thorax ellipsoid (its +x semi-axis end): a tackler's contact point."""
    R, c = body_frames(state, "thorax", times)
    a = state.character.body("thorax").semi_axes[0]
    return c + a * R[:, :, 0]


def _ray_to_surface(R: np.ndarray, c: np.ndarray, semi, direction: np.ndarray) -> np.ndarray:
    """Where the ray from an ellipsoid's centre along ``direction`` (world) leaves it."""
    d = R.T @ direction
    return c + direction / max(float(np.linalg.norm(d / np.asarray(semi))), 1e-9)


def torso_distance(state: CharacterState, point, t: float) -> float:
    """Signed distance (m, < 0 inside) of a world point from the torso (thorax ∪ abdomen
    ellipsoids) at time t, measured along the ray from each ellipsoid's centre (exact on the
    surface, an upper bound of the Euclidean distance off it)."""
    point = np.asarray(point, float)
    best = np.inf
    for body in TORSO_BODIES:
        R, c = body_frames(state, body, [t])
        x = R[0].T @ (point - c[0])
        n = float(np.linalg.norm(x))
        k = float(np.linalg.norm(x / np.asarray(state.character.body(body).semi_axes)))
        best = min(best, n * (1.0 - 1.0 / k) if k > 1e-12 else -float(min(state.character.body(body).semi_axes)))
    return best


def _horizontal_unit(v, fallback=(1.0, 0.0)) -> np.ndarray:
    v = np.asarray(v, float)[:2]
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.asarray(fallback, float)


def tackle_measure(attacker: CharacterState, target: CharacterState, t: float, h: float = 0.01) -> dict:
    """What a tackle achieved at time t: the attacker's contact point (front of the chest)
    against the target's torso surface, and the closing speed — the contact point's velocity
    relative to the target's thorax centre along the horizontal line between them (backward
    difference over ``h``; the impact is usually the last instant of the scenario)."""
    ta = [t - h, t]
    front = chest_front(attacker, ta)
    _, c_t = body_frames(target, "thorax", ta)
    _, c_a = body_frames(attacker, "thorax", ta)
    u = _horizontal_unit(c_t[1] - c_a[1])
    rel_v = ((front[1] - front[0]) - (c_t[1] - c_t[0])) / h
    palms = handle_track(attacker, "palm_l", [t])[0], handle_track(attacker, "palm_r", [t])[0]
    return {"contact_distance": float(torso_distance(target, front[1], t)),
            "closing_speed": float(np.dot(rel_v[:2], u)),
            "contact_point": front[1].tolist(),
            "chest_to_chest": float(np.linalg.norm(c_t[1] - c_a[1])),
            "palm_distances": [float(torso_distance(target, p, t)) for p in palms]}


def avoid_measure(me: CharacterState, other: CharacterState, t: float) -> float:
    """Clearance of an avoid goal: the smaller distance of my pelvis and chest from the
    other's chest at time t (the sphere's centre)."""
    o = handle_track(other, "chest", [t])[0]
    return min(float(np.linalg.norm(handle_track(me, hd, [t])[0] - o)) for hd in ("pelvis", "chest"))


def reach_budget(g: GoalSpec, me: CharacterState, window: tuple[float, float] | None) -> float:
    """How far (m) a soft tackle/avoid target may ask a handle to move in one solve: ½ REACH_ACCEL τ²,
    τ = the goal time minus the start of the optimised window (the reaction time left).  Later
    cycles of the decreasing horizon have less time to react; asking for more than a body can
    do in that time would only buy large, implausible forces (and stall the solver)."""
    t0 = me.motion.start if window is None else window[0]
    tau = max(float(g.time) - float(t0), 0.0)
    return 0.5 * REACH_ACCEL * tau * tau


def _clamp(current: np.ndarray, wanted: np.ndarray, budget: float) -> np.ndarray:
    d = wanted - current
    n = float(np.linalg.norm(d))
    return wanted if n <= budget else current + d * (budget / n)


def _tackle_targets(scene: Scene, g: GoalSpec, me: CharacterState, budget: float = np.inf,
                    weight: float = TARGET_WEIGHT) -> list[HandleTarget]:
    """Soft springs of a tackle for the attacker, from the target's current motion: the chest
    centre where its front touches the target's torso (on the side facing the attacker's
    approach), the chest TACKLE_SPEED_LEAD s earlier where the goal's closing speed puts it,
    and with ``hands_around_torso`` the palms beside and behind the target's chest.  When
    the chest would have to move more than ``budget`` (:func:`reach_budget`), every target is
    shifted back so that it moves by the budget."""
    min_speed, hands, speed = g.data
    goal_speed = float(speed) if speed is not None else 1.1 * float(min_speed)
    other = scene.character(g.partner)
    t, lead = g.time, TACKLE_SPEED_LEAD
    R, c = body_frames(other, "thorax", [t - 0.01, t])  # her velocity at the impact (as measured)
    my_then, my = handle_track(me, "chest", [max(t - 0.25, me.motion.start), t])
    u = _horizontal_unit(c[1] - my_then)  # the approach direction (not the last instant's)
    u3, lat3 = np.r_[u, 0.0], np.r_[-u[1], u[0], 0.0]
    semi = other.character.body("thorax").semi_axes
    surf = _ray_to_surface(R[1], c[1], semi, -u3)
    chest = surf - u3 * me.character.body("thorax").semi_axes[0]
    v_other = (c[1] - c[0]) / 0.01
    shift = _clamp(my, chest, budget) - chest
    chest, c = chest + shift, c + shift
    out = [HandleTarget("chest", t, tuple(float(v) for v in chest), weight, name=f"goal:{g.name}")]
    for h in (lead, lead / 2):  # the approach at the goal's closing speed (two points: no last-instant lunge)
        before = chest - h * (goal_speed + float(np.dot(v_other, u3))) * u3
        out.append(HandleTarget("chest", t - h, tuple(float(v) for v in before), weight / 3,
                                name=f"goal:{g.name}"))
    if hands:  # palms on the target's flanks, a little behind her chest centre
        for side, sgn in (("l", 1.0), ("r", -1.0)):
            flank = _ray_to_surface(R[1], c[1], semi, sgn * lat3)
            p = flank + sgn * lat3 * 0.03 + u3 * 0.06
            out.append(HandleTarget(f"palm_{side}", t, tuple(float(v) for v in p), weight / 3,
                                    name=f"goal:{g.name}"))
    return out


def _avoid_targets(scene: Scene, g: GoalSpec, me: CharacterState, budget: float = np.inf,
                   weight: float = AVOID_WEIGHT) -> list[HandleTarget]:
    """Soft escape springs of an avoid goal, from the other's current motion.

    The pelvis and chest that are inside the sphere (+ AVOID_MARGIN) at the goal time are
    pulled out of it sideways to the other's approach — horizontally, perpendicular to its
    chest velocity, on the side the pelvis already is (or the side it moves toward) — by at
    most ``budget`` (asking the same displacement 0.05 s earlier as well made the dodger's
    first solve creep to its iteration cap).  Soft, so that a
    dodge that cannot be done with physical forces is traded off against the dynamics
    instead of being forced by non-physical root forces (a hard sphere constraint did exactly
    that: root residuals of 0.6 body weight in the short late windows)."""
    other = scene.character(g.partner)
    t = g.time
    c0, centre = handle_track(other, "chest", [max(t - 0.1, other.motion.start), t])
    v = _horizontal_unit(centre - c0)
    perp = np.array([-v[1], v[0]])
    pel0, pel = handle_track(me, "pelvis", [max(t - 0.1, me.motion.start), t])
    off = float(np.dot(pel[:2] - centre[:2], perp))
    side = np.sign(off) if abs(off) > 0.02 else (np.sign(float(np.dot(pel[:2] - pel0[:2], perp))) or 1.0)
    u = np.r_[perp * side, 0.0]
    need = g.data[0] + AVOID_MARGIN
    out = []
    for hd in ("pelvis", "chest"):
        p = handle_track(me, hd, [t])[0]
        w = p - centre
        if float(np.linalg.norm(w)) >= need:
            continue
        # the smallest s >= 0 with |p + s u - centre| = need
        b = float(np.dot(w, u))
        s_ = -b + math.sqrt(max(b * b - (float(np.dot(w, w)) - need * need), 0.0))
        d = _clamp(p, p + s_ * u, budget) - p
        out.append(HandleTarget(hd, float(t), tuple(float(x) for x in p + d), weight, name=f"goal:{g.name}"))
    return out


def goal_weight(g: GoalSpec) -> float:
    """The spring weight a goal gets when its caller gives none (the compiler writes the same
    numbers into each Step: scenarios/weights.py): AVOID_WEIGHT for avoid, else TARGET_WEIGHT."""
    return AVOID_WEIGHT if g.type == "avoid" else TARGET_WEIGHT


def goal_targets(scene: Scene, character: str, goals, window: tuple[float, float] | None = None
                 ) -> tuple[tuple[HandleTarget, ...], tuple[Avoid, ...]]:
    """Solver terms for the goals that bind ``character``, from the current Scene.

    ``goals``: a mapping goal name → weight (a Step's ``goal:<name>`` terms: a spring weight in
    1/m² of the normalised objective, or ``"hard"`` for an equality), or goal names (weights
    :func:`goal_weight`).  A tackle's approach and palm springs weigh a third of its chest
    spring.  ``window``: the optimised world-time window (None: the whole motion); tackle and
    avoid targets ask for no more than the reaction time from its start allows
    (:func:`reach_budget`).  Footprints are footsteps, not targets (the Scene holds them)."""
    targets, avoid = [], []
    me = scene.character(character)
    weights = dict(goals) if isinstance(goals, dict) else {n: None for n in goals}
    for gname, w in weights.items():
        try:
            g = scene.goal(gname)
        except KeyError:
            continue
        if g.character != character:
            continue
        hard = w == "hard"
        wt = goal_weight(g) if w is None or hard else float(w)
        if g.type == "walk_to":
            (x, y), _ = g.data
            z = float(handle_track(me, "pelvis", [g.time])[0][2])
            targets.append(HandleTarget("pelvis", g.time, (float(x), float(y), z), wt, hard=hard,
                                        name=f"goal:{g.name}"))
        elif g.type == "reach":
            handle, point = g.data
            targets.append(HandleTarget(handle, g.time, tuple(point), wt, hard=hard, name=f"goal:{g.name}"))
        elif g.type == "tackle":
            targets += [replace(t, hard=hard) for t in _tackle_targets(scene, g, me, reach_budget(g, me, window), wt)]
        elif g.type == "avoid":
            targets += [replace(t, hard=hard) for t in _avoid_targets(scene, g, me, reach_budget(g, me, window), wt)]
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
