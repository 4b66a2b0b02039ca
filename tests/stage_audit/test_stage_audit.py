"""`compose audit` against synthetic ground truth: stages written here with pxr alone (one
rigid box or cylinder per SkelRoot, rigidly skinned to a one-joint skeleton) whose motion
and forces are known in closed form or by accurate integration."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenegraph.stage_audit import AuditSettings, audit_stage
from scenegraph.stage_audit.momenta import G

pxr = pytest.importorskip("pxr")
ROOT = Path(__file__).resolve().parents[2]


# --- synthetic stages ------------------------------------------------------------------------

def box_mesh(size, center=(0.0, 0.0, 0.0)):
    """Closed box (8 points, 6 quads wound outward), body frame."""
    a, b, c = (s / 2 for s in size)
    P = np.array([[x, y, z] for z in (-c, c) for y in (-b, b) for x in (-a, a)], float) + center
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return P, faces


def cylinder_mesh(radius, width, n=96):
    """Closed prism approximating a cylinder along body y, axis through the origin."""
    ang = 2 * np.pi * np.arange(n) / n
    ring = np.stack([radius * np.cos(ang), np.zeros(n), radius * np.sin(ang)], 1)
    P = np.concatenate([ring + [0, -width / 2, 0], ring + [0, width / 2, 0]])
    faces = [[k, n + k, n + (k + 1) % n, (k + 1) % n] for k in range(n)]  # outward
    faces.append(list(range(n)))  # the y = -w/2 cap: increasing angle in x-z turns about -y
    faces.append([n + k for k in range(n)][::-1])
    return P, faces


def write_stage(path, bodies, fps, up="Z", mpu=1.0):
    """``bodies``: list of dicts name, points (n,3), faces, R (T,3,3), p (T,3), optional mass.
    One SkelRoot per body; the joint's world transform at frame k is (R[k], p[k])."""
    from pxr import Gf, Usd, UsdGeom, UsdPhysics, UsdSkel, Vt
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    T = bodies[0]["p"].shape[0]
    stage.SetTimeCodesPerSecond(fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(T - 1)
    UsdGeom.Xform.Define(stage, "/World")
    conv = np.eye(3) if up == "Z" else np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)  # Z-up -> Y-up
    for b in bodies:
        root = f"/World/{b['name']}"
        UsdSkel.Root.Define(stage, root)
        skel = UsdSkel.Skeleton.Define(stage, f"{root}/Skel")
        anim = UsdSkel.Animation.Define(stage, f"{root}/Skel/Anim")
        skel.CreateJointsAttr(Vt.TokenArray(["body"]))
        anim.CreateJointsAttr(Vt.TokenArray(["body"]))
        skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
        skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        for k in range(T):
            R = conv @ b["R"][k] @ conv.T
            p = conv @ b["p"][k] / mpu
            q = Gf.Quatf(Gf.Matrix4d(*[float(x) for x in np.block([[R.T, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]).ravel()]).ExtractRotationQuat())
            anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, p))]), k)
            anim.CreateRotationsAttr().Set(Vt.QuatfArray([q]), k)
            anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)]), k)
        mesh = UsdGeom.Mesh.Define(stage, f"{root}/{b['name']}_mesh")
        P = (np.asarray(b["points"], float) @ conv.T) / mpu
        mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, x)) for x in P]))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([len(f) for f in b["faces"]]))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([i for f in b["faces"] for i in f]))
        bind = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        bind.CreateSkeletonRel().SetTargets([skel.GetPath()])
        bind.CreateJointIndicesPrimvar(constant=True, elementSize=1).Set(Vt.IntArray([0]))
        bind.CreateJointWeightsPrimvar(constant=True, elementSize=1).Set(Vt.FloatArray([1.0]))
        bind.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
        if b.get("mass") is not None:
            UsdPhysics.MassAPI.Apply(mesh.GetPrim()).CreateMassAttr(float(b["mass"]))
    stage.GetRootLayer().Save()
    return path


def rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def torque_free(I_body, R0, L_world, t, substeps=200):
    """Orientations (T,3,3) of a free rigid body with constant world angular momentum."""
    Iinv = np.linalg.inv(I_body)
    out = [R0]
    R = R0.copy()
    for k in range(1, len(t)):
        h = (t[k] - t[k - 1]) / substeps
        for _ in range(substeps):
            def w(Rx):
                return Rx @ Iinv @ Rx.T @ L_world
            k1 = w(R)
            k2 = w(rot(k1, np.linalg.norm(k1) * h / 2) @ R) if np.linalg.norm(k1) else k1
            k3 = w(rot(k2, np.linalg.norm(k2) * h / 2) @ R) if np.linalg.norm(k2) else k2
            k4 = w(rot(k3, np.linalg.norm(k3) * h) @ R) if np.linalg.norm(k3) else k3
            om = (k1 + 2 * k2 + 2 * k3 + k4) / 6
            R = rot(om, np.linalg.norm(om) * h) @ R
        out.append(R.copy())
    return np.array(out)


SIZE = (0.4, 0.25, 0.15)  # m, a box with three different inertias
MASS_DEFAULT = 1000.0 * SIZE[0] * SIZE[1] * SIZE[2]  # 15 kg at the default density


def box_inertia(m, size):
    a, b, c = size
    return m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


@pytest.fixture(scope="module")
def tumbling(tmp_path_factory):
    fps = 120.0
    t = np.arange(0, 0.8, 1 / fps)
    p0, v0 = np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.5, 4.0])
    p = p0 + v0 * t[:, None] + 0.5 * np.array([0, 0, -G]) * t[:, None] ** 2
    I = box_inertia(MASS_DEFAULT, SIZE)
    L = I @ np.array([3.0, 0.4, 5.0])  # not along a principal axis: a real tumble (nutation)
    R = torque_free(I, np.eye(3), L, t)
    P, F = box_mesh(SIZE)
    d = tmp_path_factory.mktemp("tumble")
    free = write_stage(d / "tumble.usda", [dict(name="box", points=P, faces=F, R=R, p=p)], fps)
    # the same path, spun at a constant rate about that non-principal axis: needs a torque
    om = np.linalg.inv(I) @ L
    Rc = np.array([rot(om, np.linalg.norm(om) * tk) for tk in t])
    forced = write_stage(d / "spun.usda", [dict(name="box", points=P, faces=F, R=Rc, p=p)], fps)
    return free, forced, I, om


def test_ballistic_tumbling_body_needs_no_external_wrench(tumbling):
    free, _, _, _ = tumbling
    rep = audit_stage(free)
    s = rep["systems"]["box"]
    assert rep["characters"]["box"]["mass_kg"] == pytest.approx(MASS_DEFAULT, rel=1e-6)
    assert rep["characters"]["box"]["mass_sources"] == ["default density"]
    assert s["free_flight_frames"] == s["frames_audited"] == len(np.arange(0, 0.8, 1 / 120)) - 2
    assert s["flight_wrench_max_bw"] < 1e-3
    assert s["flight_torque_rms_bw_rg"] < 1e-3  # body weight × gyration radius
    a, b, c = SIZE
    assert s["gyration_radius_m"] == pytest.approx(math.sqrt((a * a + b * b + c * c) / 12), rel=1e-6)
    assert s["flight_ang_momentum_drift"] < 1e-3 * np.linalg.norm(box_inertia(MASS_DEFAULT, SIZE) @ [3, .4, 5])
    assert rep["passes"], rep["failures"]


