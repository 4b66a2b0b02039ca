"""Motion-capture import: BVH clip → our axes, metres, floor at z = 0, 30 fps → fitted q.

Pipeline (:func:`load_clip` runs all of it):

1. :func:`~scenegraph.mocap.bvh.read_bvh` parses the file strictly (errors carry file and line).
2. A **rig** (``scenarios/rigs/*.yaml``, see ``cmu.yaml``) is matched against the joint
   names: it gives the unit, the axes and the map BVH joint → point of our character.
   A JOINT the matched variant does not know is rejected at its line.
3. :func:`read_clip` skips a leading T-pose frame (cgspeed conversions put one in front),
   resamples the local joint rotations by quaternion slerp (never Euler lerp: root Euler
   angles of CMU files pass near gimbal lock) to ``fps``, runs forward kinematics, converts
   axes (file forward/left/up → our +X/+Y/+Z, a proper rotation) and units, and estimates
   the floor height (5th percentile of the rig's floor points over the whole clip), which is
   subtracted, so the floor is z = 0.  It also estimates the performer's stature as the
   least-squares scale of our character's segment lengths to the clip's.
4. :func:`~scenegraph.mocap.retarget.retarget` fits our character, scaled to that stature, to the
   mapped points of every frame at once (CasADi + IPOPT, joint limits kept, a small
   smoothness term), giving q (T, 35).
5. :func:`~scenegraph.mocap.contacts.detect_footsteps` finds per-foot contact intervals.
6. :func:`reconstruct` (NIO paper, Appendix A) turns the fitted clip into a smooth
   :class:`~scenegraph.model.motion.Motion` whose root residual is (softly) zero, with contact
   forces at the detected contacts; :func:`reconstruct_clip` also returns the forces,
   footprints, fit error and residual.

Nothing here writes files.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from scenarios.errors import InputError, Location
from scenarios.yamlio import load_model

from scenegraph.model.body import Character, default_character, make_character, PRESETS
from scenegraph.mocap.bvh import (BvhFile, END_SUFFIX, bvh_forward_kinematics, bvh_local_pose, read_bvh, resample_pose)
from scenegraph.mocap.retarget import PointSpec, Reconstruction, point_name as _point_name, point_positions, reconstruct, \
    reconstruct_clip, retarget

__all__ = ["Rig", "RigVariant", "load_rig", "RIG_DIR", "ClipData", "MocapClip", "read_clip", "load_clip",
           "detect_tpose", "estimate_floor", "estimate_stature", "axes_matrix", "PointSpec",
           "reconstruct", "reconstruct_clip", "Reconstruction"]

import scenarios as _scenarios

RIG_DIR = Path(_scenarios.__file__).resolve().parent / "rigs"  # bundled rig files
DEFAULT_RIG = "cmu"
MIN_STATURE, MAX_STATURE = 0.5, 2.5  # m: the statures a character can be built at
_AXES = {"+X": (0, 1.0), "-X": (0, -1.0), "+Y": (1, 1.0), "-Y": (1, -1.0), "+Z": (2, 1.0), "-Z": (2, -1.0)}


# --- rig files -----------------------------------------------------------------------------

class RigAxes(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    forward: Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
    left: Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]
    up: Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]

    @model_validator(mode="after")
    def _proper(self):
        M = axes_matrix(self)
        if abs(abs(np.linalg.det(M)) - 1.0) > 1e-9:
            raise ValueError("forward, left and up must be three different file axes")
        if np.linalg.det(M) < 0:
            raise ValueError("forward, left, up would mirror the motion (left-handed); flip one axis")
        return self


class SegmentSpec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    between: tuple[str, str]
    weight: float = Field(1.0, gt=0)


class Rig(BaseModel):
    """A BVH skeleton family and its map to our character (see ``scenarios/rigs/cmu.yaml``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str
    unit_m: float = Field(gt=0, le=100)
    axes: RigAxes
    variants: dict[str, dict[str, str | PointSpec | None]] = Field(min_length=1)
    weights: dict[str, float] = Field(default_factory=dict)
    floor: list[str] = Field(min_length=1)
    stature: list[SegmentSpec] = Field(min_length=1)
    source: str | None = None

    @field_validator("variants")
    @classmethod
    def _points_known(cls, v):
        for vname, jmap in v.items():
            if not jmap:
                raise ValueError(f"variant {vname!r} maps no joints")
            seen: set[str] = set()
            for bvh_name, ours in jmap.items():
                if ours is None:
                    continue
                name = ours if isinstance(ours, str) else ours.name
                if isinstance(ours, str):
                    _check_point(ours)
                if name in seen:
                    raise ValueError(f"variant {vname!r}: point {name!r} is mapped twice")
                seen.add(name)
        return v

    @field_validator("weights")
    @classmethod
    def _weights_ok(cls, v):
        for k, w in v.items():
            if not (0 <= w <= 1e3):
                raise ValueError(f"weight of {k!r} must be in [0, 1000], got {w}")
        return v

    @model_validator(mode="after")
    def _refs(self):
        for vname, jmap in self.variants.items():
            mapped = {_point_name(o) for o in jmap.values() if o}
            for k in self.weights:
                if k not in mapped:
                    raise ValueError(f"weight given for {k!r}, which variant {vname!r} does not map")
            for p in self.floor:
                if p not in mapped:
                    raise ValueError(f"floor point {p!r} is not mapped in variant {vname!r}")
            for s in self.stature:
                for p in s.between:
                    if p not in mapped:
                        raise ValueError(f"stature point {p!r} is not mapped in variant {vname!r}")
        return self

    def match(self, bvh: BvhFile) -> "RigVariant":
        """The variant that knows the most of the file's joints; every JOINT must be known."""
        names = [j.name for j in bvh.joints if not j.end_site]
        best = max(self.variants, key=lambda v: sum(n in self.variants[v] for n in names))
        jmap = self.variants[best]
        for j in bvh.joints:
            if not j.end_site and j.name not in jmap:
                known = ", ".join(k for k in jmap if not k.endswith(END_SUFFIX))
                raise InputError(f"unknown joint {j.name!r} for rig {self.name}/{best} (known: {known})",
                                 Location(bvh.path, j.line))
        present = {j.name for j in bvh.joints}
        mapped = [(b, o) for b, o in jmap.items() if o is not None]
        missing = [b for b, _ in mapped if b not in present]
        if missing:
            root = bvh.joints[0]
            raise InputError(f"rig {self.name}/{best} needs joints missing from the file: {', '.join(missing)}",
                             Location(bvh.path, root.line))
        return RigVariant(self, best, tuple(o for _, o in mapped), tuple(bvh.index(b) for b, _ in mapped))


@dataclass(frozen=True)
class RigVariant:
    """A rig matched to one file: our points and the BVH joint index of each."""

    rig: Rig
    name: str
    specs: tuple[PointSpec | str, ...]  # our points, in fit order (str: handle or origin:BODY)
    joint_index: tuple[int, ...]  # index into BvhFile.joints

    @property
    def points(self) -> tuple[str, ...]:
        return tuple(_point_name(s) for s in self.specs)

    @property
    def label(self) -> str:
        return f"{self.rig.name}/{self.name}"

    def weight(self, point: str) -> float:
        return float(self.rig.weights.get(point, 1.0))


def _check_point(p: str) -> None:
    ch = default_character()  # the default character knows every handle and body name
    if p.startswith("origin:"):
        body = p[len("origin:"):]
        if body not in {b.name for b in ch.bodies}:
            raise ValueError(f"unknown body {body!r} in {p!r}")
    elif p not in {h.name for h in ch.handles}:
        raise ValueError(f"unknown point {p!r}: not a handle of our character nor 'origin:BODY'")


def load_rig(rig: str | os.PathLike | Rig | None = None) -> Rig:
    """A rig by name (``scenarios/rigs/NAME.yaml``), by path, or the default CMU rig."""
    if isinstance(rig, Rig):
        return rig
    if rig is None:
        rig = DEFAULT_RIG
    p = Path(rig)
    if p.suffix not in (".yaml", ".yml"):
        p = RIG_DIR / f"{rig}.yaml"
        if not p.exists():
            known = ", ".join(sorted(x.stem for x in RIG_DIR.glob("*.yaml")))
            raise InputError(f"unknown rig {str(rig)!r} (known: {known})")
    return load_model(Rig, p)


def axes_matrix(axes: RigAxes) -> np.ndarray:
    """3×3 matrix A with p_ours = A @ p_file (rows: our X, Y, Z)."""
    A = np.zeros((3, 3))
    for row, a in enumerate((axes.forward, axes.left, axes.up)):
        col, sign = _AXES[a]
        A[row, col] = sign
    return A


# --- clip import ---------------------------------------------------------------------------

@dataclass(frozen=True)
class ClipData:
    """A BVH clip in our world (Z up, metres, floor at z = 0), resampled, not yet fitted.

    ``joints`` holds every BVH joint and End Site (``joint_names``); ``targets`` the rig's
    mapped points (``target_names`` are our point names) with ``target_weights``.
    ``frame_range`` gives the first and last *source* frame numbers used (inclusive).
    """

    file: str
    rig: str
    fps: float
    times: np.ndarray  # (T,) s, 0 at the first used source frame
    joints: np.ndarray  # (T, J, 3) m
    joint_names: tuple[str, ...]
    targets: np.ndarray  # (T, K, 3) m
    target_names: tuple[str, ...]
    target_weights: np.ndarray  # (K,)
    target_specs: tuple  # (K,) str (handle, origin:BODY) or PointSpec
    floor_height: float  # m, along our up axis, before it was subtracted
    performer_height: float  # m, stature in our character's proportions
    frame_range: tuple[int, int]
    source_fps: float
    source_frames: int
    tpose_skipped: bool

    @property
    def n_frames(self) -> int:
        return int(self.times.shape[0])

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0]) if len(self.times) else 0.0

    def joint(self, name: str) -> np.ndarray:
        """(T, 3) positions of a BVH joint (or ``Name/End``)."""
        return self.joints[:, self.joint_names.index(name)]

    def target(self, point: str) -> np.ndarray:
        """(T, 3) positions of the clip point mapped to our point ``point``."""
        return self.targets[:, self.target_names.index(point)]


