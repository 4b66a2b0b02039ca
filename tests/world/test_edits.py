"""Edits of one style (paper §7): the ground model, the edited scenarios, their measured effects.

Fast (default run): the ground model (flat ground changes nothing; planes, normals, friction
pyramids, the CasADi height), footsteps and the audit against the ground, the ramp mesh, and
the edited scenarios as built scenes (body edits, slopes, initial motions).

Slow (``-m slow``): every edited scenario solved end to end with its compiled schedule (as
``compose run`` does), its goals and physics audit checked, and the effects the paper reports
measured against the plain ``walk`` solved the same way:

* suitcase (3 kg at the right palm): the trunk leans away from the load (mean trunk roll
  toward the left) and the right hand swings less (fore–aft excursion relative to the pelvis);
* uphill (8° ramp): the trunk leans forward more than on level ground (mean trunk pitch);
* limp (left knee locked at 5°, left hip flexion −15°…25°): the knee stays in its lock at
  every sampled frame and the pelvis twists more (peak-to-peak pelvis yaw);
* turn180: the walker turns through 180° and leans into the turn (toward the centre, left).

Trunk: the vector from the pelvis handle to the head handle.  Roll is its angle from the
vertical toward the walker's left (in the pelvis-yaw frame), pitch its angle toward the
walker's front; both in degrees, averaged over 121 frames spanning the motion.
"""
from __future__ import annotations

import io
import math

import casadi as ca
import numpy as np
import pytest

from scenarios.loader import load_scenario
from scenegraph.model.audit import audit_motion
from scenegraph.model.body import make_character, standing_pose
from scenegraph.model.dynamics import MU, friction_basis
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.ground import FLAT, Ground, Plane, ground_from_environment
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.motion import Motion
from scenegraph.world.scene import build_scene
from scenegraph.model.style import default_style

EDITS = ("suitcase", "limp", "uphill", "downhill", "turn180", "springy_run")
CH = make_character("adult_male")
RAMP = Plane(math.radians(10.0), 0.0, (-1.0, -1.0, 2.0, 1.0), (-1.0, 0.0), name="ramp")


# --- the ground model ----------------------------------------------------------------------------

def test_flat_ground_is_the_old_ground():
    assert FLAT.flat and FLAT.friction == MU
    x, y = np.meshgrid(np.linspace(-3, 3, 7), np.linspace(-2, 2, 5))
    assert np.all(FLAT.height(x, y) == 0.0)
    np.testing.assert_array_equal(FLAT.normal(x, y)[..., 2], 1.0)
    assert np.array_equal(FLAT.friction_basis(0.3, -0.2), friction_basis())  # bit for bit
    assert FLAT.z(ca.MX.sym("x"), ca.MX.sym("y")) == 0.0  # the solver's rows stay as they were


def test_plane_height_normal_and_region():
    g = Ground(planes=(RAMP,))
    t = math.tan(math.radians(10.0))
    np.testing.assert_allclose(g.height([-1.0, 0.0, 2.0], 0.0), [0.0, t, 3 * t])
    assert g.height(2.01, 0.0) == 0.0 and g.height(0.0, 1.01) == 0.0  # outside the region: flat
    n = g.normal(0.5, 0.2)
    np.testing.assert_allclose(n, [-math.sin(math.radians(10)), 0.0, math.cos(math.radians(10))], atol=1e-15)
    # the normal is perpendicular to the plane: to the difference of two points on it
    p, q = np.array([0.0, 0.0, g.height(0.0, 0.0)]), np.array([1.3, -0.4, g.height(1.3, -0.4)])
    assert abs(n @ (q - p)) < 1e-12
    # a sideways slope (heading 90°) rises along +Y
    side = Ground(planes=(Plane(math.radians(5.0), math.pi / 2, (-1, -1, 1, 1), (0.0, 0.0)),))
    assert side.height(0.7, 0.5) == pytest.approx(0.5 * math.tan(math.radians(5.0)))


