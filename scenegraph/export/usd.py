"""USD stage export: one UsdSkel character per track, markers, debug forces, a camera.

Layout of a stage written here (``NAME`` is a character's prim-safe name)::

    /World                         Xform, the default prim (no transform ops)
      /NAME                        SkelRoot (no transform ops)
        /NAME_Skeleton             Skeleton: 18 joints, bind = rest = the standing pose
          /NAME_Animation          SkelAnimation: translations float3[], rotations quatf[],
                                   scales half3[], a time sample at every frame
        /NAME_pelvis ...           Mesh per body: an ellipsoid, rigidly skinned (constant
                                   jointIndices / jointWeights) to its joint
      /Markers/NAME                Cylinder (footprint discs) or Sphere (goals and others)
      /Looks/...                   UsdPreviewSurface materials (one per colour)
      /Debug/NAME                  BasisCurves force arrows (purpose = guide), optional
      /Camera                      a static camera that frames the whole action

Conventions and the facts they follow (issue 6):
  * Stage: ``metersPerUnit = 1``, ``upAxis = Z``, ``timeCodesPerSecond = framesPerSecond =
    fps``; time code ``c`` is world time ``c / fps`` s.  Blender maps a time code to a frame
    1:1 and ignores the rate, so time codes are integers: a track's ``start_time`` must
    be a whole number of frames.
  * Joint paths are the body tree (``pelvis/abdomen/thorax/...``), parents before children;
    leaf names are the body names (unique per skeleton, well under 63 bytes) because
    Blender names bones by the last path component.  Prim names carry the character's name
    because Blender turns prim names into global object names.
  * Meshes sit directly under the SkelRoot beside the Skeleton; their points are in the
    skeleton's space at the bind pose and ``geomBindTransform`` is the identity (Blender
    uses it as the mesh object's local matrix).
  * Rotations are ``quatf`` (w, x, y, z as ``Gf.Quatf`` prints them; note that numpy
    buffers for ``Vt.QuatfArray`` are laid out x, y, z, w), translations ``float3``,
    scales ``half3``.  Gf matrices are row-vector: a numpy column-vector transform
    ``M`` is stored as ``M.T``.
  * Float precision: UsdSkel stores translations in 32-bit floats, so a joint at distance
    ``d`` from the origin is reproduced to about ``6e-8 * d`` m (1e-6 m up to ~15 m).
  * Marker visibility is time-sampled (hidden outside a marker's interval) for viewers that
    honour it (usdview, Houdini); Blender does not import animated visibility, so each
    marker also carries ``compose:startTime`` / ``compose:endTime`` (s).

The write is atomic: the stage is composed in memory, exported into a temporary directory
next to the destination, packaged there for ``.usdz``, and renamed over the destination.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from scenarios.atomic import atomic_path
from scenarios.errors import ComposeError, InputError
from scenarios.versions import compose_version

from scenegraph.model.body import (N_DOF, Character, box_inertia, carried_half_extents, drawn_shapes,
                                   ellipsoid_inertia, keel_points, standing_pose)
from scenegraph.model.kinematics import numeric_fk
from scenegraph.model.rotations import quat_from_matrix

__all__ = [
    "CharacterTrack", "Marker", "ForceArrow", "export_usd", "joint_paths", "validate_stage",
    "character_prim_name", "SUPPORTED_EXTENSIONS", "readback_errors", "build_stage",
]

SUPPORTED_EXTENSIONS = (".usda", ".usdc", ".usdz")
MAX_NAME_BYTES = 63  # Blender's object / bone name limit

# A small palette (linear RGB) for characters; markers by kind.
_CHARACTER_COLORS = [
    (0.80, 0.30, 0.20), (0.20, 0.45, 0.80), (0.25, 0.65, 0.30), (0.75, 0.60, 0.15),
    (0.55, 0.30, 0.70), (0.20, 0.65, 0.65),
]
_MARKER_COLORS = {
    "footprint": (0.15, 0.15, 0.15), "goal": (0.95, 0.75, 0.10), "contact": (0.85, 0.20, 0.20),
}
_DEFAULT_MARKER_COLOR = (0.5, 0.5, 0.9)
_GROUND_COLOR = (0.55, 0.5, 0.42)  # ramps and slopes


@dataclass(frozen=True, eq=False)
class CharacterTrack:
    """One character's motion as frames: ``q[k]`` is the pose at ``start_time + k / fps``.

    ``name`` becomes the prim name (made a valid identifier); ``color`` is optional RGB.
    """

    name: str
    character: Character
    q: np.ndarray  # (T, 35)
    start_time: float = 0.0
    color: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Marker:
    """A footprint, goal or other point of interest on the stage.

    ``kind`` "footprint" gives a flat disc on the ground at ``position`` (its z is the
    ground height), anything else a sphere centred at ``position``.  ``interval`` is the
    world-time interval (s) during which the marker applies, or None for always.
    """

    name: str
    kind: str
    position: tuple[float, float, float]
    interval: tuple[float, float] | None = None
    radius: float = 0.06
    character: str | None = None


@dataclass(frozen=True, eq=False)
class ForceArrow:
    """A time-varying force drawn as a line from ``origins[k]`` along ``vectors[k] * scale``.

    ``origins`` and ``vectors`` (N) are sampled at the export frames, from ``start_time``.
    """

    name: str
    origins: np.ndarray  # (T, 3) m
    vectors: np.ndarray  # (T, 3) N
    kind: str = "force"
    scale: float = 1e-3  # m per N
    start_time: float = 0.0
    character: str | None = None  # who feels it (written as compose:character; compose audit reads it)


# --- helpers -----------------------------------------------------------------------------------

def _usd_version() -> str:
    from pxr import Usd
    return ".".join(str(v) for v in Usd.GetVersion())


def character_prim_name(name: str) -> str:
    """The prim-safe name used for a character (``Tf.MakeValidIdentifier``)."""
    from pxr import Tf
    return Tf.MakeValidIdentifier(str(name)) if name else "character"


def _topological_bodies(ch: Character) -> list[int]:
    """Body indices ordered parents before children (stable w.r.t. ``ch.bodies``)."""
    names = [b.name for b in ch.bodies]
    done: set[str] = set()
    order: list[int] = []
    remaining = list(range(len(names)))
    while remaining:
        progressed = False
        for i in list(remaining):
            par = ch.bodies[i].parent
            if par is None or par in done:
                order.append(i)
                done.add(names[i])
                remaining.remove(i)
                progressed = True
        if not progressed:
            raise InputError(f"character body tree has a cycle or unknown parent among {[names[i] for i in remaining]}")
    return order


def joint_paths(ch: Character) -> tuple[list[int], list[str]]:
    """(body indices in skeleton order, UsdSkel joint paths) — parents before children."""
    order = _topological_bodies(ch)
    by_name = {b.name: b for b in ch.bodies}
    paths: dict[str, str] = {}
    for i in order:
        b = ch.bodies[i]
        paths[b.name] = b.name if b.parent is None else f"{paths[by_name[b.parent].name]}/{b.name}"
    return order, [paths[ch.bodies[i].name] for i in order]


def _continuous_quats(q: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 (time) so consecutive quaternions lie in one hemisphere
    (interpolating between time codes then takes the short way)."""
    q = q.copy()
    if q.shape[0]:
        q[0][q[0, ..., 0] < 0] *= -1  # the first frame: w >= 0
    for t in range(1, q.shape[0]):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0
        q[t][flip] *= -1
    return q


