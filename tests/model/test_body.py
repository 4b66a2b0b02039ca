"""The character model: structure, anthropometry, scaling, handles, bad presets."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from conftest import character
from scenarios.errors import ComposeError, InputError
from scenegraph.model.body import DENSITY, DOF_NAMES, default_character, JOINT_DOF_NAMES, N_DOF, N_JOINT, PRESETS, make_character, standing_pose
from scenegraph.model.kinematics import handle_positions_fn

LIMBS = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toes")


def test_structure(adult):
    assert len(adult.bodies) == 18
    assert len(adult.dofs) == N_DOF == 35 and N_JOINT == 29
    assert len(DOF_NAMES) == len(set(DOF_NAMES)) == 35 and len(JOINT_DOF_NAMES) == 29
    assert tuple(adult.dof_names) == DOF_NAMES  # the literal DOF order agrees with make_character
    assert default_character() is default_character() and tuple(default_character().dof_names) == DOF_NAMES
    assert [d.kind for d in adult.dofs[:3]] == ["prismatic"] * 3
    assert all(d.kind == "revolute" for d in adult.dofs[3:])
    for i, d in enumerate(adult.dofs):
        assert d.parent < i  # parents come first
        assert np.isclose(np.linalg.norm(d.axis), 1.0)
        assert d.lower < d.upper
    # every body hangs on exactly one DOF frame, each DOF frame carries at most one body
    frames = [b.frame for b in adult.bodies]
    assert len(set(frames)) == 18 and all(adult.dofs[f].body == b.name for f, b in zip(frames, adult.bodies))


JOINTS = {  # joint -> its DOFs: ball joints 3, saddles 2, hinges 1
    "waist": ["waist_flex", "waist_lat", "waist_twist"],
    "hip_l": ["hip_flex_l", "hip_abd_l", "hip_rot_l"], "hip_r": ["hip_flex_r", "hip_abd_r", "hip_rot_r"],
    "shoulder_l": ["shoulder_flex_l", "shoulder_twist_l", "shoulder_abd_l"],
    "shoulder_r": ["shoulder_flex_r", "shoulder_twist_r", "shoulder_abd_r"],
    "ankle_l": ["ankle_flex_l", "ankle_inv_l"], "ankle_r": ["ankle_flex_r", "ankle_inv_r"],
    "knee_l": ["knee_flex_l"], "knee_r": ["knee_flex_r"], "elbow_l": ["elbow_flex_l"], "elbow_r": ["elbow_flex_r"],
    "chest": ["chest_flex"], "neck": ["neck_flex"], "wrist_l": ["wrist_flex_l"], "wrist_r": ["wrist_flex_r"],
    "toe_l": ["toe_flex_l"], "toe_r": ["toe_flex_r"],
}


def test_joint_types(adult):
    """17 joints between 18 bodies; a multi-DOF joint is a chain of DOFs about distinct axes
    at one point, and only its last DOF frame carries the child body."""
    assert sum(len(v) for v in JOINTS.values()) == N_JOINT
    assert sorted(sum(JOINTS.values(), [])) == sorted(JOINT_DOF_NAMES)
    for joint, names in JOINTS.items():
        idx = [adult.dof_index(n) for n in names]
        axes = {tuple(np.abs(adult.dofs[i].axis)) for i in idx}
        assert len(axes) == len(names), joint
        for a, b in zip(idx, idx[1:]):
            assert adult.dofs[b].parent == a and adult.dofs[b].offset == (0.0, 0.0, 0.0)
        assert [adult.dofs[i].body is not None for i in idx] == [False] * (len(idx) - 1) + [True]


@pytest.mark.parametrize("preset", list(PRESETS))
def test_masses_sum_to_total(preset):
    for scale in (None, 1.3):
        mass = None if scale is None else PRESETS[preset].mass * scale
        ch = make_character(preset, mass=mass)
        expected = PRESETS[preset].mass if mass is None else mass
        assert ch.total_mass == pytest.approx(expected, rel=1e-12)
        assert all(b.mass > 0 for b in ch.bodies)


@pytest.mark.parametrize("preset,sex", [("adult_male", 0), ("adult_female", 1)])
def test_de_leva_mass_fractions(preset, sex):
    """Segment masses follow de Leva (1996): thigh 14.16 % (m) / 14.78 % (f), head 6.94 / 6.68 %, ..."""
    ch = make_character(preset)
    table = {"head": (6.94, 6.68), "thigh_l": (14.16, 14.78), "shank_r": (4.33, 4.81), "upper_arm_l": (2.71, 2.55),
             "forearm_r": (1.62, 1.38), "hand_l": (0.61, 0.56), "pelvis": (11.17, 12.47)}
    for body, frac in table.items():
        assert ch.body(body).mass / ch.total_mass == pytest.approx(frac[sex] / 100, rel=2e-3), body
    feet = ch.body("foot_l").mass + ch.body("toes_l").mass
    assert feet / ch.total_mass == pytest.approx((1.37, 1.29)[sex] / 100, rel=2e-3)
    # left and right are mirror images
    for limb in LIMBS:
        left, right = ch.body(f"{limb}_l"), ch.body(f"{limb}_r")
        assert left.mass == right.mass and left.semi_axes == right.semi_axes


def test_child_has_relatively_heavier_head():
    child, adult = make_character("child"), make_character("adult_male")
    assert child.body("head").mass / child.total_mass > adult.body("head").mass / adult.total_mass


@pytest.mark.parametrize("preset", list(PRESETS))
def test_presets_scale_with_height_and_mass(preset):
    p = PRESETS[preset]
    base = make_character(preset)
    assert (base.height, base.mass) == (p.height, p.mass)
    k, m = 1.2, 1.5
    big = make_character(preset, height=p.height * k, mass=p.mass * m)
    assert big.total_mass == pytest.approx(base.total_mass * m, rel=1e-12)
    for a, b in zip(base.dofs, big.dofs):
        assert np.allclose(np.array(b.offset), k * np.array(a.offset), rtol=1e-12, atol=1e-15)
        assert (a.lower, a.upper) == (b.lower, b.upper) or a.name.startswith("root_")
    for a, b in zip(base.bodies, big.bodies):
        assert b.mass == pytest.approx(m * a.mass, rel=1e-12)
        assert np.allclose(b.center, k * np.array(a.center), rtol=1e-12, atol=1e-15)
        # the segment axis scales with height, the cross-section keeps the density: sqrt(m / k)
        ratio = sorted(np.array(b.semi_axes) / np.array(a.semi_axes), key=lambda r: abs(r - k))
        assert np.allclose(ratio, [k, math.sqrt(m / k), math.sqrt(m / k)], rtol=1e-12), b.name
    for a, b in zip(base.handles, big.handles):
        assert np.allclose(b.point, k * np.array(a.point), rtol=1e-12, atol=1e-15)
    assert standing_pose(big)[2] == pytest.approx(k * standing_pose(base)[2], rel=1e-12)


def test_presets_differ():
    m, f, c = (make_character(p) for p in ("adult_male", "adult_female", "child"))
    assert c.height < f.height < m.height and c.total_mass < f.total_mass < m.total_mass


REQUIRED_HANDLES = [f"{p}_{s}" for p in ("heel", "toe", "ball", "palm") for s in "lr"] + ["pelvis", "chest", "head"]


def test_handles_exist(adult):
    names = {h.name for h in adult.handles}
    assert set(REQUIRED_HANDLES) <= names
    assert len(names) == len(adult.handles)
    with pytest.raises(InputError, match="unknown handle"):
        adult.handle("nose")


@pytest.mark.parametrize("preset", list(PRESETS))
def test_standing_pose_soles_on_ground(preset):
    ch = make_character(preset)
    q = standing_pose(ch)
    names = ("heel_l", "heel_r", "ball_l", "ball_r", "toe_l", "toe_r", "palm_l", "palm_r", "head_top", "pelvis",
             "chest")
    P = np.array(handle_positions_fn(ch, names)(q))
    z = dict(zip(names, P[2]))
    for sole in names[:6]:
        assert z[sole] == pytest.approx(0.0, abs=1e-12), sole
    assert z["head_top"] == pytest.approx(ch.height, rel=0.05)  # head top near stature
    assert 0 < z["palm_l"] < z["pelvis"] < z["chest"] < z["head_top"]
    y = dict(zip(names, P[1]))
    assert y["heel_l"] > 0 > y["heel_r"]  # left is +Y
    x = dict(zip(names, P[0]))
    assert x["toe_l"] > x["ball_l"] > x["heel_l"]  # facing +X
    assert np.all((q >= ch.lower) & (q <= ch.upper))


def test_ellipsoid_inertia(adult):
    """Body inertia is that of a uniform ellipsoid (checked against Pinocchio's formula), and the
    ellipsoid has the body's mass at 1000 kg/m³ with its major axis the segment length."""
    for b in adult.bodies:
        a, bb, c = b.semi_axes
        ref = pin.Inertia.FromEllipsoid(b.mass, a, bb, c).inertia
        assert np.allclose(b.inertia, ref, rtol=1e-12)
        assert DENSITY * 4 / 3 * math.pi * a * bb * c == pytest.approx(b.mass, rel=1e-12)
    th = adult.body("thigh_l")
    assert 2 * max(th.semi_axes) == pytest.approx(-adult.dofs[adult.dof_index("knee_flex_l")].offset[2], rel=1e-12)
    # a sphere: 2/5 m r²
    from scenegraph.model.body import Body
    s = Body("ball", 0, None, 3.0, (0, 0, 0), (0.1, 0.1, 0.1))
    assert np.allclose(s.inertia, np.eye(3) * 0.4 * 3.0 * 0.01)


@pytest.mark.parametrize("kwargs,match", [
    (dict(preset="giant"), "unknown body preset 'giant'"),
    (dict(preset="adult_male", height=0.0), "height"),
    (dict(preset="adult_male", height=float("nan")), "height"),
    (dict(preset="child", mass=-5.0), "mass"),
    (dict(preset="adult_female", mass=1e4), "mass"),
])
def test_bad_presets_raise_input_error(kwargs, match):
    with pytest.raises(InputError, match=match) as exc:
        make_character(**kwargs)
    assert isinstance(exc.value, ComposeError) and exc.value.exit_code == 2


def test_joint_limits_and_modifiers(adult):
    knee = adult.dofs[adult.dof_index("knee_flex_l")]
    assert knee.lower == 0.0 and math.radians(120) < knee.upper < math.radians(170)
    stiff = adult.with_limits("knee_flex_l", 0.0, 0.5)
    assert stiff.upper[adult.dof_index("knee_flex_l")] == 0.5 and adult.upper[adult.dof_index("knee_flex_l")] != 0.5
    with pytest.raises(InputError):
        adult.with_limits("knee_flex_l", 1.0, 0.0)
    loaded = adult.with_extra_mass("palm_r", 10.0)
    assert loaded.total_mass == pytest.approx(adult.total_mass + 10.0)
    assert loaded.fingerprint() != adult.fingerprint() and character().fingerprint() == adult.fingerprint()


# Anatomical sign conventions: a positive angle moves the named handle the stated way
# (world axes at the standing pose; +X forward, +Y left, +Z up).
SIGNS = [
    ("waist_flex", "head", 0, +1), ("chest_flex", "head", 0, +1), ("neck_flex", "head_top", 0, +1),
    ("hip_flex_l", "knee_l", 0, +1), ("hip_flex_r", "knee_r", 0, +1),
    ("hip_abd_l", "ankle_l", 1, +1), ("hip_abd_r", "ankle_r", 1, -1),
    ("knee_flex_l", "ankle_l", 0, -1), ("ankle_flex_l", "toe_l", 2, +1), ("toe_flex_l", "toe_l", 2, +1),
    ("shoulder_flex_l", "elbow_l", 0, +1), ("shoulder_abd_l", "elbow_l", 1, +1), ("shoulder_abd_r", "elbow_r", 1, -1),
    ("elbow_flex_l", "wrist_l", 0, +1),
]


@pytest.mark.parametrize("dof, handle, axis, sign", SIGNS)
def test_positive_angles_move_the_body_anatomically(dof, handle, axis, sign):
    import numpy as np
    from scenegraph.model.body import make_character, standing_pose
    from scenegraph.model.kinematics import handle_positions_fn

    ch = make_character()
    f = handle_positions_fn(ch, (handle,))
    q = standing_pose(ch)
    before = np.asarray(f(q)).ravel()
    q[ch.dof_index(dof)] += 0.2
    after = np.asarray(f(q)).ravel()
    assert np.sign(after[axis] - before[axis]) == sign


def test_a_carried_load_has_the_inertia_of_the_box_drawn_for_it(adult):
    """with_extra_mass: the loaded body's inertia about its new centre equals that of the two
    solids the stage draws — the body's own uniform ellipsoid and the uniform box of
    carried_half_extents centred on the handle — integrated here by sampling them (an
    independent check of the parallel-axis terms and the box's own inertia)."""
    from scenegraph.model.body import carried_half_extents
    rng = np.random.default_rng(3)
    loaded = adult.with_extra_mass("palm_r", 3.0)
    h = adult.handle("palm_r")
    own = next(b for b in adult.bodies if b.name == h.body)
    new = next(b for b in loaded.bodies if b.name == h.body)
    n = 400_000
    u = rng.uniform(-1, 1, (3 * n, 3))
    ell = u[(u ** 2).sum(1) <= 1][:n] * own.semi_axes + own.center  # uniform in the ellipsoid
    box = rng.uniform(-1, 1, (n, 3)) * carried_half_extents(3.0) + h.point
    pts = np.concatenate([ell, box])
    w = np.concatenate([np.full(len(ell), own.mass / len(ell)), np.full(n, 3.0 / n)])
    c = w @ pts / w.sum()
    d = pts - c
    I = np.einsum("n,nij->ij", w, (d ** 2).sum(1)[:, None, None] * np.eye(3) - d[:, :, None] * d[:, None, :])
    assert new.mass == pytest.approx(own.mass + 3.0) and np.allclose(new.center, c, atol=2e-4)
    assert np.allclose(new.inertia, I, rtol=0.01, atol=2e-4 * np.trace(I))
    assert np.trace(new.inertia) > 3 * np.trace(own.inertia)  # the box, not the hand, dominates
    # unloaded bodies are untouched
    assert all(np.array_equal(a.inertia, b.inertia) for a, b in zip(adult.bodies, loaded.bodies) if a.name != h.body)
