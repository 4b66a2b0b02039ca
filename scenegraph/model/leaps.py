"""Jumps and hops as stages: ground contacts (footsteps), flights, and an initial motion.

A character's leaps (:class:`scenegraph.world.goals.jump.Jump` records, in time order) cut its
motion into stages (thesis §3.4): a ground stage before each take-off, a flight stage from
take-off to landing (no footstep: no contact force; the transcription makes the root
residual zero there, so the centre of mass falls with g and the angular momentum about it
is constant), and a ground stage after the landing.  This module turns the leaps into

* footsteps (:func:`scenegraph.model.footsteps.leap_footsteps`, the one footstep generator):
  both feet (a jump) or one foot (a hop) planted at the
  take-off until the take-off time, the heel lifting 0.12 s before it; planted at the
  landing from the landing time, ball first, heel 0.05 s later.  A region instead of a
  position gives a free footprint bounded by it (``Footstep.bounds``);
* flights (:func:`leap_flights`): (take-off, landing) world seconds;
* an initial motion (:func:`leap_motion`): a countermovement dip before the take-off, a
  ballistic pelvis parabola in flight (vertical speed g·t_f/2 at take-off), a landing dip,
  the heading turning through the flight after winding up the other way in the dip
  (WIND_UP of the turn), arms swinging back in the dip and forward at the take-off.  The solver starts from it; nothing of it is held.

Units: m, s, rad; world frame z up, headings from +X counter-clockwise.
"""
from __future__ import annotations


import numpy as np

from scenegraph.model.body import N_DOF, Character, standing_pose
from scenegraph.model.footsteps import leap_footsteps
from scenegraph.model.motion import Motion

__all__ = ["leap_footsteps", "leap_flights", "leap_motion", "DIP", "WIND_UP"]

DIP = 0.14  # m: pelvis drop of the countermovement and the landing absorption of a jump (CMU 16_05: 0.13)
WIND_UP = 0.44  # the counter-rotation before a turning take-off, as a fraction of the turn (thesis ch. 3's
# twist jump winds up the other way).  Measured on twist_jump (docs/dynamic-motion.md): started with a wind-up
# of 0°, 20°, 40° the solver ends at E 737, 629, 608 (the pelvis winding up 1.3°, 3.2°, 7.4°): from none it stays
# in a worse local optimum
G = 9.81
D = np.deg2rad


def leap_flights(leaps) -> tuple[tuple[float, float], ...]:
    """(take-off, landing) world seconds of each leap."""
    return tuple((float(lp.t_off), float(lp.t_land)) for lp in leaps)


def _hermite(t, knots):
    """Piecewise cubic Hermite through knots [(t, value, slope)] (clamped to the ends)."""
    ts = np.array([k[0] for k in knots])
    out = np.empty_like(t)
    for i, x in enumerate(t):
        if x <= ts[0]:
            out[i] = knots[0][1]
            continue
        if x >= ts[-1]:
            out[i] = knots[-1][1]
            continue
        j = int(np.searchsorted(ts, x)) - 1
        (t0, y0, m0), (t1, y1, m1) = knots[j], knots[j + 1]
        hh = t1 - t0
        s = (x - t0) / hh
        out[i] = ((2 * s ** 3 - 3 * s ** 2 + 1) * y0 + (s ** 3 - 2 * s ** 2 + s) * hh * m0
                  + (-2 * s ** 3 + 3 * s ** 2) * y1 + (s ** 3 - s ** 2) * hh * m1)
    return out


