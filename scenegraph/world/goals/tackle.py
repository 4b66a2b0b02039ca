"""``tackle``: the attacker's chest front hits the target's torso at a time and speed.

Scene: the attacker runs at where the target is at the impact (``build_scene``); both are
solved by the decreasing-horizon schedule, who plans last wins.  Solver: soft springs from
the target's current motion (:func:`tackle_targets`), limited by the reaction time left in
the window (``measure.reach_budget``).  Measure: contact distance of the chest front from
the torso surface (|d| ≤ TACKLE_CONTACT_TOL) and closing speed (within ±TACKLE_SPEED_TOL of
``speed``, or ≥ ``min_speed``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenarios.weights import TARGET_WEIGHT

from scenegraph.model.footsteps import gait_footsteps
from scenegraph.problem import HandleTarget
from scenegraph.world.footplan import RANK_CHASE, RANK_WALK_AHEAD, StepPlan, walk_ahead
from scenegraph.world.goals.base import AdversarialGoal, where_of
from scenegraph.world.measure import body_frames, clamp, handle_track, horizontal_unit, ray_to_surface, tackle_measure

__all__ = ["Tackle", "tackle_targets", "tackle_entry", "TACKLE_CONTACT_TOL", "TACKLE_SPEED_TOL",
           "TACKLE_SPEED_LEAD"]

TACKLE_CONTACT_TOL = 0.05  # m: the tackler's chest front within this of the target's torso surface
TACKLE_SPEED_TOL = 0.10    # relative: closing speed within ±10 % of the goal speed
TACKLE_SPEED_LEAD = 0.1    # s: the speed is asked for as a chest position this long before the impact


def adversarial(g, entry: dict) -> dict:
    """The outcome fields every tackle/avoid entry carries: who plans last, whether this goal
    is expected to hold (its side plans last and wins by design), and a plain note."""
    expected = bool(g.expected_to_hold)
    entry.update({"plans_last": g.plans_last, "expected_to_hold": expected,
                  "note": (f"{g.character} plans last: expected to hold" if expected else
                           f"expected to FAIL by design: {g.plans_last} plans last and wins")})
    return entry


TOUCH_LEAD = 0.15  # s: a tackler's and its target's bodies may meet from this long before the hit


@dataclass(frozen=True, kw_only=True)
class Tackle(AdversarialGoal):
    """min_speed, speed: m/s (closing speed; ``speed`` None: at least min_speed); hands_around_torso."""

    kind = "tackle"
    min_speed: float = 2.0
    hands_around_torso: bool = True
    speed: float | None = None

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Tackle":
        return cls(name=name, character=g.attacker, partner=g.target, time=float(g.time),
                   tolerance=TACKLE_CONTACT_TOL, where=where_of(scn, ("goals", j), name), plans_last=plans_last,
                   min_speed=float(g.min_speed), hands_around_torso=bool(g.hands_around_torso),
                   speed=None if g.speed is None else float(g.speed))

    def springs(self, scene, me, budget: float, weight: float) -> list:
        return tackle_targets(scene, self, me, budget, weight)

    def touches(self) -> tuple[str, str]:
        return (self.character, self.partner)

    def touches_from(self) -> float:
        """The approach is kept apart until TOUCH_LEAD before the hit."""
        return self.time - TOUCH_LEAD

    def step_rank(self, who: str) -> int | None:
        """The attacker's run (2); the target walks straight ahead unless it walks (3)."""
        return RANK_CHASE if who == self.character else RANK_WALK_AHEAD if who == self.partner else None

    @classmethod
    def plan_steps(cls, goals: list, ctx) -> StepPlan:
        """The attacker: one run at constant speed from its start through a point 0.35 m short
        of where the target's chest is at the (first) impact — the target's initial plan, or
        its start when it is not built yet — kept up to the end of the scenario (a missed
        tackle does not stop dead).  The target: :func:`~scenegraph.world.footplan.walk_ahead`."""
        g = min(goals, key=lambda g: g.time)
        if ctx.who != g.character:
            return walk_ahead(ctx)
        other = ctx.placed.get(g.partner)
        aim = handle_track(other, "chest", [g.time])[0][:2] if other is not None else \
            np.asarray(ctx.starts[g.partner], float)
        s = np.asarray(ctx.start[:2])
        d = aim - s
        stop = aim - d / max(np.linalg.norm(d), 1e-6) * 0.35
        end = s + (stop - s) * ctx.duration / max(g.time, 1e-6)
        return StepPlan(tuple(gait_footsteps(s, end, 0.0, ctx.duration, foot_length=ctx.foot_length, before="run")),
                        True)

    def entry(self, scene, audits) -> dict:
        m = tackle_measure(scene.character(self.character), scene.character(self.partner), self.time)
        return tackle_entry(self, m)


