"""BVH export of one character for mocap tools.

Hierarchy: one BVH joint per body (``pelvis`` is the ROOT; the tree of ``Character.bodies``),
an ``End Site`` at the far tip of each leaf body's ellipsoid (head top, finger tips, toe
tips).  The root has ``Xposition Yposition Zposition Zrotation Yrotation Xrotation``, every
other joint ``Zrotation Yrotation Xrotation``: the local rotation is R = Rz·Ry·Rx (degrees),
``p_child = p_parent + R_parent · OFFSET``.  At all-zero channels the character stands in
our rest pose (q = 0: upright, arms hanging down).

Axes and units (BVH is usually Y up): the file is **Y up, facing +Z, left +X, centimetres**
by default, i.e. file (X, Y, Z) = our (Y, Z, X) · 100.  That is a proper rotation (no
mirroring) and the convention of the CMU files, so a rig file with ``forward: +Z, left: +X,
up: +Y, unit_m: 0.01`` reads it back.  ``units="m"`` writes metres instead.

Frame rate: ``fps`` is the file's rate; the track's frames (at ``source_fps``) are resampled
by linear interpolation of the generalized coordinates q, which is exact at the source
frames.  For a motion that is a spline in q, export the track at a high rate or at the
target rate directly.

Euler angles are chosen continuous over time (of the two ZYX solutions the one nearest the
previous frame, then unwrapped), so curves do not jump by 360°.  With Y up, the middle (Y)
rotation of the root is the heading: near ±90° of the ZYX middle angle the other two are
ill-conditioned (gimbal lock) — the composed rotation stays exact, only the curves get
steep there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenarios.atomic import atomic_write
from scenarios.errors import InputError

from scenegraph.model.body import N_DOF, Character, drawn_shapes
from scenegraph.model.kinematics import numeric_fk

__all__ = ["BvhSkeleton", "export_bvh", "bvh_text", "skeleton_of", "euler_zyx", "AXES", "UNITS"]

# file axis  <- our axis: file X = our Y (left), file Y = our Z (up), file Z = our X (forward)
AXES = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
UNITS = {"cm": 100.0, "m": 1.0, "mm": 1000.0}


@dataclass(frozen=True)
class BvhSkeleton:
    """Joint names, parents (-1 for the root), offsets (m, parent frame, our axes) and the
    End Site offsets of leaves ({joint index: offset in m})."""

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray  # (J, 3)
    end_sites: dict[int, np.ndarray]


def _body_order(ch: Character) -> list[int]:
    from scenegraph.export.usd import joint_paths
    return joint_paths(ch)[0]


def skeleton_of(ch: Character) -> tuple[BvhSkeleton, list[int]]:
    """The BVH skeleton of a character and the body index of each BVH joint."""
    order = _body_order(ch)
    names = [ch.bodies[i].name for i in order]
    pos = {n: j for j, n in enumerate(names)}
    parents = [-1 if ch.bodies[i].parent is None else pos[ch.bodies[i].parent] for i in order]
    R0, p0 = numeric_fk(ch, np.zeros(N_DOF))  # rest: every frame parallel to the world
    offsets = np.zeros((len(order), 3))
    for j, bi in enumerate(order):
        if parents[j] >= 0:
            pb = order[parents[j]]
            offsets[j] = R0[pb].T @ (p0[bi] - p0[pb])
    ends = {}
    drawn = drawn_shapes(ch)
    has_child = set(parents)
    for j, bi in enumerate(order):
        if j not in has_child:
            ends[j] = end_site_of(*drawn[bi].bounds())  # the drawn solid (a keel solid for the toes)
    return BvhSkeleton(tuple(names), tuple(parents), offsets, ends), order


def end_site_of(center, semi_axes) -> np.ndarray:
    """The far tip of a leaf body's ellipsoid (joint frame): along the axis on which the
    ellipsoid's centre lies farthest from the joint, away from the joint."""
    c, s = np.asarray(center, dtype=float), np.asarray(semi_axes, dtype=float)
    k = int(np.argmax(np.abs(c)))
    tip = c.copy()
    tip[k] += math.copysign(s[k], c[k]) if abs(c[k]) > 1e-9 else s[k]
    return tip


def euler_zyx(R: np.ndarray) -> np.ndarray:
    """Angles (T, 3) = (z, y, x) rad with R = Rz(z)·Ry(y)·Rx(x) for rotations (T, 3, 3),
    continuous over time."""
    R = np.asarray(R, dtype=float)
    sy = np.clip(-R[:, 2, 0], -1.0, 1.0)
    y = np.arcsin(sy)
    cy = np.cos(y)
    z = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    x = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    lock = cy < 1e-9
    if np.any(lock):  # gimbal lock: put everything into z, x = 0
        x = np.where(lock, 0.0, x)
        z = np.where(lock, np.arctan2(-R[:, 0, 1], R[:, 1, 1]), z)
    ang = np.stack([z, y, x], axis=1)
    for t in range(1, ang.shape[0]):  # pick the nearer of the two equivalent solutions
        a = ang[t]
        alt = np.array([a[0] + math.pi, math.pi - a[1], a[2] + math.pi])
        prev = ang[t - 1]
        d = lambda v: np.sum(np.abs((v - prev + math.pi) % (2 * math.pi) - math.pi))  # noqa: E731
        if d(alt) < d(a) - 1e-12:
            ang[t] = alt
        ang[t] = prev + (ang[t] - prev + math.pi) % (2 * math.pi) - math.pi  # unwrap
    return ang


