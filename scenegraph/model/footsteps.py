"""Footsteps: where and when a foot is planted (thesis Eq. 6.2), and the one generator of
footstep plans (walks, runs, gait changes, standing), with one foot width FOOT_WIDTH.

A footstep plants one foot over a world-time interval.  During the first part of the
stance the heel touches the ground, later the ball; fractions of the stance say when.
The planted point is ``position`` (x, y of the ball handle, m) with the foot's ``heading``
(rad, yaw of the foot's long axis); the heel lies behind the ball along that heading.
``free`` lets the solver move the position.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from scenegraph.model.body import Character

__all__ = ["Footstep", "contact_points", "WALK_HEEL", "WALK_BALL", "RUN_BALL", "footsteps_for_walk", "Gait",
           "GAITS", "CADENCE", "STANCE_FRACTION", "FOOT_WIDTH", "foot_length", "gait_footsteps",
           "walk_footsteps", "standing_footsteps", "leap_footsteps", "LEAP_HEEL_LIFT", "LEAP_HEEL_DOWN", "HOP_SWAP",
           "planted_interval", "airborne_gaps"]

WALK_HEEL = (0.0, 0.6)   # heel on the ground during this part of the stance
WALK_BALL = (0.15, 1.0)  # ball on the ground during this part
RUN_BALL = (0.0, 1.0)
CADENCE = 1.85          # steps per second of generated walks
STANCE_FRACTION = 0.62  # stance / stride of generated walks (> 0.5: double support)
FOOT_WIDTH = 0.18       # m, lateral distance between the feet of every generated footstep plan
LEAP_HEEL_LIFT = 0.12  # s: before a jump's take-off the heel leaves the ground this long before the ball
LEAP_HEEL_DOWN = 0.05  # s: at a landing the heel meets the ground this long after the ball
HOP_SWAP = 0.3  # s: after a hop's landing the other foot comes down this long later (or half the stance)


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
    bounds: tuple[tuple[float, float], tuple[float, float]] | None = None  # a free ball position's
    # ((x_min, y_min), (x_max, y_max)) m; None: within 0.5 m of ``position`` (a jump's landing region)

    def __post_init__(self):
        if self.foot not in ("l", "r"):
            raise ValueError(f"foot must be 'l' or 'r', not {self.foot!r}")
        if not self.t1 > self.t0:
            raise ValueError(f"footstep interval must be positive, got [{self.t0}, {self.t1}]")


def contact_points(ch: Character, step: Footstep, position=None,
                   ground=None) -> list[tuple[str, tuple[float, float], object]]:
    """[(handle, (t_from, t_to), target xy)] for the handles this footstep plants.

    ``position`` overrides the ball position (a numpy pair or a CasADi 2-vector).  On an
    inclined ``ground`` (:class:`~scenegraph.model.ground.Ground`) the heel lies a foot length
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


@functools.lru_cache(maxsize=16)
def planted_interval(step: Footstep) -> tuple[float, float]:
    """World s (first, last) instant at which any handle of ``step`` is planted."""
    parts = [p for p in (step.heel, step.ball) if p is not None]
    span = step.t1 - step.t0
    return step.t0 + min(p[0] for p in parts) * span, step.t0 + max(p[1] for p in parts) * span


def airborne_gaps(footsteps: tuple[Footstep, ...], min_gap: float = 1e-3) -> tuple[tuple[float, float], ...]:
    """World s (lift-off, touch-down) of every interval between two planted intervals of the
    plan in which no handle is planted — a running gait's flights.  The time before the first
    and after the last footstep is not included (a motion's ends are not flights of the plan);
    gaps shorter than ``min_gap`` s are contacts that merely touch."""
    spans = sorted(planted_interval(f) for f in footsteps)
    out, reach = [], None
    for a, b in spans:
        if reach is not None and a - reach > min_gap:
            out.append((reach, a))
        reach = b if reach is None else max(reach, b)
    return tuple(out)


def foot_length(ch: Character) -> float:
    """Heel-to-ball distance (m) of the character's foot (the ball handle's x minus the heel's)."""
    return float(ch.handle("ball_l").point[0] - ch.handle("heel_l").point[0])


def _part(frac, a, b, c, d):
    """Fractions of the clipped stance [c, d] during which the part (fractions of [a, b]) is down."""
    if frac is None:
        return None
    lo, hi = max(a + frac[0] * (b - a), c), min(a + frac[1] * (b - a), d)
    if hi - lo < 0.02:
        return None
    return (float((lo - c) / (d - c)), float((hi - c) / (d - c)))


@dataclass(frozen=True)
class Gait:
    """Timing and size of generated steps: steps per second, stance / stride, step length (m)."""

    cadence: float
    stance_fraction: float
    step_length: float
    heel: tuple[float, float] | None
    ball: tuple[float, float] | None


GAITS = {"walk": Gait(CADENCE, STANCE_FRACTION, 0.7, WALK_HEEL, WALK_BALL),
         "run": Gait(2.8, 0.38, 1.1, None, RUN_BALL)}


