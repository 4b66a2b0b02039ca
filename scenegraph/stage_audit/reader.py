"""Read a UsdSkel stage into sampled geometry: per character, every skinned mesh's vertices
at every audit frame, its triangles, and the mass it carries.  Nothing else is read.

A **character** is a ``UsdSkel.Root`` with at least one skinned mesh; its name is the
SkelRoot's prim name.  Meshes are skinned with ``UsdSkel`` itself (linear blend skinning,
any number of influences, ``geomBindTransform`` honoured), so any UsdSkel stage works, not
only compose's.  Positions are converted to metres and to a **Z-up** world (a Y-up stage
is rotated: (x, y, z) -> (x, -z, y)), the frame the checks use.

Mass of a mesh (kg), first that applies:
  1. ``physics:mass`` of ``UsdPhysics.MassAPI`` on the mesh (> 0);
  2. ``physics:density`` of ``UsdPhysics.MassAPI`` on the mesh (kg per stage unit³) × volume;
  3. ``DEFAULT_DENSITY`` (1000 kg/m³, water, close to the human body's 985–1100) × volume.
A mesh whose volume is not positive (open, inside-out, or a flat card) carries no mass and
is listed in ``massless``.  Mass is spread uniformly through the mesh's volume.

Asked-for contacts between characters (held hands, a tackle) may be listed in the layer's
``customLayerData["compose"]["allowedContacts"]`` as patterns 'charA/meshA~charB/meshB'.

Ground: every mesh outside the characters whose prim has ``compose:kind`` = "slope" or
"ground" (or lies under ``/World/Ground``) is a ramp: the ground height under a point is the
highest upward-facing triangle of those meshes over it (below 0 on a downhill), else 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenarios.errors import ComposeError, InputError

__all__ = ["DEFAULT_DENSITY", "MeshSet", "CharacterSamples", "StageSamples", "Ground", "read_stage"]

DEFAULT_DENSITY = 1000.0  # kg/m^3


@dataclass(frozen=True)
class Ground:
    """Height field z = h(x, y) (m): over a ramp (upward-facing triangles (K, 3, 3)) its
    highest face, which may be below 0 (a downhill); elsewhere the floor z = 0."""

    triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height (m) under the points (x, y) (any equal shapes)."""
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        h = np.full(np.broadcast(x, y).shape, -np.inf)  # the highest ramp face over the point
        for a, b, c in self.triangles:
            d = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1])
            if abs(d) < 1e-12:
                continue
            l1 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / d
            l2 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / d
            l3 = 1.0 - l1 - l2
            inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l3 >= -1e-9)
            z = l1 * a[2] + l2 * b[2] + l3 * c[2]
            h = np.where(inside, np.maximum(h, z), h)
        return np.where(np.isfinite(h), h, 0.0)  # off every ramp: the floor z = 0

    @property
    def flat(self) -> bool:
        return len(self.triangles) == 0


@dataclass(frozen=True, eq=False)
class MeshSet:
    """The meshes of one character, concatenated.

    ``points`` (T, N, 3) m, world, Z up, at the audit frames; ``tris`` (F, 3) vertex indices
    into N, outward (counter-clockwise seen from outside); ``tri_mesh`` (F,) the mesh each
    triangle belongs to; ``vert_mesh`` (N,) the same for vertices; ``density`` (M,) kg/m³;
    ``names`` (M,) mesh prim names; ``mass`` (M,) kg; ``mass_source`` (M,) "mass", "density"
    or "default density"."""

    points: np.ndarray
    tris: np.ndarray
    tri_mesh: np.ndarray
    vert_mesh: np.ndarray
    names: tuple[str, ...]
    density: np.ndarray
    mass: np.ndarray
    mass_source: tuple[str, ...]
    massless: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class CharacterSamples:
    name: str
    path: str
    meshes: MeshSet

    @property
    def mass(self) -> float:
        return float(self.meshes.mass.sum())


@dataclass(frozen=True, eq=False)
class StageSamples:
    """Everything the checks need: ``times`` (T,) s, characters, ground, and the stage's
    own time-code rate ``stage_fps`` (to say when the audit rate exceeds the samples)."""

    path: str
    times: np.ndarray
    fps: float
    stage_fps: float
    characters: tuple[CharacterSamples, ...]
    ground: Ground
    up_axis: str
    meters_per_unit: float
    debug_forces: tuple = ()  # (character, kind, origins (T,3), vectors (T,3)) from compose's debug prims
    allowed_contacts: tuple[str, ...] = ()  # the stage's own list (customLayerData compose.allowedContacts)


def _triangulate(counts, indices) -> np.ndarray:
    tris = []
    o = 0
    for n in counts:
        f = indices[o:o + n]
        for k in range(1, n - 1):
            tris.append((f[0], f[k], f[k + 1]))
        o += n
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def _signed_volume(P: np.ndarray, tris: np.ndarray) -> float:
    a, b, c = P[tris[:, 0]], P[tris[:, 1]], P[tris[:, 2]]
    o = P.mean(axis=0)
    return float(np.einsum("ij,ij->i", a - o, np.cross(b - o, c - o)).sum() / 6.0)