def bvh_text(skel: BvhSkeleton, root_pos: np.ndarray, local_rot: np.ndarray, fps: float, units: str = "cm") -> str:
    """BVH file text from root positions (F, 3) m and local rotations (F, J, 3, 3), our axes."""
    if units not in UNITS:
        raise InputError(f"unknown BVH units {units!r} (known: {', '.join(UNITS)})")
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"BVH frame rate must be positive, got {fps}")
    scale = UNITS[units]
    F, J = local_rot.shape[:2]
    A = AXES
    children: dict[int, list[int]] = {j: [] for j in range(J)}
    for j, p in enumerate(skel.parents):
        if p >= 0:
            children[p].append(j)
    lines: list[str] = ["HIERARCHY"]
    chan_order: list[int] = []

    def fmt(v):
        return " ".join(f"{x:.6f}" for x in v)

    def emit(j, depth):
        ind = "\t" * depth
        if skel.parents[j] < 0:
            lines.append(f"{ind}ROOT {skel.names[j]}")
        else:
            lines.append(f"{ind}JOINT {skel.names[j]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}\tOFFSET {fmt(A @ skel.offsets[j] * scale)}")
        if skel.parents[j] < 0:
            lines.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation")
        else:
            lines.append(f"{ind}\tCHANNELS 3 Zrotation Yrotation Xrotation")
        chan_order.append(j)
        for c in children[j]:
            emit(c, depth + 1)
        if j in skel.end_sites:
            lines.append(f"{ind}\tEnd Site")
            lines.append(f"{ind}\t{{")
            lines.append(f"{ind}\t\tOFFSET {fmt(A @ skel.end_sites[j] * scale)}")
            lines.append(f"{ind}\t}}")
        lines.append(f"{ind}}}")

    roots = [j for j in range(J) if skel.parents[j] < 0]
    if len(roots) != 1:
        raise InputError(f"a BVH skeleton needs exactly one root joint, found {len(roots)}")
    emit(roots[0], 0)
    cols = []
    for j in chan_order:
        Rb = A @ local_rot[:, j] @ A.T  # (F, 3, 3) in file axes
        ang = np.degrees(euler_zyx(Rb))
        if skel.parents[j] < 0:
            cols.append(root_pos @ A.T * scale)
        cols.append(ang)
    data = np.concatenate(cols, axis=1)
    lines += ["MOTION", f"Frames: {F}", f"Frame Time: {1.0 / fps:.10f}"]
    lines += [" ".join(f"{x:.6f}" for x in row) for row in data]
    return "\n".join(lines) + "\n"


def resample_q(q: np.ndarray, source_fps: float, fps: float) -> np.ndarray:
    """Linear interpolation of q (T, n) from ``source_fps`` to ``fps`` over the same duration."""
    q = np.asarray(q, dtype=float)
    if abs(source_fps - fps) < 1e-12 * fps:
        return q
    T = q.shape[0]
    duration = (T - 1) / source_fps
    n = int(math.floor(duration * fps + 1e-9)) + 1
    ts = np.arange(n) / fps
    src = np.arange(T) / source_fps
    return np.stack([np.interp(ts, src, q[:, j]) for j in range(q.shape[1])], axis=1)


def export_bvh(path, track, fps: float, *, source_fps: float | None = None, units: str = "cm") -> Path:
    """Write one :class:`~scenegraph.export.usd.CharacterTrack` as a BVH file at ``fps``.

    ``track.q`` is sampled at ``source_fps`` (default: ``fps``, i.e. no resampling).
    The write is atomic.  Returns the path."""
    path = Path(path)
    fps = float(fps)
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"BVH frame rate must be positive, got {fps}")
    src = fps if source_fps is None else float(source_fps)
    q = np.asarray(track.q, dtype=float)
    if q.ndim != 2 or q.shape[1] != N_DOF or q.shape[0] < 1 or not np.all(np.isfinite(q)):
        raise InputError(f"character {track.name!r}: q must be a finite array of shape (T, {N_DOF})")
    q = resample_q(q, src, fps)
    ch = track.character
    skel, order = skeleton_of(ch)
    from scenegraph.export.usd import _local_transforms
    R, p = numeric_fk(ch, q)
    Rl, _ = _local_transforms(ch, order, R, p)
    text = bvh_text(skel, p[:, order[0]], Rl, fps, units)
    atomic_write(path, text, encoding="ascii")
    return path


def bvh_from_joint_transforms(path, names, parents, local: np.ndarray, fps: float, units: str = "cm",
                              end_sites: dict[int, np.ndarray] | None = None) -> Path:
    """Write a BVH from joint-local 4×4 column-vector transforms (F, J, 4, 4) in our axes
    (e.g. read back from a USD stage).  Offsets are the first frame's local translations."""
    local = np.asarray(local, dtype=float)
    offsets = local[0, :, :3, 3].copy()
    root = [j for j, p in enumerate(parents) if p < 0]
    if len(root) != 1:
        raise InputError(f"a BVH skeleton needs exactly one root joint, found {len(root)}")
    offsets[root[0]] = 0.0
    skel = BvhSkeleton(tuple(names), tuple(parents), offsets, dict(end_sites or {}))
    text = bvh_text(skel, local[:, root[0], :3, 3], local[:, :, :3, :3], fps, units)
    atomic_write(Path(path), text, encoding="ascii")
    return Path(path)


__all__ += ["resample_q", "bvh_from_joint_transforms", "end_site_of"]
