"""Contact semantics (issue #15 item 3): a planted foot keeps its footstep's frame
(scenegraph/problem/stance_frame.py) and foot handles near the floor do not slide
(scenegraph/problem/no_slip.py); both terms in full steps only, densely at 120 Hz."""
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from scenegraph.model.body import N_DOF, make_character, standing_pose
from scenegraph.model.footsteps import Footstep, footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.ground import FLAT
from scenegraph.model.motion import Motion, basis
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe
from scenegraph.problem.no_slip import (H_NO_SLIP, handle_slip, handle_state_fn, no_slip_residuals, phi)
from scenegraph.problem.stance_frame import stance_frame_deviation, stance_frame_residuals

CH = make_character()
STYLE = default_style(CH.total_mass)
K = 12
YAW, ROLL, PITCH = 3, 5, 4  # root DOFs: yaw, pitch, roll (body.py)


def _still(dq=None, x0=0.0) -> Motion:
    """A standing pose held for 1 s; ``dq(s)`` (35) adds a motion: control points = pose + dq(s_i)."""
    q0 = np.asarray(standing_pose(CH), float)
    q0[0] = x0
    s = np.linspace(0, 1, K)
    ctrl = np.array([q0 + (dq(v) if dq else 0.0) for v in s])
    return Motion(ctrl, Motion.uniform_warp(0.0, 1.0, 6))


# both feet planted over the whole second, heading 0, ball at the standing pose's ball
def _planted(m: Motion) -> tuple:
    from scenegraph.model.kinematics import handle_positions_fn
    P = np.asarray(handle_positions_fn(CH, ("ball_l", "ball_r"))(m.canonical([0.0])[0]))
    return (Footstep("l", (P[0, 0], P[1, 0]), 0.0, 1.0, 0.0, heel=(0.0, 1.0), ball=(0.0, 1.0)),
            Footstep("r", (P[0, 1], P[1, 1]), 0.0, 1.0, 0.0, heel=(0.0, 1.0), ball=(0.0, 1.0)))


def _frame_cost(m: Motion, steps, weight=1.0) -> float:
    s = np.linspace(0, 1, 121)
    r = stance_frame_residuals(CH, steps, FLAT, m.time(s), s, 1 / 120, ca.DM(m.ctrl), K, weight)
    return float(ca.sumsqr(r))


def _slip_cost(m: Motion, weight=1.0) -> float:
    s = np.linspace(0, 1, 121)
    r = no_slip_residuals(CH, FLAT, s, 1 / 120, ca.DM(m.ctrl), ca.DM(m.warp), K, len(m.warp), weight)
    return float(ca.sumsqr(r))


def test_a_still_foot_on_its_frame_costs_nothing():
    m = _still()
    steps = _planted(m)
    assert _frame_cost(m, steps) < 1e-20
    assert _slip_cost(m) < 1e-20
    dev = stance_frame_deviation(CH, steps, FLAT, m.time(np.linspace(0, 1, 50)), m.canonical(np.linspace(0, 1, 50)))
    assert max(abs(y) + abs(r) for _, _, y, r in dev) < 1e-9


def test_pitch_is_free_but_swivel_and_roll_cost():
    """A planted foot may pitch (heel-off rolls over the ball) but not yaw or roll: the whole
    body turned 3° about each axis, feet with it."""
    base = _still()
    steps = _planted(base)

    def turned(i):
        return _still(lambda v: np.eye(N_DOF)[i] * np.radians(3.0) * v)
    assert _frame_cost(turned(PITCH), steps) < 1e-20
    yaw, roll = _frame_cost(turned(YAW), steps), _frame_cost(turned(ROLL), steps)
    # Σ dt |Δ|² with |Δ| = 2 sin(θ/2) for a turn θ(s) about an axis across y: two feet, inner samples
    s = np.linspace(0, 1, 121)[1:-1]
    for i, cost in ((YAW, yaw), (ROLL, roll)):
        th = turned(i).canonical(s)[:, i]
        assert cost == pytest.approx(2 * np.sum((2 * np.sin(th / 2)) ** 2) / 120, rel=1e-6)
    assert yaw > 1e-3
    t = np.linspace(0, 1, 11)
    d = stance_frame_deviation(CH, steps, FLAT, t, turned(YAW).canonical(t))
    assert max(abs(y) for _, _, y, _ in d) == pytest.approx(turned(YAW).canonical([0.9])[0, YAW], rel=1e-6)
    assert max(abs(r) for _, _, _, r in d) < 1e-6


