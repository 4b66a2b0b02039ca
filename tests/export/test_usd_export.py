"""USD export: read the stage back with UsdSkel and compare with our own forward kinematics.

Golden files: ``tests/golden/two_characters.usda`` is compared *structurally* (prim paths,
types, property names and types, array sizes, stage metadata; numbers with a tolerance).
Regenerate it after a deliberate change of the stage layout with::

    COMPOSE_REGEN_GOLDEN=1 python -m pytest tests/export/test_usd_export.py -k golden

and review the diff before committing it.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt  # noqa: E402

from scenarios.errors import ComposeError, InputError  # noqa: E402
from scenegraph.model.body import drawn_shapes, make_character, standing_pose  # noqa: E402
from scenegraph.model.kinematics import numeric_fk  # noqa: E402
from scenegraph.model.rotations import quat_from_matrix  # noqa: E402
from scenegraph.export import usd as usd_export  # noqa: E402
from scenegraph.export.usd import (CharacterTrack, ForceArrow, Marker, export_usd, joint_paths,  # noqa: E402
                                   validate_stage)

GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "two_characters.usda"
FPS = 30.0


def synthetic_q(ch, T: int, fps: float, seed: int, shift=(0.0, 0.0)) -> np.ndarray:
    """Standing pose + random sinusoids on every DOF (inside the joint limits), walking root."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    q = np.tile(standing_pose(ch), (T, 1))
    lo, hi = ch.lower, ch.upper
    for j in range(6, q.shape[1]):
        mid = np.clip(0.0, lo[j], hi[j])
        amp = 0.45 * min(hi[j] - lo[j], 2.0) * rng.uniform(0.3, 1.0)
        q[:, j] = np.clip(mid + amp * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t + rng.uniform(0, 2 * np.pi)),
                          lo[j], hi[j])
    q[:, 0] = shift[0] + 1.2 * t + 0.05 * np.sin(5 * t)
    q[:, 1] = shift[1] + 0.3 * np.sin(2 * t)
    q[:, 2] += 0.03 * np.sin(7 * t)
    q[:, 3] = rng.uniform(-np.pi, np.pi) + 0.8 * np.sin(1.3 * t)  # yaw: any direction
    q[:, 4] = 0.4 * np.sin(3.1 * t)
    q[:, 5] = 0.3 * np.sin(2.3 * t + 1)
    return q


@pytest.fixture(scope="module")
def tracks():
    a = make_character("adult_male")
    b = make_character("child")
    return [
        CharacterTrack("Alice", a, synthetic_q(a, 24, FPS, seed=1)),
        CharacterTrack("Bob the child", b, synthetic_q(b, 20, FPS, seed=2, shift=(1.0, 1.5)), start_time=2 / FPS),
    ]


MARKERS = [
    Marker("step_0", "footprint", (0.1, 0.1, 0.0), (0.0, 0.3), radius=0.07, character="Alice"),
    Marker("step_1", "footprint", (0.6, -0.1, 0.0), (0.3, 0.6), radius=0.07, character="Alice"),
    Marker("goal_ball", "goal", (2.0, 0.5, 1.0), None, radius=0.1),
]
METADATA = {"scenario": "synthetic.yaml", "styles": {"Alice": "walk", "Bob the child": "run"},
            "energies": [12.5, 11.0, 10.75], "schedule": "coupled"}


def _forces(T):
    return [ForceArrow("hand_hold", np.zeros((T, 3)) + [0.5, 0.7, 1.0], np.tile([40.0, -10.0, 5.0], (T, 1)),
                       kind="coupling")]


@pytest.fixture(scope="module")
def stage_path(tmp_path_factory, tracks):
    path = tmp_path_factory.mktemp("usd") / "scene.usda"
    export_usd(path, tracks, FPS, markers=MARKERS, metadata=METADATA, debug_forces=_forces(24))
    return path


