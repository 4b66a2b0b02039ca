"""``footprints``: explicit footprints, hard constraints of every subproblem.

Scene: fixed footsteps (``build_scene``); the solver holds them as constraints (no targets).
Measure: the physics audit's largest distance of a planted handle from its footprint at
120 Hz (m), within FOOTPRINT_REPORT_TOL.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scenegraph.model.footsteps import Footstep
from scenegraph.world.footplan import RANK_FOOTPRINTS, StepPlan
from scenegraph.world.goals.base import GoalRecord, where_of

__all__ = ["Footprints", "FOOTPRINT_REPORT_TOL", "FOOTPRINT_SOLVER_TOL"]

FOOTPRINT_REPORT_TOL = 0.025  # m: report bound at 120 Hz (the solver holds them exactly at its points)
FOOTPRINT_SOLVER_TOL = 2e-3  # m


@dataclass(frozen=True, kw_only=True)
class Footprints(GoalRecord):
    """steps: (foot "l"|"r", (x, y) m midpoint of heel and ball, (t0, t1) s, heading rad or None)."""

    kind = "footprints"
    steps: tuple[tuple[str, tuple[float, float], tuple[float, float], float | None], ...] = ()

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Footprints":
        steps = tuple((fp.foot, (float(fp.position[0]), float(fp.position[1])), (float(fp.time[0]), float(fp.time[1])),
                       None if fp.heading is None else math.radians(fp.heading)) for fp in g.steps)
        return cls(name=name, character=g.character, time=None, tolerance=FOOTPRINT_SOLVER_TOL,
                   where=where_of(scn, ("goals", j), name), steps=steps)

    def step_rank(self, who: str) -> int | None:
        return RANK_FOOTPRINTS if who == self.character else None

    @classmethod
    def plan_steps(cls, goals: list, ctx) -> StepPlan:
        """The written footprints (headings default to the start heading); a footprint gives
        the midpoint of heel and ball, a Footstep the ball."""
        out = []
        for g in goals:
            for foot, (x, y), (t0, t1), heading in g.steps:
                h = ctx.start[2] if heading is None else heading
                ball = (x + ctx.foot_length / 2 * math.cos(h), y + ctx.foot_length / 2 * math.sin(h))
                out.append(Footstep(foot, (float(ball[0]), float(ball[1])), t0, t1, h))
        return StepPlan(tuple(out))

    def entry(self, scene, audits) -> dict:
        val = (audits or {}).get(self.character, {}).get("footstep_error_max")
        e = self._entry(val, "max distance of a planted handle from its footprint, sampled at 120 Hz "
                             "(solver enforces it exactly at collocation points)",
                        holds=bool(val is not None and val <= FOOTPRINT_REPORT_TOL))
        e["tolerance"] = FOOTPRINT_REPORT_TOL
        return e
