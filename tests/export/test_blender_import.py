"""Import an exported stage into Blender (bpy) and compare it with UsdSkel's evaluation.

bpy is not a project dependency: its wheels are large and pin their own numpy (bpy 5.0.x
needs numpy < 2), so it lives in its own virtual environment.  The test runs Blender in a
subprocess with that environment's interpreter, so the project's environment stays as is:

    python3.11 -m venv /tmp/bpyenv && /tmp/bpyenv/bin/pip install bpy
    COMPOSE_BPY_PYTHON=/tmp/bpyenv/bin/python python -m pytest tests/export/test_blender_import.py

(bpy's Python version must match the wheel: bpy 4.2–5.0 are built for Python 3.11.)
If ``bpy`` is importable in the test's own interpreter, that interpreter is used.  Without
either, the test is skipped with the reason.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, UsdSkel, Vt  # noqa: E402

from scenegraph.model.body import make_character, standing_pose  # noqa: E402
from scenegraph.export.usd import CharacterTrack, Marker, export_usd  # noqa: E402


def _bpy_python() -> str | None:
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    env = os.environ.get("COMPOSE_BPY_PYTHON")
    if env and os.path.exists(env):
        return env
    return None


BPY_PYTHON = _bpy_python()
pytestmark = pytest.mark.skipif(
    BPY_PYTHON is None,
    reason="bpy is not importable (install it in its own venv: python3.11 -m venv /tmp/bpyenv && "
           "/tmp/bpyenv/bin/pip install bpy; then set COMPOSE_BPY_PYTHON=/tmp/bpyenv/bin/python)")

PROBE = textwrap.dedent('''
    import json, sys
    import bpy
    stage, out, mesh_frames = sys.argv[1], sys.argv[2], [int(x) for x in sys.argv[3].split(",")]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=stage, import_skeletons=True, set_frame_range=True)
    scene = bpy.context.scene
    res = {"result": sorted(result), "version": bpy.app.version_string,
           "frame_start": scene.frame_start, "frame_end": scene.frame_end,
           "objects": {o.name: o.type for o in scene.objects}, "armatures": {}, "meshes": {}}
    arms = [o for o in scene.objects if o.type == "ARMATURE"]
    meshes = [o for o in scene.objects if o.type == "MESH"]
    for a in arms:
        res["armatures"][a.name] = {"bones": [b.name for b in a.data.bones], "frames": {}}
    for f in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(f)
        for a in arms:
            res["armatures"][a.name]["frames"][str(f)] = {pb.name: list(a.matrix_world @ pb.head) for pb in a.pose.bones}
        if f in mesh_frames:
            dg = bpy.context.evaluated_depsgraph_get()
            for o in meshes:
                ev = o.evaluated_get(dg)
                res["meshes"].setdefault(o.name, {})[str(f)] = [list(ev.matrix_world @ v.co) for v in ev.data.vertices]
    json.dump(res, open(out, "w"))
''')


def _q(ch, T, fps, seed, shift):
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    q = np.tile(standing_pose(ch), (T, 1))
    lo, hi = ch.lower, ch.upper
    for j in range(6, q.shape[1]):
        amp = 0.4 * min(hi[j] - lo[j], 2.0)
        q[:, j] = np.clip(amp * np.sin(2 * np.pi * rng.uniform(0.5, 1.5) * t + rng.uniform(0, 6.3)), lo[j], hi[j])
    q[:, 0] = shift[0] + 1.0 * t
    q[:, 1] = shift[1]
    q[:, 3] = rng.uniform(-3, 3) + 0.7 * t
    q[:, 4] = 0.2 * np.sin(3 * t)
    return q


def _usdskel_reference(path):
    """{skeleton prim name: {frame: {leaf joint name: world position}}}, skinned points."""
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    joints_out, points_out = {}, {}
    xf = UsdGeom.XformCache()
    t0, t1 = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            sq = cache.GetSkelQuery(binding.GetSkeleton())
            leaves = [str(j).rsplit("/", 1)[-1] for j in sq.GetJointOrder()]
            frames = {}
            for f in range(t0, t1 + 1):
                xf.SetTime(f)
                W = sq.ComputeJointWorldTransforms(xf)
                frames[f] = {n: np.array(W[i].ExtractTranslation()) for i, n in enumerate(leaves)}
            joints_out[binding.GetSkeleton().GetPrim().GetName()] = frames
            for skq in binding.GetSkinningTargets():
                pts0 = UsdGeom.Mesh(skq.GetPrim()).GetPointsAttr().Get()
                per = {}
                for f in (t0, (t0 + t1) // 2, t1):
                    pts = Vt.Vec3fArray(pts0)
                    skq.ComputeSkinnedPoints(sq.ComputeSkinningTransforms(f), pts, f)
                    per[f] = np.asarray(pts, dtype=float)
                points_out[skq.GetPrim().GetName()] = per
    return (t0, t1), joints_out, points_out


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usdz"])
def test_blender_imports_stage_with_animation_intact(tmp_path, ext):
    fps = 24.0
    a, b = make_character("adult_male"), make_character("adult_female")
    tracks = [CharacterTrack("Hero", a, _q(a, 20, fps, 1, (0.0, 0.0))),
              CharacterTrack("Partner", b, _q(b, 16, fps, 2, (0.5, 1.2)), start_time=3 / fps)]
    stage = export_usd(tmp_path / f"scene{ext}", tracks, fps,
                       markers=[Marker("fp", "footprint", (0.2, 0.1, 0.0), (0.0, 0.4)),
                                Marker("goal", "goal", (2.0, 0.0, 1.0))])
    (t0, t1), ref_joints, ref_points = _usdskel_reference(stage)
    probe = tmp_path / "probe.py"
    probe.write_text(PROBE)
    out = tmp_path / "blender.json"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    proc = subprocess.run([BPY_PYTHON, str(probe), str(stage), str(out), f"{t0},{(t0 + t1) // 2},{t1}"],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    res = json.loads(out.read_text())
    assert res["result"] == ["FINISHED"]
    # one armature per character, 18 bones named after the joints' leaf names
    assert sorted(res["armatures"]) == sorted(ref_joints) == ["Hero_Skeleton", "Partner_Skeleton"]
    assert (res["frame_start"], res["frame_end"]) == (t0, t1) == (0, 19)
    worst = 0.0
    for arm, data in res["armatures"].items():
        assert len(data["bones"]) == 18 and sorted(data["bones"]) == sorted(ref_joints[arm][t0])
        for f in range(t0, t1 + 1):
            for bone, pos in data["frames"][str(f)].items():
                worst = max(worst, float(np.abs(np.array(pos) - ref_joints[arm][f][bone]).max()))
    assert worst <= 1e-3, f"joint world positions differ from UsdSkel by up to {worst} m"
    # skinned meshes: every vertex where UsdSkel puts it
    assert set(ref_points) <= set(res["meshes"]) and len(ref_points) == 36
    assert {"fp", "goal", "Camera"} <= set(res["objects"])  # markers (as meshes) and the camera
    worst_v = 0.0
    for name in ref_points:
        for f, verts in res["meshes"][name].items():
            worst_v = max(worst_v, float(np.abs(np.array(verts) - ref_points[name][int(f)]).max()))
    assert worst_v <= 1e-3, f"skinned vertices differ from UsdSkel by up to {worst_v} m"
    print(f"Blender {res['version']}: joints within {worst:.2e} m, vertices within {worst_v:.2e} m")