def test_spinning_about_a_non_principal_axis_needs_the_gyroscopic_torque(tumbling):
    _, forced, I, om = tumbling
    rep = audit_stage(forced)
    fr = rep["systems"]["box"]["frames"]
    k = len(fr["t"]) // 2
    t = fr["t"][k]
    R = rot(om, np.linalg.norm(om) * t)
    w = om  # body rate along a fixed axis: world ω = R ω_b = ω_b (axis invariant)
    tau = np.cross(w, R @ I @ R.T @ w)  # dH/dt = ω × H for constant ω
    bw = MASS_DEFAULT * G
    assert np.allclose(np.array(fr["torque_com_bw_m"][k]) * bw, tau, atol=0.01 * np.linalg.norm(tau))
    s = rep["systems"]["box"]
    assert s["flight_torque_rms_bw_rg"] * bw * s["gyration_radius_m"] > 0.5 * np.linalg.norm(tau)
    assert not rep["passes"] and any("flight_torque" in f for f in rep["failures"])


def test_pushed_body_needs_exactly_the_push(tmp_path):
    fps, m = 120.0, 12.5
    t = np.arange(0, 0.6, 1 / fps)
    Fext = np.array([30.0, -20.0, 60.0])  # N, constant, besides gravity
    a = Fext / m + [0, 0, -G]
    p = np.array([0, 0, 1.5]) + np.array([0.5, 0, 1.0]) * t[:, None] + 0.5 * a * t[:, None] ** 2
    R = np.tile(np.eye(3), (len(t), 1, 1))
    P, F = box_mesh(SIZE)
    path = write_stage(tmp_path / "pushed.usda", [dict(name="crate", points=P, faces=F, R=R, p=p, mass=m)], fps)
    rep = audit_stage(path)
    assert rep["characters"]["crate"]["mass_kg"] == pytest.approx(m)
    assert rep["characters"]["crate"]["mass_sources"] == ["mass"]
    f = np.array(rep["systems"]["crate"]["frames"]["force_bw"]) * m * G
    assert np.allclose(f, Fext, atol=1e-3 * np.linalg.norm(Fext))
    s = rep["systems"]["crate"]
    assert s["flight_wrench_rms_bw"] == pytest.approx(np.linalg.norm(Fext) / (m * G), rel=1e-3)
    assert not rep["passes"] and any("flight_wrench_rms_bw" in x for x in rep["failures"])


def test_force_prims_on_the_stage_explain_the_push(tmp_path):
    """compose's debug force prims (compose:force, compose:character): what they supply is
    subtracted from what the motion needs."""
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    fps, m = 120.0, 12.5
    t = np.arange(0, 0.3, 1 / fps)
    Fext = np.array([30.0, -20.0, 60.0])
    p = np.array([0, 0, 1.5]) + 0.5 * (Fext / m + [0, 0, -G]) * t[:, None] ** 2
    P, F = box_mesh(SIZE)
    path = write_stage(tmp_path / "f.usda", [dict(name="crate", points=P, faces=F,
                                                  R=np.tile(np.eye(3), (len(t), 1, 1)), p=p, mass=m)], fps)
    stage = Usd.Stage.Open(str(path))
    for name, share in (("push_a", 0.5), ("push_b", 0.25)):
        c = UsdGeom.BasisCurves.Define(stage, f"/World/Debug/{name}")
        c.CreateCurveVertexCountsAttr(Vt.IntArray([2]))
        prim = c.GetPrim()
        prim.CreateAttribute("compose:character", Sdf.ValueTypeNames.String, custom=True).Set("crate")
        fa = prim.CreateAttribute("compose:force", Sdf.ValueTypeNames.Double3, custom=True)
        for k in range(len(t)):
            fa.Set(Gf.Vec3d(*(share * Fext)), k)
            c.CreatePointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, p[k])), Gf.Vec3f(*map(float, p[k] + 0.1))]), k)
    stage.GetRootLayer().Save()
    rep = audit_stage(path)
    s = rep["systems"]["crate"]
    assert s["residual_vs_stage_forces_max_bw"] == pytest.approx(0.25 * np.linalg.norm(Fext) / (m * G), rel=2e-3)
    assert rep["summary"]["residual_vs_stage_forces_max_bw"] == s["residual_vs_stage_forces_max_bw"]


