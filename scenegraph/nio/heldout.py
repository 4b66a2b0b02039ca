"""Measures of a held-out evaluation: a predicted motion against a real trial (issue #18).

Everything here is plain numpy on sampled generalized coordinates ``q`` (T, N_DOF) in
body.py's DOF order (root: x, y, z in m, yaw, pitch, roll in rad; then the 29 joint DOFs in
rad), so the measures can be checked on synthetic arrays.  Frames of the prediction and the
real trial are aligned by time; a prediction that plants the trial's own footsteps at the
trial's own times (what ``compose evaluate-style`` synthesises) has its footfalls at the
trial's footfalls, so time alignment is footfall alignment there (:func:`align_by_footfalls`
warps a prediction with other footfall times piecewise linearly onto the trial's).
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import JOINT_DOF_NAMES, N_ROOT

__all__ = ["JOINT_GROUPS", "group_indices", "group_rms_deg", "dof_rms_deg", "root_path_error_m", "style_features",
           "FEATURE_NAMES", "stride_windows", "per_stride_rms_deg", "noise_floor_deg", "bootstrap_mean_ci",
           "direction_score", "align_by_footfalls"]

_LEGS = ("hip_", "knee_", "ankle_", "toe_")
_TRUNK = ("waist_", "chest_", "neck_")
_ARMS = ("shoulder_", "elbow_", "wrist_")
JOINT_GROUPS = ("legs", "pelvis_trunk", "arms", "trunk_arms", "all")


def group_indices(group: str) -> np.ndarray:
    """Column indices into a full ``q`` (root first) of a joint group's DOFs (root excluded).

    legs: hip, knee, ankle, toe; pelvis_trunk: waist, chest, neck (the pelvis's own rotation
    is the root's, read by the pelvis features of :func:`style_features`); arms:
    shoulder, elbow, wrist; trunk_arms: pelvis_trunk and arms together (the upper body, where
    issue #18's goal compares styles); all: every joint DOF."""
    pre = {"legs": _LEGS, "pelvis_trunk": _TRUNK, "arms": _ARMS, "trunk_arms": _TRUNK + _ARMS,
           "all": ("",)}.get(group)
    if pre is None:
        raise ValueError(f"unknown joint group {group!r} (one of {', '.join(JOINT_GROUPS)})")
    return np.array([N_ROOT + j for j, d in enumerate(JOINT_DOF_NAMES) if d.startswith(pre)], int)


def group_rms_deg(q_pred: np.ndarray, q_real: np.ndarray) -> dict[str, float]:
    """Joint-angle RMS (degrees) of ``q_pred`` vs ``q_real`` (both (T, N_DOF), same frames) per
    group of :data:`JOINT_GROUPS`, over every frame and DOF of the group."""
    a, b = np.asarray(q_pred, float), np.asarray(q_real, float)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    return {g: float(np.degrees(np.sqrt(np.mean((a[:, group_indices(g)] - b[:, group_indices(g)]) ** 2))))
            for g in JOINT_GROUPS}


def dof_rms_deg(q_pred: np.ndarray, q_real: np.ndarray) -> dict[str, float]:
    """Angle RMS (degrees) of ``q_pred`` vs ``q_real`` per DOF: the root's yaw, pitch and roll
    (``root_yaw`` …) and every joint DOF by name (body.py's names), over every frame; says which
    DOFs carry a group's RMS."""
    a, b = np.asarray(q_pred, float), np.asarray(q_real, float)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    r = np.degrees(np.sqrt(np.mean((a - b) ** 2, axis=0)))
    out = {f"root_{n}": float(r[3 + i]) for i, n in enumerate(("yaw", "pitch", "roll"))}
    out.update({d: float(r[N_ROOT + j]) for j, d in enumerate(JOINT_DOF_NAMES)})
    return out


def root_path_error_m(q_pred: np.ndarray, q_real: np.ndarray) -> dict[str, float]:
    """Root (pelvis) position error (m): RMS and max of the 3-D distance per frame, and RMS of
    the vertical component alone."""
    d = np.asarray(q_pred, float)[:, :3] - np.asarray(q_real, float)[:, :3]
    n = np.linalg.norm(d, axis=1)
    return {"rms": float(np.sqrt(np.mean(n ** 2))), "max": float(n.max()),
            "vertical_rms": float(np.sqrt(np.mean(d[:, 2] ** 2)))}


def _col(name: str) -> int:
    return N_ROOT + JOINT_DOF_NAMES.index(name)


FEATURE_NAMES = ("trunk_pitch_mean_deg", "trunk_roll_mean_deg", "turn_lean_deg", "pelvis_vertical_excursion_m",
                 "pelvis_yaw_amplitude_deg", "pelvis_roll_amplitude_deg", "arm_swing_amplitude_deg",
                 "elbow_flexion_mean_deg", "stance_knee_flexion_deg", "swing_knee_flexion_peak_deg")


def _detrend(x: np.ndarray) -> np.ndarray:
    if len(x) < 2:
        return x - x.mean()
    k = np.arange(len(x), dtype=float)
    return x - np.polyval(np.polyfit(k, x, 1), k)


def style_features(t: np.ndarray, q: np.ndarray, stance: np.ndarray) -> dict[str, float]:
    """Style features an animator reads, from frames ``q`` (T, N_DOF) at times ``t`` (s) with
    ``stance`` (T, 2) booleans [left, right] (the foot is planted).

    - trunk pitch / roll: root pitch + waist_flex + chest_flex, root roll + waist_lat (deg),
      mean over frames (the chest's orientation in the heading frame, to first order);
    - turn_lean_deg: mean trunk roll signed by the turning direction (sign of the yaw rate,
      frames turning faster than 10°/s only; 0 on a straight walk);
    - pelvis vertical excursion: max − min root height (m); pelvis yaw / roll amplitude:
      max − min of the linearly detrended root yaw / roll (deg);
    - arm swing: max − min shoulder_flex, mean of both sides (deg); elbow flexion: mean of
      both elbow_flex (deg);
    - stance knee flexion: mean knee_flex over the frames the foot is planted; peak swing
      knee flexion: max knee_flex over the frames it is not; mean of the sides that have such
      frames (deg; NaN if none)."""
    t, q, stance = np.asarray(t, float), np.asarray(q, float), np.asarray(stance, bool)
    deg = np.degrees
    pitch = q[:, 4] + q[:, _col("waist_flex")] + q[:, _col("chest_flex")]
    roll = q[:, 5] + q[:, _col("waist_lat")]
    yaw = np.unwrap(q[:, 3])
    rate = np.gradient(yaw, t) if len(t) > 1 else np.zeros(len(t))
    turning = np.abs(rate) > np.radians(10.0)
    lean = float(deg(np.mean(roll[turning] * np.sign(rate[turning])))) if turning.any() else 0.0
    stance_knee, swing_knee = [], []
    for k, side in enumerate("lr"):
        knee = q[:, _col(f"knee_flex_{side}")]
        if stance[:, k].any():
            stance_knee.append(float(deg(knee[stance[:, k]].mean())))
        if (~stance[:, k]).any():
            swing_knee.append(float(deg(knee[~stance[:, k]].max())))
    arms = [np.ptp(q[:, _col(f"shoulder_flex_{s}")]) for s in "lr"]
    return {
        "trunk_pitch_mean_deg": float(deg(pitch.mean())),
        "trunk_roll_mean_deg": float(deg(roll.mean())),
        "turn_lean_deg": lean,
        "pelvis_vertical_excursion_m": float(np.ptp(q[:, 2])),
        "pelvis_yaw_amplitude_deg": float(deg(np.ptp(_detrend(yaw)))),
        "pelvis_roll_amplitude_deg": float(deg(np.ptp(_detrend(q[:, 5])))),
        "arm_swing_amplitude_deg": float(deg(np.mean(arms))),
        "elbow_flexion_mean_deg": float(deg(np.mean([q[:, _col(f"elbow_flex_{s}")] for s in "lr"]))),
        "stance_knee_flexion_deg": float(np.mean(stance_knee)) if stance_knee else float("nan"),
        "swing_knee_flexion_peak_deg": float(np.mean(swing_knee)) if swing_knee else float("nan"),
    }


def stride_windows(strikes: np.ndarray) -> list[tuple[float, float]]:
    """[(t_a, t_b)] between consecutive foot strikes of one foot (s): the strides."""
    s = np.sort(np.asarray(strikes, float))
    return [(float(a), float(b)) for a, b in zip(s[:-1], s[1:]) if b > a]


def per_stride_rms_deg(t: np.ndarray, q_pred: np.ndarray, q_real: np.ndarray,
                       windows: list[tuple[float, float]]) -> dict[str, list[float]]:
    """Joint-angle RMS (deg) per group inside each stride window [t_a, t_b)."""
    t = np.asarray(t, float)
    out: dict[str, list[float]] = {g: [] for g in JOINT_GROUPS}
    for a, b in windows:
        m = (t >= a) & (t < b)
        if m.sum() < 2:
            continue
        for g, v in group_rms_deg(q_pred[m], q_real[m]).items():
            out[g].append(v)
    return out


def _stride_phase_samples(t, q, windows, n: int = 51) -> np.ndarray:
    """(strides, n, N_DOF): each stride resampled on n evenly spaced phases."""
    out = []
    for a, b in windows:
        ph = np.linspace(a, b, n)
        out.append(np.column_stack([np.interp(ph, t, q[:, j]) for j in range(q.shape[1])]))
    return np.array(out)


def noise_floor_deg(t: np.ndarray, q: np.ndarray, windows: list[tuple[float, float]]) -> dict[str, float] | None:
    """Stride-to-stride variability of a real trial by the group RMS: each stride (resampled
    on phase) against the mean of the *other* strides, RMS over strides (deg).  None with
    fewer than two strides."""
    t, q = np.asarray(t, float), np.asarray(q, float)
    windows = [(a, b) for a, b in windows if a >= t[0] - 1e-9 and b <= t[-1] + 1e-9]
    if len(windows) < 2:
        return None
    S = _stride_phase_samples(t, q, windows)
    sq = {g: [] for g in JOINT_GROUPS}
    for i in range(len(S)):
        rest = np.delete(S, i, axis=0).mean(axis=0)
        for g, v in group_rms_deg(S[i], rest).items():
            sq[g].append(v ** 2)
    return {g: float(np.sqrt(np.mean(v))) for g, v in sq.items()}


def bootstrap_mean_ci(values, n_boot: int = 2000, level: float = 0.95, seed: int = 0) -> dict:
    """Mean of ``values`` (one per stride) with a percentile bootstrap interval over them."""
    v = np.asarray(values, float)
    if len(v) == 0:
        return {"mean": None, "lo": None, "hi": None, "n": 0}
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, len(v), size=(n_boot, len(v)))].mean(axis=1)
    lo, hi = np.quantile(means, [(1 - level) / 2, 1 - (1 - level) / 2])
    return {"mean": float(v.mean()), "lo": float(lo), "hi": float(hi), "n": int(len(v))}


