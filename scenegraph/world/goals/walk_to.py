"""``walk_to``: the pelvis reaches a point by a time; footprints are chosen by the optimisation.

Scene: free footsteps along the path (``scenegraph.model.footsteps``; built in ``build_scene``),
then standing on the target, facing ``heading``.  Solver: a pelvis spring toward (x, y, z)
at ``time`` (z: the pelvis height of the current motion).  Measure: the horizontal pelvis
distance from the target at ``time`` (m), within ``tolerance``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenegraph.model.footsteps import gait_footsteps, standing_footsteps, walk_footsteps
from scenegraph.problem import HandleTarget
from scenegraph.world.footplan import RANK_WALK, StepPlan
from scenegraph.world.goals.base import GoalRecord, Marker, where_of
from scenegraph.world.measure import handle_track

__all__ = ["WalkTo"]


@dataclass(frozen=True, kw_only=True)
class WalkTo(GoalRecord):
    """target: (x, y) m; heading: rad or None (final facing); waypoints: (x, y) m passed on the way."""

    kind = "walk_to"
    target: tuple[float, float]
    heading: float | None = None
    waypoints: tuple[tuple[float, float], ...] = ()

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "WalkTo":
        return cls(name=name, character=g.character, time=float(g.time), tolerance=float(g.tolerance),
                   where=where_of(scn, ("goals", j), name),
                   target=(float(g.target[0]), float(g.target[1])),
                   heading=None if g.heading is None else math.radians(g.heading),
                   waypoints=tuple((float(w[0]), float(w[1])) for w in g.waypoints))

    def step_rank(self, who: str) -> int | None:
        return RANK_WALK if who == self.character else None

    def sequence_span(self) -> tuple[None, float, float]:
        """A walk begins when the goal before it hands off and hands off on arrival."""
        return (None, float(self.time), float(self.time))

    @classmethod
    def plan_steps(cls, goals: list, ctx) -> StepPlan:
        """Free footsteps along each walk's legs (start → waypoints → target) in time order,
        each leg's time in proportion to its length, in the character's gait (through its gait
        change, if any); then standing at the last target for the rest of the scenario, facing
        the last walk's ``heading`` or else the direction from the start.  In a sequence
        (``ctx.t0``, ``ctx.first``) the walk starts at ``ctx.start`` at ``ctx.t0`` s."""
        steps, p, t = [], ctx.start[:2], float(ctx.t0)
        change, before = ctx.change, ctx.gait
        for g in sorted(goals, key=lambda g: g.time):
            pts = list(g.waypoints) + [g.target]
            legs = [(np.asarray(a, float), np.asarray(b, float)) for a, b in zip([p] + pts[:-1], pts)]
            lens = np.array([np.linalg.norm(b - a) for a, b in legs])
            total = max(float(lens.sum()), 1e-9)
            for (a, b), ln in zip(legs, lens):
                dt = (g.time - t) * ln / total if total > 1e-6 else (g.time - t) / len(legs)
                if dt <= 1e-6:
                    continue
                first = (ctx.first or "r") if not steps else ("l" if steps[-1].foot == "r" else "r")
                if change is not None and t - 1e-6 <= change[0] <= t + dt + 1e-6:
                    steps += gait_footsteps(a, b, t, t + dt, change, foot_length=ctx.foot_length, first=first,
                                            before=before)
                elif before == "run":
                    steps += gait_footsteps(a, b, t, t + dt, foot_length=ctx.foot_length, first=first, before="run")
                else:
                    steps += walk_footsteps(a, b, t, t + dt, foot_length=ctx.foot_length, first=first)
                t += dt
            p = g.target
        last = max(goals, key=lambda g: g.time)
        h = math.atan2(*(np.asarray(p) - np.asarray(ctx.start[:2]))[::-1]) if last.heading is None \
            else last.heading
        if t < ctx.duration - 1e-6:
            steps += standing_footsteps((p[0], p[1], h), t, ctx.duration, ctx.foot_length)
        if steps and len(legs) and last.heading is None:  # the facing of the last leg
            d = np.asarray(legs[-1][1]) - np.asarray(legs[-1][0])
            h = math.atan2(d[1], d[0]) if np.linalg.norm(d) > 1e-6 else h
        return StepPlan(tuple(steps), before == "run" and change is None, end=(float(p[0]), float(p[1]), float(h)))

    def targets(self, scene, me, weight, window, hard: bool = False) -> list:
        z = float(handle_track(me, "pelvis", [self.time])[0][2])
        return [HandleTarget("pelvis", self.time, (self.target[0], self.target[1], z), weight, hard=hard,
                             name=f"goal:{self.name}")]

    def entry(self, scene, audits) -> dict:
        p = handle_track(scene.character(self.character), "pelvis", [self.time])[0]
        d = float(np.hypot(p[0] - self.target[0], p[1] - self.target[1]))
        return self._entry(d, "horizontal pelvis distance from the target at the time")

    def markers(self) -> list[Marker]:
        return [(f"goal_{self.name}", (self.target[0], self.target[1], 0.05), 0.08)]