def test_y_up_centimetre_stage_gives_the_same_figures(tmp_path):
    fps, m = 120.0, 12.5
    t = np.arange(0, 0.5, 1 / fps)
    Fext = np.array([10.0, 0.0, 40.0])
    p = np.array([0, 0, 1.5]) + 0.5 * (Fext / m + [0, 0, -G]) * t[:, None] ** 2
    R = np.tile(np.eye(3), (len(t), 1, 1))
    P, F = box_mesh(SIZE)
    path = write_stage(tmp_path / "yup.usda", [dict(name="crate", points=P, faces=F, R=R, p=p)], fps, up="Y", mpu=0.01)
    rep = audit_stage(path)
    assert rep["up_axis"] == "Y"
    assert rep["characters"]["crate"]["mass_kg"] == pytest.approx(MASS_DEFAULT, rel=1e-5)
    f = np.array(rep["systems"]["crate"]["frames"]["force_bw"]) * MASS_DEFAULT * G
    assert np.allclose(f, Fext / m * MASS_DEFAULT, atol=0.05)


def test_sliding_block_friction_use_cop_and_slide(tmp_path):
    fps, mu_true, v0 = 120.0, 0.5, 1.2
    t = np.arange(0, 0.2, 1 / fps)  # decelerating until it stops at v0 / (μ g) = 0.245 s
    x = v0 * t - 0.5 * mu_true * G * t ** 2
    h = SIZE[2]
    p = np.stack([x, np.zeros_like(t), np.full_like(t, h / 2)], 1)
    R = np.tile(np.eye(3), (len(t), 1, 1))
    P, F = box_mesh(SIZE)
    path = write_stage(tmp_path / "slide.usda", [dict(name="block", points=P, faces=F, R=R, p=p)], fps)
    rep = audit_stage(path)
    s = rep["systems"]["block"]
    assert s["contact_frames"] == s["frames_audited"] and s["free_flight_frames"] == 0
    assert s["friction_use_max"] == pytest.approx(mu_true, rel=2e-3)
    fr = s["frames"]
    k = len(fr["t"]) // 2
    # a decelerating block presses on its leading edge: CoP = COM + μ h/2 ahead, on the floor
    assert fr["cop"][k][0] == pytest.approx(x[k + 1] + mu_true * h / 2, abs=1e-3)
    assert fr["cop_outside_cm"][k] == 0.0
    assert s["dense_residual_max_bw"] < 1e-3  # inside the cone of μ = 0.8
    c = rep["characters"]["block"]
    assert c["penetration_max_mm"] < 1e-3
    # never slow, it is not a stance but a scuff at 1.2 m/s; once it comes to rest, its whole
    # slide is one stance: v0² / (2 μ g)
    assert c["stances"] == 0 and c["scuff_speed_max_mps"] == pytest.approx(v0 - mu_true * G / fps / 2, rel=1e-3)
    stop = v0 / (mu_true * G)
    t2 = np.arange(0, 0.4, 1 / fps)
    x2 = np.where(t2 < stop, v0 * t2 - 0.5 * mu_true * G * t2 ** 2, v0 * v0 / (2 * mu_true * G))
    p2 = np.stack([x2, np.zeros_like(t2), np.full_like(t2, h / 2)], 1)
    rep3 = audit_stage(write_stage(tmp_path / "stop.usda", [dict(name="block", points=P, faces=F,
                                                                  R=np.tile(np.eye(3), (len(t2), 1, 1)), p=p2)], fps))
    assert rep3["characters"]["block"]["stance_slide_max_mm"] == pytest.approx(x2[-1] * 1000, rel=1e-3)
    assert not rep3["passes"] and any("stance_slide" in f for f in rep3["failures"])
    # with μ = 0.3 the same sliding needs more friction than the cone holds: a residual
    rep2 = audit_stage(path, settings=AuditSettings(mu=0.3))
    excess = (mu_true - 0.3) / math.sqrt(1 + 0.09)
    assert rep2["systems"]["block"]["dense_residual_max_bw"] == pytest.approx(excess, rel=1e-2)