def _gf_matrices(R: np.ndarray, p: np.ndarray):
    """Vt.Matrix4dArray from rotations (N,3,3) and translations (N,3) (column-vector form)."""
    from pxr import Vt
    n = R.shape[0]
    M = np.zeros((n, 4, 4))
    M[:, :3, :3] = R
    M[:, :3, 3] = p
    M[:, 3, 3] = 1.0
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(M.transpose(0, 2, 1)))


def _local_transforms(ch: Character, order: list[int], R: np.ndarray, p: np.ndarray):
    """Joint-local rotations/translations (T, J, 3, 3), (T, J, 3) in skeleton order from body
    world transforms (T, nb, 3, 3), (T, nb, 3)."""
    idx = {b.name: i for i, b in enumerate(ch.bodies)}
    T = R.shape[0]
    J = len(order)
    Rl = np.empty((T, J, 3, 3))
    tl = np.empty((T, J, 3))
    for j, bi in enumerate(order):
        par = ch.bodies[bi].parent
        if par is None:
            Rl[:, j] = R[:, bi]
            tl[:, j] = p[:, bi]
        else:
            pi = idx[par]
            RpT = np.swapaxes(R[:, pi], -1, -2)
            Rl[:, j] = RpT @ R[:, bi]
            tl[:, j] = np.einsum("tij,tj->ti", RpT, p[:, bi] - p[:, pi])
    return Rl, tl


def ellipsoid_mesh(center, semi_axes, n_around: int = 16, n_rings: int = 10):
    """A UV ellipsoid: points (N,3), normals (N,3), faceVertexCounts, faceVertexIndices.

    Poles on the local z axis; faces wind counter-clockwise seen from outside (USD's default
    right-handed orientation)."""
    c = np.asarray(center, dtype=float)
    s = np.asarray(semi_axes, dtype=float)
    units = [np.array([0.0, 0.0, 1.0])]
    for i in range(1, n_rings):
        th = math.pi * i / n_rings
        for k in range(n_around):
            ph = 2 * math.pi * k / n_around
            units.append(np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]))
    units.append(np.array([0.0, 0.0, -1.0]))
    U = np.array(units)
    pts = c + U * s
    nrm = U / (s * s)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    counts: list[int] = []
    idx: list[int] = []
    last = len(units) - 1

    def ring(i, k):  # i = 1..n_rings-1
        return 1 + (i - 1) * n_around + (k % n_around)

    for k in range(n_around):  # top cap
        counts.append(3)
        idx += [0, ring(1, k), ring(1, k + 1)]
    for i in range(1, n_rings - 1):
        for k in range(n_around):
            counts.append(4)
            idx += [ring(i, k), ring(i + 1, k), ring(i + 1, k + 1), ring(i, k + 1)]
    for k in range(n_around):  # bottom cap
        counts.append(3)
        idx += [last, ring(n_rings - 1, k + 1), ring(n_rings - 1, k)]
    return pts, nrm, counts, idx