def _to_world(P: np.ndarray, up: str, mpu: float) -> np.ndarray:
    P = np.asarray(P, float) * mpu
    if up == "Y":
        P = np.stack([P[..., 0], -P[..., 2], P[..., 1]], axis=-1)
    return P


def _mesh_mass(prim, volume_m3: float, mpu: float) -> tuple[float, str]:
    from pxr import UsdPhysics
    if prim.HasAPI(UsdPhysics.MassAPI):
        api = UsdPhysics.MassAPI(prim)
        m = api.GetMassAttr().Get()
        if m is not None and m > 0:
            return float(m), "mass"
        d = api.GetDensityAttr().Get()
        if d is not None and d > 0:
            return float(d) / mpu ** 3 * volume_m3, "density"
    return DEFAULT_DENSITY * volume_m3, "default density"


def read_stage(path, fps: float | None = None) -> StageSamples:
    """Sample every character of the stage at ``path`` at ``fps`` (default: the stage's own
    time codes per second) over [startTimeCode, endTimeCode].  Raises InputError (exit 2) for
    a missing or unreadable file, a stage without characters or time range."""
    from pxr import Sdf, Usd, UsdGeom, UsdSkel
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{path}: no such stage file")
    try:
        stage = Usd.Stage.Open(str(p))
    except Exception as exc:  # pxr raises Tf.ErrorException
        raise InputError(f"{path}: not a readable USD stage ({str(exc).strip().splitlines()[-1] if str(exc).strip() else exc})") from exc
    if stage is None:
        raise InputError(f"{path}: not a readable USD stage")
    up = str(UsdGeom.GetStageUpAxis(stage)).upper()
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    tcps = float(stage.GetTimeCodesPerSecond() or 24.0)
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps must be positive, got {fps}")
    rate = float(fps) if fps is not None else tcps
    c0, c1 = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if not stage.HasAuthoredTimeCodeRange() or c1 <= c0:
        raise InputError(f"{path}: the stage has no time range (startTimeCode/endTimeCode): nothing moves to audit")
    t0, t1 = c0 / tcps, c1 / tcps
    n = int(np.floor((t1 - t0) * rate + 1e-6)) + 1
    times = t0 + np.arange(n) / rate
    codes = times * tcps
    if n < 5:
        raise InputError(f"{path}: {n} frames at {rate:g} fps; the audit needs at least 5")

    cache = UsdSkel.Cache()
    chars = []
    skel_roots = [pr for pr in stage.Traverse() if pr.IsA(UsdSkel.Root)]
    for pr in skel_roots:
        root = UsdSkel.Root(pr)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        bindings = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        per_mesh = []  # (name, prim, tris, points (T, n, 3))
        for b in bindings:
            sq = cache.GetSkelQuery(b.GetSkeleton())
            skel_xf = UsdGeom.Xformable(b.GetSkeleton().GetPrim())
            targets = [t for t in b.GetSkinningTargets() if t.GetPrim().IsA(UsdGeom.Mesh)]
            if not targets:
                continue
            store = {t.GetPrim().GetPath(): np.empty((n, len(UsdGeom.Mesh(t.GetPrim()).GetPointsAttr().Get() or []), 3))
                     for t in targets}
            for k, code in enumerate(codes):
                tc = Usd.TimeCode(float(code))
                xf = sq.ComputeSkinningTransforms(tc)
                W = np.array(skel_xf.ComputeLocalToWorldTransform(tc)).T  # column-vector 4x4
                for t in targets:
                    mesh = UsdGeom.Mesh(t.GetPrim())
                    pts = mesh.GetPointsAttr().Get(tc)
                    if pts is None or len(pts) == 0:
                        continue
                    if xf is None or not t.ComputeSkinnedPoints(xf, pts, tc):
                        raise ComposeError(f"{path}: UsdSkel could not skin {t.GetPrim().GetPath()} at time code {code:g}")
                    P = np.asarray(pts, float)
                    store[t.GetPrim().GetPath()][k] = P @ W[:3, :3].T + W[:3, 3]
            for t in targets:
                mesh = UsdGeom.Mesh(t.GetPrim())
                counts = list(mesh.GetFaceVertexCountsAttr().Get() or [])
                idx = list(mesh.GetFaceVertexIndicesAttr().Get() or [])
                P = store[t.GetPrim().GetPath()]
                if P.shape[1] == 0 or not counts:
                    continue
                tris = _triangulate(counts, idx)
                if str(mesh.GetOrientationAttr().Get()) == "leftHanded":
                    tris = tris[:, ::-1]
                per_mesh.append((t.GetPrim().GetName(), t.GetPrim(), tris, P))
        if not per_mesh:
            continue
        pts_all, tris_all, tri_mesh, vert_mesh, names, dens, masses, srcs, massless = [], [], [], [], [], [], [], [], []
        off = 0
        for mi, (name, prim, tris, P) in enumerate(per_mesh):
            Pw = _to_world(P, up, mpu)
            vol = _signed_volume(Pw[0], tris)
            if vol <= 1e-12:
                mass, src, rho = 0.0, "no volume", 0.0
                massless.append(name)
            else:
                mass, src = _mesh_mass(prim, vol, mpu)
                rho = mass / vol
            pts_all.append(Pw)
            tris_all.append(tris + off)
            tri_mesh.append(np.full(len(tris), mi))
            vert_mesh.append(np.full(Pw.shape[1], mi))
            names.append(name)
            dens.append(rho)
            masses.append(mass)
            srcs.append(src)
            off += Pw.shape[1]
        ms = MeshSet(np.concatenate(pts_all, axis=1), np.concatenate(tris_all), np.concatenate(tri_mesh),
                     np.concatenate(vert_mesh), tuple(names), np.array(dens), np.array(masses), tuple(srcs),
                     tuple(massless))
        chars.append(CharacterSamples(pr.GetName(), str(pr.GetPath()), ms))
    if not chars:
        raise InputError(f"{path}: no character found (a UsdSkel SkelRoot with a skinned mesh)")
    names = [c.name for c in chars]
    if len(set(names)) != len(names):  # same prim name under different parents: use paths
        chars = [CharacterSamples(c.path, c.path, c.meshes) for c in chars]

    ground = _read_ground(stage, skel_roots, codes[0], up, mpu)
    forces = _read_debug_forces(stage, codes, up, mpu)
    info = stage.GetRootLayer().customLayerData.get("compose", {}) or {}
    allowed = info.get("allowedContacts", ()) if hasattr(info, "get") else ()
    allowed = tuple(str(a) for a in allowed) if not isinstance(allowed, str) else (allowed,)
    return StageSamples(str(path), times, rate, tcps, tuple(chars), ground, up, mpu, forces, allowed)