def tackle_targets(scene, g: "Tackle", me, budget: float = np.inf,
                   weight: float = TARGET_WEIGHT) -> list[HandleTarget]:
    """Soft springs of a tackle for the attacker, from the target's current motion: the chest
    centre where its front touches the target's torso (on the side facing the attacker's
    approach), the chest TACKLE_SPEED_LEAD s earlier where the goal's closing speed puts it,
    and with ``hands_around_torso`` the palms beside and behind the target's chest.  When
    the chest would have to move more than ``budget`` (:func:`reach_budget`), every target is
    shifted back so that it moves by the budget."""
    hands = g.hands_around_torso
    goal_speed = float(g.speed) if g.speed is not None else 1.1 * float(g.min_speed)
    other = scene.character(g.partner)
    t, lead = g.time, TACKLE_SPEED_LEAD
    R, c = body_frames(other, "thorax", [t - 0.01, t])  # her velocity at the impact (as measured)
    my_then, my = handle_track(me, "chest", [max(t - 0.25, me.motion.start), t])
    u = horizontal_unit(c[1] - my_then)  # the approach direction (not the last instant's)
    u3, lat3 = np.r_[u, 0.0], np.r_[-u[1], u[0], 0.0]
    semi = other.character.body("thorax").semi_axes
    surf = ray_to_surface(R[1], c[1], semi, -u3)
    chest = surf - u3 * me.character.body("thorax").semi_axes[0]
    v_other = (c[1] - c[0]) / 0.01
    shift = clamp(my, chest, budget) - chest
    chest, c = chest + shift, c + shift
    out = [HandleTarget("chest", t, tuple(float(v) for v in chest), weight, name=f"goal:{g.name}")]
    for h in (lead, lead / 2):  # the approach at the goal's closing speed (two points: no last-instant lunge)
        before = chest - h * (goal_speed + float(np.dot(v_other, u3))) * u3
        out.append(HandleTarget("chest", t - h, tuple(float(v) for v in before), weight / 3,
                                name=f"goal:{g.name}"))
    if hands:  # palms on the target's flanks, a little behind her chest centre
        for side, sgn in (("l", 1.0), ("r", -1.0)):
            flank = ray_to_surface(R[1], c[1], semi, sgn * lat3)
            p = flank + sgn * lat3 * 0.03 + u3 * 0.06
            out.append(HandleTarget(f"palm_{side}", t, tuple(float(v) for v in p), weight / 3,
                                    name=f"goal:{g.name}"))
    return out


def tackle_entry(g: Tackle, m: dict) -> dict:
    """Report entry of a tackle goal from :func:`scenegraph.world.measure.tackle_measure` numbers.

    Holds when the attacker's contact point (front of its chest) is within the goal's
    tolerance (5 cm) of the target's torso surface (either side: touching, not buried) and
    the closing speed is within ±10 % of the goal's ``speed`` (or, without one, at least
    ``min_speed``).  The palms' distances from the torso are reported for the hands-around
    part (``hands_around_torso``), which does not decide ``holds``."""
    min_speed, hands, goal_speed = g.min_speed, g.hands_around_torso, g.speed
    d, v = m["contact_distance"], m["closing_speed"]
    contact_ok = abs(d) <= g.tolerance
    if goal_speed is not None:
        speed_ok = abs(v - goal_speed) <= TACKLE_SPEED_TOL * goal_speed
        speed_what = f"within ±{TACKLE_SPEED_TOL:.0%} of {goal_speed:g} m/s"
    else:
        speed_ok = v >= min_speed
        speed_what = f">= min_speed {min_speed:g} m/s"
    palms = m["palm_distances"]
    return adversarial(g, {
        "type": g.type,
        "what": "distance of the attacker's contact point (front of its chest) from the target's torso "
                f"surface at the impact (|d| <= tolerance), and closing speed {speed_what}",
        "measured": abs(d), "tolerance": g.tolerance, "unit": "m",
        "contact_distance": d, "contact_holds": bool(contact_ok),
        "speed": v, "closing_speed": v, "goal_speed": goal_speed, "min_speed": min_speed,
        "speed_tolerance": TACKLE_SPEED_TOL * goal_speed if goal_speed is not None else None,
        "speed_holds": bool(speed_ok),
        "chest_to_chest": m["chest_to_chest"], "contact_point": m["contact_point"],
        "hands_around_torso": bool(hands), "palm_torso_distances": palms,
        "holds": bool(contact_ok and speed_ok), "where": g.where})
