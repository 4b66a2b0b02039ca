"""Initial motions for synthesis (paper §7): root from the footprints, joints from an example.

1. The root's horizontal path is a smooth curve through the midpoints of consecutive
   footprints, its heading the curve's tangent, its height the standing height.
2. Joint angles come from the most similar pose of an example motion, matched by the gait
   phase of each leg (stance or swing and how far into it).  Without a mocap example a
   built-in example gait is used: a few smooth curves of hip, knee, ankle, toe and arm
   angles over the phase, shaped after textbook gait kinematics.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from scenegraph.model.body import N_DOF, N_ROOT, Character, standing_pose
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion

__all__ = ["initial_motion", "leg_phase", "example_gait_pose", "phase_code", "example_poses", "style_gait",
           "RUN_FLIGHT_FRACTION"]

RUN_FLIGHT_FRACTION = 0.15  # a style whose example motion has both feet off the ground this often is a run

D = np.deg2rad
ROOT_HEIGHT = 0.95  # initial pelvis height as a fraction of the standing height
RUN_BLEND = 0.6  # s, walk → run pose blend of initial motions with a gait change


def leg_phase(footsteps: tuple[Footstep, ...], foot: str, t: float) -> tuple[str, float]:
    """("stance"|"swing", fraction in [0, 1]) of one leg at world time t."""
    steps = sorted((f for f in footsteps if f.foot == foot), key=lambda f: f.t0)
    for f in steps:
        if f.t0 <= t <= f.t1:
            return "stance", (t - f.t0) / (f.t1 - f.t0)
    prev = [f for f in steps if f.t1 < t]
    nxt = [f for f in steps if f.t0 > t]
    typical_stance = np.mean([f.t1 - f.t0 for f in footsteps]) if footsteps else 0.6
    period = 2 * np.mean(np.diff(sorted(f.t0 for f in footsteps))) if len(footsteps) > 1 else 1.1
    swing = max(period - typical_stance, 0.2)
    t_off = prev[-1].t1 if prev else (nxt[0].t0 - swing if nxt else t)
    t_on = nxt[0].t0 if nxt else t_off + swing
    return "swing", float(np.clip((t - t_off) / max(t_on - t_off, 1e-3), 0, 1))


def example_gait_pose(ch: Character, phase_l, phase_r, run: bool = False) -> np.ndarray:
    """Joint angles (35-vector, root zero) of the built-in example gait for two leg phases."""
    q = np.zeros(N_DOF)
    idx = ch.dof_index
    for side, (kind, u) in (("l", phase_l), ("r", phase_r)):
        if kind == "stance":
            hip = D(22) - D(32) * u if not run else D(25) - D(40) * u
            knee = D(8) + D(12) * np.sin(np.pi * u) if not run else D(20) + D(25) * np.sin(np.pi * u)
            ankle = D(-5) + D(15) * np.sin(np.pi * min(u * 1.3, 1.0)) - D(15) * max(0.0, u - 0.8) / 0.2
            toe = D(25) * max(0.0, u - 0.7) / 0.3
            hip_phase = -1.0 + 2.0 * u  # -1 at landing → +1 at toe-off: arm swings forward later
        else:
            hip = D(-10) + D(32) * (1 - np.cos(np.pi * u)) / 2 if not run else D(-15) + D(45) * (1 - np.cos(np.pi * u)) / 2
            knee = D(60) * np.sin(np.pi * min(u * 1.25, 1.0)) + D(5) if not run else D(95) * np.sin(np.pi * u) + D(15)
            ankle = D(5) * np.sin(np.pi * u)
            toe = D(10) * (1 - u)
            hip_phase = 1.0 - 2.0 * u
        q[idx(f"hip_flex_{side}")] = hip
        q[idx(f"knee_flex_{side}")] = knee
        q[idx(f"ankle_flex_{side}")] = ankle
        q[idx(f"toe_flex_{side}")] = toe
        # arms swing opposite to the same-side leg
        q[idx(f"shoulder_flex_{side}")] = D(12) * hip_phase
        q[idx(f"shoulder_abd_{side}")] = D(6)
        q[idx(f"elbow_flex_{side}")] = D(20) if not run else D(80)
    return q


def _root_path(footsteps: tuple[Footstep, ...], times: np.ndarray):
    # stances cut by the motion's ends count from their real heel strike / to their real toe-off:
    # a cut first stance (both feet down at t = 0, one about to lift) otherwise put the first
    # midpoint late, and two stances of one foot could pair up (walk: pelvis 14 cm behind its start)
    steps = sorted(_uncut(footsteps, times[0], times[-1]), key=lambda f: f.t0)
    mids = [((a.t0 + a.t1 + b.t0 + b.t1) / 4, (np.array(a.position) + np.array(b.position)) / 2)
            for a, b in zip(steps, steps[1:])]
    if not mids:
        f = steps[0]
        mids = [((f.t0 + f.t1) / 2, np.array(f.position))]
    kt = np.array([m[0] for m in mids])
    kp = np.array([m[1] for m in mids])
    # knots at the same time (e.g. three footprints whose outer two share t0 + t1) are merged
    # into their mean: equal times would divide by zero and make the root path NaN
    kt, inv = np.unique(kt, return_inverse=True)
    kp = np.stack([kp[inv == k].mean(axis=0) for k in range(len(kt))])
    if len(kt) == 1:
        xy = np.repeat(kp, len(times), axis=0)
        heading = np.full(len(times), steps[0].heading)
    else:
        # piecewise-linear through the midpoints, extrapolated at the ends, then smoothed
        xy = np.stack([np.interp(times, kt, kp[:, i], left=np.nan, right=np.nan) for i in (0, 1)], axis=1)
        v0 = (kp[1] - kp[0]) / (kt[1] - kt[0])
        v1 = (kp[-1] - kp[-2]) / (kt[-1] - kt[-2])
        before, after = times < kt[0], times > kt[-1]
        xy[before] = kp[0] + np.outer(times[before] - kt[0], v0)
        xy[after] = kp[-1] + np.outer(times[after] - kt[-1], v1)
        vel = np.gradient(xy, times, axis=0)
        heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
    return xy, heading


def initial_motion(ch: Character, footsteps: tuple[Footstep, ...], t0: float, t1: float,
                   ctrl_per_second: float = 24.0, run: bool | float = False,
                   example=None, ground=None) -> Motion:
    """An initial motion over [t0, t1] (s) for the given footsteps.

    ``example``: optional example poses matched by leg phase, (codes (T, 2), joint angles
    (T, 29)) as :func:`example_poses` returns them; without it the built-in example gait is used.
    ``run``: True for running poses throughout, or the world time (s) of a walk → run change
    (poses blended over RUN_BLEND around it).
    ``ground`` (a :class:`~scenegraph.model.ground.Ground`): the pelvis height follows the ground
    height under the pelvis (default flat, z = 0).
    """
    times = np.linspace(t0, t1, max(8, int((t1 - t0) * 60) + 1))
    xy, heading = _root_path(footsteps, times)
    stand = standing_pose(ch)
    q = np.zeros((len(times), N_DOF))
    ex_phases = None
    if example is not None:
        ex_phases, ex_joints = (np.asarray(a, float) for a in example)
    # phases counted from the real heel strike, as the root path is: a stance the scene start cuts in
    # half is at mid-stance at t0, the pelvis over its foot
    phase_steps = _uncut(footsteps, t0, t1)
    for i, t in enumerate(times):
        ph_l, ph_r = leg_phase(phase_steps, "l", t), leg_phase(phase_steps, "r", t)
        if isinstance(run, bool):
            w_run = float(run)
        else:  # walk → run over RUN_BLEND seconds around the given time (smoothstep)
            u = float(np.clip((t - run) / RUN_BLEND + 0.5, 0.0, 1.0))
            w_run = u * u * (3 - 2 * u)
        if ex_phases is None:
            q[i] = ((1 - w_run) * example_gait_pose(ch, ph_l, ph_r, False)
                    + w_run * example_gait_pose(ch, ph_l, ph_r, True))
        else:
            code = np.array([phase_code(ph_l), phase_code(ph_r)])
            j = int(np.argmin(np.sum(_phase_dist(ex_phases, code), axis=1)))
            q[i, N_ROOT:] = ex_joints[j]
        q[i, 0:2] = xy[i]
        q[i, 3] = heading[i]
        q[i, 2] = stand[2] * (ROOT_HEIGHT - 0.02 * w_run)
        if ground is not None and not ground.flat:
            q[i, 2] += ground.height(xy[i, 0], xy[i, 1])
        q[i, 4] = np.deg2rad(3 + 5 * w_run)  # slight forward lean, more when running
    # an edited body (locked joints, reduced ranges) starts inside its limits
    q[:, N_ROOT:] = np.clip(q[:, N_ROOT:], ch.lower[N_ROOT:], ch.upper[N_ROOT:])
    return Motion.from_samples(times, q, max(6, int(round((t1 - t0) * ctrl_per_second)) + 3))


def example_poses(footsteps: tuple[Footstep, ...], times, joints) -> tuple[np.ndarray, np.ndarray]:
    """(codes (T, 2), joint angles (T, 29)): an example motion's poses (``joints`` at world
    ``times``, s) keyed by the phase codes of its left and right leg under ``footsteps``.
    A stance cut short by the start or end of the example (under 80 % of the longest) is
    first extended to the longest, so its phase counts from the real heel strike / to the
    real toe-off (07_01's last 0.07 s of a stance would otherwise read as a whole stance)."""
    times = np.asarray(times, float)
    footsteps = _uncut(footsteps, times[0], times[-1])
    codes = np.array([[phase_code(leg_phase(footsteps, f, t)) for f in ("l", "r")] for t in times])
    return codes, np.asarray(joints, float)


def _uncut(footsteps: tuple[Footstep, ...], t0: float, t1: float) -> tuple[Footstep, ...]:
    """Stances cut by the ends t0, t1 (s) of a motion (under 80 % of the longest stance)
    extended to the longest, beyond the motion, so that leg phases count from the real heel
    strike / to the real toe-off."""
    lo, hi = t0 + 1e-6, t1 - 1e-6
    d = max((f.t1 - f.t0 for f in footsteps), default=0.0)
    return tuple(f if f.t1 - f.t0 >= 0.8 * d else
                 replace(f, t0=f.t1 - d) if f.t0 <= lo else
                 replace(f, t1=f.t0 + d) if f.t1 >= hi else f for f in footsteps)


def phase_code(ph: tuple[str, float]) -> float:
    """Map a leg phase onto one cycle coordinate in [0, 2): stance [0, 1), swing [1, 2)."""
    kind, u = ph
    return u if kind == "stance" else 1.0 + u


def _phase_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.abs(a - b)
    return np.minimum(d, 2.0 - d)


def style_gait(style) -> str:
    """The gait a style moves in: ``"run"`` when the example motion it was learned from
    (``Style.example``, phase codes: stance [0, 1), swing [1, 2)) has both legs in swing — a
    flight phase — in at least RUN_FLIGHT_FRACTION of its samples, else ``"walk"`` (also for a
    style without an example, like the built-in default).  Measured on the bundled styles:
    run 31 of 47 samples in flight, walk 0/69, walk_person2 3/61, walk_stylized 1/69."""
    ex = getattr(style, "example", None)
    if ex is None:
        return "walk"
    pl, pr = np.asarray(ex.phase_l, float), np.asarray(ex.phase_r, float)
    flight = float(np.mean((pl >= 1.0) & (pr >= 1.0))) if pl.size else 0.0
    return "run" if flight >= RUN_FLIGHT_FRACTION else "walk"