def _read_ground(stage, skel_roots, code, up: str, mpu: float) -> Ground:
    from pxr import Usd, UsdGeom
    roots = [str(r.GetPath()) for r in skel_roots]
    tris = []
    for pr in stage.Traverse():
        if not pr.IsA(UsdGeom.Mesh) or any(str(pr.GetPath()).startswith(r + "/") for r in roots):
            continue
        kind = pr.GetAttribute("compose:kind")
        kind = kind.Get() if kind and kind.IsValid() else None
        if kind not in ("slope", "ground") and not str(pr.GetPath()).startswith("/World/Ground/"):
            continue
        mesh = UsdGeom.Mesh(pr)
        tc = Usd.TimeCode(float(code))
        P = np.asarray(mesh.GetPointsAttr().Get(tc), float)
        M = np.array(UsdGeom.Xformable(pr).ComputeLocalToWorldTransform(tc)).T
        P = _to_world(P @ M[:3, :3].T + M[:3, 3], up, mpu)
        T = _triangulate(list(mesh.GetFaceVertexCountsAttr().Get()), list(mesh.GetFaceVertexIndicesAttr().Get()))
        for a, b, c in T:
            nrm = np.cross(P[b] - P[a], P[c] - P[a])
            if np.linalg.norm(nrm) > 0 and nrm[2] / np.linalg.norm(nrm) > 0.3:
                tris.append(P[[a, b, c]])
    return Ground(np.asarray(tris, float).reshape(-1, 3, 3))


def _read_debug_forces(stage, codes, up: str, mpu: float) -> tuple:
    """compose's optional force prims (``compose:force`` N, time-sampled, on BasisCurves whose
    first point is the point of application, with ``compose:character`` naming who feels it)."""
    from pxr import Usd, UsdGeom
    out = []
    for pr in stage.Traverse():
        fa = pr.GetAttribute("compose:force")
        who = pr.GetAttribute("compose:character")
        if not (fa and fa.IsValid() and who and who.IsValid() and pr.IsA(UsdGeom.BasisCurves)):
            continue
        kind = pr.GetAttribute("compose:kind").Get() if pr.GetAttribute("compose:kind") else "force"
        pa = UsdGeom.BasisCurves(pr).GetPointsAttr()
        O = np.zeros((len(codes), 3))
        F = np.zeros((len(codes), 3))
        for k, c in enumerate(codes):
            tc = Usd.TimeCode(float(c))
            f = fa.Get(tc)
            pts = pa.Get(tc)
            if f is None or pts is None or len(pts) == 0:
                continue
            F[k] = np.asarray(f, float)
            O[k] = np.asarray(pts[0], float)
        O = _to_world(O, up, mpu)
        if up == "Y":
            F = np.stack([F[:, 0], -F[:, 2], F[:, 1]], axis=-1)
        out.append((str(who.Get()), str(kind), O, F))
    return tuple(out)