def gait_footsteps(start_xy, target_xy, t0: float, t1: float, change: tuple[float, float, str] | None = None,
                   *, width: float = FOOT_WIDTH, foot_length: float = 0.2, first: str = "r",
                   before: str = "walk") -> tuple[Footstep, ...]:
    """Free footsteps along start → target over [t0, t1] (world m, s) through a gait change.

    ``change`` = (time, blend, gait after) (s, s, name in GAITS): cadence, stance fraction and
    step length move from ``before``'s to the new gait's over [time − blend/2, time + blend/2]
    (smoothstep).  Stance k is centred where the step phase ∫ cadence dt reaches k; the
    pelvis advances in proportion to ∫ cadence · step length dt, scaled to reach the target
    at t1; each foot lands under it (± width/2).  A stance is a walk's (heel, then ball) or
    a run's (ball only, flight between stances) by which gait dominates at its middle.
    Without ``change`` the whole path uses ``before`` and every footstep is free; with it only
    the stances centred inside the blend are.
    """
    tc, blend, after = change or (t0, 0.0, before)
    g0, g1 = GAITS[before], GAITS[after]
    tt = np.linspace(t0, t1, 2001)
    w = np.clip((tt - (tc - blend / 2)) / max(blend, 1e-6), 0.0, 1.0)
    w = w * w * (3 - 2 * w)
    cad = g0.cadence + (g1.cadence - g0.cadence) * w
    sf = g0.stance_fraction + (g1.stance_fraction - g0.stance_fraction) * w
    speed = cad * (g0.step_length + (g1.step_length - g0.step_length) * w)
    dt = np.diff(tt)
    phase = np.r_[0.0, np.cumsum((cad[1:] + cad[:-1]) / 2 * dt)]
    dist_t = np.r_[0.0, np.cumsum((speed[1:] + speed[:-1]) / 2 * dt)]
    p0, p1 = np.asarray(start_xy, float), np.asarray(target_xy, float)
    d = p1 - p0
    u = d / max(float(np.linalg.norm(d)), 1e-9)
    lat = np.array([-u[1], u[0]])
    heading = math.atan2(u[1], u[0])
    steps = []
    for k in range(int(math.floor(phase[-1])) + 1):
        tm = float(np.interp(k, phase, tt))
        i = int(np.searchsorted(tt, tm).clip(0, len(tt) - 1))
        stance = 2 * sf[i] / cad[i]
        a, b = tm - stance / 2, tm + stance / 2
        c, e = max(a, t0), min(b, t1)
        this = first if k % 2 == 0 else ("l" if first == "r" else "r")
        pel = p0 + d * dist_t[i] / dist_t[-1]
        side = 1.0 if this == "l" else -1.0
        ball = pel + side * width / 2 * lat + u * foot_length / 2
        gg = g1 if w[i] >= 0.5 else g0
        heel, ballf = _part(gg.heel, a, b, c, e), _part(gg.ball, a, b, c, e)
        if e - c < 0.04 or (heel is None and ballf is None):
            continue
        # with a change, the footprints of the transition are placed by the solver; the
        # walk's before it and the run's after it keep their gaits' spacing and timing
        free = change is None or abs(tm - tc) <= blend / 2
        steps.append(Footstep(this, (float(ball[0]), float(ball[1])), float(c), float(e), heading,
                              heel=heel, ball=ballf, free=free))
    return tuple(steps)


def walk_footsteps(start_xy, target_xy, t0: float, t1: float, *, cadence: float = CADENCE,
                   stance_fraction: float = STANCE_FRACTION, width: float = FOOT_WIDTH, foot_length: float = 0.2,
                   free: bool = True, first: str = "r") -> tuple[Footstep, ...]:
    """Free footsteps along the straight line start → target over [t0, t1] (world m, s).

    The pelvis is assumed to move uniformly; each foot lands under it (± width/2) at the
    middle of its stance.  Stances that begin before t0 or end after t1 are clipped, and
    their heel/ball parts clipped with them.
    """
    p0, p1 = np.asarray(start_xy, float), np.asarray(target_xy, float)
    T = t1 - t0
    d = p1 - p0
    dist = float(np.linalg.norm(d))
    u = d / dist if dist > 1e-6 else np.array([1.0, 0.0])
    lat = np.array([-u[1], u[0]])
    heading = math.atan2(u[1], u[0])
    n = max(2, int(round(T * cadence)))
    period = T / n
    stance = 2 * period * stance_fraction
    steps = []
    for k in range(n + 1):  # stance k is centred at t0 + k * period; feet alternate
        this = first if k % 2 == 0 else ("l" if first == "r" else "r")
        tm = t0 + k * period
        a, b = tm - stance / 2, tm + stance / 2
        c, e = max(a, t0), min(b, t1)
        pel = p0 + d * (tm - t0) / T
        side = 1.0 if this == "l" else -1.0
        ball = pel + side * width / 2 * lat + u * foot_length / 2
        heel = _part(WALK_HEEL, a, b, c, e)
        ballf = _part(WALK_BALL, a, b, c, e)
        if e - c < 0.04 or (heel is None and ballf is None):
            continue
        steps.append(Footstep(this, (float(ball[0]), float(ball[1])), float(c), float(e), heading,
                              heel=heel, ball=ballf, free=free))
    return tuple(steps)