def test_skid_on_the_floor_costs_and_high_handles_are_free():
    """A body sliding 0.1 m/s along the floor pays ∫ φ v² dt per handle (φ = 1 on the floor); lifted
    by 2 H_NO_SLIP it pays nothing."""
    skid = _still(lambda v: np.eye(N_DOF)[0] * 0.1 * v * 1.0)
    heel_h = float(handle_slip(CH, FLAT, skid.canonical([0.5]), skid.canonical([0.5], 1))[0][0, 0])
    assert abs(heel_h) < 1e-3  # the standing pose's heels are on the floor
    c = _slip_cost(skid)
    h, v, ph = handle_slip(CH, FLAT, skid.canonical(np.linspace(0, 1, 121)), skid.canonical(np.linspace(0, 1, 121), 1))
    assert c == pytest.approx(np.sum(ph * v ** 2) / 120, rel=1e-9)
    assert c > 0.5 * 4 * 0.01  # at least the four sole handles (heel, ball) at ~0.1 m/s for a second
    lifted = _still(lambda v: np.eye(N_DOF)[0] * 0.1 * v + np.eye(N_DOF)[2] * 2 * H_NO_SLIP)
    assert _slip_cost(lifted) < 1e-20


def test_phi_shape():
    h = np.array([-0.005, 0.0, 0.005, H_NO_SLIP, 0.05])
    np.testing.assert_allclose(phi(h), [2.25, 1.0, 0.25, 0.0, 0.0])
    x = ca.SX.sym("x")
    assert float(ca.Function("f", [x], [phi(x)])(0.0025)) == pytest.approx(0.5625)


def test_handle_velocity_matches_finite_differences():
    rng = np.random.default_rng(3)
    q = np.asarray(standing_pose(CH), float) + 0.1 * rng.standard_normal(N_DOF)
    qd = rng.standard_normal(N_DOF)
    f = handle_state_fn(CH)
    p0, v = (np.asarray(a) for a in f(q, qd))
    e = 1e-6
    fd = (np.asarray(f(q + e * qd, qd)[0]) - np.asarray(f(q - e * qd, qd)[0])) / (2 * e)
    np.testing.assert_allclose(v, fd, atol=1e-7)


@pytest.mark.parametrize("which", ["frame", "slip"])
def test_gradients_match_finite_differences(which):
    """The residuals' Jacobian (what IPOPT's Gauss–Newton Hessian is built of) against central
    differences of the summed squares, at a swivelling, skidding, low pose."""
    m = _still(lambda v: np.eye(N_DOF)[YAW] * 0.05 * v + np.eye(N_DOF)[0] * 0.1 * v - np.eye(N_DOF)[2] * 0.003)
    steps = _planted(_still())
    x = ca.MX.sym("x", K * N_DOF)
    P = ca.reshape(x, N_DOF, K).T
    s = np.linspace(0, 1, 121)
    if which == "frame":
        r = stance_frame_residuals(CH, steps, FLAT, m.time(s), s, 1 / 120, P, K, 1.0)
    else:
        r = no_slip_residuals(CH, FLAT, s, 1 / 120, P, ca.DM(m.warp), K, len(m.warp), 1.0)
    f = ca.Function("f", [x], [ca.sumsqr(r)])
    g = ca.Function("g", [x], [ca.gradient(ca.sumsqr(r), x)])
    x0 = np.asarray(m.ctrl, float).ravel()
    grad = np.asarray(g(x0)).ravel()
    rng = np.random.default_rng(0)
    for _ in range(5):
        d = rng.standard_normal(x0.size)
        e = 1e-6
        fd = (float(f(x0 + e * d)) - float(f(x0 - e * d))) / (2 * e)
        assert grad @ d == pytest.approx(fd, rel=1e-4, abs=1e-9)


def _short_walk():
    steps = footsteps_for_walk(n_steps=3)
    return steps, initial_motion(CH, steps, steps[1].t0, steps[-1].t0)


