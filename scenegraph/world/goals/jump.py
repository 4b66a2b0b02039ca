"""``jump`` and ``hop``: a ground stage, a flight stage, a ground stage (thesis ch. 3).

Scene: the leap's footsteps (both feet, or the hopping foot, planted at the take-off until
``t_off`` and at the landing from ``t_land``; a region gives a free footprint bounded by it)
and its flight (``scenegraph.model.leaps``); the solver holds the root residual at zero in flight
(the Step's ``flight:<name>=hard`` term), so the centre of mass is ballistic and the angular
momentum about it constant.  Solver targets: with ``obstacle_height`` h, springs pulling the
foot handles to h + OBSTACLE_MARGIN at mid-flight.  Measure: the distance of the landing feet's
midpoint (heel and ball handles, LAND_SETTLE after touch-down) from the landing position, or
from the region (0 inside), within ``tolerance``; the report adds the turn in the air
(pelvis yaw, landing − take-off, deg), the flight time and the foot clearance at mid-flight.

Units: m, s, rad (``turn``, ``heading``); times are world seconds of the initial motion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenegraph.model.footsteps import leap_footsteps
from scenegraph.model.leaps import leap_motion
from scenegraph.problem import HandleTarget
from scenegraph.world.footplan import RANK_LEAP, StepPlan
from scenegraph.world.goals.base import GoalRecord, Marker, where_of
from scenegraph.world.measure import handle_track

__all__ = ["Jump", "Hop", "OBSTACLE_MARGIN", "LAND_SETTLE"]

OBSTACLE_MARGIN = 0.05  # m: the feet aim this far above an obstacle at mid-flight
LAND_SETTLE = 0.1  # s: the landing is measured this long after touch-down (heels down)
FOOT_HANDLES = ("heel_l", "ball_l", "heel_r", "ball_r")


@dataclass(frozen=True, kw_only=True)
class Jump(GoalRecord):
    """takeoff/landing: (x, y) m (the feet midpoint; a hop: the foot's); *_region: ((x0, y0),
    (x1, y1)) or None; t_off/t_land: s; heading: take-off feet (rad); turn: rad in the air;
    foot: None (jump) or "l"/"r" (hop); obstacle_height: m or None."""

    kind = "jump"
    takeoff: tuple[float, float]
    landing: tuple[float, float]
    t_off: float
    t_land: float
    heading: float
    turn: float = 0.0
    foot: str | None = None
    takeoff_region: tuple | None = None
    landing_region: tuple | None = None
    obstacle_height: float | None = None

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Jump":
        from scenarios.schema import HopGoal, JumpGoal, WalkToGoal, leap_sequence
        c = scn.character(g.character)
        leaps = [(i, x) for i, x in enumerate(scn.goals) if isinstance(x, (JumpGoal, HopGoal))
                 and x.character == g.character]
        walks = [(i, x) for i, x in enumerate(scn.goals) if isinstance(x, WalkToGoal) and x.character == g.character]
        heading = math.radians(c.start.heading)
        for (i, x), (t0, t1), here, facing in leap_sequence(c, leaps, walks):
            if facing is not None:  # a walk before it: the take-off faces the walk's last leg
                heading = facing
            if i == j:
                break
            heading += math.radians(x.turn_deg)

        def reg(end):
            return None if end.region is None else (tuple(end.region.min), tuple(end.region.max))
        return cls(name=name, character=g.character, time=float(t1), tolerance=float(g.tolerance),
                   where=where_of(scn, ("goals", j), name), takeoff=g.takeoff.centre() or tuple(here),
                   landing=g.landing.centre(),
                   t_off=float(t0), t_land=float(t1), heading=heading, turn=math.radians(g.turn_deg),
                   foot=getattr(g, "foot", None), takeoff_region=reg(g.takeoff), landing_region=reg(g.landing),
                   obstacle_height=g.obstacle_height)

    @property
    def flight(self) -> tuple[float, float]:
        return (self.t_off, self.t_land)

    def step_rank(self, who: str) -> int | None:
        return RANK_LEAP if who == self.character else None

    def sequence_span(self) -> tuple[float, float, float]:
        """From LEAP_PUSH_MIN before the take-off to the landing; hands off LEAP_LAND_HOLD after it."""
        from scenarios.schema import LEAP_LAND_HOLD, LEAP_PUSH_MIN
        return (self.t_off - LEAP_PUSH_MIN, self.t_land, self.t_land + LEAP_LAND_HOLD)

    def sequence_entry(self) -> tuple[float, float]:
        return (float(self.takeoff[0]), float(self.takeoff[1]))

    @classmethod
    def plan_steps(cls, goals: list, ctx) -> StepPlan:
        """Ground and flight stages of every jump and hop of the character, in time order
        (:func:`scenegraph.model.footsteps.leap_footsteps`), with the leaping initial motion."""
        leaps = sorted(goals, key=lambda g: g.t_off)
        last = leaps[-1]
        return StepPlan(leap_footsteps(leaps, ctx.start, ctx.duration, ctx.foot_length, ctx.t0),
                        initial=lambda ch: leap_motion(ch, leaps, ctx.start, ctx.duration),
                        end=(float(last.landing[0]), float(last.landing[1]), float(last.heading + last.turn)))

    def _handles(self) -> tuple[str, ...]:
        return FOOT_HANDLES if self.foot is None else (f"heel_{self.foot}", f"ball_{self.foot}")

    def targets(self, scene, me, weight, window, hard: bool = False) -> list:
        if self.obstacle_height is None:
            return []
        tm = (self.t_off + self.t_land) / 2
        out = []
        for h in self._handles() if self.foot is None else FOOT_HANDLES:
            p = handle_track(me, h, [tm])[0]
            out.append(HandleTarget(h, tm, (float(p[0]), float(p[1]), self.obstacle_height + OBSTACLE_MARGIN),
                                    weight, hard=hard, name=f"goal:{self.name}"))
        return out

    def measures(self, me) -> dict:
        """landing (m), turn (deg), flight (s), clearance (m: lowest foot handle at mid-flight)."""
        t = min(self.t_land + LAND_SETTLE, me.motion.end)
        feet = np.array([handle_track(me, h, [t])[0] for h in self._handles()])
        mid = feet[:, :2].mean(axis=0)  # the heel/ball midpoint is the footprint's reference
        if self.landing_region is not None:
            (x0, y0), (x1, y1) = self.landing_region
            d = float(np.hypot(max(x0 - mid[0], 0.0, mid[0] - x1), max(y0 - mid[1], 0.0, mid[1] - y1)))
        else:
            d = float(np.hypot(*(mid - np.asarray(self.landing))))
        yaw = [float(me.motion.state_at_s(me.motion.to_canonical([x]))[0][0][3]) for x in (self.t_off, self.t_land)]
        tm = (self.t_off + self.t_land) / 2
        low = min(float(handle_track(me, h, [tm])[0][2]) for h in FOOT_HANDLES)
        return {"landing": d, "turn_deg": math.degrees(yaw[1] - yaw[0]), "flight_s": self.t_land - self.t_off,
                "clearance": low}

    def entry(self, scene, audits) -> dict:
        m = self.measures(scene.character(self.character))
        e = self._entry(m["landing"], "distance of the landing feet's midpoint from the landing position "
                                      f"(0 inside a region), {LAND_SETTLE:g} s after touch-down")
        e["turn_deg"] = {"asked": math.degrees(self.turn), "measured": m["turn_deg"]}
        e["flight_s"] = m["flight_s"]
        if self.obstacle_height is not None:
            e["clearance"] = {"obstacle": self.obstacle_height, "lowest_foot_mid_flight": m["clearance"]}
            e["holds"] = bool(e["holds"] and m["clearance"] >= self.obstacle_height)
        return e

    def markers(self) -> list[Marker]:
        return [(f"goal_{self.name}", (self.landing[0], self.landing[1], 0.02), 0.06)]


@dataclass(frozen=True, kw_only=True)
class Hop(Jump):
    """A hop: ``foot`` takes off and lands (see :class:`Jump`)."""

    kind = "hop"