def test_first_matching_plane_wins():
    low = Plane(math.radians(5.0), 0.0, (0.0, -1.0, 2.0, 1.0), (0.0, 0.0))
    high = Plane(math.radians(20.0), 0.0, (-1.0, -1.0, 3.0, 1.0), (-1.0, 0.0))
    g = Ground(planes=(low, high))
    assert g.height(1.0, 0.0) == pytest.approx(math.tan(math.radians(5.0)))  # both cover it: the first
    assert g.height(-0.5, 0.0) == pytest.approx(0.5 * math.tan(math.radians(20.0)))  # only the second


def test_friction_pyramid_follows_the_slope():
    g = Ground(friction=0.6, planes=(RAMP,))
    R = g.frame(0.4, 0.1)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], g.normal(0.4, 0.1), atol=1e-15)
    V = g.friction_basis(0.4, 0.1)
    n = g.normal(0.4, 0.1)
    for col in V.T:  # every edge of the pyramid lies on the Coulomb cone about the normal
        fn = col @ n
        ft = np.linalg.norm(col - fn * n)
        assert fn > 0 and ft == pytest.approx(0.6 * fn)
        assert g.cone_violation(0.4, 0.1, col) == pytest.approx(0.0, abs=1e-12)
    # a vertical force on a 10° slope with μ = 0.6 is inside (tan 10° < 0.6); a horizontal one is not
    assert g.cone_violation(0.4, 0.1, [0, 0, 100.0]) == 0.0
    assert g.cone_violation(0.4, 0.1, [100.0, 0, 0]) > 0.0
    # the slope's own μ overrides the ground's
    icy = Ground(friction=0.6, planes=(Plane(RAMP.angle, 0.0, RAMP.region, RAMP.origin, friction=0.1),))
    assert icy.friction_at(0.0, 0.0) == 0.1 and icy.friction_at(5.0, 0.0) == 0.6


def test_casadi_height_matches_numpy():
    g = Ground(planes=(RAMP, Plane(math.radians(-8.0), 2.0, (2.5, -1.0, 4.0, 1.0), (3.0, 0.5))))
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    f = ca.Function("h", [x, y], [g.z(x, y)])
    rng = np.random.default_rng(7)
    for px, py in rng.uniform([-2, -1.5], [5, 1.5], size=(200, 2)):
        assert float(f(px, py)) == pytest.approx(g.height(px, py), abs=1e-12)
    assert g.z(0.5, 0.0) == pytest.approx(g.height(0.5, 0.0))  # numeric input: a number


def test_plane_validation():
    with pytest.raises(ValueError):
        Plane(math.radians(90.0), 0.0, (0, 0, 1, 1), (0, 0))
    with pytest.raises(ValueError):
        Plane(0.1, 0.0, (1, 0, 0, 1), (0, 0))


def test_ground_from_the_scenario():
    scn = load_scenario("uphill")
    g = ground_from_environment(scn.environment)
    (pl,) = g.planes
    assert pl.angle == pytest.approx(math.radians(8.0)) and pl.heading == 0.0
    assert pl.region == (-1.2, -1.0, 2.0, 1.0) and pl.origin == (-1.2, 0.0)
    assert g.friction == MU and pl.friction is None
    down = ground_from_environment(load_scenario("downhill").environment)
    # walking +X goes down: the ground falls by tan 10° per metre
    assert down.height(0.0, 0.0) - down.height(1.0, 0.0) == pytest.approx(math.tan(math.radians(10.0)))
    assert ground_from_environment(load_scenario("walk").environment).flat


# --- footsteps, audit and stage on the ground ----------------------------------------------------

def test_heel_lies_a_foot_length_along_the_slope():
    g = Ground(planes=(RAMP,))
    step = Footstep("l", (0.5, 0.1), 0.0, 0.6, heading=0.0)
    foot_len = CH.handle("ball_l").point[0] - CH.handle("heel_l").point[0]
    pts = {h: np.array([xy[0], xy[1], g.height(xy[0], xy[1])]) for h, _, xy in contact_points(CH, step, None, g)}
    assert np.linalg.norm(pts["ball_l"] - pts["heel_l"]) == pytest.approx(foot_len, rel=1e-12)
    flat = {h: xy for h, _, xy in contact_points(CH, step)}
    assert np.hypot(*(np.subtract(flat["ball_l"], flat["heel_l"]))) == pytest.approx(foot_len)