def keel_mesh(keel_center, semi_axes, n_around: int = 16, n_rings: int = 10, pitch: float = 0.0):
    """A keel solid (see :class:`~scenegraph.model.body.DrawnShape`): points (N,3), normals (N,3),
    counts, indices.  ``keel_center`` is the keel's midpoint, ``semi_axes`` (a, b, c),
    ``pitch`` the turn of its frame about y.  The two ends (on the keel) are single vertices
    and every cross-section ring has a vertex on the keel, so the keel is drawn exactly.
    Faces wind outward; normals are the section ellipses' (a fair shading normal)."""
    pts = keel_points(keel_center, semi_axes, pitch, n_around, n_rings)
    a, b, c = (max(float(x), 1e-12) for x in semi_axes)
    ca, sa = math.cos(pitch), math.sin(pitch)
    R = np.array([[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]])
    L = (pts - np.asarray(keel_center, float)) @ R  # local coordinates
    n_len = max(2, int(n_rings))
    sig = np.sqrt(np.clip(1.0 - (L[:, 0] / a) ** 2, 1e-12, None))
    nrm = np.stack([-L[:, 0] / (a * a) * 0.5, L[:, 1] / (b * b * sig), (L[:, 2] - c * sig) / (c * c * sig)], 1)
    nrm[0], nrm[-1] = (-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)) @ R.T
    last = len(pts) - 1
    counts: list[int] = []
    idx: list[int] = []

    def ring(i, k):
        return 1 + (i - 1) * n_around + (k % n_around)

    for k in range(n_around):  # the rear end
        counts.append(3)
        idx += [0, ring(1, k + 1), ring(1, k)]
    for i in range(1, n_len - 1):
        for k in range(n_around):
            counts.append(4)
            idx += [ring(i, k), ring(i, k + 1), ring(i + 1, k + 1), ring(i + 1, k)]
    for k in range(n_around):  # the front end
        counts.append(3)
        idx += [last, ring(n_len - 1, k), ring(n_len - 1, k + 1)]
    return pts, nrm, counts, idx


def box_mesh(center, half_extents):
    """A closed box: points (8,3), normals (8,3) (corner directions), counts, indices."""
    c = np.asarray(center, float)
    h = np.asarray(half_extents, float)
    U = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return c + U * h, U / np.sqrt(3.0), [4] * 6, [i for f in faces for i in f]


def _to_vt(value: Any):
    """Convert plain Python metadata into something a layer's customLayerData can hold."""
    from pxr import Vt
    if isinstance(value, dict):
        return {str(k): _to_vt(v) for k, v in value.items() if v is not None}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, (str, os.PathLike)):
        return str(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        vals = list(value)
        if all(isinstance(v, str) for v in vals):
            return Vt.StringArray(vals)
        if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in vals):
            return Vt.DoubleArray([float(v) for v in vals])
    return json.dumps(value, default=str, sort_keys=True)


def _check_name_bytes(name: str, what: str) -> None:
    if len(name.encode("utf-8")) > MAX_NAME_BYTES:
        raise InputError(f"{what} name {name!r} is longer than {MAX_NAME_BYTES} bytes (Blender truncates it)")


# --- stage building ----------------------------------------------------------------------------

@dataclass
class _Prepared:
    track: CharacterTrack
    prim: str
    start_code: int
    order: list[int]
    paths: list[str]
    R: np.ndarray  # (T, nb, 3, 3) body world rotations
    p: np.ndarray  # (T, nb, 3) body world origins
    color: tuple[float, float, float]
    extents: np.ndarray = field(default=None)  # (T, 2, 3)


def _start_code(start_time: float, fps: float, what: str) -> int:
    c = float(start_time) * fps
    ci = int(round(c))
    if abs(c - ci) > 1e-6:
        raise InputError(f"{what}: start time {start_time} s is not a whole number of frames at {fps} fps")
    return ci