def test_cop_outside_as_a_moment_at_a_small_normal_force(tmp_path):
    """A box touching the floor (bottom within the contact band) while it falls at 9 m/s²
    (normal force 0.08 bw) and spins up about x: the needed moment I α puts the centre of
    pressure (I α / F_z) beyond the box's half-width b/2; the distance outside is
    I α / F_z − b/2 and, as a moment, I α − F_z b/2 (ground truth in closed form)."""
    fps, az, offset = 120.0, -9.0, 0.25  # CoP wanted 0.25 m from the centre, half-width 0.125 m
    m = MASS_DEFAULT
    Fz = m * (G + az)
    Ixx = box_inertia(m, SIZE)[0, 0]
    alpha = Fz * offset / Ixx
    t = np.arange(0, 5) / fps
    p = np.stack([np.zeros_like(t), np.zeros_like(t), SIZE[2] / 2 + 0.003 + 0.5 * az * t ** 2], 1)
    R = np.array([rot([1, 0, 0], 0.5 * alpha * tk ** 2) for tk in t])
    P, F = box_mesh(SIZE)
    rep = audit_stage(write_stage(tmp_path / "tip.usda", [dict(name="box", points=P, faces=F, R=R, p=p)], fps))
    s = rep["systems"]["box"]
    bw = m * G
    assert s["contact_frames"] == s["frames_audited"] == 3
    fr = s["frames"]
    assert np.allclose([f[2] for f in fr["force_bw"]], Fz / bw, rtol=1e-3)  # 0.08 bw
    assert np.allclose(fr["cop_outside_cm"], (offset - SIZE[1] / 2) * 100, rtol=0.03)
    want = (Ixx * alpha - Fz * SIZE[1] / 2) / bw  # bw·m
    assert np.allclose(fr["cop_moment_outside_bw_m"], want, rtol=0.03)
    assert s["cop_moment_outside_max_bw_m"] == pytest.approx(want, rel=0.03)
    assert rep["summary"]["cop_moment_outside_max_bw_m"] == s["cop_moment_outside_max_bw_m"]
    w = s["cop_outside_worst"]
    assert w["normal_bw"] == pytest.approx(Fz / bw, rel=1e-3) and w["moment_bw_m"] == pytest.approx(want, rel=0.03)
    assert not rep["passes"] and any("cop_outside_max_cm" in f for f in rep["failures"])


def _roller(tmp_path, name, rolling):
    fps, R_, v = 120.0, 0.06, 0.8
    t = np.arange(0, 0.5, 1 / fps)
    p = np.stack([v * t, np.zeros_like(t), np.full_like(t, R_)], 1)
    Rm = np.array([rot([0, 1, 0], v * tk / R_ if rolling else 0.0) for tk in t])
    P, F = cylinder_mesh(R_, 0.1)
    return audit_stage(write_stage(tmp_path / f"{name}.usda", [dict(name=name, points=P, faces=F, R=Rm, p=p)], fps))


def test_rolling_foot_does_not_slide_but_a_dragged_one_does(tmp_path):
    roll = _roller(tmp_path, "roll", True)
    drag = _roller(tmp_path, "drag", False)
    c = roll["characters"]["roll"]
    assert c["stances"] > 0
    # a rolling point's path near the floor is a cycloid: while it is within the contact
    # tolerance h it moves 2 R (θ − sin θ) with R (1 − cos θ) = h — about 1.4 mm here
    th = math.acos(1 - AuditSettings().contact_tol / 0.06)
    assert c["stance_slide_max_mm"] <= 2 * 0.06 * (th - math.sin(th)) * 1000 * 1.01
    assert c["penetration_max_mm"] < 1e-3
    # dragged at a steady 0.8 m/s: never planted, so a scuff (a clearance fault), not a stance
    assert drag["characters"]["drag"]["stances"] == 0
    assert drag["characters"]["drag"]["scuff_speed_max_mps"] == pytest.approx(0.8, rel=1e-3)
    s = roll["systems"]["roll"]
    assert s["cop_outside_max_cm"] < 0.1 and s["friction_use_max"] < 1e-3
    assert roll["characters"]["roll"]["scuffs"] == 0


