"""Footsteps: where and when a foot is planted (thesis Eq. 6.2).

A footstep plants one foot over a world-time interval.  During the first part of the
stance the heel touches the ground, later the ball; fractions of the stance say when.
The planted point is ``position`` (x, y of the ball handle, m) with the foot's ``heading``
(rad, yaw of the foot's long axis); the heel lies behind the ball along that heading.
``free`` lets the solver move the position.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .body import Character

__all__ = ["Footstep", "contact_points", "WALK_HEEL", "WALK_BALL", "RUN_BALL", "footsteps_for_walk"]

WALK_HEEL = (0.0, 0.6)   # heel on the ground during this part of the stance
WALK_BALL = (0.15, 1.0)  # ball on the ground during this part
RUN_BALL = (0.0, 1.0)


@dataclass(frozen=True)
class Footstep:
    foot: str  # "l" or "r"
    position: tuple[float, float]  # world x, y of the ball handle (m)
    t0: float  # start of stance (s, world time of the initial motion)
    t1: float  # end of stance (s)
    heading: float = 0.0  # rad
    heel: tuple[float, float] | None = WALK_HEEL
    ball: tuple[float, float] | None = WALK_BALL
    free: bool = False

    def __post_init__(self):
        if self.foot not in ("l", "r"):
            raise ValueError(f"foot must be 'l' or 'r', not {self.foot!r}")
        if not self.t1 > self.t0:
            raise ValueError(f"footstep interval must be positive, got [{self.t0}, {self.t1}]")


def contact_points(ch: Character, step: Footstep, position=None,
                   ground=None) -> list[tuple[str, tuple[float, float], object]]:
    """[(handle, (t_from, t_to), target xy)] for the handles this footstep plants.

    ``position`` overrides the ball position (a numpy pair or a CasADi 2-vector).  On an
    inclined ``ground`` (:class:`~scenegraph.ground.Ground`) the heel lies a foot length
    behind the ball *along the ground*, so its horizontal offset shrinks by the slope's
    cosine along the foot (the slope is taken at the footstep's nominal position).
    """
    pos = step.position if position is None else position
    heel_h, ball_h = ch.handle(f"heel_{step.foot}"), ch.handle(f"ball_{step.foot}")
    foot_len = ball_h.point[0] - heel_h.point[0]
    d = np.array([np.cos(step.heading), np.sin(step.heading)])
    if ground is not None and not ground.flat:
        rise = float(ground.gradient(*step.position) @ d)  # dz per m along the foot
        foot_len = foot_len / np.sqrt(1.0 + rise * rise)
    out = []
    span = step.t1 - step.t0
    if step.ball is not None:
        out.append((ball_h.name, (step.t0 + step.ball[0] * span, step.t0 + step.ball[1] * span), pos))
    if step.heel is not None:
        heel_xy = (pos[0] - foot_len * d[0], pos[1] - foot_len * d[1])
        out.append((heel_h.name, (step.t0 + step.heel[0] * span, step.t0 + step.heel[1] * span), heel_xy))
    return out


def footsteps_for_walk(n_steps: int = 4, step_length: float = 0.7, cadence: float = 1.85,
                       stance_fraction: float = 0.62, width: float = 0.17, start: float = 0.0,
                       first: str = "r", gait: str = "walk") -> tuple[Footstep, ...]:
    """A straight walk (or run) along +X: alternating footsteps (m, s).

    ``cadence`` is steps per second; one step later the other foot lands.  A stance lasts
    ``stance_fraction`` of a stride (two steps): > 0.5 gives double support (walk), < 0.5
    flight phases (run).
    """
    period = 1.0 / cadence
    stance = 2 * period * stance_fraction
    heel, ball = (WALK_HEEL, WALK_BALL) if gait == "walk" else (None, RUN_BALL)
    steps = []
    foot = first
    for i in range(n_steps):
        t0 = start + i * period
        y = width / 2 if foot == "l" else -width / 2
        steps.append(Footstep(foot, (0.1 + i * step_length, y), t0, t0 + stance, heel=heel, ball=ball))
        foot = "l" if foot == "r" else "r"
    return tuple(steps)