def detect_tpose(positions_m: np.ndarray, threshold: float = 0.20) -> bool:
    """True when frame 0 is far from frame 1 in root-relative joint positions (m).

    cgspeed conversions prepend a T-pose whose root position equals frame 1's, so the test
    uses positions relative to the root: the arms move ~0.7 m between the T-pose and the
    first motion frame, against ~1–3 cm between captured frames.
    """
    if positions_m.shape[0] < 3:
        return False
    rel = positions_m - positions_m[:, :1]
    d01 = np.max(np.linalg.norm(rel[0] - rel[1], axis=-1))
    n = min(positions_m.shape[0] - 1, 20)
    typ = np.median([np.max(np.linalg.norm(rel[k + 1] - rel[k], axis=-1)) for k in range(1, n)])
    return bool(d01 > threshold and d01 > 8.0 * typ)


def estimate_floor(heights: np.ndarray, percentile: float = 5.0) -> float:
    """Floor height (m): a low percentile of the floor points' heights over all frames."""
    return float(np.percentile(np.asarray(heights).ravel(), percentile))


def estimate_stature(targets: np.ndarray, specs: tuple, rig: Rig, preset: str = "adult_male") -> float:
    """Stature H (m) minimising Σ w (c·H − L)² over the rig's stature segments, where L is the
    clip's segment length (median over frames) and c·H our character's at height H."""
    from scenegraph.model.body import standing_pose

    ch1 = make_character(preset, height=1.0, mass=PRESETS[preset].mass)
    target_names = [_point_name(p) for p in specs]
    ours = dict(zip(target_names, point_positions(ch1, tuple(specs), standing_pose(ch1))))
    num = den = 0.0
    for s in rig.stature:
        a, b = s.between
        L = float(np.median(np.linalg.norm(targets[:, target_names.index(a)] - targets[:, target_names.index(b)],
                                           axis=-1)))
        c = float(np.linalg.norm(ours[a] - ours[b]))
        num += s.weight * c * L
        den += s.weight * c * c
    return num / den


