"""``avoid``: stay outside a sphere around another character's chest at a time.

Solver: soft escape springs on the pelvis and chest (:func:`avoid_targets`), sideways to
the other's approach, limited by the reaction time left (``measure.reach_budget``).
Measure: the clearance of my pelvis and chest from the other's chest at ``time`` (m), at
least ``radius``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenarios.weights import AVOID_WEIGHT

from scenegraph.problem import HandleTarget
from scenegraph.world.footplan import RANK_WALK_AHEAD, StepPlan, walk_ahead
from scenegraph.world.measure import avoid_measure, clamp, handle_track, horizontal_unit
from scenegraph.world.goals.base import AdversarialGoal, where_of
from scenegraph.world.goals.tackle import adversarial

__all__ = ["Avoid", "avoid_targets", "avoid_entry", "AVOID_MARGIN"]

AVOID_MARGIN = 0.25        # m: the escape target lies this far outside the avoided sphere (0.08 left
#                            tackle_dodge's learned-style target 0.34-0.45 m from a `run` tackler)


@dataclass(frozen=True, kw_only=True)
class Avoid(AdversarialGoal):
    """radius: m, around the other's chest."""

    kind = "avoid"
    default_weight = AVOID_WEIGHT
    radius: float

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Avoid":
        return cls(name=name, character=g.character, partner=g.around, time=float(g.time), tolerance=1e-3,
                   where=where_of(scn, ("goals", j), name), plans_last=plans_last, radius=float(g.radius))

    def springs(self, scene, me, budget: float, weight: float) -> list:
        return avoid_targets(scene, self, me, budget, weight)

    def step_rank(self, who: str) -> int | None:
        return RANK_WALK_AHEAD if who == self.character else None

    @classmethod
    def plan_steps(cls, goals: list, ctx) -> StepPlan:
        """The dodger without a walk of its own walks straight ahead (its initial plan)."""
        return walk_ahead(ctx)

    def entry(self, scene, audits) -> dict:
        return avoid_entry(self, avoid_measure(scene.character(self.character), scene.character(self.partner),
                                               self.time))


def avoid_targets(scene, g: "Avoid", me, budget: float = np.inf,
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
    v = horizontal_unit(centre - c0)
    perp = np.array([-v[1], v[0]])
    pel0, pel = handle_track(me, "pelvis", [max(t - 0.1, me.motion.start), t])
    off = float(np.dot(pel[:2] - centre[:2], perp))
    side = np.sign(off) if abs(off) > 0.02 else (np.sign(float(np.dot(pel[:2] - pel0[:2], perp))) or 1.0)
    u = np.r_[perp * side, 0.0]
    need = g.radius + AVOID_MARGIN
    out = []
    for hd in ("pelvis", "chest"):
        p = handle_track(me, hd, [t])[0]
        w = p - centre
        if float(np.linalg.norm(w)) >= need:
            continue
        # the smallest s >= 0 with |p + s u - centre| = need
        b = float(np.dot(w, u))
        s_ = -b + math.sqrt(max(b * b - (float(np.dot(w, w)) - need * need), 0.0))
        d = clamp(p, p + s_ * u, budget) - p
        out.append(HandleTarget(hd, float(t), tuple(float(x) for x in p + d), weight, name=f"goal:{g.name}"))
    return out


def avoid_entry(g: Avoid, clearance: float) -> dict:
    """Report entry of an avoid goal: clearance (closest of pelvis and chest to the other's
    chest) must be at least the sphere radius."""
    r = g.radius
    return adversarial(g, {"type": g.type, "what": "closest pelvis/chest distance to the other's chest",
                           "measured": clearance, "clearance": clearance, "tolerance": r, "radius": r,
                           "unit": "m (must be >=)", "holds": bool(clearance >= r - 1e-3), "where": g.where})