def _standing_motion(x: float = 0.0) -> Motion:
    q = standing_pose(CH)
    q[0] = x
    times = np.linspace(0.0, 0.5, 16)
    return Motion.from_samples(times, np.tile(q, (len(times), 1)), 8)


def test_audit_measures_penetration_against_the_ground():
    m = _standing_motion(0.3)
    style = default_style(CH.total_mass)
    flat = audit_motion(CH, style, m, ground=FLAT)
    assert flat.penetration_max <= 1e-6  # the standing pose has its soles on z = 0
    g = Ground(planes=(RAMP,))
    on_ramp = audit_motion(CH, style, m, ground=g)
    names = ("heel_l", "ball_l", "toe_l", "heel_r", "ball_r", "toe_r")
    q, _, _ = m.at(np.array([0.25]))
    hp = np.asarray(handle_positions_fn(CH, names)(q[0])).T  # (handle, xyz)
    expect = max(g.height(p[0], p[1]) - p[2] for p in hp)
    assert expect > 0.1  # the ramp is 0.1–0.3 m above the soles there
    assert on_ramp.penetration_max == pytest.approx(expect, abs=1e-6)


def test_ramp_mesh_and_stage():
    from scenegraph.export.usd import CharacterTrack, build_stage, ramp_mesh
    pts, counts, idx = ramp_mesh(RAMP)
    assert pts.shape == (8, 3) and counts == [4] * 6 and sorted(set(idx)) == list(range(8))
    top = pts[:4]
    np.testing.assert_allclose(top[:, 2], [RAMP.plane_height(x, y) for x, y in top[:, :2]])
    assert pts[4:, 2].max() < min(0.0, top[:, 2].min())
    # every edge is shared by exactly two faces: a closed slab
    edges: dict = {}
    for f in np.array(idx).reshape(6, 4):
        for a, b in zip(f, np.roll(f, -1)):
            edges[frozenset((a, b))] = edges.get(frozenset((a, b)), 0) + 1
    assert set(edges.values()) == {2}
    pytest.importorskip("pxr")
    from pxr import UsdGeom
    q = np.tile(standing_pose(CH), (3, 1))
    stage = build_stage([CharacterTrack("walker", CH, q)], 30.0, ground=Ground(planes=(RAMP,)))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Ground/ramp_0"))
    assert mesh and len(mesh.GetPointsAttr().Get()) == 8
    assert mesh.GetPrim().GetAttribute("compose:angleDeg").Get() == pytest.approx(10.0)
    flat_stage = build_stage([CharacterTrack("walker", CH, q)], 30.0)
    assert not flat_stage.GetPrimAtPath("/World/Ground").IsValid()


# --- the edited scenarios as scenes ---------------------------------------------------------------

@pytest.mark.parametrize("name", EDITS)
def test_edited_scenarios_build(name):
    scn = load_scenario(name)
    scene = build_scene(scn)
    (st,) = scene.characters
    plain = make_character("adult_male")
    idx = plain.dof_index
    if name == "suitcase":
        assert st.character.total_mass == pytest.approx(plain.total_mass + 3.0)
    if name == "limp":
        i = idx("knee_flex_l")
        assert st.character.lower[i] == st.character.upper[i] == pytest.approx(math.radians(5.0))
        j = idx("hip_flex_l")
        assert (st.character.lower[j], st.character.upper[j]) == pytest.approx((math.radians(-15), math.radians(25)))
        q, _, _ = st.motion.at(np.linspace(0, scene.duration, 50))  # the initial motion respects the edit
        assert np.abs(q[:, i] - math.radians(5.0)).max() < 0.02
    if name == "springy_run":
        from scenarios.bundled import STYLES_DIR
        from scenegraph.model.style import load_style
        # the bundled run style's shoe (learned on the same adult_male body: no mass scaling), 5x
        assert st.style.k_shoe == pytest.approx(5.0 * load_style(STYLES_DIR / "run.yaml").k_shoe)
        steps = sorted(st.footsteps, key=lambda f: f.t0)
        assert all(b.t0 - a.t1 > 0.05 for a, b in zip(steps, steps[1:]))  # flight phases
    if name in ("uphill", "downhill"):
        assert not scene.ground.flat
        # the initial pelvis height follows the ground under it
        t = np.linspace(0.05, scene.duration - 0.05, 20)
        q, _, _ = st.motion.at(t)
        above = q[:, 2] - scene.ground.height(q[:, 0], q[:, 1])
        assert np.ptp(above) < 0.02
    else:
        assert scene.ground.flat
    if name == "turn180":
        heads = [f.heading for f in sorted(st.footsteps, key=lambda f: f.t0)]
        assert heads[0] == 0.0 and heads[-1] == pytest.approx(math.pi)