def direction_score(train: dict[str, float], test: dict[str, float], pred: dict[str, float],
                    min_change: dict[str, float] | None = None) -> dict:
    """The fraction of features whose change from the training clip to the test trial the
    prediction gets in the same direction (sign of pred − train equals sign of test − train).
    Features whose real change is below ``min_change[name]`` (default 0.5 for degrees, 0.005
    for metres) or NaN are not counted."""
    hits, counted = {}, 0
    for k in FEATURE_NAMES:
        a, b, c = train.get(k), test.get(k), pred.get(k)
        if a is None or b is None or c is None or not np.all(np.isfinite([a, b, c])):
            continue
        thr = (min_change or {}).get(k, 0.005 if k.endswith("_m") else 0.5)
        if abs(b - a) < thr:
            continue
        hits[k] = bool(np.sign(c - a) == np.sign(b - a))
        counted += 1
    return {"score": (sum(hits.values()) / counted) if counted else None, "counted": counted, "hits": hits}


def align_by_footfalls(t: np.ndarray, strikes_pred, strikes_real) -> np.ndarray:
    """Times ``t`` of a prediction mapped onto the real trial's clock: piecewise linear through
    matching footfalls (same count and order), linear extrapolation outside them."""
    p, r = np.asarray(strikes_pred, float), np.asarray(strikes_real, float)
    if p.shape != r.shape or len(p) < 2 or np.any(np.diff(p) <= 0):
        raise ValueError("need the same number (>= 2) of increasing footfall times")
    t = np.asarray(t, float)
    out = np.interp(t, p, r)
    lo, hi = t < p[0], t > p[-1]
    out[lo] = r[0] + (t[lo] - p[0]) * (r[1] - r[0]) / (p[1] - p[0])
    out[hi] = r[-1] + (t[hi] - p[-1]) * (r[-1] - r[-2]) / (p[-1] - p[-2])
    return out