def read_clip(path: str | os.PathLike, rig: str | os.PathLike | Rig | None = None, fps: float = 30.0,
              frames: tuple[int | None, int | None] | None = None, skip_tpose: bool | None = None,
              preset: str = "adult_male") -> ClipData:
    """Import a BVH clip into our world without fitting our character.

    ``frames`` = (first, stop) source frame numbers, Python-slice style (stop exclusive,
    None = to the end), counted in the file (frame 0 is the file's first frame).  With
    ``skip_tpose`` None the T-pose is detected; True forces skipping frame 0.
    """
    bvh = read_bvh(path)
    rig_ = load_rig(rig)
    var = rig_.match(bvh)
    if not (1.0 <= fps <= 1000.0):
        raise InputError(f"fps must be between 1 and 1000, got {fps}")
    A = axes_matrix(rig_.axes) * rig_.unit_m
    quats, trans = bvh_local_pose(bvh)
    parents = [j.parent for j in bvh.joints]
    pos_src, _ = bvh_forward_kinematics(parents, quats, trans)
    pos_src = pos_src @ A.T
    tpose = detect_tpose(pos_src) if skip_tpose is None else bool(skip_tpose)
    first_motion = 1 if tpose else 0
    F = bvh.n_frames
    if frames is None:
        a, b = first_motion, F
    else:
        a = first_motion if frames[0] is None else int(frames[0])
        b = F if frames[1] is None else int(frames[1])
        if a < 0:
            a += F
        if b < 0:
            b += F
        if not (0 <= a < b <= F):
            raise InputError(f"frames {frames[0]}:{frames[1]} outside the clip's frames 0:{F}",
                             Location(str(path), bvh.frames_line))
        if tpose and a == 0:
            raise InputError("frame 0 is a T-pose, not motion; start at frame 1", Location(str(path), bvh.motion_line))
    if b - a < 2:
        raise InputError(f"need at least 2 motion frames, got {b - a}", Location(str(path), bvh.frames_line))

    # Floor from the whole motion at the source rate (a short window may lack stances).
    floor_idx = [var.joint_index[var.points.index(p)] for p in rig_.floor]
    floor = estimate_floor(pos_src[first_motion:, floor_idx, 2])

    dt = bvh.dt
    t_src = (np.arange(a, b) - a) * dt
    n_new = int(np.floor(t_src[-1] * fps + 1e-6)) + 1
    t_new = np.arange(n_new) / fps
    q_new, tr_new = resample_pose(quats[a:b], trans[a:b], t_src, t_new)
    pos, _ = bvh_forward_kinematics(parents, q_new, tr_new)
    pos = pos @ A.T
    pos[..., 2] -= floor
    targets = pos[:, list(var.joint_index)]
    weights = np.array([var.weight(p) for p in var.points])
    H = estimate_stature(targets, var.specs, rig_, preset)
    if not (MIN_STATURE <= H <= MAX_STATURE):  # what make_character accepts (BodySpec.height)
        raise InputError(f"the performer's segment lengths give a stature of {H:.3g} m, outside "
                         f"{MIN_STATURE:g}–{MAX_STATURE:g} m: wrong OFFSETs, or a unit the rig "
                         f"{rig_.name} (1 unit = {rig_.unit_m:g} m) does not expect", Location(str(path), bvh.joints[0].line))
    for arr in (t_new, pos, targets, weights):
        arr.setflags(write=False)
    return ClipData(str(path), var.label, float(fps), t_new, pos, tuple(bvh.joint_names), targets, var.points,
                    weights, var.specs, floor, H, (a, b - 1), bvh.fps, F, tpose)