# --- measured effects (end-to-end solves) ---------------------------------------------------------

def trunk_angles(ch, motion: Motion, n: int = 121) -> tuple[np.ndarray, np.ndarray]:
    """(roll toward the left, pitch toward the front) of the pelvis→head vector (deg, n frames)."""
    t = np.linspace(motion.start, motion.end, n)
    q, _, _ = motion.state_at_s(motion.to_canonical(t))
    hp = np.asarray(handle_positions_fn(ch, ("pelvis", "head")).map(n)(q.T)).reshape(3, 2, n, order="F")
    v = hp[:, 1] - hp[:, 0]
    yaw = q[:, 3]
    fwd = np.cos(yaw) * v[0] + np.sin(yaw) * v[1]
    lat = -np.sin(yaw) * v[0] + np.cos(yaw) * v[1]
    return np.degrees(np.arctan2(lat, v[2])), np.degrees(np.arctan2(fwd, v[2]))


def hand_swing(ch, motion: Motion, side: str, n: int = 121) -> float:
    """Peak-to-peak fore–aft excursion (m) of a palm relative to the pelvis, in the pelvis-yaw frame."""
    t = np.linspace(motion.start, motion.end, n)
    q, _, _ = motion.state_at_s(motion.to_canonical(t))
    hp = np.asarray(handle_positions_fn(ch, ("pelvis", f"palm_{side}")).map(n)(q.T)).reshape(3, 2, n, order="F")
    d = hp[:2, 1] - hp[:2, 0]
    return float(np.ptp(np.cos(q[:, 3]) * d[0] + np.sin(q[:, 3]) * d[1]))


def dof_track(ch, motion: Motion, name: str, n: int = 121) -> np.ndarray:
    t = np.linspace(motion.start, motion.end, n)
    q, _, _ = motion.state_at_s(motion.to_canonical(t))
    return q[:, ch.dof_index(name)]


_SOLVED: dict = {}


def solved(name: str, tmp_path_factory, style: str | None = None):
    """(final CharacterState, audit, goal report, run records) of a bundled scenario, solved
    with its compiled schedule exactly as ``compose run`` does (once per test session);
    ``style``: every character's style replaced by this one (a reference walk in the style of
    an edit)."""
    key = (name, style)
    if key not in _SOLVED:
        from schedules.cli.run import goal_report
        from schedules.plan.compiler import compile_schedule
        from schedules.execution.executor import run_schedule
        scn = load_scenario(name)
        if style is not None:
            scn = scn.model_copy(update={"characters": [c.model_copy(update={"style": style})
                                                        for c in scn.characters]})
        res = run_schedule(build_scene(scn), compile_schedule(scn), run_dir=tmp_path_factory.mktemp(name),
                           fingerprint=f"test-edits-{name}-{style}", log=io.StringIO())
        (st,) = res.scene.characters
        aud = audit_motion(st.character, st.style, st.motion, st.footsteps, res.contact_forces.get(st.name),
                           ground=res.scene.ground)
        goals, _ = goal_report(res.scene, {st.name: aud.to_dict()})
        _SOLVED[key] = (st, aud, goals, res.records)
    return _SOLVED[key]


@pytest.mark.slow
@pytest.mark.parametrize("name", ("walk",) + EDITS)
def test_edited_scenario_solves_with_goals_and_audit(name, tmp_path_factory):
    st, aud, goals, records = solved(name, tmp_path_factory)
    # every step was accepted by the executor (converged, "Stalled": its stall detection keeps
    # a full step whose objective stopped falling, or capped: kept at its iteration cap — both
    # only with every hard constraint satisfied)
    # (a timing step is only a warm start: one that did not converge is discarded and reported)
    from schedules.execution.executor import VIOLATION_TOL
    for r in records:
        if r.kind == "full":
            assert r.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level", "Stalled",
                                "Maximum_Iterations_Exceeded"), (r.id, r.status)
            assert all(v <= VIOLATION_TOL for v in r.violations.values()), (r.id, r.violations)
    assert goals and all(g["holds"] for g in goals.values()), goals
    # the audit at 120 Hz passes the gate `compose run` applies (exit 1 otherwise)
    from schedules.cli.run import AUDIT_TOLERANCES
    assert aud.passes(**AUDIT_TOLERANCES), aud
    assert aud.joint_limit_violation_max <= 1e-6, aud


