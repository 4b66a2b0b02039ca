"""Planning a character's initial footsteps from its goals: the context the goal records plan in.

Which goal plans a character's footsteps is a property of the goal kind
(:meth:`~scenegraph.world.goals.base.GoalRecord.step_rank`): among a character's goals the
lowest rank plans them all (``RANK_*`` below: explicit footprints, then jumps and hops, then
walk_to, then a tackler's run, then a walk straight ahead for a tackle or avoid target); a
character no goal plans for stands on both feet.  A planner may also give the initial motion
(jumps: :func:`scenegraph.model.leaps.leap_motion`); otherwise it is made from the footsteps.  A gait change (``style_change`` with ``gait``) reshapes the generated footsteps
(:meth:`~scenegraph.world.goals.base.GoalRecord.gait_change`).

Units: world frame, z up; m, s, rad.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from scenegraph.model.footsteps import GAITS, Footstep, standing_footsteps, walk_footsteps

__all__ = ["FootContext", "StepPlan", "plan_footsteps", "plan_sequence", "join_at_seam", "blend_initial", "walk_ahead", "RANK_FOOTPRINTS", "RANK_LEAP", "RANK_WALK",
           "RANK_CHASE", "RANK_WALK_AHEAD"]

# step ranks (GoalRecord.step_rank): the lowest rank among a character's goals plans its footsteps
RANK_FOOTPRINTS = 0   # written footprints
RANK_LEAP = 1         # jumps and hops: ground and flight stages
RANK_WALK = 2         # walk_to: free footsteps along its legs
RANK_CHASE = 3        # planned from another character's motion (a tackler's run): built after it
RANK_WALK_AHEAD = 4   # a tackle or avoid target without a walk of its own


@dataclass(frozen=True)
class FootContext:
    """What a goal needs to plan ``who``'s footsteps.

    start        (x, y, heading) m, m, rad: where ``who`` stands at t = 0
    duration     s: the scenario's duration
    foot_length  m: heel-to-ball distance of ``who``'s foot
    gait         "walk" | "run": the gait of ``who``'s initial style
    change       (time s, blend s, gait) of ``who``'s first gait change, or None
    placed       characters already built (name → CharacterState), e.g. a tackle's target
    starts       every character's start position (name → (x, y) m)
    t0           s: when the plan begins (a segment of a sequence: :func:`plan_sequence`), at ``start``
    first        "l" | "r" | None: the foot of a walk's first step (None: the planner's choice)
    """

    who: str
    start: tuple[float, float, float]
    duration: float
    foot_length: float
    gait: str = "walk"
    change: tuple[float, float, str] | None = None
    placed: dict = field(default_factory=dict)
    starts: dict = field(default_factory=dict)
    t0: float = 0.0
    first: str | None = None


@dataclass(frozen=True)
class StepPlan:
    """Footsteps (sorted by start time) and how the initial motion moves: ``run`` False (walk),
    True (runs throughout) or a time (s) from which it runs; ``initial``: the initial motion as
    a function of the character, when the planner makes its own (else the gait generator's)."""

    steps: tuple[Footstep, ...]
    run: bool | float = False
    initial: Callable | None = None
    end: tuple[float, float, float] | None = None  # (x, y, heading) m, m, rad where the plan leaves the
    # character at its last goal (a sequence's next segment starts there)


def walk_ahead(ctx: FootContext) -> StepPlan:
    """A walk straight ahead at the walk gait's speed for the whole scenario (the initial plan
    of a tackle or avoid target without a walk of its own)."""
    x, y, h = ctx.start
    u = np.array([math.cos(h), math.sin(h)])
    end = np.array([x, y]) + u * GAITS["walk"].cadence * GAITS["walk"].step_length * ctx.duration
    return StepPlan(tuple(walk_footsteps((x, y), end, 0.0, ctx.duration, foot_length=ctx.foot_length)))


def plan_footsteps(goals, ctx: FootContext) -> StepPlan:
    """The footsteps of ``ctx.who``: its lowest-ranked goals plan them (every goal of that rank,
    in file order, by the first one's kind); standing on both feet when no goal has a say.
    When the lowest rank belongs to a kind that plans a time segment
    (``GoalRecord.sequence_span``: walk_to, jump, hop) and goals of another such kind are
    there too, they plan in time order (:func:`plan_sequence`: a run-up, a leap, a run on)."""
    ranked = [(g.step_rank(ctx.who), i, g) for i, g in enumerate(goals)]
    ranked = [r for r in ranked if r[0] is not None]
    if not ranked:
        return StepPlan(tuple(standing_footsteps(ctx.start, 0.0, ctx.duration, ctx.foot_length)))
    rank, _, first = min(ranked, key=lambda r: (r[0], r[1]))
    seq = [r for r in ranked if r[2].sequence_span() is not None]
    if first.sequence_span() is not None and len({k for k, _, _ in seq}) > 1:
        return plan_sequence([g for _, _, g in seq], ctx)
    plan = type(first).plan_steps([g for k, _, g in ranked if k == rank], ctx)
    return StepPlan(tuple(sorted(plan.steps, key=lambda f: (f.t0, f.foot))), plan.run, plan.initial, plan.end)


SEAM_SAME_PLACE = 0.05  # m: two stances of one foot meeting at a seam are one stance when this close
SEAM_SWING_MIN = 0.15  # s: a foot lifted elsewhere comes down at the next segment's first stance no sooner


def _delayed(st: Footstep, t0: float) -> Footstep:
    """``st`` beginning at ``t0`` (s) instead, its heel and ball contact times kept (clipped)."""
    def rel(part):
        if part is None:
            return None
        a, b = _part_abs(st, part)
        a = max(a, t0)
        return None if b <= a else ((a - t0) / (st.t1 - t0), (b - t0) / (st.t1 - t0))
    return replace(st, t0=float(t0), heel=rel(st.heel), ball=rel(st.ball))


def _part_abs(st: Footstep, part):
    return None if part is None else (st.t0 + part[0] * (st.t1 - st.t0), st.t0 + part[1] * (st.t1 - st.t0))


def _merge(a: Footstep, b: Footstep) -> Footstep:
    """One stance from two stances of a foot that meet in time at one place (``a`` ends where
    ``b`` begins): heel and ball contact intervals joined where they touch at the seam (else
    the later one's); position, heading and bounds of the held one (a leap's) if one is held."""
    t0, t1 = a.t0, b.t1

    def joined(pa, pb):
        if pa is not None and pb is not None and pa[1] >= a.t1 - 1e-6 and pb[0] <= b.t0 + 1e-6:
            return (pa[0], pb[1])
        return pb if pb is not None else pa

    def rel(iv):
        return None if iv is None else ((iv[0] - t0) / (t1 - t0), (iv[1] - t0) / (t1 - t0))
    held = b if not b.free else a
    return Footstep(b.foot, held.position, t0, t1, held.heading,
                    heel=rel(joined(_part_abs(a, a.heel), _part_abs(b, b.heel))),
                    ball=rel(joined(_part_abs(a, a.ball), _part_abs(b, b.ball))), free=a.free and b.free,
                    bounds=held.bounds)


def join_at_seam(before: list, after: list, t: float, where: str) -> list:
    """Footsteps of two consecutive segments joined at the seam time ``t`` (s): a foot planted
    across the seam (a stance of ``before`` ending at ``t`` and one of ``after`` beginning at
    ``t``) becomes one stance when both are at one place; a foot lifted elsewhere less than
    SEAM_SWING_MIN before its next stance comes down SEAM_SWING_MIN after the lift; any other
    overlap in time of one foot's stances is an InputError located at ``where`` (the later
    segment's first goal)."""
    from scenarios.errors import InputError, Location
    out = list(before)
    for st in sorted(after, key=lambda f: f.t0):
        prev = [k for k, f in enumerate(out) if f.foot == st.foot and f.t1 > st.t0 - 1e-6]
        if not prev:
            lifted = [f.t1 for f in out if f.foot == st.foot and math.dist(f.position, st.position) > SEAM_SAME_PLACE]
            if lifted and st.t0 < max(lifted) + SEAM_SWING_MIN and st.t1 - (max(lifted) + SEAM_SWING_MIN) >= 0.1:
                st = _delayed(st, max(lifted) + SEAM_SWING_MIN)  # time to swing the foot over
            out.append(st)
            continue
        k = prev[-1]
        a = out[k]
        seam = abs(a.t1 - t) < 1e-6 and abs(st.t0 - t) < 1e-6
        if len(prev) == 1 and seam and math.dist(a.position, st.position) <= SEAM_SAME_PLACE:
            out[k] = _merge(a, st)
            continue
        raise InputError(f"the {st.foot} foot is planned twice over {max(a.t0, st.t0):.3g}–{min(a.t1, st.t1):.3g} s: "
                         f"at ({a.position[0]:.3g}, {a.position[1]:.3g}) by the goal before and at "
                         f"({st.position[0]:.3g}, {st.position[1]:.3g}) by this one (a walk must arrive where the "
                         "leap takes off, facing its way; a walk after a landing must leave in the landing's "
                         "direction)", Location(field=where))
    return out


def plan_sequence(goals: list, ctx: FootContext) -> StepPlan:
    """Footsteps of ``ctx.who`` planned by goals of several kinds in time order (thesis ch. 3:
    run up, leap, land, run on).  ``GoalRecord.sequence_span`` gives each goal's (begins or
    None, ends, hands off) s; consecutive goals of one rank form a segment planned by their
    kind over [previous hand-off, its last hand-off] (the last segment: to the scenario's end)
    from where the previous segment left the character (``StepPlan.end``); the segments'
    footsteps are joined at the seams (:func:`join_at_seam`); a walk followed by a goal with a
    ``sequence_entry`` (a leap's take-off) plans its footsteps to end there (its pelvis spring
    keeps the walk's own target).  The initial motion is the gait
    generator's over all footsteps, with each segment's own initial motion (a leap's) blended
    in over its segment (:func:`blend_initial`)."""
    order = sorted(goals, key=lambda g: (g.sequence_span()[1], g.step_rank(ctx.who)))
    segments: list[list] = []
    for g in order:
        if segments and segments[-1][0].step_rank(ctx.who) == g.step_rank(ctx.who):
            segments[-1].append(g)
        else:
            segments.append([g])
    steps: list[Footstep] = []
    start, t0, run, pieces = ctx.start, 0.0, False, []
    for i, seg in enumerate(segments):
        last = i == len(segments) - 1
        t1 = ctx.duration if last else max(g.sequence_span()[2] for g in seg)
        entry = None if last else segments[i + 1][0].sequence_entry()
        if entry is not None and hasattr(seg[-1], "target"):  # a walk's footsteps end where the leap takes off
            seg = seg[:-1] + [replace(seg[-1], target=entry)]
        sub = replace(ctx, start=start, t0=t0, duration=t1, change=None)
        plan = type(seg[0]).plan_steps(seg, sub)
        mine = [f for f in plan.steps if f.t1 > t0 + 1e-6]
        steps = join_at_seam(steps, mine, t0, seg[0].where) if i else list(mine)
        if plan.initial is not None:
            pieces.append((t0, t1, plan.initial))
        run = run or bool(plan.run)
        if plan.end is None:
            raise ValueError(f"{seg[0].kind} plans no end pose for a sequence")
        start, t0 = plan.end, t1
    steps.sort(key=lambda f: (f.t0, f.foot))
    return StepPlan(tuple(steps), run, initial=lambda ch: blend_initial(ch, tuple(steps), ctx.duration, pieces, run),
                    end=start)


SEQUENCE_BLEND = (0.15, 0.3)  # s: a segment's own initial motion fades in over this before its start and out
# over this after its end


def blend_initial(ch, steps: tuple, T: float, pieces: list, run: bool):
    """The gait generator's initial motion over [0, T] s for ``steps``, with each piece
    (t0, t1, motion of ch) faded in over SEQUENCE_BLEND[0] s before t0 and out over
    SEQUENCE_BLEND[1] s after t1 (smoothstep weights), sampled at 120 Hz and refitted."""
    from scenegraph.model.gait import initial_motion
    from scenegraph.model.motion import Motion
    base = initial_motion(ch, steps, 0.0, T, run=run)
    t = np.linspace(0.0, T, max(8, int(T * 120) + 1))
    q = base.at(t)[0]
    for a, b, make in pieces:
        m = make(ch)
        qa = m.at(np.clip(t, m.start, m.end))[0]
        up = np.ones_like(t) if a <= 1e-9 else np.clip((t - (a - SEQUENCE_BLEND[0])) / SEQUENCE_BLEND[0], 0.0, 1.0)
        down = np.ones_like(t) if b >= T - 1e-9 else np.clip(1.0 - (t - b) / SEQUENCE_BLEND[1], 0.0, 1.0)
        w = np.minimum(up, down)
        w = (w * w * (3 - 2 * w))[:, None]
        q = (1 - w) * q + w * qa
    return Motion.from_samples(t, q, base.n_ctrl)