def standing_footsteps(start, t0: float, t1: float, foot_length: float, width: float = FOOT_WIDTH):
    x, y, h = start
    u, lat = np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])
    out = []
    for foot, side in (("l", 1.0), ("r", -1.0)):
        ball = np.array([x, y]) + side * width / 2 * lat + u * foot_length / 2
        out.append(Footstep(foot, (float(ball[0]), float(ball[1])), t0, t1, h, heel=(0.0, 1.0), ball=(0.0, 1.0)))
    return tuple(out)




def footsteps_for_walk(n_steps: int = 4, step_length: float = 0.7, cadence: float = CADENCE,
                       stance_fraction: float = STANCE_FRACTION, width: float = FOOT_WIDTH, start: float = 0.0,
                       first: str = "r", gait: str = "walk") -> tuple[Footstep, ...]:
    """A straight walk (or run) along +X: ``n_steps`` alternating fixed footsteps (m, s), the
    first ball at x = 0.1 m.

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


# --- jumps and hops (scenegraph/model/leaps.py: the stages) ---------------------------------------

def _feet(P, heading: float, foot_length: float, foot: str | None) -> dict[str, tuple[float, float]]:
    """Ball positions (x, y) of the feet standing around P (a jump: the feet midpoint; a hop:
    the hopping foot's heel-ball midpoint, the other foot FOOT_WIDTH to its side)."""
    u = np.array([math.cos(heading), math.sin(heading)])
    lat = np.array([-u[1], u[0]])
    P = np.asarray(P, float)
    out = {}
    for f, side in (("l", 1.0), ("r", -1.0)):
        if foot is None:
            c = P + side * FOOT_WIDTH / 2 * lat
        elif f == foot:
            c = P
        else:
            c = P + (FOOT_WIDTH if foot == "r" else -FOOT_WIDTH) * lat
        b = c + u * foot_length / 2
        out[f] = (float(b[0]), float(b[1]))
    return out


def _bounds(region, offset) -> tuple[tuple[float, float], tuple[float, float]]:
    """Bounds of a ball position whose feet midpoint lies in ``region`` ((x0, y0), (x1, y1))."""
    (x0, y0), (x1, y1) = region
    return ((x0 + offset[0], y0 + offset[1]), (x1 + offset[0], y1 + offset[1]))


def _stance(foot, heading, t0, t1, *, lift: bool, land: bool, free=False, bounds=None, ball_xy=None):
    """One leap stance: heel down LEAP_HEEL_DOWN after the ball at a landing, up LEAP_HEEL_LIFT
    before a take-off."""
    span = t1 - t0
    a = min(LEAP_HEEL_DOWN / span, 0.3) if land else 0.0
    b = 1.0 - min(LEAP_HEEL_LIFT / span, 0.4) if lift else 1.0
    return Footstep(foot, ball_xy, float(t0), float(t1), float(heading), heel=(a, b), ball=(0.0, 1.0), free=free,
                    bounds=bounds)


def leap_footsteps(leaps, start, T: float, foot_length: float, t0: float = 0.0) -> tuple[Footstep, ...]:
    """Footsteps of a character that stands at ``start`` (x, y, heading; m, rad) from ``t0`` s
    and leaps ``leaps`` (Jump records in time order) within [t0, T] s."""
    steps: list[Footstep] = []
    P, h = (start[0], start[1]), start[2]
    t_prev, prev_foot, prev_region = float(t0), None, None  # start: standing on both feet
    seq = list(leaps) + [None]
    for k, lp in enumerate(seq):
        t_end = lp.t_off if lp is not None else T
        if lp is not None:  # the take-off stance: where the leap's take-off says (default: where it stands)
            P = lp.takeoff
        feet_next = ("l", "r") if lp is None or lp.foot is None else (lp.foot,)
        down = ("l", "r") if prev_foot is None else (prev_foot,)
        balls = _feet(P, h, foot_length, prev_foot)
        for f in ("l", "r"):
            on_from = t_prev if f in down else None
            if on_from is None and (f in feet_next or lp is None):  # the other foot comes down after a hop
                on_from = t_prev + min(HOP_SWAP, (t_end - t_prev) / 2)
            if on_from is None:
                continue
            off_at = t_end
            if lp is not None and f not in feet_next:  # lifts before a hop on the other foot
                off_at = on_from + (t_end - on_from) / 2
            if off_at - on_from < 0.05:
                continue
            bounds = None
            if prev_region is not None:
                mid = np.asarray(balls[f]) - np.asarray(P)
                bounds = _bounds(prev_region, mid)
            steps.append(_stance(f, h, on_from, off_at, lift=lp is not None and f in feet_next,
                                 land=k > 0 and f in down, free=bounds is not None, bounds=bounds,
                                 ball_xy=balls[f]))
        if lp is None:
            break
        P, h = lp.landing, lp.heading + lp.turn
        t_prev, prev_foot, prev_region = lp.t_land, lp.foot, lp.landing_region
    steps.sort(key=lambda f: (f.t0, f.foot))
    return tuple(steps)
