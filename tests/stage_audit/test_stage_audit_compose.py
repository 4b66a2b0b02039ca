"""compose's own stages under `compose audit`: one body geometry (the contact handles lie on
the drawn soles, the feet rest on the floor when the handles do) and a stage that carries
everything the dynamics had (carried loads, true masses)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from scenegraph.model.body import PRESETS, drawn_shapes, make_character, standing_pose
from scenegraph.model.kinematics import numeric_fk
from scenegraph.stage_audit import audit_stage, read_stage
from scenegraph.export.usd import CharacterTrack, build_stage, export_usd

pxr = pytest.importorskip("pxr")


def _handle_world(ch, q, name):
    R, p = numeric_fk(ch, q[None, :])
    h = ch.handle(name)
    bi = [b.name for b in ch.bodies].index(h.body)
    return R[0, bi] @ np.array(h.point) + p[0, bi]


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_contact_handles_lie_on_the_drawn_soles(preset, tmp_path):
    ch = make_character(preset)
    q = standing_pose(ch)
    path = export_usd(tmp_path / "s.usda", [CharacterTrack("c", ch, np.tile(q, (5, 1)))], 120.0)
    samples = read_stage(path)
    ms = samples.characters[0].meshes
    P = ms.points[0]
    for side in ("l", "r"):
        for handle, body in (("heel", "foot"), ("ball", "foot"), ("toe", "toes")):
            x = _handle_world(ch, q, f"{handle}_{side}")
            on = P[ms.vert_mesh == ms.names.index(f"c_{body}_{side}")]
            assert np.linalg.norm(on - x, axis=1).min() < 1e-6, (handle, side)  # a vertex of the sole rim
            assert abs(x[2]) < 1e-9  # standing: every handle on the floor
        for body in ("foot", "toes"):
            on = P[ms.vert_mesh == ms.names.index(f"c_{body}_{side}")]
            assert on[:, 2].min() == pytest.approx(0.0, abs=1e-6)  # the drawn sole rests on the floor too


def test_drawn_feet_keep_the_dynamics_mass_and_centre():
    ch = make_character("adult_female")
    shapes = drawn_shapes(ch)
    for d, b in zip(shapes, ch.bodies):
        assert d.mass == pytest.approx(b.mass) and np.allclose(d.com, b.center)
        if d.kind == "keel":
            # the keel solid's own centre of mass, from its shape, is the body's centre
            com = np.array(d.center) + d.rotation @ [0.0, 0.0, 9 * math.pi / 32 * d.semi_axes[2]]
            assert np.allclose(com, b.center)
            if b.name.startswith("foot"):
                assert d.volume * 1000.0 == pytest.approx(b.mass)
            rel = np.abs(np.diag(d.inertia) - np.diag(b.inertia)) / np.diag(b.inertia)
            # drawn vs the dynamics' ellipsoid: the foot within 5 %; the toes (0.16 kg, a thin
            # wedge as wide as the foot) within 65 % of a tiny inertia (docs/usd-output.md)
            assert rel.max() < (0.05 if b.name.startswith("foot") else 0.65), (b.name, rel)
    assert sum(d.kind == "keel" for d in shapes) == 4


def test_keel_inertia_by_monte_carlo():
    """The keel's inertia formula against sampling its solid."""
    ch = make_character()
    d = [s for s in drawn_shapes(ch) if s.body == "foot_l"][0]
    a, b, c = d.semi_axes
    rng = np.random.default_rng(0)
    X = rng.uniform([-a, -b, 0], [a, b, 2 * c], size=(400000, 3))
    sig = np.sqrt(np.clip(1 - (X[:, 0] / a) ** 2, 0, None))
    inside = (X[:, 1] / (b * sig + 1e-12)) ** 2 + ((X[:, 2] - c * sig) / (c * sig + 1e-12)) ** 2 <= 1
    Y = X[inside]
    vol = inside.mean() * (2 * a) * (2 * b) * (2 * c)
    assert vol == pytest.approx(d.volume, rel=0.01)
    Y = Y - Y.mean(0)
    I = d.mass * np.diag([np.mean(Y[:, 1] ** 2 + Y[:, 2] ** 2), np.mean(Y[:, 0] ** 2 + Y[:, 2] ** 2),
                          np.mean(Y[:, 0] ** 2 + Y[:, 1] ** 2)])
    assert np.allclose(np.diag(d.inertia), np.diag(I), rtol=0.02)