def _prepare(tracks: Sequence[CharacterTrack], fps: float) -> list[_Prepared]:
    if not tracks:
        raise InputError("export_usd needs at least one character track")
    seen: dict[str, str] = {}
    out = []
    for n, tr in enumerate(tracks):
        q = np.asarray(tr.q, dtype=float)
        if q.ndim != 2 or q.shape[1] != N_DOF or q.shape[0] < 1:
            raise InputError(f"character {tr.name!r}: q must have shape (T, {N_DOF}), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise InputError(f"character {tr.name!r}: q contains NaN or inf")
        prim = character_prim_name(tr.name)
        if prim in seen:
            raise InputError(f"characters {seen[prim]!r} and {tr.name!r} map to the same prim name {prim!r}")
        seen[prim] = tr.name
        _check_name_bytes(prim + "_Animation", f"character {tr.name!r}: prim")
        order, paths = joint_paths(tr.character)
        for b in tr.character.bodies:
            _check_name_bytes(f"{prim}_{b.name}", f"character {tr.name!r}: mesh")
        R, p = numeric_fk(tr.character, q)
        color = tuple(tr.color) if tr.color is not None else _CHARACTER_COLORS[n % len(_CHARACTER_COLORS)]
        prep = _Prepared(tr, prim, _start_code(tr.start_time, fps, f"character {tr.name!r}"), order, paths, R, p, color)
        prep.extents = _world_extents(tr.character, R, p)
        out.append(prep)
    return out


def _world_extents(ch: Character, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Exact axis-aligned bounds (T, 2, 3) of all ellipsoids of a character over time."""
    C = np.array([b.center for b in ch.bodies])  # (nb, 3)
    S = np.array([b.semi_axes for b in ch.bodies])
    cw = p + np.einsum("tbij,bj->tbi", R, C)
    half = np.sqrt(np.einsum("tbij,bj->tbi", R * R, S * S))
    return np.stack([(cw - half).min(axis=1), (cw + half).max(axis=1)], axis=1)


def _define_material(stage, path: str, color) -> Any:
    from pxr import Gf, Sdf, UsdShade
    mat = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return mat


def _bind_material(prim, mat) -> None:
    from pxr import UsdShade
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)


def _write_character(stage, prep: _Prepared, looks: str, segments: tuple[int, int]) -> None:
    from pxr import Gf, Sdf, UsdGeom, UsdPhysics, UsdSkel, Vt
    ch = prep.track.character
    root_path = f"/World/{prep.prim}"
    skel_root = UsdSkel.Root.Define(stage, root_path)
    skel_path = f"{root_path}/{prep.prim}_Skeleton"
    skel = UsdSkel.Skeleton.Define(stage, skel_path)
    anim = UsdSkel.Animation.Define(stage, f"{skel_path}/{prep.prim}_Animation")
    order, paths = prep.order, prep.paths
    J = len(order)

    # Bind = rest = the standing pose (all joint frames parallel to the world).
    q_bind = standing_pose(ch)
    Rb, pb = numeric_fk(ch, q_bind[None, :])
    Rl_b, tl_b = _local_transforms(ch, order, Rb, pb)
    joint_tokens = Vt.TokenArray(paths)
    skel.CreateJointsAttr(joint_tokens)
    skel.CreateJointNamesAttr(Vt.TokenArray([ch.bodies[i].name for i in order]))
    skel.CreateBindTransformsAttr(_gf_matrices(Rb[0][order], pb[0][order]))
    skel.CreateRestTransformsAttr(_gf_matrices(Rl_b[0], tl_b[0]))
    skel_binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())
    skel_binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    for attr, val in (("compose:character", prep.track.name), ("compose:preset", ch.preset)):
        skel.GetPrim().CreateAttribute(attr, Sdf.ValueTypeNames.String, custom=True).Set(val)
    skel.GetPrim().CreateAttribute("compose:height", Sdf.ValueTypeNames.Double, custom=True).Set(float(ch.height))
    # compose:mass is everything the dynamics move (the body and its carried loads, kg)
    skel.GetPrim().CreateAttribute("compose:mass", Sdf.ValueTypeNames.Double, custom=True).Set(float(ch.total_mass))
    skel.GetPrim().CreateAttribute("compose:bodyMass", Sdf.ValueTypeNames.Double, custom=True).Set(float(ch.mass))
    skel.GetPrim().CreateAttribute("compose:carriedMass", Sdf.ValueTypeNames.Double, custom=True).Set(
        float(sum(m for _, m in ch.loads)))

    # Animation: one sample per frame for translations, rotations and scales.
    anim.CreateJointsAttr(joint_tokens)
    Rl, tl = _local_transforms(ch, order, prep.R, prep.p)
    quat = _continuous_quats(quat_from_matrix(Rl))  # (T, J, 4) w, x, y, z
    xyzw = np.ascontiguousarray(np.concatenate([quat[..., 1:], quat[..., :1]], axis=-1).astype(np.float32))
    trans = np.ascontiguousarray(tl.astype(np.float32))
    ones = Vt.Vec3hArray.FromNumpy(np.ones((J, 3), dtype=np.float16))
    ta, ra, sa = anim.CreateTranslationsAttr(), anim.CreateRotationsAttr(), anim.CreateScalesAttr()
    ext_attr = skel_root.CreateExtentAttr()  # SkelRoot is Boundable: time-varying bounds of the skinned body
    for k in range(quat.shape[0]):
        code = prep.start_code + k
        ta.Set(Vt.Vec3fArray.FromNumpy(trans[k]), code)
        ra.Set(Vt.QuatfArray.FromNumpy(xyzw[k]), code)  # numpy layout of Gf.Quatf is (x, y, z, w)
        sa.Set(ones, code)
        lo, hi = prep.extents[k]
        ext = Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))])
        ext_attr.Set(ext, code)

    # Meshes: one solid per body (body.drawn_shapes: ellipsoids, keel solids for feet and toes), in
    # the skeleton's space at the bind pose, with the dynamics' mass properties (UsdPhysics).
    mat = _define_material(stage, f"{looks}/{prep.prim}_Material", prep.color)
    joint_of_body = {bi: j for j, bi in enumerate(order)}
    ident = Gf.Matrix4d(1.0)

    def skinned_mesh(name, bi, pts, nrm, counts, idx, color):
        Rbb, pbb = Rb[0, bi], pb[0, bi]
        pts_w = pts @ Rbb.T + pbb
        nrm_w = nrm @ Rbb.T
        mesh = UsdGeom.Mesh.Define(stage, f"{root_path}/{name}")
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts_w.astype(np.float32))))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(idx))
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(nrm_w.astype(np.float32))))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, pts_w.min(0))), Gf.Vec3f(*map(float, pts_w.max(0)))]))
        mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*color)]))
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        binding.CreateJointIndicesPrimvar(constant=True, elementSize=1).Set(Vt.IntArray([joint_of_body[bi]]))
        binding.CreateJointWeightsPrimvar(constant=True, elementSize=1).Set(Vt.FloatArray([1.0]))
        binding.CreateGeomBindTransformAttr(ident)
        return mesh, Rbb, pbb

    def mass_api(prim, mass, com_body, inertia_body, Rbb, pbb):
        """UsdPhysics.MassAPI in the mesh's space (the skeleton's at the bind pose)."""
        api = UsdPhysics.MassAPI.Apply(prim)
        api.CreateMassAttr(float(mass))
        api.CreateCenterOfMassAttr(Gf.Vec3f(*map(float, Rbb @ np.asarray(com_body, float) + pbb)))
        w, V = np.linalg.eigh(Rbb @ np.asarray(inertia_body, float) @ Rbb.T)
        if np.linalg.det(V) < 0:
            V[:, 0] *= -1
        api.CreateDiagonalInertiaAttr(Gf.Vec3f(*map(float, w)))
        qa = quat_from_matrix(V)
        api.CreatePrincipalAxesAttr(Gf.Quatf(float(qa[0]), float(qa[1]), float(qa[2]), float(qa[3])))

    for bi, (b, shape) in enumerate(zip(ch.bodies, drawn_shapes(ch))):
        if shape.kind == "keel":
            pts, nrm, counts, idx = keel_mesh(shape.center, shape.semi_axes, *segments, pitch=shape.pitch)
        else:
            pts, nrm, counts, idx = ellipsoid_mesh(shape.center, shape.semi_axes, *segments)
        mesh, Rbb, pbb = skinned_mesh(f"{prep.prim}_{b.name}", bi, pts, nrm, counts, idx, prep.color)
        prim = mesh.GetPrim()
        prim.CreateAttribute("compose:body", Sdf.ValueTypeNames.String, custom=True).Set(b.name)
        prim.CreateAttribute("compose:shape", Sdf.ValueTypeNames.String, custom=True).Set(shape.kind)
        # the dynamics' own numbers: mass, centre, the ellipsoid's inertia (Body.inertia; a body
        # with a load: its own mass's ellipsoid, the load is its own prim below)
        own_I = b.inertia if not b.inertia_extra else ellipsoid_inertia(shape.mass, b.semi_axes)
        mass_api(prim, shape.mass, shape.com, own_I, Rbb, pbb)
        _bind_material(prim, mat)
    # Carried loads (with_extra_mass, e.g. a suitcase): a box centred on the handle that holds
    # it, skinned to that handle's joint, with the load's mass and inertia (the dynamics' box).
    body_index = {b.name: i for i, b in enumerate(ch.bodies)}
    for n, (handle, extra) in enumerate(ch.loads):
        h = ch.handle(handle)
        bi = body_index[h.body]
        half = carried_half_extents(extra)
        pts, nrm, counts, idx = box_mesh(h.point, half)
        name = f"{prep.prim}_carried_{n}"
        _check_name_bytes(name, f"character {prep.track.name!r}: carried object")
        mesh, Rbb, pbb = skinned_mesh(name, bi, pts, nrm, counts, idx, (0.35, 0.25, 0.15))
        prim = mesh.GetPrim()
        prim.CreateAttribute("compose:carried", Sdf.ValueTypeNames.String, custom=True).Set(handle)
        prim.CreateAttribute("compose:body", Sdf.ValueTypeNames.String, custom=True).Set(h.body)
        mass_api(prim, extra, h.point, box_inertia(extra, half), Rbb, pbb)
        _bind_material(prim, mat)


def _write_markers(stage, markers: Sequence[Marker], fps: float, t0: int, t1: int, looks: str) -> list[np.ndarray]:
    from pxr import Gf, Sdf, UsdGeom, Vt
    if not markers:
        return []
    UsdGeom.Scope.Define(stage, "/World/Markers")
    mats: dict[str, Any] = {}
    seen: set[str] = set()
    pts = []
    for m in markers:
        name = character_prim_name(m.name)
        if name in seen:
            raise InputError(f"two markers map to the same prim name {name!r}")
        seen.add(name)
        _check_name_bytes(name, "marker")
        pos = np.asarray(m.position, dtype=float).reshape(3)
        if not np.all(np.isfinite(pos)) or not (m.radius > 0):
            raise InputError(f"marker {m.name!r}: position must be finite and radius positive")
        path = f"/World/Markers/{name}"
        if m.kind == "footprint":
            thickness = 0.004
            g = UsdGeom.Cylinder.Define(stage, path)
            g.CreateAxisAttr(UsdGeom.Tokens.z)
            g.CreateRadiusAttr(float(m.radius))
            g.CreateHeightAttr(thickness)
            g.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-m.radius, -m.radius, -thickness / 2),
                                              Gf.Vec3f(m.radius, m.radius, thickness / 2)]))
            centre = pos + np.array([0.0, 0.0, thickness / 2])
        else:
            g = UsdGeom.Sphere.Define(stage, path)
            g.CreateRadiusAttr(float(m.radius))
            g.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-m.radius, -m.radius, -m.radius),
                                              Gf.Vec3f(m.radius, m.radius, m.radius)]))
            centre = pos
        g.AddTranslateOp().Set(Gf.Vec3d(*map(float, centre)))
        color = _MARKER_COLORS.get(m.kind, _DEFAULT_MARKER_COLOR)
        g.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*color)]))
        if m.kind not in mats:
            mats[m.kind] = _define_material(stage, f"{looks}/marker_{character_prim_name(m.kind)}", color)
        _bind_material(g.GetPrim(), mats[m.kind])
        prim = g.GetPrim()
        prim.CreateAttribute("compose:kind", Sdf.ValueTypeNames.String, custom=True).Set(m.kind)
        if m.character is not None:
            prim.CreateAttribute("compose:character", Sdf.ValueTypeNames.String, custom=True).Set(m.character)
        if m.interval is not None:
            a, b = float(m.interval[0]), float(m.interval[1])
            if not (b >= a):
                raise InputError(f"marker {m.name!r}: interval end {b} is before start {a}")
            prim.CreateAttribute("compose:startTime", Sdf.ValueTypeNames.Double, custom=True).Set(a)
            prim.CreateAttribute("compose:endTime", Sdf.ValueTypeNames.Double, custom=True).Set(b)
            ca, cb = int(math.floor(a * fps + 1e-9)), int(math.ceil(b * fps - 1e-9))
            vis = g.CreateVisibilityAttr()
            if ca > t0:
                vis.Set(UsdGeom.Tokens.invisible, t0)
            vis.Set(UsdGeom.Tokens.inherited, max(ca, t0))
            if cb < t1:
                vis.Set(UsdGeom.Tokens.invisible, cb + 1)
        pts.append(pos)
        pts.append(pos + float(m.radius))
        pts.append(pos - float(m.radius))
    return pts


def ramp_mesh(plane) -> tuple[np.ndarray, list[int], list[int]]:
    """A closed slab under a :class:`~scenegraph.model.ground.Plane`: its top face is the plane over
    the region, its bottom at min(0, lowest corner) − 2 cm; (points (8, 3) m, face counts,
    indices), faces wound counter-clockwise seen from outside."""
    x0, y0, x1, y1 = plane.region
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    top = [(x, y, float(plane.plane_height(x, y))) for x, y in corners]
    zb = min(0.0, min(p[2] for p in top)) - 0.02
    pts = np.array(top + [(x, y, zb) for x, y in corners], float)
    faces = [[0, 1, 2, 3], [7, 6, 5, 4], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    return pts, [4] * len(faces), [i for f in faces for i in f]


def _write_ground(stage, ground, looks: str) -> list[np.ndarray]:
    """One Mesh per inclined plane of ``ground`` under /World/Ground (flat ground: nothing)."""
    from pxr import Gf, Sdf, UsdGeom, Vt
    if ground is None or not getattr(ground, "planes", ()):
        return []
    UsdGeom.Scope.Define(stage, "/World/Ground")
    mat = _define_material(stage, f"{looks}/ground", _GROUND_COLOR)
    pts_all = []
    for i, plane in enumerate(ground.planes):
        name = character_prim_name(plane.name or f"slope_{i}")
        pts, counts, idx = ramp_mesh(plane)
        mesh = UsdGeom.Mesh.Define(stage, f"/World/Ground/{name}_{i}")
        mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in pts]))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(idx))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, pts.min(0))), Gf.Vec3f(*map(float, pts.max(0)))]))
        mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*_GROUND_COLOR)]))
        _bind_material(mesh.GetPrim(), mat)
        prim = mesh.GetPrim()
        prim.CreateAttribute("compose:kind", Sdf.ValueTypeNames.String, custom=True).Set("slope")
        prim.CreateAttribute("compose:angleDeg", Sdf.ValueTypeNames.Double, custom=True).Set(
            math.degrees(plane.angle))
        prim.CreateAttribute("compose:headingDeg", Sdf.ValueTypeNames.Double, custom=True).Set(
            math.degrees(plane.heading))
        pts_all.append(pts)
    return pts_all


def _write_forces(stage, forces: Sequence[ForceArrow], fps: float) -> None:
    from pxr import Gf, Sdf, UsdGeom, Vt
    if not forces:
        return
    UsdGeom.Scope.Define(stage, "/World/Debug")
    seen: set[str] = set()
    for f in forces:
        name = character_prim_name(f.name)
        if name in seen:
            raise InputError(f"two debug forces map to the same prim name {name!r}")
        seen.add(name)
        o = np.asarray(f.origins, dtype=float).reshape(-1, 3)
        v = np.asarray(f.vectors, dtype=float).reshape(-1, 3)
        if o.shape != v.shape or not (np.all(np.isfinite(o)) and np.all(np.isfinite(v))):
            raise InputError(f"debug force {f.name!r}: origins and vectors must be finite arrays of the same shape")
        c0 = _start_code(f.start_time, fps, f"debug force {f.name!r}")
        curves = UsdGeom.BasisCurves.Define(stage, f"/World/Debug/{name}")
        curves.CreateTypeAttr(UsdGeom.Tokens.linear)
        curves.CreateCurveVertexCountsAttr(Vt.IntArray([2]))
        curves.CreateWidthsAttr(Vt.FloatArray([0.01]))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.constant)
        curves.CreatePurposeAttr(UsdGeom.Tokens.guide)
        curves.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(0.9, 0.1, 0.9)]))
        prim = curves.GetPrim()
        prim.CreateAttribute("compose:kind", Sdf.ValueTypeNames.String, custom=True).Set(f.kind)
        prim.CreateAttribute("compose:scale", Sdf.ValueTypeNames.Double, custom=True).Set(float(f.scale))
        if f.character is not None:
            prim.CreateAttribute("compose:character", Sdf.ValueTypeNames.String, custom=True).Set(
                character_prim_name(f.character))
        force_attr = prim.CreateAttribute("compose:force", Sdf.ValueTypeNames.Double3, custom=True)
        pa, ea = curves.CreatePointsAttr(), curves.CreateExtentAttr()
        for k in range(o.shape[0]):
            a, b = o[k], o[k] + v[k] * f.scale
            pa.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, a)), Gf.Vec3f(*map(float, b))]), c0 + k)
            lo, hi = np.minimum(a, b) - 0.005, np.maximum(a, b) + 0.005
            ea.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]), c0 + k)
            force_attr.Set(Gf.Vec3d(*map(float, v[k])), c0 + k)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4×4 column-vector camera-to-world matrix of a USD camera (looks along its -Z, Y up)."""
    eye, target, up = (np.asarray(x, dtype=float) for x in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(np.array([0.0, 1.0, 0.0]), back)
    right /= np.linalg.norm(right)
    upv = np.cross(back, right)
    M = np.eye(4)
    M[:3, 0], M[:3, 1], M[:3, 2], M[:3, 3] = right, upv, back, eye
    return M


def frame_camera(points: np.ndarray, direction=(0.45, -1.0, 0.35), h_aperture: float = 0.36,
                 v_aperture: float = 0.2025, focal: float = 0.35) -> tuple[np.ndarray, np.ndarray, float]:
    """(eye, target, distance) of a camera looking along -``direction`` that sees every point."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = pts.min(0), pts.max(0)
    target = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.5)
    fov = 2 * math.atan(min(h_aperture, v_aperture) / 2 / focal)
    dist = radius / math.sin(fov / 2) * 1.05
    d = np.asarray(direction, dtype=float)
    d /= np.linalg.norm(d)
    return target + d * dist, target, dist


def _write_camera(stage, points: np.ndarray) -> None:
    from pxr import Gf, UsdGeom
    # USD camera lens values are in tenths of a scene unit: 35 mm lens on a 36×20.25 mm sensor.
    h_ap, v_ap, focal = 0.36, 0.2025, 0.35
    eye, target, dist = frame_camera(points, h_aperture=h_ap, v_aperture=v_ap, focal=focal)
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    cam.CreateFocalLengthAttr(focal)
    cam.CreateHorizontalApertureAttr(h_ap)
    cam.CreateVerticalApertureAttr(v_ap)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.05, float(max(1000.0, 4 * dist))))
    cam.CreateFocusDistanceAttr(float(dist))
    M = look_at(eye, target)
    cam.AddTransformOp().Set(Gf.Matrix4d(M.T.tolist()))


def build_stage(characters: Sequence[CharacterTrack], fps: float, *, markers: Sequence[Marker] = (),
                metadata: dict | None = None, debug_forces: Sequence[ForceArrow] = (),
                mesh_segments: tuple[int, int] = (16, 10), ground=None):
    """Compose the stage in memory (a ``Usd.Stage`` on an anonymous layer).

    ``mesh_segments`` = (segments around, rings pole to pole) of each ellipsoid mesh.
    ``ground`` (a :class:`~scenegraph.model.ground.Ground`): its slopes become ramp meshes."""
    from pxr import Usd, UsdGeom
    fps = float(fps)
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be positive, got {fps}")
    segments = (int(mesh_segments[0]), int(mesh_segments[1]))
    if segments[0] < 3 or segments[1] < 2:
        raise InputError(f"mesh_segments must be at least (3, 2), got {mesh_segments}")
    preps = _prepare(list(characters), fps)
    t0 = min(pp.start_code for pp in preps)
    t1 = max(pp.start_code + pp.p.shape[0] - 1 for pp in preps)

    stage = Usd.Stage.CreateInMemory("compose.usda")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(t0)
    stage.SetEndTimeCode(t1)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    Usd.ModelAPI(world.GetPrim()).SetKind("assembly")
    looks = "/World/Looks"
    UsdGeom.Scope.Define(stage, looks)

    for pp in preps:
        _write_character(stage, pp, looks, segments)
    marker_pts = _write_markers(stage, markers, fps, t0, t1, looks)
    marker_pts = list(marker_pts) + [p for pts in _write_ground(stage, ground, looks) for p in pts]
    _write_forces(stage, debug_forces, fps)
    pts = [pp.extents.reshape(-1, 3) for pp in preps] + [np.asarray(marker_pts).reshape(-1, 3)]
    _write_camera(stage, np.concatenate(pts, axis=0))

    info = {
        "composeVersion": compose_version(),
        "usdVersion": _usd_version(),
        "fps": fps,
        "characters": [pp.track.name for pp in preps],
    }
    info.update(metadata or {})
    stage.GetRootLayer().customLayerData = {"compose": _to_vt(info)}
    stage.GetRootLayer().comment = "Written by compose (scenegraph.export.usd)"
    return stage


def _export_layer(layer, path: str) -> None:
    """Write ``layer`` to ``path`` (format by extension).  Separate so tests can break it."""
    if not layer.Export(path):
        raise ComposeError(f"USD could not write {path}")


def export_usd(path, characters: Sequence[CharacterTrack], fps: float, *, markers: Iterable[Marker] = (),
               metadata: dict | None = None, debug_forces: Iterable[ForceArrow] = (),
               mesh_segments: tuple[int, int] = (16, 10), ground=None) -> Path:
    """Write the characters' motions (sampled at ``fps``) as a USD stage at ``path``.

    The format follows the extension (``.usda``, ``.usdc``, ``.usdz``).  The write is atomic:
    on any failure the destination keeps its previous content (or stays absent) and no
    temporary file is left behind.  Returns the written path.
    """
    from pxr import UsdUtils
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise InputError(f"cannot export USD to {path.name!r}: the extension must be one of {', '.join(SUPPORTED_EXTENSIONS)}")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"cannot export USD to {path}: directory {parent} does not exist")
    stage = build_stage(characters, fps, markers=list(markers), metadata=metadata, debug_forces=list(debug_forces),
                        mesh_segments=mesh_segments, ground=ground)
    with atomic_path(path, suffix=ext) as tmp:
        if ext == ".usdz":
            with tempfile.TemporaryDirectory(prefix="compose-usdz-") as tmpdir:
                inner = os.path.join(tmpdir, path.stem + ".usdc")
                _export_layer(stage.GetRootLayer(), inner)
                # The package records the file's mtime: pin it so the same input gives the same bytes.
                stamp = int(os.environ.get("SOURCE_DATE_EPOCH", "946684800"))  # default 2000-01-01
                os.utime(inner, (stamp, stamp))
                if not UsdUtils.CreateNewUsdzPackage(inner, str(tmp)):
                    raise ComposeError(f"USD could not package {path}")
        else:
            _export_layer(stage.GetRootLayer(), str(tmp))
    _reload_if_open(path)
    return path


def _reload_if_open(path: Path) -> None:
    """If this process holds the destination layer open, reload it so it shows the new file."""
    from pxr import Sdf
    layer = Sdf.Layer.Find(os.path.abspath(path))
    if layer is not None:
        layer.Reload(force=True)


def readback_errors(path, characters: Sequence[CharacterTrack], fps: float) -> tuple[float, float, int]:
    """Read a written stage back with UsdSkel and compare every joint's world transform at
    every frame with :func:`~scenegraph.model.kinematics.numeric_fk` of the tracks.

    Returns (max position error in m, max rotation error in rad, frames checked).  For
    end-to-end checks of ``compose run`` output (the issue asks for <= 1e-6 m, <= 1e-4 rad)."""
    from pxr import Usd, UsdGeom, UsdSkel
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    roots = {p.GetName(): UsdSkel.Root(p) for p in stage.Traverse() if p.IsA(UsdSkel.Root)}
    dp = dr = 0.0
    n = 0
    for tr in characters:
        name = character_prim_name(tr.name)
        if name not in roots:
            raise ComposeError(f"{path}: no SkelRoot for character {tr.name!r}")
        cache.Populate(roots[name], Usd.PrimDefaultPredicate)
        (binding,) = cache.ComputeSkelBindings(roots[name], Usd.PrimDefaultPredicate)
        sq = cache.GetSkelQuery(binding.GetSkeleton())
        order, paths = joint_paths(tr.character)
        if [str(j) for j in sq.GetJointOrder()] != paths:
            raise ComposeError(f"{path}: joint order of {tr.name!r} differs from the character's")
        q = np.asarray(tr.q, dtype=float)
        R, p = numeric_fk(tr.character, q)
        c0 = _start_code(tr.start_time, float(fps), tr.name)
        xf = UsdGeom.XformCache()
        for k in range(q.shape[0]):
            xf.SetTime(Usd.TimeCode(c0 + k))
            W = np.array(sq.ComputeJointWorldTransforms(xf)).transpose(0, 2, 1)[:, :3, :]
            dp = max(dp, float(np.abs(W[:, :3, 3] - p[k, order]).max()))
            D = np.swapaxes(W[:, :3, :3], 1, 2) @ R[k, order]
            s = np.linalg.norm(np.stack([D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0], D[:, 1, 0] - D[:, 0, 1]], 1), axis=1) / 2
            c = (np.trace(D, axis1=1, axis2=2) - 1) / 2
            dr = max(dr, float(np.arctan2(s, c).max()))
            n += 1
    return dp, dr, n


def validate_stage(stage_or_path) -> list[str]:
    """Run every registered ``pxr.UsdValidation`` validator; return one line per finding."""
    from pxr import Usd, UsdValidation
    stage = Usd.Stage.Open(str(stage_or_path)) if not isinstance(stage_or_path, Usd.Stage) else stage_or_path
    reg = UsdValidation.ValidationRegistry()
    ctx = UsdValidation.ValidationContext(reg.GetOrLoadAllValidators())
    findings = []
    for err in ctx.Validate(stage):
        sites = ", ".join(str(s.GetPrim().GetPath()) if s.IsPrim() else str(s.GetLayer().identifier if s.GetLayer() else "")
                          for s in err.GetSites())
        findings.append(f"{err.GetName()} [{err.GetType()}] {sites}: {err.GetMessage()}")
    return findings