def _rot_angle(Ra, Rb):
    """Angle (rad) of Ra^T Rb, well conditioned near zero (acos of the trace is not)."""
    D = Ra.T @ Rb
    s = np.linalg.norm([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]]) / 2.0
    c = (np.trace(D) - 1.0) / 2.0
    return math.atan2(s, c)


def _skel_roots(stage):
    return [UsdSkel.Root(p) for p in stage.Traverse() if p.IsA(UsdSkel.Root)]


def compare_with_fk(path, tracks, fps=FPS):
    """Max position (m) and rotation (rad) error of UsdSkel's joint world transforms against
    numeric_fk, over every frame of every character."""
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    roots = {r.GetPrim().GetName(): r for r in _skel_roots(stage)}
    assert len(roots) == len(tracks)
    max_dp = max_dr = 0.0
    n_checked = 0
    for tr in tracks:
        root = roots[usd_export.character_prim_name(tr.name)]
        cache.Populate(root, Usd.PrimDefaultPredicate)
        skels = [p for p in Usd.PrimRange(root.GetPrim()) if p.IsA(UsdSkel.Skeleton)]
        assert len(skels) == 1
        sq = cache.GetSkelQuery(UsdSkel.Skeleton(skels[0]))
        order, paths = joint_paths(tr.character)
        assert [str(j) for j in sq.GetJointOrder()] == paths
        R, p = numeric_fk(tr.character, tr.q)
        c0 = int(round(tr.start_time * fps))
        xf = UsdGeom.XformCache()
        for k in range(tr.q.shape[0]):
            xf.SetTime(Usd.TimeCode(c0 + k))
            W = np.array(sq.ComputeJointWorldTransforms(xf)).transpose(0, 2, 1)  # row-vector -> column
            for j, bi in enumerate(order):
                max_dp = max(max_dp, float(np.abs(W[j, :3, 3] - p[k, bi]).max()))
                max_dr = max(max_dr, _rot_angle(W[j, :3, :3], R[k, bi]))
            n_checked += 1
    return max_dp, max_dr, n_checked


def test_joint_world_transforms_match_fk_at_every_frame(stage_path, tracks):
    dp, dr, n = compare_with_fk(stage_path, tracks)
    assert n == 24 + 20
    assert dp <= 1e-6, dp
    assert dr <= 1e-4, dr


def test_library_readback_helper_agrees(stage_path, tracks):
    dp, dr, n = usd_export.readback_errors(stage_path, tracks, FPS)
    assert n == 44 and dp <= 1e-6 and dr <= 1e-4
    assert (dp, dr, n) == pytest.approx(compare_with_fk(stage_path, tracks), abs=1e-9)


def test_rotation_samples_are_hemisphere_continuous(stage_path):
    """Consecutive quaternions of a joint have a non-negative dot product, so UsdSkel's
    interpolation between time codes takes the short way round."""
    stage = Usd.Stage.Open(str(stage_path))
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Animation):
            attr = UsdSkel.Animation(prim).GetRotationsAttr()
            Q = np.array([[[q.GetReal(), *q.GetImaginary()] for q in attr.Get(t)] for t in attr.GetTimeSamples()])
            assert np.all(np.sum(Q[1:] * Q[:-1], axis=-1) >= 0)
            assert np.allclose(np.linalg.norm(Q, axis=-1), 1, atol=1e-6)


def test_validation_reports_no_finding(stage_path):
    assert validate_stage(stage_path) == []


def test_validation_catches_a_broken_stage():
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Mesh.Define(stage, "/m").GetPrim().CreateRelationship("skel:skeleton")
    names = " ".join(validate_stage(stage))
    assert "MissingSkelBindingAPI" in names and "MissingUpAxisMetadata" in names


