"""BVH motion files: a strict parser, quaternion maths, forward kinematics, resampling.

No third-party BVH library.  The parser keeps the line of every joint and frame, so a
malformed file fails with an :class:`~scenarios.errors.InputError` that names the file and
line (and the column of a bad number).  Nothing here writes files.

Conventions of the format as read here
--------------------------------------
* ``CHANNELS`` lists translations (``Xposition`` …) and rotations (``Zrotation`` …) in any
  order; the local rotation is the product of the rotation channels in the listed order,
  e.g. ``Zrotation Yrotation Xrotation`` gives R = Rz·Ry·Rx (degrees in the file).
* A joint's local translation is its ``OFFSET`` plus its position channels (roots only in
  practice).  World: p_child = p_parent + R_parent · t_child, R_child = R_parent · R_local.
* An ``End Site`` becomes a pseudo-joint named ``<parent>/End`` with no channels.

Quaternions are numpy arrays ``(..., 4)`` in (w, x, y, z) order, unit norm.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from scenarios.yamlio import read_text
from scenarios.errors import InputError, Location

__all__ = [
    "BvhJoint", "BvhFile", "parse_bvh", "read_bvh", "END_SUFFIX",
    "quat_mul", "quat_rotate", "quat_from_axis_angle", "quat_to_matrix",
    "quat_slerp", "euler_channels_to_quat", "bvh_local_pose", "bvh_forward_kinematics", "resample_pose",
]

END_SUFFIX = "/End"
# Input limits, checked before anything is allocated (docs/reliability.md): a CMU clip has 31
# joints (+ End Sites) 8 deep, 62 or 96 channels, a few thousand frames, a few MB.
MAX_BYTES = 100_000_000  # file size
MAX_JOINTS = 512  # joints and End Sites
MAX_DEPTH = 64  # nesting of JOINT blocks
MAX_CHANNELS = 1024  # channels of one motion line
MAX_FRAMES = 1_000_000  # frames (2.3 h at 120 fps)
MAX_VALUE = 1e6  # |OFFSET| and |channel value|: file units (10 km in cm) or degrees
_ROT = {"Xrotation": 0, "Yrotation": 1, "Zrotation": 2}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


@dataclass(frozen=True)
class BvhJoint:
    """One joint (or End Site pseudo-joint) of a BVH hierarchy.

    ``offset`` is in file units, in the parent's frame; ``channels`` are the channel names
    in file order; ``first_channel`` is the index of the first one in a motion line.
    """

    name: str
    parent: int  # index into BvhFile.joints, -1 for the root
    offset: tuple[float, float, float]
    channels: tuple[str, ...]
    first_channel: int
    line: int
    end_site: bool = False


@dataclass(frozen=True)
class BvhFile:
    """A parsed BVH file: hierarchy plus the raw channel values (frames × channels)."""

    path: str
    joints: tuple[BvhJoint, ...]
    frame_time: float  # s
    motion: np.ndarray  # (F, C) raw values, file units and degrees
    motion_line: int  # line of the first frame
    frames_line: int  # line of "Frames:"

    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.motion.shape[1])

    @property
    def fps(self) -> float:
        """Frame rate (Hz); a rounded frame time (0.0083333) snaps to its integer rate (120)."""
        r = 1.0 / self.frame_time
        return float(round(r)) if abs(r - round(r)) < 1e-4 * r else r

    @property
    def dt(self) -> float:
        """Frame period (s) consistent with :attr:`fps`."""
        return 1.0 / self.fps

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    def index(self, name: str) -> int:
        for i, j in enumerate(self.joints):
            if j.name == name:
                return i
        raise KeyError(name)

    @property
    def channel_joints(self) -> list[BvhJoint]:
        """Joints that carry channels (the root and the JOINTs; no End Sites)."""
        return [j for j in self.joints if not j.end_site]


# --- parsing ------------------------------------------------------------------------------

class _Tokens:
    """Header tokens with their (line, column); column is 1-based."""

    def __init__(self, lines: list[str], file: str):
        self.file = file
        self.toks: list[tuple[str, int, int]] = []
        self.lines = lines
        self.pos = 0
        self.end_line = len(lines) + 1

    def loc(self, line: int, col: int | None = None, field: str | None = None) -> Location:
        return Location(self.file, line, col, field)

    def error(self, msg: str, tok: tuple[str, int, int] | None = None) -> InputError:
        if tok is None:
            tok = self.peek()
        if tok is None:
            return InputError(msg, self.loc(self.end_line))
        return InputError(msg, self.loc(tok[1], tok[2]))

    def peek(self):
        return self.toks[self.pos] if self.pos < len(self.toks) else None

    def next(self, what: str):
        t = self.peek()
        if t is None:
            raise InputError(f"unexpected end of file, expected {what}", self.loc(self.end_line))
        self.pos += 1
        return t

    def expect(self, word: str):
        t = self.next(repr(word))
        if t[0] != word:
            raise self.error(f"expected {word!r}, found {t[0]!r}", t)
        return t

    def number(self, what: str) -> float:
        t = self.next(what)
        try:
            v = float(t[0])
        except ValueError:
            raise self.error(f"expected a number for {what}, found {t[0]!r}", t) from None
        if not math.isfinite(v):
            raise self.error(f"{what} must be finite, found {t[0]!r}", t)
        if abs(v) > MAX_VALUE:
            raise self.error(f"{what} is {t[0]}, beyond the limit of ±{MAX_VALUE:g}", t)
        return v

    def integer(self, what: str) -> int:
        t = self.next(what)
        try:
            return int(t[0])
        except ValueError:
            raise self.error(f"expected an integer for {what}, found {t[0]!r}", t) from None


def _split_with_columns(line: str) -> list[tuple[str, int]]:
    out = []
    i, n = 0, len(line)
    while i < n:
        while i < n and line[i].isspace():
            i += 1
        if i >= n:
            break
        j = i
        while j < n and not line[j].isspace():
            j += 1
        out.append((line[i:j], i + 1))
        i = j
    return out


def parse_bvh(text: str, file: str = "<bvh>") -> BvhFile:
    """Parse BVH text.  Raises InputError(file, line, column) on any malformed input."""
    lines = text.splitlines()
    tk = _Tokens(lines, file)
    motion_at = None
    for ln, line in enumerate(lines, start=1):
        parts = _split_with_columns(line)
        if parts and parts[0][0] == "MOTION":
            tk.toks.append(("MOTION", ln, parts[0][1]))
            motion_at = ln
            break
        for word, col in parts:
            tk.toks.append((word, ln, col))
    if not tk.toks:
        raise InputError("empty file, expected 'HIERARCHY'", Location(file, 1))
    tk.expect("HIERARCHY")
    joints: list[BvhJoint] = []
    names: dict[str, int] = {}
    n_channels = 0

    def parse_joint(parent: int, kw_tok, end_site: bool, depth: int = 1):
        nonlocal n_channels
        if depth > MAX_DEPTH:
            raise tk.error(f"joints nested deeper than {MAX_DEPTH} levels", kw_tok)
        if len(joints) >= MAX_JOINTS:
            raise tk.error(f"more than {MAX_JOINTS} joints and End Sites", kw_tok)
        if end_site:
            tk.expect("Site")
            name = joints[parent].name + END_SUFFIX
        else:
            name_tok = tk.next("a joint name")
            name = name_tok[0]
            if name in ("{", "}") or name in ("OFFSET", "CHANNELS", "JOINT", "End"):
                raise tk.error(f"expected a joint name after {kw_tok[0]!r}, found {name!r}", name_tok)
            if name in names:
                raise tk.error(f"duplicate joint name {name!r}", name_tok)
        tk.expect("{")
        tk.expect("OFFSET")
        off = tuple(tk.number(f"the OFFSET of {name!r}") for _ in range(3))
        channels: tuple[str, ...] = ()
        first = n_channels
        if not end_site:
            ct = tk.expect("CHANNELS")
            n = tk.integer(f"the channel count of {name!r}")
            if n < 0 or n > 6:
                raise tk.error(f"channel count of {name!r} must be 0..6, found {n}", ct)
            chans = []
            for k in range(n):
                c = tk.next("a channel name")
                if c[0] in ("JOINT", "End", "}", "{", "OFFSET", "CHANNELS", "MOTION"):
                    raise tk.error(f"joint {name!r}: CHANNELS declares {n} channels but lists {k}", ct)
                if c[0] not in _ROT and c[0] not in _POS:
                    raise tk.error(f"joint {name!r}: unknown channel {c[0]!r} (CHANNELS says {n}; "
                                   f"known: Xposition … Zrotation)", c)
                if c[0] in chans:
                    raise tk.error(f"joint {name!r}: channel {c[0]!r} repeated", c)
                chans.append(c[0])
            channels = tuple(chans)
            n_channels += n
            if n_channels > MAX_CHANNELS:
                raise tk.error(f"more than {MAX_CHANNELS} channels in all", ct)
        idx = len(joints)
        joints.append(BvhJoint(name, parent, off, channels, first, kw_tok[1], end_site))
        names[name] = idx
        while True:
            t = tk.next("'}', 'JOINT' or 'End Site'")
            if t[0] == "}":
                return
            if end_site:
                raise tk.error(f"an End Site holds only an OFFSET, found {t[0]!r}", t)
            if t[0] == "JOINT":
                parse_joint(idx, t, False, depth + 1)
            elif t[0] == "End":
                parse_joint(idx, t, True, depth + 1)
            elif t[0] in _ROT or t[0] in _POS:
                raise tk.error(f"joint {name!r}: more channel names than CHANNELS declares "
                               f"({len(channels)})", t)
            else:
                raise tk.error(f"expected '}}', 'JOINT' or 'End Site', found {t[0]!r}", t)

    root = tk.expect("ROOT")
    parse_joint(-1, root, False)
    t = tk.next("'MOTION'")
    if t[0] != "MOTION":
        raise tk.error(f"expected 'MOTION' after the hierarchy (one ROOT only), found {t[0]!r}", t)
    assert motion_at is not None

    # MOTION section: "Frames: N", "Frame Time: dt", then N lines of n_channels numbers.
    ln = motion_at
    body = lines[motion_at:]  # lines after MOTION; line number = motion_at + 1 + k

    def next_nonblank(k):
        while k < len(body) and not body[k].strip():
            k += 1
        return k

    k = next_nonblank(0)
    if k >= len(body):
        raise InputError("unexpected end of file, expected 'Frames:'", Location(file, len(lines) + 1))
    parts = body[k].split()
    ln = motion_at + 1 + k
    if len(parts) != 2 or parts[0] != "Frames:":
        raise InputError(f"expected 'Frames: N', found {body[k].strip()!r}", Location(file, ln, 1))
    try:
        n_frames = int(parts[1])
    except ValueError:
        raise InputError(f"frame count must be an integer, found {parts[1]!r}", Location(file, ln)) from None
    if n_frames < 1:
        raise InputError(f"frame count must be at least 1, found {n_frames}", Location(file, ln))
    if n_frames > MAX_FRAMES:
        raise InputError(f"frame count {n_frames} is above the limit of {MAX_FRAMES}", Location(file, ln))
    frames_line = ln
    k = next_nonblank(k + 1)
    if k >= len(body):
        raise InputError("unexpected end of file, expected 'Frame Time:'", Location(file, len(lines) + 1))
    parts = body[k].split()
    ln = motion_at + 1 + k
    if len(parts) != 3 or parts[0] != "Frame" or parts[1] != "Time:":
        raise InputError(f"expected 'Frame Time: seconds', found {body[k].strip()!r}", Location(file, ln, 1))
    try:
        dt = float(parts[2])
    except ValueError:
        raise InputError(f"frame time must be a number, found {parts[2]!r}", Location(file, ln)) from None
    if not (math.isfinite(dt) and 1e-5 <= dt <= 10.0):
        raise InputError(f"frame time must be between 1e-5 and 10 s, found {parts[2]}", Location(file, ln))

    # count the motion lines before allocating: "Frames: 900000" over 3 lines is a truncated
    # file, not a reason to allocate 900000 rows
    present = sum(1 for kk in range(k + 1, len(body)) if body[kk].strip())
    if present < n_frames:
        raise InputError(f"truncated motion: 'Frames: {n_frames}' (line {frames_line}) but only {present} frame lines",
                         Location(file, len(lines) + 1))
    data = np.empty((n_frames, n_channels))
    f = 0
    first_line = None
    for kk in range(k + 1, len(body)):
        line = body[kk]
        if not line.strip():
            continue
        ln = motion_at + 1 + kk
        if f >= n_frames:
            raise InputError(f"more motion lines than 'Frames: {n_frames}' (line {frames_line}) announces",
                             Location(file, ln, 1))
        if first_line is None:
            first_line = ln
        toks = line.split()
        if len(toks) != n_channels:
            raise InputError(f"frame {f} has {len(toks)} values, the hierarchy declares {n_channels} channels",
                             Location(file, ln, 1))
        try:
            row = [float(x) for x in toks]
        except ValueError:
            for col_tok, col in _split_with_columns(line):
                try:
                    float(col_tok)
                except ValueError:
                    raise InputError(f"frame {f}: {col_tok!r} is not a number", Location(file, ln, col)) from None
            raise  # pragma: no cover
        data[f] = row
        if not np.all(np.isfinite(data[f])):
            bad = next(c for (x, c) in _split_with_columns(line) if not math.isfinite(float(x)))
            raise InputError(f"frame {f}: values must be finite", Location(file, ln, bad))
        if np.any(np.abs(data[f]) > MAX_VALUE):
            bad = next(c for (x, c) in _split_with_columns(line) if abs(float(x)) > MAX_VALUE)
            raise InputError(f"frame {f}: a value beyond ±{MAX_VALUE:g} (file units or degrees)",
                             Location(file, ln, bad))
        f += 1
    if f < n_frames:
        raise InputError(f"truncated motion: 'Frames: {n_frames}' (line {frames_line}) but only {f} frame lines",
                         Location(file, len(lines) + 1))
    data.setflags(write=False)
    return BvhFile(file, tuple(joints), dt, data, first_line or frames_line + 2, frames_line)


def read_bvh(path: str | os.PathLike) -> BvhFile:
    """Read and parse a BVH file."""
    return parse_bvh(read_text(path, "BVH", MAX_BYTES), str(path))


# --- quaternions (w, x, y, z) -------------------------------------------------------------

def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_from_axis_angle(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotation about coordinate axis 0/1/2 by ``angle`` (rad), any shape."""
    angle = np.asarray(angle, dtype=float)
    out = np.zeros(angle.shape + (4,))
    out[..., 0] = np.cos(angle / 2)
    out[..., 1 + axis] = np.sin(angle / 2)
    return out


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def quat_slerp(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation a→b at fractions u (broadcast over leading axes);
    takes the short way (b is flipped into a's hemisphere)."""
    u = np.asarray(u, dtype=float)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-8
    s_safe = np.where(small, 1.0, s)
    wa = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / s_safe)
    wb = np.where(small, u, np.sin(u * theta) / s_safe)
    q = wa * a + wb * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def euler_channels_to_quat(angles_deg: np.ndarray, order: tuple[int, ...]) -> np.ndarray:
    """Product of axis rotations in channel order: angles (..., n) degrees, axes ``order``."""
    angles = np.radians(np.asarray(angles_deg, dtype=float))
    q = np.zeros(angles.shape[:-1] + (4,))
    q[..., 0] = 1.0
    for k, ax in enumerate(order):
        q = quat_mul(q, quat_from_axis_angle(ax, angles[..., k]))
    return q


# --- pose, forward kinematics, resampling -------------------------------------------------

def bvh_local_pose(bvh: BvhFile) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame local rotations (F, J, 4) and local translations (F, J, 3) in file units.

    End Sites get the identity rotation and their offset.
    """
    F = bvh.n_frames
    J = len(bvh.joints)
    quats = np.zeros((F, J, 4))
    quats[..., 0] = 1.0
    trans = np.broadcast_to(np.array([j.offset for j in bvh.joints], dtype=float), (F, J, 3)).copy()
    for i, j in enumerate(bvh.joints):
        if not j.channels:
            continue
        rot_cols = [j.first_channel + k for k, c in enumerate(j.channels) if c in _ROT]
        rot_axes = tuple(_ROT[c] for c in j.channels if c in _ROT)
        if rot_cols:
            quats[:, i] = euler_channels_to_quat(bvh.motion[:, rot_cols], rot_axes)
        for k, c in enumerate(j.channels):
            if c in _POS:
                trans[:, i, _POS[c]] += bvh.motion[:, j.first_channel + k]
    return quats, trans


def bvh_forward_kinematics(parents: list[int] | tuple[int, ...], quats: np.ndarray, trans: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """World positions (F, J, 3) and world rotations (F, J, 4); parents precede children."""
    F, J = quats.shape[:2]
    pos = np.empty((F, J, 3))
    rot = np.empty((F, J, 4))
    for i, p in enumerate(parents):
        if p < 0:
            rot[:, i] = quats[:, i]
            pos[:, i] = trans[:, i]
        else:
            rot[:, i] = quat_mul(rot[:, p], quats[:, i])
            pos[:, i] = pos[:, p] + quat_rotate(rot[:, p], trans[:, i])
    return pos, rot


def resample_pose(quats: np.ndarray, trans: np.ndarray, times: np.ndarray, new_times: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Resample local rotations by slerp and translations linearly at ``new_times`` (s).

    ``times`` must be increasing; ``new_times`` must lie within [times[0], times[-1]].
    """
    times = np.asarray(times, dtype=float)
    new_times = np.asarray(new_times, dtype=float)
    if new_times.size and (new_times[0] < times[0] - 1e-9 or new_times[-1] > times[-1] + 1e-9):
        raise ValueError("resample times outside the clip")
    idx = np.clip(np.searchsorted(times, new_times, side="right") - 1, 0, len(times) - 2) if len(times) > 1 \
        else np.zeros(len(new_times), dtype=int)
    if len(times) == 1:
        return quats[idx].copy(), trans[idx].copy()
    u = np.clip((new_times - times[idx]) / (times[idx + 1] - times[idx]), 0.0, 1.0)
    q = quat_slerp(quats[idx], quats[idx + 1], np.broadcast_to(u[:, None], (len(u), quats.shape[1])))
    t = trans[idx] * (1.0 - u)[:, None, None] + trans[idx + 1] * u[:, None, None]
    return q, t
