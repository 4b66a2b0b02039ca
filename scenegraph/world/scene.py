"""The Scene: what a scenario describes, turned into the world model the solver works on.

``build_scene(scenario)`` gives, per character, its :class:`~scenegraph.model.body.Character`
(preset plus edits), its styles, its footsteps (explicit footprints, or free footsteps
generated for ``walk_to``, a run through the impact point for a tackler, a walk straight
ahead for a tackle/avoid target without a walk of its own, or both feet planted for a
character without locomotion goals), and an initial :class:`~scenegraph.model.motion.Motion` over
[0, duration] (running poses for a tackler).  Goals and couplings are typed records, one
module per kind (:mod:`scenegraph.world.goals`), each with its scenario location; their solver
targets depend on the partners' *current* motions and are computed on demand with
:func:`goal_targets` / :func:`coupling_targets`, which ask each record.  Tackle and avoid are
soft springs (never hard spheres) limited by the reaction time left in the optimised window
(:func:`~scenegraph.world.measure.reach_budget`).

Scenario files use degrees; everything here is in radians (SI units otherwise).
The Scene is immutable: ``scene.with_motion(name, motion, footsteps)`` returns a new one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from scenarios.errors import InputError
from scenarios.schema import Scenario, WalkToGoal, joint_dofs

from scenegraph.model.body import PRESETS, Character, make_character
from scenegraph.model.footsteps import Footstep, airborne_gaps, foot_length
from scenegraph.model.gait import initial_motion, style_gait
from scenegraph.world.footplan import RANK_FOOTPRINTS, RANK_CHASE, FootContext, plan_footsteps
from scenegraph.model.ground import FLAT, Ground, ground_from_environment
from scenegraph.model.knot_warp import align_knots
from scenegraph.model.motion import Motion
from scenegraph.world.goals import Coupling, GoalRecord, coupling_records, goal_records
from scenegraph.world.goals.tackle import TACKLE_CONTACT_TOL
from scenegraph.world.measure import (avoid_measure, body_frames, chest_front, handle_track, reach_budget,
                      tackle_measure, torso_distance)
from scenegraph.problem import Avoid, HandleTarget, Spring
from scenegraph.model.style import Style, default_style, load_style

__all__ = ["Scene", "CharacterState", "GoalSpec", "CouplingSpec", "build_scene", "goal_targets",
           "goal_weight", "coupling_targets", "coupling_springs", "handle_track", "adversarial_plans_last",
           "tackle_measure", "avoid_measure", "scale_style_to_body", "TACKLE_CONTACT_TOL", "body_frames",
           "chest_front", "torso_distance", "reach_budget"]

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
    plan: Motion | None = None  # the initial motion, kept when ``motion`` is replaced: the planned entry

    @property
    def planned(self) -> "CharacterState":
        """This character with its initial (planned) motion as the current one."""
        return self if self.plan is None else replace(self, motion=self.plan)

    @property
    def style(self) -> Style:
        return self.styles[0][1]

    def style_of(self, ref: str) -> Style:
        for r, s in self.styles:
            if r == ref:
                return s
        raise KeyError(ref)


GoalSpec = GoalRecord  # a goal of the Scene: a typed record per kind (scenegraph.world.goals)
CouplingSpec = Coupling


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
        found = next((c for c in self.characters if c.name == name), None)
        if found is None:
            raise KeyError(name)
        return found

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

    def world_time(self, who: str, t: float) -> float:
        """World time (s) of the goal time ``t`` of character ``who``.  With fixed timing goal
        times are world times (``t``).  With ``timing: free`` they are canonical: the world time
        of s = t / duration on the character's current timewarp, so a goal moves with the
        motion when a timing step stretches it."""
        if self.duration_bounds is None:
            return float(t)
        m = self.character(who).motion
        return float(np.asarray(m.time([min(max(float(t) / self.duration, 0.0), 1.0)])).ravel()[0])

    def goal_at_world_time(self, g: GoalRecord) -> GoalRecord:
        """``g`` with its time in world seconds (:meth:`world_time`; unchanged with fixed timing)."""
        if g.time is None or self.duration_bounds is None:
            return g
        return replace(g, time=self.world_time(g.character, g.time))

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


# --- footsteps (planned by the goal records, scenegraph/world/footplan.py) ---------------------

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
        pair = getattr(g, "opponents", None)  # (who plans last by default, the other)
        if pair is not None:
            choices.setdefault(frozenset(pair), []).append((g.plans_last, pair[0]))
    out = {}
    for pair, cs in choices.items():
        explicit = sorted({c for c, _ in cs if c is not None})
        out[pair] = explicit[0] if explicit else sorted(d for _, d in cs)[0]
    return out


# --- build -----------------------------------------------------------------------------------

def build_scene(scn: Scenario) -> Scene:
    """The initial Scene of a scenario (see the module docstring)."""
    if scn.is_edit:
        raise InputError("an edit scenario has no scene to build: it edits its clip (scenarios/edit_block.py)",
                         scn.location(("edit",)))
    T = float(scn.duration)
    chars, refs = [], {}
    last = adversarial_plans_last(scn)
    goals = list(goal_records(scn, last))
    couplings = list(coupling_records(scn))

    ground = ground_from_environment(scn.environment, friction=scn.environment.ground.friction)
    starts = {c.name: (float(c.start.position[0]), float(c.start.position[1])) for c in scn.characters}
    # a character whose footsteps are planned from another's motion (a tackler) is built after it
    waits = {c.name for c in scn.characters if any(g.step_rank(c.name) == RANK_CHASE for g in goals)}
    order = sorted(scn.characters, key=lambda c: c.name in waits)
    for spec in order:
        ch = _character(spec)
        for cpl in couplings:
            for handle, kg in cpl.loads(spec.name):
                ch = ch.with_extra_mass(handle, kg)
        styles = []
        for _, ref, _ in scn.style_timeline(spec.name):
            if ref not in dict(styles):
                st, where = _style(scn, ref, ch, spec.body.shoe_stiffness_scale)
                styles.append((ref, st))
                refs[ref] = where
        start = (float(spec.start.position[0]), float(spec.start.position[1]), math.radians(spec.start.heading))
        changes = sorted((c for c in (g.gait_change(spec.name) for g in goals) if c is not None), key=lambda c: c[0])
        change = changes[0] if changes else None  # the first gait change shapes the generated footsteps
        _check_walk_heading(scn, spec.name, any(g.step_rank(spec.name) == RANK_FOOTPRINTS for g in goals), T)
        ctx = FootContext(spec.name, start, T, foot_length(ch), style_gait(styles[0][1]), change,
                          {c.name: c for c in chars}, starts)
        plan = plan_footsteps(goals, ctx)
        steps = plan.steps
        run_from = change[0] if change is not None and change[2] == "run" else plan.run
        motion = plan.initial(ch) if plan.initial is not None else \
            initial_motion(ch, steps, 0.0, T, ground=ground, run=run_from, example=_example(scn, spec, styles))
        motion = align_knots(motion, [t for gap in airborne_gaps(steps) for t in gap])  # q̈ may kink at flight ends
        chars.append(CharacterState(spec.name, ch, tuple(styles), steps, motion, start, plan=motion))
    chars.sort(key=lambda c: scn.character_names.index(c.name))
    bounds = None
    if scn.timing == "free":
        bounds = tuple(float(b) for b in scn.duration_bounds) if scn.duration_bounds else \
            (FREE_DURATION_RANGE[0] * T, FREE_DURATION_RANGE[1] * T)
    return Scene(scn.name, T, tuple(chars), tuple(goals), tuple(couplings),
                 float(ground.friction), tuple(sorted(refs.items())), ground, bounds)


# --- targets from the current scene ------------------------------------------------------------

def goal_weight(g: GoalRecord) -> float:
    """The spring weight a goal gets when its caller gives none: its kind's ``default_weight``
    (the number the compiler writes into each Step, scenarios/weights.py)."""
    return float(g.default_weight)


def goal_targets(scene: Scene, character: str, goals, window: tuple[float, float] | None = None
                 ) -> tuple[tuple[HandleTarget, ...], tuple[Avoid, ...]]:
    """Solver terms for the goals that bind ``character``, from the current Scene.

    ``goals``: a mapping goal name → weight (a Step's ``goal:<name>`` terms: a spring weight in
    1/m² of the normalised objective, or ``"hard"`` for an equality), or goal names (weights
    :func:`goal_weight`).  Each goal kind makes its own targets (``GoalRecord.targets``);
    ``window``: the optimised world-time window (None: the whole motion), which limits tackle
    and avoid targets to what the reaction time allows.  Footprints are footsteps, not targets."""
    targets: list[HandleTarget] = []
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
        g = scene.goal_at_world_time(g)
        targets += g.targets(scene, me, goal_weight(g) if w is None or hard else float(w), window, hard=hard)
    return tuple(targets), ()


def coupling_targets(scene: Scene, character: str, coupling: str, stiffness: float,
                     window: tuple[float, float], rate: float = 10.0) -> tuple[HandleTarget, ...]:
    """Rubber-band target points of a coupling (by name) for ``character`` (see
    :func:`scenegraph.world.goals.couplings.coupling_targets`)."""
    return scene.coupling(coupling).targets(scene, character, stiffness, window, rate)


def coupling_springs(scene: Scene, character: str, coupling: str, stiffness: float,
                     window: tuple[float, float], rate: float = 60.0) -> tuple[Spring, ...]:
    """The physical rubber band of a coupling (by name) for ``character`` (a hand-hold's
    springs; see :func:`scenegraph.world.goals.couplings.coupling_springs`)."""
    return scene.coupling(coupling).springs(scene, character, stiffness, window, rate)