def test_transcription_adds_the_terms_only_with_full_dynamics():
    steps, m = _short_walk()
    sp = Subproblem(CH, STYLE, m, steps, free=frozenset({"q"}), joint_speed_limit=False)  # a full-dynamics term too
    n0 = transcribe(sp, derivatives=False).rho_extra_fn.size1_out(0)
    on = dict(stance_frame_weight=1e3, no_slip_weight=100.0)
    n_full = transcribe(replace(sp, **on), derivatives=False).rho_extra_fn.size1_out(0)
    n_relaxed = transcribe(replace(sp, dynamics="relaxed", **on), derivatives=False).rho_extra_fn.size1_out(0)
    n_kin = transcribe(replace(sp, dynamics="kinematic", **on), derivatives=False).rho_extra_fn.size1_out(0)
    n_s = int(round(m.duration * 120)) + 1
    assert n_full - n0 >= 2 * len(("heel_l", "ball_l", "toe_l", "heel_r", "ball_r", "toe_r")) * n_s
    assert n_relaxed == n0 and n_kin == transcribe(replace(sp, dynamics="kinematic"),
                                                    derivatives=False).rho_extra_fn.size1_out(0)


def test_lowering_sets_the_weights_in_full_steps_only():
    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene
    from schedules.execution.lower import lower
    from schedules.plan.compiler import compile_schedule
    from scenarios import bundled_scenarios, parse_scenario
    text = bundled_scenarios()["walk"].read_text() + "schedule:\n  timewarp: true\n"  # a timing step too
    scn = parse_scenario(text, "walk_timed.yaml")
    scene = build_scene(scn)
    kinds = set()
    for step in compile_schedule(scn).order():
        sp, _ = lower(scene, step, "walker")
        kinds.add(step.kind)
        assert (sp.stance_frame_weight > 0) == (sp.no_slip_weight > 0) == (step.kind == "full"), step.id
    assert {"full", "timing"} <= kinds


@pytest.mark.slow
def test_walk_stage_feet_do_not_slide(tmp_path, monkeypatch):
    """End to end: `compose run walk --fps 120`, then the stage alone through `compose audit`:
    no stance slides more than 5 mm (before the terms: 18 mm, a touch-down skid and a heel-strike
    swivel; docs/results.md) and the drawn feet stay within 2 mm of the floor; the stage-only
    diagnosis (tests/benchmarks/where_feet_slide.py) finds no swivel or roll above 1°."""
    import importlib.util
    from pathlib import Path
    from scenegraph.stage_audit import AuditSettings, audit_stage
    from schedules.cli import main as cli
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "walk", "-o", "w.usda", "--fps", "120", "--run-dir", "r", "--report", "w.json"]) == 0
    rep = audit_stage(tmp_path / "w.usda", 120.0, AuditSettings())
    s = rep["summary"]
    assert s["stance_slide_max_mm"] <= 5.0 and s["penetration_max_mm"] <= 2.0, s
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "where_feet_slide.py"
    spec = importlib.util.spec_from_file_location("where_feet_slide", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    recs = mod.diagnose(tmp_path / "w.usda")
    assert len(recs) >= 3
    assert max(r["swivel_deg"] for r in recs) < 1.0 and max(r["roll_deg"] for r in recs) < 1.0, recs


def _diagnosis_module():
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "where_feet_slide.py"
    spec = importlib.util.spec_from_file_location("where_feet_slide", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("kind", ["swivel", "glide"])
def test_stage_diagnosis_names_a_known_swivel_and_glide(kind, tmp_path):
    """where_feet_slide.py on synthetic stages: a standing body turned 4° about the vertical
    (both feet swivel 4°) or pushed 6 mm along x (both feet glide 6 mm) over 0.5 s."""
    pytest.importorskip("pxr")
    from scenegraph.export.usd import CharacterTrack, export_usd
    q0 = np.asarray(standing_pose(CH), float)
    u = np.linspace(0, 1, 61)[:, None]
    q = np.tile(q0, (61, 1))
    if kind == "swivel":
        q[:, YAW] += np.radians(4.0) * u[:, 0]
    else:
        q[:, 0] += 0.006 * u[:, 0]
    path = export_usd(tmp_path / "s.usda", [CharacterTrack("c", CH, q)], 120.0)
    recs = _diagnosis_module().diagnose(path)
    assert sorted(r["foot"] for r in recs) == ["l", "r"]
    for r in recs:
        if kind == "swivel":
            assert r["swivel_deg"] == pytest.approx(4.0, abs=0.05) and r["roll_deg"] < 0.05
        else:
            assert r["glide_mm"] == pytest.approx(6.0, abs=0.05) and r["swivel_deg"] < 0.05
            assert r["slide_mm"] == pytest.approx(6.0, abs=0.05) and r["cause"] == "glide"
