"""``footprints``: explicit footprints, hard constraints of every subproblem.

Scene: fixed footsteps (``build_scene``); the solver holds them as constraints (no targets).
Measure: the physics audit's largest distance of a planted handle from its footprint at
120 Hz (m), within FOOTPRINT_REPORT_TOL.
"""
from __future__ import annotations

from dataclasses import dataclass

from scenegraph.world.goals.base import GoalRecord, where_of

__all__ = ["Footprints", "FOOTPRINT_REPORT_TOL", "FOOTPRINT_SOLVER_TOL"]

FOOTPRINT_REPORT_TOL = 0.025  # m: report bound at 120 Hz (the solver holds them exactly at its points)
FOOTPRINT_SOLVER_TOL = 2e-3  # m


@dataclass(frozen=True, kw_only=True)
class Footprints(GoalRecord):
    kind = "footprints"

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Footprints":
        return cls(name=name, character=g.character, time=None, tolerance=FOOTPRINT_SOLVER_TOL,
                   where=where_of(scn, ("goals", j), name))

    def entry(self, scene, audits) -> dict:
        val = (audits or {}).get(self.character, {}).get("footstep_error_max")
        e = self._entry(val, "max distance of a planted handle from its footprint, sampled at 120 Hz "
                             "(solver enforces it exactly at collocation points)",
                        holds=bool(val is not None and val <= FOOTPRINT_REPORT_TOL))
        e["tolerance"] = FOOTPRINT_REPORT_TOL
        return e
