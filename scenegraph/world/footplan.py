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
from dataclasses import dataclass, field

import numpy as np

from scenegraph.model.footsteps import GAITS, Footstep, standing_footsteps, walk_footsteps

__all__ = ["FootContext", "StepPlan", "plan_footsteps", "walk_ahead", "RANK_FOOTPRINTS", "RANK_LEAP", "RANK_WALK",
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
    """

    who: str
    start: tuple[float, float, float]
    duration: float
    foot_length: float
    gait: str = "walk"
    change: tuple[float, float, str] | None = None
    placed: dict = field(default_factory=dict)
    starts: dict = field(default_factory=dict)


@dataclass(frozen=True)
class StepPlan:
    """Footsteps (sorted by start time) and how the initial motion moves: ``run`` False (walk),
    True (runs throughout) or a time (s) from which it runs; ``initial``: the initial motion as
    a function of the character, when the planner makes its own (else the gait generator's)."""

    steps: tuple[Footstep, ...]
    run: bool | float = False
    initial: Callable | None = None


def walk_ahead(ctx: FootContext) -> StepPlan:
    """A walk straight ahead at the walk gait's speed for the whole scenario (the initial plan
    of a tackle or avoid target without a walk of its own)."""
    x, y, h = ctx.start
    u = np.array([math.cos(h), math.sin(h)])
    end = np.array([x, y]) + u * GAITS["walk"].cadence * GAITS["walk"].step_length * ctx.duration
    return StepPlan(tuple(walk_footsteps((x, y), end, 0.0, ctx.duration, foot_length=ctx.foot_length)))


def plan_footsteps(goals, ctx: FootContext) -> StepPlan:
    """The footsteps of ``ctx.who``: its lowest-ranked goals plan them (every goal of that rank,
    in file order, by the first one's kind); standing on both feet when no goal has a say."""
    ranked = [(g.step_rank(ctx.who), i, g) for i, g in enumerate(goals)]
    ranked = [r for r in ranked if r[0] is not None]
    if not ranked:
        return StepPlan(tuple(standing_footsteps(ctx.start, 0.0, ctx.duration, ctx.foot_length)))
    rank, _, first = min(ranked, key=lambda r: (r[0], r[1]))
    plan = type(first).plan_steps([g for k, _, g in ranked if k == rank], ctx)
    return StepPlan(tuple(sorted(plan.steps, key=lambda f: (f.t0, f.foot))), plan.run, plan.initial)
