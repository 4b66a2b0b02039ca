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

from scenegraph.world.measure import handle_track
from scenegraph.problem import HandleTarget
from scenegraph.world.goals.base import GoalRecord, Marker, where_of

__all__ = ["WalkTo"]


@dataclass(frozen=True, kw_only=True)
class WalkTo(GoalRecord):
    """target: (x, y) m; heading: rad or None (final facing)."""

    kind = "walk_to"
    target: tuple[float, float]
    heading: float | None = None

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "WalkTo":
        return cls(name=name, character=g.character, time=float(g.time), tolerance=float(g.tolerance),
                   where=where_of(scn, ("goals", j), name),
                   target=(float(g.target[0]), float(g.target[1])),
                   heading=None if g.heading is None else math.radians(g.heading))

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