# --- fitted clip ---------------------------------------------------------------------------

def _from_data(name: str) -> property:
    """A read-only attribute of a :class:`MocapClip` that is its ``data``'s attribute ``name``."""
    return property(lambda self: getattr(self.data, name), doc=f"``data.{name}``")


@dataclass(frozen=True)
class MocapClip:
    """A mocap clip with our character fitted to it.

    ``q`` (T, 35) follows body.py's DOF order at ``fps``; ``data`` keeps the imported clip
    (source joint positions, floor, stature, frames); ``fit_error`` (T, K) is the distance
    (m) of each fitted point to its clip point.
    """

    data: ClipData
    character: Character
    q: np.ndarray
    fit_error: np.ndarray
    solver: dict = field(default_factory=dict)

    # conveniences mirroring the brief's field list, read from ``data``: fps (Hz), times (s,
    # (T,)), file, floor_height (m), performer_height (m), frame_range (first, last source
    # frame), joints (T, J, 3) m, n_frames, duration (s)
    fps = _from_data("fps")
    times = _from_data("times")
    file = _from_data("file")
    floor_height = _from_data("floor_height")
    performer_height = _from_data("performer_height")
    frame_range = _from_data("frame_range")
    joints = _from_data("joints")
    n_frames = _from_data("n_frames")
    duration = _from_data("duration")

    def mean_fit_error(self, weighted: bool = False) -> float:
        if weighted:
            w = self.data.target_weights
            return float(np.sum(self.fit_error * w) / (w.sum() * self.fit_error.shape[0]))
        return float(self.fit_error.mean())

    def handle_positions(self, names) -> np.ndarray:
        """(T, len(names), 3) positions of our points (handles, origin:BODY, PointSpec) over the clip."""
        return point_positions(self.character, tuple(names), self.q)


def load_clip(path: str | os.PathLike, rig: str | os.PathLike | Rig | None = None, fps: float = 30.0,
              frames: tuple[int | None, int | None] | None = None, skip_tpose: bool | None = None,
              preset: str = "adult_male", height: float | None = None, mass: float | None = None,
              smoothness: float = 1e-3) -> MocapClip:
    """Import a BVH clip and fit our character to every frame.  See :func:`read_clip`.

    The character is ``make_character(preset, height, mass)`` with ``height`` defaulting to
    the clip's estimated stature and ``mass`` to the preset's body-mass index at that height.
    """
    data = read_clip(path, rig, fps, frames, skip_tpose, preset)
    H = data.performer_height if height is None else float(height)
    if mass is None:
        p = PRESETS[preset]
        mass = p.mass * (H / p.height) ** 2
    ch = make_character(preset, height=H, mass=mass)
    q, fit_error, info = retarget(data, ch, smoothness=smoothness)
    return MocapClip(data, ch, q, fit_error, info)