def test_stage_metadata(stage_path, tracks):
    stage = Usd.Stage.Open(str(stage_path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == 23  # Bob: frames 2..21
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    info = stage.GetRootLayer().customLayerData["compose"]
    assert info["scenario"] == "synthetic.yaml"
    assert dict(info["styles"]) == {"Alice": "walk", "Bob the child": "run"}
    assert list(info["energies"]) == [12.5, 11.0, 10.75]
    assert info["usdVersion"] == ".".join(map(str, Usd.GetVersion()))
    assert info["composeVersion"]
    assert list(info["characters"]) == ["Alice", "Bob the child"]


def test_skeleton_layout(stage_path, tracks):
    stage = Usd.Stage.Open(str(stage_path))
    skel_names = []
    for root in _skel_roots(stage):
        assert root.GetPrim().GetParent().GetPath() == Sdf.Path("/World")
        assert not UsdGeom.Xformable(root).GetOrderedXformOps()
        skels = [c for c in root.GetPrim().GetChildren() if c.IsA(UsdSkel.Skeleton)]
        assert len(skels) == 1
        skel = UsdSkel.Skeleton(skels[0])
        skel_names.append(skels[0].GetName())
        joints = [str(j) for j in skel.GetJointsAttr().Get()]
        assert len(joints) == 18
        for i, j in enumerate(joints):  # parents before children
            if "/" in j:
                assert j.rsplit("/", 1)[0] in joints[:i]
        leaves = [j.rsplit("/", 1)[-1] for j in joints]
        assert len(set(leaves)) == 18 and all(len(x.encode()) <= 63 for x in leaves)
        anim = UsdSkel.Animation(stage.GetPrimAtPath(UsdSkel.BindingAPI(skels[0]).GetAnimationSourceRel().GetTargets()[0]))
        n = len(anim.GetRotationsAttr().GetTimeSamples())
        assert n == len(anim.GetTranslationsAttr().GetTimeSamples()) == len(anim.GetScalesAttr().GetTimeSamples())
        assert n in (24, 20)
        assert anim.GetRotationsAttr().GetTypeName() == Sdf.ValueTypeNames.QuatfArray
        assert anim.GetTranslationsAttr().GetTypeName() == Sdf.ValueTypeNames.Float3Array
        assert anim.GetScalesAttr().GetTypeName() == Sdf.ValueTypeNames.Half3Array
        meshes = [c for c in root.GetPrim().GetChildren() if c.IsA(UsdGeom.Mesh)]
        assert len(meshes) == 18
        for m in meshes:
            assert not UsdGeom.Xformable(m).GetOrderedXformOps()
            assert UsdSkel.BindingAPI(m).GetGeomBindTransformAttr().Get() == Gf.Matrix4d(1)
    assert len(set(skel_names)) == len(skel_names) == 2


def test_skinned_mesh_points_lie_on_our_ellipsoids(stage_path, tracks):
    stage = Usd.Stage.Open(str(stage_path))
    cache = UsdSkel.Cache()
    worst = 0.0
    reach = []
    for tr, root in zip(tracks, _skel_roots(stage)):
        cache.Populate(root, Usd.PrimDefaultPredicate)
        (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        sq = cache.GetSkelQuery(binding.GetSkeleton())
        R, p = numeric_fk(tr.character, tr.q)
        c0 = int(round(tr.start_time * FPS))
        bodies = {b.name: (i, b) for i, b in enumerate(tr.character.bodies)}
        shapes = {d.body: d for d in drawn_shapes(tr.character)}
        targets = binding.GetSkinningTargets()
        assert len(targets) == 18
        for k in (0, tr.q.shape[0] // 2, tr.q.shape[0] - 1):
            xforms = sq.ComputeSkinningTransforms(c0 + k)
            for skq in targets:
                assert skq.IsRigidlyDeformed()
                bi, b = bodies[skq.GetPrim().GetAttribute("compose:body").Get()]
                rest = UsdGeom.Mesh(skq.GetPrim()).GetPointsAttr().Get()
                pts = Vt.Vec3fArray(rest)
                assert skq.ComputeSkinnedPoints(xforms, pts, c0 + k)
                X = np.asarray(pts, dtype=float)
                shape = shapes[b.name]  # the drawn solid: the body's ellipsoid, or a keel for feet and toes
                u = ((X - p[k, bi]) @ R[k, bi] - np.array(shape.center)) @ shape.rotation  # the solid's frame
                s = np.array(shape.semi_axes)
                if shape.kind == "keel":  # sections: ellipses (b·σ, c·σ) standing on the keel, σ = sqrt(1 − (x/a)²)
                    sig = np.sqrt(np.clip(1 - (u[:, 0] / s[0]) ** 2, 0, None))
                    tip = sig < 0.05  # the two ends (float32 points: σ is not exactly 0 there)
                    assert tip.sum() == 2 and np.allclose(u[tip][:, 1:], 0, atol=1e-6)
                    r = np.hypot(u[~tip, 1] / (s[1] * sig[~tip]), (u[~tip, 2] - s[2] * sig[~tip]) / (s[2] * sig[~tip]))
                    assert u[:, 2].min() > -1e-6
                    u = u - [0.0, 0.0, s[2]]  # its own box: centred c above the keel, half extents (a, b, c)
                    # float32 points: within 1 µm of the surface, relative to the section's size
                    size = np.minimum(s[1], s[2]) * sig[~tip]
                    assert float((np.abs(r - 1.0) * size).max()) < 1e-6
                else:
                    r = np.linalg.norm(u / s, axis=1)
                    worst = max(worst, float(np.abs(r - 1.0).max()))
                # float32 points: the thin toes keel (1 cm) reaches its box to 1e-4 of its size
                reach.append(np.minimum(np.abs(u).max(axis=0) / s, 1.0 + (1e-5 if shape.kind == "ellipsoid" else 0.0)))
                assert np.all(np.abs(u).max(axis=0) / s < 1.0 + 1e-4)
    assert worst < 1e-5, worst
    assert np.all(np.array(reach) > 0.95) and np.all(np.array(reach) < 1.0 + 1e-5)


def test_markers_forces_camera(stage_path):
    stage = Usd.Stage.Open(str(stage_path))
    fp = stage.GetPrimAtPath("/World/Markers/step_1")
    assert fp.IsA(UsdGeom.Cylinder)
    assert fp.GetAttribute("compose:kind").Get() == "footprint"
    assert fp.GetAttribute("compose:startTime").Get() == pytest.approx(0.3)
    vis = UsdGeom.Imageable(fp).GetVisibilityAttr()
    assert vis.Get(0) == UsdGeom.Tokens.invisible and vis.Get(12) == UsdGeom.Tokens.inherited
    assert vis.Get(23) == UsdGeom.Tokens.invisible
    goal = stage.GetPrimAtPath("/World/Markers/goal_ball")
    assert goal.IsA(UsdGeom.Sphere) and UsdGeom.Sphere(goal).GetRadiusAttr().Get() == pytest.approx(0.1)
    xf = UsdGeom.Xformable(goal).ComputeLocalToWorldTransform(0)
    assert np.allclose(xf.ExtractTranslation(), (2.0, 0.5, 1.0))
    force = UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/Debug/hand_hold"))
    assert force.GetPurposeAttr().Get() == UsdGeom.Tokens.guide
    pts = np.asarray(force.GetPointsAttr().Get(5))
    assert np.allclose(pts[1] - pts[0], np.array([40.0, -10.0, 5.0]) * 1e-3, atol=1e-6)
    # The camera sees every joint at every frame: project and check it lands in the frame.
    cam_prim = stage.GetPrimAtPath("/World/Camera")
    cam = UsdGeom.Camera(cam_prim).GetCamera(0)
    frustum = cam.frustum
    cache = UsdSkel.Cache()
    for root in _skel_roots(stage):
        cache.Populate(root, Usd.PrimDefaultPredicate)
        skel = [p for p in Usd.PrimRange(root.GetPrim()) if p.IsA(UsdSkel.Skeleton)][0]
        sq = cache.GetSkelQuery(UsdSkel.Skeleton(skel))
        xfc = UsdGeom.XformCache()
        for c in range(0, 24, 4):
            xfc.SetTime(c)
            for M in sq.ComputeJointWorldTransforms(xfc):
                assert frustum.Intersects(Gf.Vec3d(M.ExtractTranslation()))


@pytest.mark.parametrize("ext", [".usdc", ".usdz"])
def test_binary_and_package_formats(tmp_path, tracks, ext):
    path = export_usd(tmp_path / f"scene{ext}", tracks, FPS, markers=MARKERS, metadata=METADATA)
    assert path.exists() and sorted(os.listdir(tmp_path)) == [f"scene{ext}"]
    if ext == ".usdc":
        assert path.read_bytes()[:8] == b"PXR-USDC"
    else:
        assert path.read_bytes()[:2] == b"PK"
    dp, dr, n = compare_with_fk(path, tracks)
    assert n == 44 and dp <= 1e-6 and dr <= 1e-4
    assert validate_stage(path) == []
    stage = Usd.Stage.Open(str(path))
    assert stage.GetRootLayer().customLayerData["compose"]["scenario"] == "synthetic.yaml"


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usdz"])
def test_output_is_deterministic(tmp_path, tracks, ext):
    a = export_usd(tmp_path / f"s{ext}", tracks, FPS, markers=MARKERS, metadata=METADATA).read_bytes()
    if ext == ".usdz":  # the package records file times: they must not come from the clock
        import zipfile
        with zipfile.ZipFile(tmp_path / f"s{ext}") as z:
            year = __import__("time").localtime(int(os.environ.get("SOURCE_DATE_EPOCH", "946684800"))).tm_year
            assert [(i.filename, i.date_time[0]) for i in z.infolist()] == [("s.usdc", year)]
    b = export_usd(tmp_path / f"s{ext}", tracks, FPS, markers=MARKERS, metadata=METADATA).read_bytes()
    assert a == b


# --- atomic write ------------------------------------------------------------------------------

def _half_write_then(exc):
    def broken(layer, path):
        with open(path, "w") as fh:
            fh.write("#usda 1.0\n(\n  half a stage")
        raise exc
    return broken


@pytest.mark.parametrize("ext", [".usda", ".usdz"])
@pytest.mark.parametrize("exc", [RuntimeError("disk full"), KeyboardInterrupt()])
def test_interrupted_write_leaves_old_file_untouched(tmp_path, tracks, monkeypatch, ext, exc):
    path = tmp_path / f"out{ext}"
    path.write_bytes(b"OLD CONTENT")
    monkeypatch.setattr(usd_export, "_export_layer", _half_write_then(exc))
    with pytest.raises(type(exc)):
        export_usd(path, tracks[:1], FPS)
    assert path.read_bytes() == b"OLD CONTENT"
    assert os.listdir(tmp_path) == [path.name]


def test_interrupted_write_leaves_no_file(tmp_path, tracks, monkeypatch):
    path = tmp_path / "fresh.usda"
    monkeypatch.setattr(usd_export, "_export_layer", _half_write_then(RuntimeError("crash")))
    with pytest.raises(RuntimeError):
        export_usd(path, tracks[:1], FPS)
    assert os.listdir(tmp_path) == []


def test_failed_rename_is_a_compose_error(tmp_path, tracks, monkeypatch):
    path = tmp_path / "out.usdc"
    path.write_bytes(b"OLD")

    def no_replace(a, b):
        raise PermissionError("read-only")
    monkeypatch.setattr(usd_export.os, "replace", no_replace)
    with pytest.raises(ComposeError, match="read-only"):
        export_usd(path, tracks[:1], FPS)
    assert path.read_bytes() == b"OLD" and os.listdir(tmp_path) == ["out.usdc"]


def test_overwrite_replaces_and_reloads(tmp_path, tracks):
    path = tmp_path / "twice.usda"
    export_usd(path, tracks[:1], FPS, metadata={"run": 1})
    held = Usd.Stage.Open(str(path))  # a stage this process keeps open
    export_usd(path, tracks[:1], FPS, metadata={"run": 2})
    assert held.GetRootLayer().customLayerData["compose"]["run"] == 2
    assert Usd.Stage.Open(str(path)).GetRootLayer().customLayerData["compose"]["run"] == 2


def test_bad_inputs_are_input_errors(tmp_path, tracks):
    ch = tracks[0].character
    with pytest.raises(InputError, match="extension"):
        export_usd(tmp_path / "x.fbx", tracks, FPS)
    with pytest.raises(InputError, match="shape"):
        export_usd(tmp_path / "x.usda", [CharacterTrack("A", ch, np.zeros((5, 34)))], FPS)
    with pytest.raises(InputError, match="same prim name"):
        export_usd(tmp_path / "x.usda", [CharacterTrack("A b", ch, tracks[0].q), CharacterTrack("A_b", ch, tracks[0].q)], FPS)
    with pytest.raises(InputError, match="whole number of frames"):
        export_usd(tmp_path / "x.usda", [CharacterTrack("A", ch, tracks[0].q, start_time=0.01)], FPS)
    with pytest.raises(InputError, match="63 bytes"):
        export_usd(tmp_path / "x.usda", [CharacterTrack("x" * 60, ch, tracks[0].q)], FPS)
    with pytest.raises(InputError, match="does not exist"):
        export_usd(tmp_path / "nodir" / "x.usda", tracks, FPS)
    assert os.listdir(tmp_path) == []


def test_quaternion_conversion_all_branches():
    rng = np.random.default_rng(0)
    mats = []
    for _ in range(200):
        A = rng.normal(size=(3, 3))
        Q, Rr = np.linalg.qr(A)
        Q *= np.sign(np.linalg.det(Q))
        mats.append(Q)
    mats += [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]), np.eye(3)]
    q = quat_from_matrix(np.array(mats))
    assert np.all(q[:, 0] >= 0)
    for M, (w, x, y, z) in zip(mats, q):
        back = np.array(Gf.Matrix3d(Gf.Rotation(Gf.Quatd(w, x, y, z)))).T  # row-vector -> column
        assert np.allclose(back, M, atol=1e-12)


# --- golden file -------------------------------------------------------------------------------

def golden_stage(path):
    """The tiny two-character motion of the golden file (3 frames, coarse meshes)."""
    a, b = make_character("adult_male"), make_character("adult_female")
    qa = synthetic_q(a, 3, 10.0, seed=5)
    qb = synthetic_q(b, 3, 10.0, seed=6, shift=(0.0, 1.2))
    markers = [Marker("foot_l0", "footprint", (0.05, 0.1, 0.0), (0.0, 0.1), character="A"),
               Marker("target", "goal", (1.0, 0.6, 1.1))]
    forces = [ForceArrow("push", np.zeros((3, 3)), np.tile([0.0, 100.0, 0.0], (3, 1)))]
    return export_usd(path, [CharacterTrack("A", a, qa), CharacterTrack("B", b, qb)], 10.0, markers=markers,
                      metadata={"scenario": "golden", "energies": [1.0, 0.5]}, debug_forces=forces,
                      mesh_segments=(6, 3))


VOLATILE_KEYS = {"composeVersion", "usdVersion"}


def _structure(layer):
    """{path: (spec type, type name / value type, info)} of every spec, plus layer metadata."""
    out = {}

    def visit(path):
        spec = layer.GetObjectAtPath(path)
        if path.IsPrimPath() or path == Sdf.Path.absoluteRootPath:
            if path != Sdf.Path.absoluteRootPath:
                out[str(path)] = ("prim", spec.typeName, spec.specifier, tuple(spec.GetInfo("apiSchemas").GetAppliedItems())
                                  if spec.HasInfo("apiSchemas") else ())
        elif isinstance(spec, Sdf.AttributeSpec):
            samples = {t: layer.QueryTimeSample(path, t) for t in layer.ListTimeSamplesForPath(path)}
            out[str(path)] = ("attr", str(spec.typeName), spec.variability, spec.custom,
                              spec.default if spec.HasDefaultValue() else None, samples,
                              tuple(str(c) for c in spec.connectionPathList.GetAddedOrExplicitItems()))
        elif isinstance(spec, Sdf.RelationshipSpec):
            out[str(path)] = ("rel", tuple(str(t) for t in spec.targetPathList.GetAddedOrExplicitItems()))
    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return out


def _same_value(a, b, where):
    if isinstance(a, float) or isinstance(b, float):
        assert math.isclose(float(a), float(b), rel_tol=1e-5, abs_tol=1e-5), where
        return
    if hasattr(a, "__len__") and not isinstance(a, str) and hasattr(b, "__len__") and not isinstance(b, str):
        assert len(a) == len(b), f"{where}: size {len(a)} != {len(b)}"
        try:
            aa, bb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        except (TypeError, ValueError):
            assert [str(x) for x in a] == [str(x) for x in b], where
            return
        assert aa.shape == bb.shape, where
        assert np.allclose(aa, bb, atol=1e-5, rtol=1e-5), f"{where}: max diff {np.abs(aa - bb).max()}"
        return
    if isinstance(a, (Gf.Matrix4d, Gf.Vec3d, Gf.Vec3f, Gf.Vec2f, Gf.Quatf)):
        _same_value(list(np.asarray(a, dtype=float).ravel()) if not isinstance(a, Gf.Quatf) else
                    [a.GetReal(), *a.GetImaginary()],
                    list(np.asarray(b, dtype=float).ravel()) if not isinstance(b, Gf.Quatf) else
                    [b.GetReal(), *b.GetImaginary()], where)
        return
    assert a == b, f"{where}: {a!r} != {b!r}"


def _meta(layer):
    info = dict(layer.customLayerData["compose"])
    for k in VOLATILE_KEYS:
        info[k] = "<volatile>" if k in info else None
    return dict(defaultPrim=layer.defaultPrim, metersPerUnit=layer.pseudoRoot.GetInfo("metersPerUnit"),
                upAxis=layer.pseudoRoot.GetInfo("upAxis"), tcps=layer.timeCodesPerSecond,
                fps=layer.framesPerSecond, start=layer.startTimeCode, end=layer.endTimeCode,
                compose={k: (list(v) if hasattr(v, "__len__") and not isinstance(v, str) else v) for k, v in info.items()})


def test_golden_usda_structure(tmp_path):
    path = golden_stage(tmp_path / "two_characters.usda")
    if os.environ.get("COMPOSE_REGEN_GOLDEN"):
        GOLDEN.parent.mkdir(exist_ok=True)
        GOLDEN.write_text(path.read_text())
        pytest.skip(f"regenerated {GOLDEN}")
    assert GOLDEN.exists(), "golden file missing: run with COMPOSE_REGEN_GOLDEN=1"
    new, old = Sdf.Layer.FindOrOpen(str(path)), Sdf.Layer.OpenAsAnonymous(str(GOLDEN))
    assert _meta(new) == _meta(old)
    s_new, s_old = _structure(new), _structure(old)
    assert sorted(s_new) == sorted(s_old), (set(s_new) ^ set(s_old))
    for key, a in s_new.items():
        b = s_old[key]
        assert a[0] == b[0], key
        if a[0] == "attr":
            assert a[1:4] == b[1:4], key
            assert (a[4] is None) == (b[4] is None), key
            if a[4] is not None:
                _same_value(a[4], b[4], key)
            assert sorted(a[5]) == sorted(b[5]), key
            for t in a[5]:
                _same_value(a[5][t], b[5][t], f"{key} @ {t}")
            assert a[6] == b[6], key
        else:
            assert a == b, key