def test_walking_pose_never_puts_the_visible_foot_below_a_handle_on_the_floor(tmp_path):
    """Heel strike (toes up) and heel-off (on the ball, toes flat): the lowest vertex of each
    foot is no lower than its lowest contact handle."""
    ch = make_character()
    q0 = standing_pose(ch)
    qs = []
    poses = ((20, 0, 0), (-25, 25, 0), (0, -30, 0), (0, 0, 10), (-20, 20, -10))  # ankle flex, toe flex, inversion (deg)
    for ankle, toe, inv in poses:
        q = q0.copy()
        q[ch.dof_index("ankle_flex_l")] = math.radians(ankle)
        q[ch.dof_index("toe_flex_l")] = math.radians(toe)
        q[ch.dof_index("ankle_inv_l")] = math.radians(inv)
        qs.append(q)
    shapes = {d.body: d for d in drawn_shapes(ch)}
    path = export_usd(tmp_path / "p.usda", [CharacterTrack("c", ch, np.array(qs * 2))], 120.0)
    ms = read_stage(path).characters[0].meshes
    for k, (q, pose) in enumerate(zip(qs, poses)):
        low = min(_handle_world(ch, q, f"{h}_l")[2] for h in ("heel", "ball", "toe"))
        psi = math.radians(abs(pose[2]))  # rolled about the keel: dips at most b² ψ² / (2c)
        dip = max(d.semi_axes[1] ** 2 / (2 * d.semi_axes[2]) for d in (shapes["foot_l"], shapes["toes_l"])) * psi ** 2
        foot = np.isin(ms.vert_mesh, [ms.names.index("c_foot_l"), ms.names.index("c_toes_l")])
        below = low - ms.points[k, foot, 2].min()  # how far the drawn foot reaches below its lowest handle
        assert below <= dip + 1e-6, (pose, below, dip)
        assert below < 0.002, (pose, below)  # the 2 mm, up to 10° of inversion


def test_stage_carries_the_suitcase_and_the_true_mass(tmp_path):
    ch = make_character().with_extra_mass("palm_r", 3.0)
    q = np.tile(standing_pose(ch), (8, 1))
    stage = build_stage([CharacterTrack("walker", ch, q)], 120.0)
    skel = stage.GetPrimAtPath("/World/walker/walker_Skeleton")
    assert skel.GetAttribute("compose:mass").Get() == pytest.approx(76.0)
    assert skel.GetAttribute("compose:carriedMass").Get() == pytest.approx(3.0)
    suitcase = stage.GetPrimAtPath("/World/walker/walker_carried_0")
    assert suitcase.GetAttribute("compose:carried").Get() == "palm_r"
    from pxr import UsdPhysics
    assert UsdPhysics.MassAPI(suitcase).GetMassAttr().Get() == pytest.approx(3.0)
    # its centre is the palm handle at the bind pose
    com = np.array(UsdPhysics.MassAPI(suitcase).GetCenterOfMassAttr().Get())
    assert np.allclose(com, _handle_world(ch, standing_pose(ch), "palm_r"), atol=1e-6)
    path = export_usd(tmp_path / "s.usda", [CharacterTrack("walker", ch, q)], 120.0)
    rep = audit_stage(path)
    assert rep["characters"]["walker"]["mass_kg"] == pytest.approx(76.0, abs=1e-3)
    assert rep["characters"]["walker"]["mesh_mass_kg"]["walker_carried_0"] == pytest.approx(3.0)
    assert rep["passes"], rep["failures"]  # standing still on the floor


def test_ramps_preview_at_their_height_and_audit_on_them(tmp_path):
    """A standing figure on a 10° ramp: the preview draws the ramp's top where the ramp is
    (not flat, not as a marker) and the auditor measures heights above the ramp."""
    from scenegraph.export import preview
    from scenegraph.model.ground import Ground, Plane
    ramp = Plane(math.radians(10.0), 0.0, (-1.0, -1.0, 2.0, 1.0), (-1.0, 0.0), name="ramp")
    ground = Ground(planes=(ramp,))
    ch = make_character()
    q = np.tile(standing_pose(ch), (10, 1))
    q[:, 0] = 1.0
    # lift the level feet 5 cm above the ramp's height under the pelvis (~0.35 m); the toes,
    # 0.2 m ahead, are then 5 − 3.5 cm above the ramp
    q[:, 2] += ramp.plane_height(1.0, 0.0) + 0.05
    path = export_usd(tmp_path / "r.usda", [CharacterTrack("c", ch, q)], 120.0, ground=ground)
    sc = preview.scene_from_stage(path)
    assert all(m.kind != "slope" for m in sc.markers)
    assert len(sc.ramps) == 1
    top = sc.ramps[0]
    assert np.allclose(top[:, 2], [ramp.plane_height(x, y) for x, y in top[:, :2]], atol=1e-6)
    assert top[:, 2].max() > 0.5
    rep = audit_stage(path)
    assert "ramp triangles" in rep["ground"]
    assert rep["characters"]["c"]["penetration_max_mm"] == 0.0
    q2 = q.copy()
    q2[:, 2] -= 0.10  # now the feet go into the ramp
    rep2 = audit_stage(export_usd(tmp_path / "r2.usda", [CharacterTrack("c", ch, q2)], 120.0, ground=ground))
    assert rep2["characters"]["c"]["penetration_max_mm"] > 20.0
    flat = audit_stage(export_usd(tmp_path / "r3.usda", [CharacterTrack("c", ch, q2)], 120.0))
    assert flat["characters"]["c"]["penetration_max_mm"] == 0.0  # the same pose above a flat floor


