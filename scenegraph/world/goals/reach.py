"""``reach``: a handle at a point at a time.

Solver: a spring of the Step's weight pulling the handle to the point at ``time``.
Measure: the handle's distance from the point at ``time`` (m), within ``tolerance``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenegraph.world.measure import handle_track
from scenegraph.problem import HandleTarget
from scenegraph.world.goals.base import GoalRecord, Marker, where_of

__all__ = ["Reach"]


@dataclass(frozen=True, kw_only=True)
class Reach(GoalRecord):
    """handle: a handle name; point: (x, y, z) m, world."""

    kind = "reach"
    handle: str
    point: tuple[float, float, float]

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Reach":
        return cls(name=name, character=g.character, time=float(g.time), tolerance=float(g.tolerance),
                   where=where_of(scn, ("goals", j), name), handle=g.handle,
                   point=tuple(float(v) for v in g.target))

    def targets(self, scene, me, weight, window, hard: bool = False) -> list:
        return [HandleTarget(self.handle, self.time, self.point, weight, hard=hard, name=f"goal:{self.name}")]

    def entry(self, scene, audits) -> dict:
        p = handle_track(scene.character(self.character), self.handle, [self.time])[0]
        d = float(np.linalg.norm(p - np.asarray(self.point)))
        return self._entry(d, f"{self.handle} distance from the target at the time")

    def markers(self) -> list[Marker]:
        return [(f"goal_{self.name}", self.point, 0.04)]