def test_overlap_between_characters_and_groups(tmp_path):
    fps = 120.0
    t = np.arange(0, 0.2, 1 / fps)
    R = np.tile(np.eye(3), (len(t), 1, 1))
    P, F = box_mesh((0.2, 0.2, 0.2))
    pa = np.tile([0.0, 0.0, 0.1], (len(t), 1))
    pb = np.tile([0.17, 0.0, 0.1], (len(t), 1))  # 3 cm into the first
    path = write_stage(tmp_path / "two.usda", [dict(name="a", points=P, faces=F, R=R, p=pa),
                                               dict(name="b", points=P, faces=F, R=R, p=pb)], fps)
    rep = audit_stage(path)
    assert rep["summary"]["interpenetration_max_cm"] == pytest.approx(3.0, abs=1e-3)
    assert rep["pairs"]["a~b"]["worst_meshes"] == "a/a_mesh~b/b_mesh"
    assert set(rep["systems"]) == {"a", "b"}
    grouped = audit_stage(path, settings=AuditSettings(groups=("auto",)))
    assert set(grouped["systems"]) == {"a+b"} and grouped["systems"]["a+b"]["mass_kg"] == pytest.approx(16.0)
    allowed = audit_stage(path, settings=AuditSettings(allowed_contacts=("a/*~b/*",)))
    assert allowed["summary"]["interpenetration_max_cm"] == 0.0
    assert allowed["pairs"]["a~b"]["asked_for_overlap_max_cm"] == pytest.approx(3.0, abs=1e-3)


# --- the command -----------------------------------------------------------------------------

def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "schedules.cli.main", "audit", *map(str, args)], cwd=cwd or ROOT,
                          capture_output=True, text=True, timeout=300,
                          env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})


def test_cli_writes_the_report_and_exits_by_verdict(tumbling, tmp_path):
    free, forced, _, _ = tumbling
    out = tmp_path / "r.json"
    p = _cli(free, "--report", out)
    assert p.returncode == 0, p.stderr
    rep = json.loads(out.read_text())
    assert rep["passes"] and rep["fps"] == 120.0
    assert "audit: pass" in p.stdout
    p = _cli(forced, "--fps", 60, "--report", out)
    assert p.returncode == 1, p.stderr
    assert json.loads(out.read_text())["fps"] == 60.0


@pytest.mark.parametrize("args, needle", [
    (["missing.usda"], "no such stage file"),
    (["{bad}"], "not a readable USD stage"),
    (["{empty}"], "no character"),
    (["{free}", "--fps", "0"], "--fps"),
    (["{free}", "--group", "box,nobody"], "no character 'nobody'"),
])
def test_cli_bad_input_exits_2_naming_the_problem(tumbling, tmp_path, args, needle):
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\n(\n  this is not usd\n")
    from pxr import Usd
    empty = tmp_path / "empty.usda"
    st = Usd.Stage.CreateNew(str(empty))
    st.SetStartTimeCode(0)
    st.SetEndTimeCode(10)
    st.GetRootLayer().Save()
    args = [a.format(bad=bad, empty=empty, free=tumbling[0]) for a in args]
    p = _cli(*args, "--report", tmp_path / "r.json", cwd=tmp_path)
    assert p.returncode == 2, (p.stdout, p.stderr)
    assert needle in p.stderr
    assert "Traceback" not in p.stderr


def test_ground_height_follows_ramps_below_the_floor_too():
    from scenegraph.stage_audit.reader import Ground
    down = np.array([[[0, -1, 0.0], [2, -1, -0.2], [2, 1, -0.2]], [[0, -1, 0.0], [2, 1, -0.2], [0, 1, 0.0]]])
    g = Ground(down)
    assert np.allclose(g.height(np.array([1.0, 3.0, -1.0]), np.array([0.0, 0.0, 0.0])), [-0.1, 0.0, 0.0])