@pytest.mark.slow
def test_suitcase_leans_away_from_the_load_and_swings_that_arm_less(tmp_path_factory):
    # suitcase.yaml keeps the built-in style (its comment says why); the level walk it is
    # compared with is the bundled walk in that same style
    case, _, _, _ = solved("suitcase", tmp_path_factory)
    walk, _, _, _ = solved("walk", tmp_path_factory, style=load_scenario("suitcase").characters[0].style)
    roll_w = trunk_angles(walk.character, walk.motion)[0].mean()
    roll_s = trunk_angles(case.character, case.motion)[0].mean()
    # measured: walk -1.99°, suitcase -1.61° (0.38° further left, away from the right-hand load)
    assert roll_s - roll_w >= 0.25, (roll_w, roll_s)
    swing_w, swing_s = hand_swing(walk.character, walk.motion, "r"), hand_swing(case.character, case.motion, "r")
    # measured: 0.373 m → 0.343 m (−8 %)
    assert swing_s <= 0.95 * swing_w, (swing_w, swing_s)


@pytest.mark.slow
def test_uphill_leans_forward_more_than_on_level_ground(tmp_path_factory):
    walk, _, _, _ = solved("walk", tmp_path_factory)
    up, _, _, _ = solved("uphill", tmp_path_factory)
    pitch_w = trunk_angles(walk.character, walk.motion)[1].mean()
    pitch_u = trunk_angles(up.character, up.motion)[1].mean()
    # measured: walk 5.0°, uphill 8.0° forward (8° ramp; a 10° ramp gave 11.5° but failed the
    # audit gate with 11 mm penetration, a 6° ramp 5.7°)
    assert pitch_u - pitch_w >= 2.0, (pitch_w, pitch_u)


@pytest.mark.slow
def test_limp_keeps_the_knee_locked_and_twists_the_pelvis_more(tmp_path_factory):
    walk, _, _, _ = solved("walk", tmp_path_factory)
    limp, _, _, _ = solved("limp", tmp_path_factory)
    knee = dof_track(limp.character, limp.motion, "knee_flex_l")
    assert np.abs(np.degrees(knee) - 5.0).max() <= 0.01  # within its lock at every sampled frame
    hip = np.degrees(dof_track(limp.character, limp.motion, "hip_flex_l"))
    assert hip.min() >= -15.0 - 1e-6 and hip.max() <= 25.0 + 1e-6
    yaw_w = np.degrees(np.ptp(dof_track(walk.character, walk.motion, "root_yaw")))
    yaw_l = np.degrees(np.ptp(dof_track(limp.character, limp.motion, "root_yaw")))
    # measured: pelvis yaw 20.8° → 26.7° peak to peak with the old (buggy) stall rule; 23.4° →
    # 26.6° (+14 %) with full steps that run to the fixed stall rule
    assert yaw_l >= 1.1 * yaw_w, (yaw_w, yaw_l)


@pytest.mark.slow
def test_turn180_turns_and_leans_into_the_turn(tmp_path_factory):
    walk, _, _, _ = solved("walk", tmp_path_factory)
    turn, _, _, _ = solved("turn180", tmp_path_factory)
    yaw = np.degrees(dof_track(turn.character, turn.motion, "root_yaw"))
    assert yaw[-1] - yaw[0] >= 150.0, (yaw[0], yaw[-1])
    roll_w = trunk_angles(walk.character, walk.motion)[0].mean()
    roll_t = trunk_angles(turn.character, turn.motion)[0].mean()
    # measured: walk -2.0°, turn +0.8° (toward the centre of the left turn)
    assert roll_t - roll_w >= 2.0, (roll_w, roll_t)