def test_run_hook_audits_a_120hz_stage_with_compose_forces(tmp_path):
    """schedules.execution.run_audit (what compose run calls after writing its stage), on the bundled
    handhold scene's initial motions (no solve): the 120 Hz stage is written with the hands'
    asked-for contact and the forces, and the verdict comes back for the report."""
    import io
    from pxr import Usd
    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene
    from schedules.execution.run_audit import allowed_contacts, audit_run_stage
    scene = build_scene(load_scenario("handhold"))
    allowed = allowed_contacts(scene)
    assert allowed and all("hand" in a for a in allowed)
    c = scene.characters[0]
    t = np.linspace(c.motion.start, c.motion.end, 7)
    forces = {c.name: {"heel_l": (t, np.tile([0.0, 0.0, 300.0], (7, 1)))}}
    log = io.StringIO()
    rep = audit_run_stage(scene, tmp_path / "unused.usda", 30.0, tmp_path, {"allowedContacts": allowed}, log, forces)
    stage = tmp_path / "stage_120hz.usdc"
    assert rep["stage"] == str(stage) and stage.is_file()
    assert rep["verdict"] in ("pass", "fail") and set(rep["summary"]) >= {"penetration_max_mm", "mass_kg"}
    assert "compose: stage audit:" in log.getvalue()
    st = Usd.Stage.Open(str(stage))
    assert list(st.GetRootLayer().customLayerData["compose"]["allowedContacts"]) == allowed
    arrow = st.GetPrimAtPath(f"/World/Debug/{c.name}_heel_l")
    assert arrow.GetAttribute("compose:character").Get() == c.name
    assert np.allclose(arrow.GetAttribute("compose:force").Get(12), (0, 0, 300.0))
    assert any("residual_vs_stage_forces_max_bw" in s for s in rep["systems"].values())


def test_solver_forces_are_interpolated_within_contact_runs_only():
    from schedules.execution.run_audit import _interp_runs
    t = np.arange(0, 1.0001, 0.05)
    ht = np.array([0.0, 0.1, 0.2, 0.3, 0.7, 0.8, 0.9])  # two contact runs, a swing between
    hf = np.stack([np.zeros(7), np.zeros(7), ht * 100], 1)
    V = _interp_runs(t, ht, hf)
    assert np.allclose(V[:, 2], np.where((t <= 0.3 + 1e-9) | ((t >= 0.7 - 1e-9) & (t <= 0.9 + 1e-9)), t * 100, 0.0))


def test_preview_draws_the_carried_suitcase_from_the_stage_as_from_the_tracks(tmp_path):
    from scenegraph.export import preview
    ch = make_character().with_extra_mass("palm_r", 3.0)
    tracks = [CharacterTrack("walker", ch, np.tile(standing_pose(ch), (3, 1)))]
    path = export_usd(tmp_path / "s.usda", tracks, 30.0)
    es = sorted((j, tuple(np.round(c, 5)), tuple(np.round(s, 5)))
                for j, c, s in preview.scene_from_stage(path).characters[0].ellipsoids)
    et = sorted((j, tuple(np.round(c, 5)), tuple(np.round(s, 5)))
                for j, c, s in preview.scene_from_tracks(tracks, 30.0).characters[0].ellipsoids)
    assert len(es) == len(et) == 19
    for (j1, c1, s1), (j2, c2, s2) in zip(es, et):
        assert j1 == j2 and np.allclose(c1, c2, atol=1e-4) and np.allclose(s1, s2, atol=1e-4)
