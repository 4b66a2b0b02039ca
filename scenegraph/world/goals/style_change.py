"""``style_change``: switch a character's style at a time (θ blended across the transition),
optionally with a gait change of its generated footsteps (walk → run).

Plan: the compiler's style timeline (``schedules.plan.step.StyleTimeline``).  Scene: with a gait,
the footsteps change cadence, stance and step length over the blend (``build_scene``), and
the timewarp is held (the plan times the walk and the run).  Measure (thesis §6.4.2, with a
gait): the speed reached over the last stride (at least SPEED_FRACTION of the new gait's
cadence × step length), the forward lean and the pelvis dip of the transition
(:func:`transition_measures`; world frame, z up, m, s, degrees).  Without a gait: the style
timeline was applied (always holds).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenegraph.model.footsteps import GAITS
from scenegraph.world.measure import handle_track
from scenegraph.world.goals.base import GoalRecord, where_of

__all__ = ["StyleChange", "transition_measures", "SPEED_FRACTION", "DEFAULT_BLEND"]

DEFAULT_BLEND = 0.6  # s: blend of a gait change's footsteps without ``blend``

SPEED_FRACTION = 0.9  # the transition holds when the final stride's speed ≥ this × the gait's speed
HZ = 60.0


def _lean_deg(pelvis: np.ndarray, chest: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Forward lean of the pelvis→chest line from vertical (deg, positive = toward ``heading``)."""
    d = chest - pelvis
    fwd = d[:, :2] @ heading
    return np.degrees(np.arctan2(fwd, d[:, 2]))


def transition_measures(state, t_change: float, blend: float, gait: str,
                        t_end: float) -> dict:
    """Speed reached, lean and dip of a gait change at ``t_change`` (s) blended over ``blend`` s.

    * ``speed``: mean horizontal pelvis speed over the last stride (two steps of the new
      gait) before ``t_end``; ``target_speed`` = cadence × step length of the new gait.
    * ``lean_before_deg`` / ``lean_during_deg``: mean forward trunk lean over the stride
      before the transition and its maximum between the start of the transition and the
      time the speed first reaches ``SPEED_FRACTION`` of the target.
    * ``dip_m``: how far the pelvis drops below its mean height over the stride before the
      transition, in that same interval.
    """
    g = GAITS[gait]
    target = g.cadence * g.step_length
    stride = 2.0 / g.cadence
    t0 = state.motion.start
    t = np.arange(t0, t_end + 1e-9, 1.0 / HZ)
    pel = handle_track(state, "pelvis", t)
    chest = handle_track(state, "chest", t)
    v = np.gradient(pel[:, :2], t, axis=0)
    speed_t = np.linalg.norm(v, axis=1)
    last = t >= t_end - stride
    span = pel[last][-1, :2] - pel[last][0, :2]
    speed = float(np.linalg.norm(span) / max(t[last][-1] - t[last][0], 1e-9))
    heading = span / max(float(np.linalg.norm(span)), 1e-9)
    lean = _lean_deg(pel, chest, heading)
    a = t_change - blend / 2.0
    before = (t >= max(t0, a - stride)) & (t < a)
    if not before.any():
        before = t < a + 1e-9
    # smooth the speed over a step before asking when it reaches the target
    k = max(1, int(round(HZ / g.cadence)))
    smooth = np.convolve(speed_t, np.ones(k) / k, mode="same")
    reached = np.nonzero((t >= a) & (smooth >= SPEED_FRACTION * target))[0]
    t_reach = float(t[reached[0]]) if reached.size else float(t_end)
    during = (t >= a) & (t <= t_reach)
    if not during.any():
        during = t >= a
    return {
        "speed": speed, "target_speed": float(target), "speed_fraction": speed / target,
        "reached_at": t_reach if reached.size else None,
        "lean_before_deg": float(lean[before].mean()), "lean_during_deg": float(lean[during].max()),
        "dip_m": float(pel[before, 2].mean() - pel[during, 2].min()),
        "holds": bool(speed >= SPEED_FRACTION * target),
    }


@dataclass(frozen=True, kw_only=True)
class StyleChange(GoalRecord):
    """style: the new style reference; gait: "walk" | "run" | None; blend: s or None."""

    kind = "style_change"
    style: str
    gait: str | None = None
    blend: float | None = None

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "StyleChange":
        return cls(name=name, character=g.character, time=float(g.time), tolerance=0.0,
                   where=where_of(scn, ("goals", j), name), style=g.style, gait=g.gait,
                   blend=None if g.blend is None else float(g.blend))

    def gait_change(self, who: str) -> tuple[float, float, str] | None:
        if self.gait is None or who != self.character:
            return None
        return (float(self.time), float(self.blend or DEFAULT_BLEND), self.gait)

    def entry(self, scene, audits) -> dict:
        if self.gait is None:
            return {"type": self.kind, "what": "style timeline applied (θ blended across the seam)",
                    "measured": None, "tolerance": None, "holds": True, "where": self.where}
        m = transition_measures(scene.character(self.character), self.time, float(self.blend or DEFAULT_BLEND),
                                self.gait, scene.duration)
        return {"type": self.kind, "what": f"mean pelvis speed over the last {self.gait} stride vs the "
                f"{self.gait}'s speed (cadence × step length); lean and dip of the transition",
                "measured": m["speed"], "tolerance": SPEED_FRACTION * m["target_speed"], "unit": "m/s (must be >=)",
                **{k: v for k, v in m.items() if k not in ("speed", "holds")}, "holds": m["holds"],
                "where": self.where}
