"""Footstep contacts from a fitted mocap clip: per foot, where and when it rests on the floor.

A handle (heel, ball, toe of each foot) is *in contact* in a frame when it is low (height
above the floor, z = 0 after import, below ``height``) and slow (speed below ``speed``).
Runs of contact frames shorter than ``min_duration`` are dropped and gaps of up to
``max_gap`` frames are closed.  A **footstep** is a maximal interval in which any handle of
one foot is in contact; its position is the mean of its handles' contact positions and its
heading the direction heel → ball.  Times are clip times (s, 0 at the clip's first frame);
the frame indices are the clip's (resampled) frames.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Contact", "Footstep", "detect_contacts", "detect_footsteps", "contact_mask", "point_speed", "FOOT_HANDLES"]

FOOT_HANDLES = ("heel", "ball", "toe")


@dataclass(frozen=True)
class Contact:
    """One handle resting on the floor over [start, end] (s); ``position`` its mean (m)."""

    side: str  # "l" | "r"
    handle: str  # "heel" | "ball" | "toe"
    start: float
    end: float
    first_frame: int
    last_frame: int
    position: tuple[float, float, float]

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class Footstep:
    """One foot on the floor over [start, end] (s) at ``position`` (m), facing ``heading`` (rad)."""

    side: str
    start: float
    end: float
    first_frame: int
    last_frame: int
    position: tuple[float, float, float]
    heading: float
    contacts: tuple[Contact, ...]

    @property
    def duration(self) -> float:
        return self.end - self.start


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (first, last) index pairs of True runs."""
    out = []
    i, n = 0, len(mask)
    while i < n:
        if mask[i]:
            j = i
            while j + 1 < n and mask[j + 1]:
                j += 1
            out.append((i, j))
            i = j + 1
        else:
            i += 1
    return out


def _clean(mask: np.ndarray, max_gap: int, min_frames: int) -> np.ndarray:
    m = mask.copy()
    runs = _runs(m)
    for (a0, a1), (b0, b1) in zip(runs, runs[1:]):
        if b0 - a1 - 1 <= max_gap:
            m[a1 + 1:b0] = True
    for a, b in _runs(m):
        if b - a + 1 < min_frames:
            m[a:b + 1] = False
    return m


def point_speed(positions: np.ndarray, fps: float, onesided: bool = False) -> np.ndarray:
    """Speed (m/s, (T,)) of one point from its positions (T, 3) at ``fps``.

    Central differences by default.  With ``onesided`` the smaller of the backward and the
    forward difference: a point that lands in frame k and then stays still is slow *at* k
    (the central difference there still carries the approach), and a point still up to k
    that leaves after it is slow at k too.  At 30 fps the central difference marks the
    touchdown and lift-off frames as moving, which removes the 2–3 frames of double support
    of a brisk walk (07_12 at 1.9 m/s came out as a run with 0.1 s "flight" phases)."""
    P = np.asarray(positions, dtype=float)
    if not onesided:
        return np.linalg.norm(np.gradient(P, 1.0 / fps, axis=0), axis=1)
    d = np.linalg.norm(np.diff(P, axis=0), axis=1) * fps
    back = np.concatenate([[d[0]], d])
    fwd = np.concatenate([d, [d[-1]]])
    return np.minimum(back, fwd)


def contact_mask(positions: np.ndarray, fps: float, height: float = 0.05, speed: float = 0.4,
                 max_gap: int = 1, min_duration: float = 0.05, onesided: bool = False) -> np.ndarray:
    """Boolean (T,) contact mask of one point from its positions (T, 3) at ``fps`` (speeds by
    :func:`point_speed`)."""
    P = np.asarray(positions, dtype=float)
    if len(P) < 2:
        return P[:, 2] < height
    sp = point_speed(P, fps, onesided)
    raw = (P[:, 2] < height) & (sp < speed)
    min_frames = max(1, int(math.ceil(min_duration * fps - 1e-9)))
    return _clean(raw, max_gap, min_frames)


def detect_contacts(clip, height: float = 0.05, speed: float = 0.4, max_gap: int = 1,
                    min_duration: float = 0.05, onesided: bool = False) -> list[Contact]:
    """Per-handle contact intervals of a :class:`~scenegraph.mocap.clip.MocapClip`, sorted by start
    (``onesided``: speeds by one-sided differences, :func:`point_speed`)."""
    names = [f"{h}_{s}" for s in ("l", "r") for h in FOOT_HANDLES]
    P = clip.handle_positions(names)
    times = np.asarray(clip.times)
    out = []
    for k, name in enumerate(names):
        h, s = name.rsplit("_", 1)
        m = contact_mask(P[:, k], clip.fps, height, speed, max_gap, min_duration, onesided)
        for a, b in _runs(m):
            pos = P[a:b + 1, k].mean(axis=0)
            out.append(Contact(s, h, float(times[a]), float(times[b]), a, b, tuple(float(x) for x in pos)))
    out.sort(key=lambda c: (c.start, c.side, FOOT_HANDLES.index(c.handle)))
    return out


def detect_footsteps(clip, height: float = 0.05, speed: float = 0.4, max_gap: int = 1,
                     min_duration: float = 0.05, onesided: bool = False) -> list[Footstep]:
    """Footsteps (per foot, merged over heel/ball/toe contacts) of a fitted clip, by start time."""
    contacts = detect_contacts(clip, height, speed, max_gap, min_duration, onesided)
    times = np.asarray(clip.times)
    steps = []
    for side in ("l", "r"):
        cs = sorted((c for c in contacts if c.side == side), key=lambda c: c.first_frame)
        groups: list[list[Contact]] = []
        for c in cs:
            if groups and c.first_frame <= max(g.last_frame for g in groups[-1]) + max_gap + 1:
                groups[-1].append(c)
            else:
                groups.append([c])
        for g in groups:
            a = min(c.first_frame for c in g)
            b = max(c.last_frame for c in g)
            pos = np.mean([c.position for c in g], axis=0)
            by = {c.handle: np.array(c.position) for c in g}
            if "heel" in by and ("ball" in by or "toe" in by):
                d = by.get("ball", by.get("toe")) - by["heel"]
                heading = math.atan2(d[1], d[0])
            else:  # heading from the fitted root yaw in the middle of the step
                heading = float(clip.q[(a + b) // 2, 3])
            steps.append(Footstep(side, float(times[a]), float(times[b]), a, b, tuple(float(x) for x in pos),
                                  heading, tuple(g)))
    steps.sort(key=lambda s: (s.start, s.side))
    return steps