def leap_motion(ch: Character, leaps, start, T: float, ctrl_per_second: float = 24.0) -> Motion:
    """The initial motion over [0, T] s of a character standing at ``start`` (x, y, heading)
    and leaping ``leaps`` (see the module docstring)."""
    t = np.linspace(0.0, T, max(8, int(T * 60) + 1))
    stand = standing_pose(ch)
    z0 = stand[2] * 0.97
    q = np.zeros((len(t), N_DOF))
    xy = np.tile(np.array(start[:2], float), (len(t), 1))
    dz = np.zeros(len(t))
    yaw = np.full(len(t), float(start[2]))
    crouch = np.zeros(len(t))  # 0 standing … 1 deepest dip
    swing = np.zeros(len(t))  # arm swing: −1 back … +1 forward
    tuck = np.zeros(len(t))
    P = np.array(start[:2], float)
    for lp in leaps:
        P = np.asarray(lp.takeoff, float)
        tf = lp.t_land - lp.t_off
        dip = DIP if lp.foot is None else DIP / 2
        ramp = 0.3
        Q = np.asarray(lp.landing, float)
        v = (Q - P) / (tf + ramp)
        for c in range(2):  # horizontal: at rest over P, ballistic speed v in flight, at rest over Q
            xy[:, c] += _hermite(t, [(lp.t_off - ramp, 0.0, 0.0), (lp.t_off, v[c] * ramp / 2, v[c]),
                                     (lp.t_land, v[c] * (ramp / 2 + tf), v[c]),
                                     (lp.t_land + ramp, Q[c] - P[c], 0.0)])
        vz = G * tf / 2
        rise = 0.05
        ground = [(lp.t_off - 0.75, 0.0, 0.0), (lp.t_off - 0.3, -dip, 0.0), (lp.t_off, rise, vz)]
        after = [(lp.t_land, rise, -vz), (lp.t_land + 0.22, -dip, 0.0), (lp.t_land + 0.6, 0.0, 0.0)]
        inside = (t > lp.t_off) & (t < lp.t_land)
        z = _hermite(t, ground + after)
        tau = t[inside] - lp.t_off
        z[inside] = rise + vz * tau - G * tau ** 2 / 2
        dz += z
        crouch += np.clip(-np.minimum(z, 0.0) / dip, 0.0, 1.0)
        yaw += lp.turn * np.clip((t - lp.t_off) / tf, 0.0, 1.0)
        wind = np.interp(t, [lp.t_off - 0.55, lp.t_off - 0.2, lp.t_off], [0.0, 1.0, 0.0])
        yaw -= WIND_UP * lp.turn * wind * wind * (3 - 2 * wind)  # counter-rotation in the dip
        w = np.interp(t, [lp.t_off - 0.75, lp.t_off - 0.3, lp.t_off, lp.t_land, lp.t_land + 0.4, lp.t_land + 0.8],
                      [0.0, -1.0, 1.0, 0.6, 0.3, 0.0])
        swing += w
        tuck += np.interp(t, [lp.t_off, (lp.t_off + lp.t_land) / 2, lp.t_land], [0.0, 1.0, 0.0])
        P = Q
    hops = {lp.foot for lp in leaps if lp.foot is not None}
    for side in ("l", "r"):
        idx = ch.dof_index
        free_leg = 0.0 if not hops or side in hops else 1.0
        q[:, idx(f"hip_flex_{side}")] = D(8) + D(70) * crouch + D(35) * tuck + D(30) * free_leg
        q[:, idx(f"knee_flex_{side}")] = D(8) + D(95) * crouch + D(45) * tuck + D(60) * free_leg
        q[:, idx(f"ankle_flex_{side}")] = D(30) * crouch
        q[:, idx(f"shoulder_flex_{side}")] = D(60) * swing
        q[:, idx(f"shoulder_abd_{side}")] = D(8)
        q[:, idx(f"elbow_flex_{side}")] = D(25)
    q[:, 0:2] = xy
    q[:, 2] = z0 + dz - 0.25 * DIP * crouch  # the thighs' flexion lowers the hips further
    q[:, 3] = yaw
    q[:, 4] = D(4) + D(25) * crouch  # trunk leans forward in the dip
    q[:, 6:] = np.clip(q[:, 6:], ch.lower[6:], ch.upper[6:])
    return Motion.from_samples(t, q, max(6, int(round(T * ctrl_per_second)) + 3))
