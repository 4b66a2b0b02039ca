"""The compiler–executor contract, and the scenario fields that used to be inert.

1. The Step vocabulary (schedules/plan/step.py: kinds, roles, free blocks, terms and their value
   classes) is handled by the lowering (schedules/execution/lower.py ``HANDLED``); what the compiler
   emits over every bundled scenario and a set of variants (explicit schedule kinds, free
   timing, receding windows, no timing step) is a subset of it — and covers it, so the
   vocabulary lists nothing the compiler never writes.  The lowering rejects an unknown item.
2. Each previously inert field now changes what is solved (the lowered Subproblem or the
   transcribed NLP differs as expected), or is rejected with its file, line and field:
   goal and start weights, ``timing: free`` / ``duration_bounds``, hard couplings
   (``schedule.kind: timewarp``), ``environment.ground.friction``, the gait of a run style in
   ``walk_to``, and ``walk_to.heading``.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scenarios.bundled import bundled_scenarios, bundled_syntheses
from scenarios.errors import ComposeError, InputError
from scenarios.loader import load_scenario, parse_scenario
from scenegraph.model.dynamics import friction_basis
from scenegraph.problem import transcribe
from scenegraph.world.scene import build_scene
from schedules.plan.compiler import compile_schedule
from schedules.execution.lower import HANDLED, check_step, lower, lower_joint
from schedules.plan.step import HARD, declared_vocabulary, vocabulary

FULL_YAML = __import__("pathlib").Path(__file__).resolve().parents[1] / "scenarios" / "full.yaml"


def _variant(name: str, extra: str = "", replace_: tuple[str, str] | None = None):
    text = bundled_scenarios()[name].read_text()
    if replace_ is not None:
        assert replace_[0] in text
        text = text.replace(*replace_)
    return parse_scenario(text + extra, f"{name}_variant.yaml")


def _variants():
    yield from (load_scenario(n) for n in sorted(bundled_syntheses()))  # edits: tests/language/test_edit_block.py
    yield load_scenario(str(FULL_YAML))
    for kind in ("timewarp", "time_layered", "coupled", "decreasing_horizon"):
        yield _variant("handhold", f"schedule:\n  kind: {kind}\n  cycles: 1\n")
        yield _variant("handhold", f"schedule:\n  kind: {kind}\n  cycles: 1\n  timewarp: true\n")
    yield _variant("walk", "schedule:\n  timewarp: false\n")
    yield _variant("walk", "schedule:\n  timewarp: true\n")
    yield _variant("walk_to", "timing: free\nduration_bounds: [1.0, 2.0]\n")
    yield _variant("walk_to", replace_=("duration: 1.4", "duration: 6.0"))


def test_the_declared_vocabulary_is_handled_by_the_lowering():
    assert declared_vocabulary() <= HANDLED, sorted(declared_vocabulary() - HANDLED)


def test_the_compiler_emits_exactly_the_declared_vocabulary():
    emitted: set = set()
    for scn in _variants():
        for step in compile_schedule(scn).order():
            emitted |= vocabulary(step)
            check_step(step)  # and each emitted Step passes the executor's check
    assert emitted <= declared_vocabulary(), sorted(emitted - declared_vocabulary())
    assert declared_vocabulary() <= emitted, f"declared but never emitted: {sorted(declared_vocabulary() - emitted)}"


@pytest.mark.parametrize("change", [
    {"free": ("q", "bogus", "lambda")},
    {"terms": (("energy", 1.0), ("dynamics", "hard"), ("environment", "hard"), ("warp_bonus", 3.0))},
    {"terms": (("energy", 1.0), ("dynamics", "soft"), ("environment", "hard"))},
    {"role": "sideways"},
])
def test_the_lowering_rejects_what_it_does_not_handle(change):
    step = compile_schedule(load_scenario("walk")).order()[-1]
    with pytest.raises(ComposeError, match="does not handle"):
        check_step(replace(step, **change))


# --- weights: the plan's numbers are the solver's -------------------------------------------------

def test_goal_and_start_weights_are_used_as_written():
    scn = load_scenario("walk_to")
    step = compile_schedule(scn).order()[-1]
    scene = build_scene(scn)
    sp, _ = lower(scene, step, "walker")
    (goal,) = [t for t in sp.targets if t.name == "goal:walk_to_0"]
    (start,) = [t for t in sp.targets if t.name == "start"]
    assert goal.weight == step.term("goal:walk_to_0") and start.weight == step.term("start")
    edited = replace(step, terms=tuple((n, 7.5 if n == "goal:walk_to_0" else 0.25 if n == "start" else w)
                                       for n, w in step.terms))
    sp2, _ = lower(scene, edited, "walker")
    assert [t.weight for t in sp2.targets if t.name == "goal:walk_to_0"] == [7.5]
    assert [t.weight for t in sp2.targets if t.name == "start"] == [0.25]
    # and the NLP's objective moves with it: the spring residuals scale by sqrt(weight)
    f1 = float(transcribe(sp, derivatives=False).f_fn(*_x0p0(sp)))
    f2 = float(transcribe(sp2, derivatives=False).f_fn(*_x0p0(sp2)))
    assert f1 != f2


def _x0p0(sp):
    nlp = transcribe(sp, derivatives=False)
    return nlp.x0, nlp.p0


# --- timing: free ----------------------------------------------------------------------------

def _end_time_group(sp):
    nlp = transcribe(sp, derivatives=False)
    (grp,) = [(sl, kind) for name, sl, kind in nlp.groups if name == "end_time"]
    return nlp.lbg[grp[0]], nlp.ubg[grp[0]], grp[1]


def test_free_timing_frees_the_duration_within_its_bounds():
    fixed = _variant("walk_to", "schedule:\n  timewarp: true\n")  # a timing step asked for, the duration fixed
    free = _variant("walk_to", "timing: free\nduration_bounds: [1.0, 2.0]\n")
    for scn, expect in ((fixed, "eq"), (free, "ineq")):
        timing = compile_schedule(scn).order()[0]
        assert timing.kind == "timing" and ("duration" in timing.free) == (expect == "ineq")
        sp, _ = lower(build_scene(scn), timing, "walker")
        lo, hi, kind = _end_time_group(sp)
        assert kind == expect
        if expect == "eq":
            assert sp.fix_end_time and lo == hi == 0.0  # x_W[-1] − end = 0
        else:
            assert not sp.fix_end_time and (lo[0], hi[0]) == (1.0, 2.0)  # 1 s ≤ x_W[-1] ≤ 2 s
    # without duration_bounds: 0.5–2 × duration
    sp, _ = lower(build_scene(_variant("walk_to", "timing: free\n")), compile_schedule(
        _variant("walk_to", "timing: free\n")).order()[0], "walker")
    assert sp.end_time_bounds == pytest.approx((0.7, 2.8))


# --- hard couplings: a joint solve ---------------------------------------------------------------

def test_a_hard_hand_hold_lowers_to_one_joint_problem():
    scn = _variant("handhold", "schedule:\n  kind: timewarp\n  timewarp: true\n")
    scene = build_scene(scn)
    steps = compile_schedule(scn).order()
    timing, full = steps
    assert lower_joint(scene, timing) is None and not timing.couplings  # timing: each character alone
    assert full.term("coupling:hold") == HARD and "coupling_forces" in full.free
    joint = lower_joint(scene, full)
    assert joint.characters == ("adult", "child")
    assert (joint.coupling.handle_a, joint.coupling.handle_b) == ("palm_r", "palm_l")
    assert joint.coupling.times[0] == 0.0 and joint.coupling.times[-1] == pytest.approx(1.2)
    for who in joint.characters:  # a hard coupling is no rubber band
        sp, _ = lower(scene, full, who)
        assert not sp.springs and not [t for t in sp.targets if t.name.startswith("coupling:")]
    # the rubber band of the auto schedule is a spring
    auto = load_scenario("handhold")
    s = next(st for st in compile_schedule(auto).order() if st.kind == "full")
    sp, _ = lower(build_scene(auto), s, s.characters[0])
    assert sp.springs and lower_joint(build_scene(auto), s) is None


CARRY = """name: lift
duration: 1.0
characters:
  - {name: a, start: {position: [0.0, 0.3]}}
  - {name: b, start: {position: [0.0, -0.3]}}
couplings:
  - type: carry
    mass: 10
    holders: [{character: a, handle: palm_r}, {character: b, handle: palm_l}]
    interval: [0.0, 1.0]
schedule:
  kind: timewarp
"""

THREE = """name: chain
duration: 1.0
characters:
  - {name: a, start: {position: [0.0, 0.6]}}
  - {name: b, start: {position: [0.0, 0.0]}}
  - {name: c, start: {position: [0.0, -0.6]}}
couplings:
  - type: hand_hold
    between: [{character: a, handle: palm_r}, {character: b, handle: palm_l}]
    interval: [0.0, 1.0]
  - type: hand_hold
    between: [{character: b, handle: palm_r}, {character: c, handle: palm_l}]
    interval: [0.0, 1.0]
schedule:
  kind: timewarp
"""


@pytest.mark.parametrize("text,where", [(CARRY, "lift.yaml:7:11 couplings[0].type"),
                                        (THREE, "chain.yaml:15:9 schedule.kind")])
def test_a_hard_coupling_without_a_joint_solve_is_rejected_with_its_location(text, where):
    name = where.split(".yaml")[0]
    with pytest.raises(InputError) as e:
        compile_schedule(parse_scenario(text, f"{name}.yaml"))
    assert str(e.value).startswith(where) and e.value.exit_code == 2


# --- ground friction ---------------------------------------------------------------------------

def test_ground_friction_sets_the_friction_pyramid():
    for mu in (0.8, 0.4):
        scn = _variant("walk", f"environment:\n  ground: {{friction: {mu}}}\n")
        scene = build_scene(scn)
        assert scene.ground.friction == scene.friction == mu
        step = compile_schedule(scn).order()[-1]
        nlp = transcribe(lower(scene, step, "walker")[0], derivatives=False)
        assert nlp.contact_basis and all(np.allclose(V, friction_basis(mu)) for V in nlp.contact_basis)


# --- gait from style ---------------------------------------------------------------------------

def _flight_and_double_support(steps, T):
    t = np.linspace(0.05, T - 0.05, 400)
    down = np.array([[any(f.foot == foot and f.t0 <= ti <= f.t1 for f in steps) for foot in "lr"] for ti in t])
    return float(np.mean(~down.any(axis=1))), float(np.mean(down.all(axis=1)))


def test_walk_to_with_a_run_style_generates_running_footsteps():
    walk = build_scene(load_scenario("walk_to")).character("walker").footsteps
    scn = _variant("walk_to", replace_=("style: walk", "style: run"))
    run = build_scene(scn).character("walker").footsteps
    fw, dw = _flight_and_double_support(walk, 1.4)
    fr, dr = _flight_and_double_support(run, 1.4)
    assert fw == 0.0 and dw > 0.1  # a walk: double support, never both feet off the ground
    assert fr > 0.1 and dr == 0.0  # a run: flight phases, never both feet down
    assert all(f.heel is None for f in run) and all(f.heel is not None for f in walk)
    # a run's stance is short (2 × 0.38 / 2.8 steps/s = 0.27 s), a walk's long (2 × 0.62 × 1.4 s / 3 = 0.58 s)
    inner = lambda st: [f.t1 - f.t0 for f in st if 1e-9 < f.t0 and f.t1 < 1.4 - 1e-9]  # noqa: E731 (unclipped)
    assert max(inner(run)) < 0.35 < 0.5 < min(inner(walk))


# --- walk_to heading ------------------------------------------------------------------------------

def test_walk_to_heading_turns_the_feet_it_stands_on():
    base = _variant("walk_to", replace_=("time: 1.4", "time: 1.0"))
    turned = _variant("walk_to", replace_=("time: 1.4", "time: 1.0\n    heading: 90"))
    a = build_scene(base).character("walker").footsteps
    b = build_scene(turned).character("walker").footsteps
    stand_a = [f for f in a if f.t1 >= 1.4 - 1e-9]
    stand_b = [f for f in b if f.t1 >= 1.4 - 1e-9]
    assert [f.heading for f in stand_a] == [0.0, 0.0]
    assert [f.heading for f in stand_b] == [math.pi / 2] * 2


def test_walk_to_heading_without_time_to_stand_is_rejected_with_its_location():
    scn = _variant("walk_to", replace_=("time: 1.4", "time: 1.4\n    heading: 90"))
    with pytest.raises(InputError) as e:
        build_scene(scn)
    assert str(e.value).startswith("walk_to_variant.yaml:15:14 goals[0].heading")


@pytest.mark.slow
def test_the_executor_solves_a_hard_hand_hold_jointly(monkeypatch):
    """solve_step on the full step of ``schedule.kind: timewarp``: one joint NLP (scenegraph/problem/joint.py)
    for both characters (3 IPOPT iterations: the plumbing, not the optimum; ~80 s to build)."""
    from schedules.execution.executor import solve_step
    monkeypatch.setenv("COMPOSE_MAX_ITER", "3")
    scn = _variant("handhold", "schedule:\n  kind: timewarp\n")
    scene = build_scene(scn)
    full = compile_schedule(scn).order()[-1]
    out = solve_step(scene, full, ())
    a, c = out["characters"]["adult"], out["characters"]["child"]
    assert a["iterations"] == c["iterations"] == 3 and a["status"] == c["status"]  # one solve
    assert a["violations"]["coupling:hold"] == c["violations"]["coupling:hold"]  # the joint hand gap
    assert "palm_r" in a["contact_forces"] and "palm_l" in c["contact_forces"]  # the hand force reported


def test_free_timing_keeps_goal_times_canonical():
    """With ``timing: free`` a goal time is canonical: when a timing step stretches the motion to
    2 s, the walk_to target (1.4 s of a 1.4 s scene) moves to the new end; with fixed timing
    a goal time is a world time and stays."""
    from scenegraph.model.motion import Motion
    for text, expect_end in (("timing: free\nduration_bounds: [1.0, 2.0]\n", 2.0), ("", 1.4)):
        scn = _variant("walk_to", text, replace_=("time: 1.4", "time: 1.0"))  # arrive at 1.0 of 1.4 s
        scene = build_scene(scn)
        m = scene.character("walker").motion
        stretched = Motion(m.ctrl, tuple(float(w) * 2.0 / 1.4 for w in m.warp))  # the same motion over 2 s
        scene = scene.with_motion("walker", stretched)
        step = compile_schedule(scn).order()[-1]
        sp, _ = lower(scene, step, "walker")
        (goal,) = [t for t in sp.targets if t.name == "goal:walk_to_0"]
        assert goal.t == pytest.approx(1.0 * (expect_end / 1.4))


@pytest.mark.slow
def test_free_timing_changes_the_solved_duration():
    """The timing step of walk_to with ``timing: free`` (bounds [1, 2] s) moves the end of the
    motion off the written 1.4 s (measured 2026-12-02: to 1.528 s, Solve_Succeeded in 54
    iterations, ~45 s); with fixed timing the end is held by an equality (see above)."""
    from schedules.execution.executor import solve_step
    scn = _variant("walk_to", "timing: free\nduration_bounds: [1.0, 2.0]\n")
    timing = compile_schedule(scn).order()[0]
    c = solve_step(build_scene(scn), timing, ("walker",))["characters"]["walker"]
    assert c["success"], c["status"]
    assert 1.0 - 1e-6 <= c["warp"][-1] <= 2.0 + 1e-6 and abs(c["warp"][-1] - 1.4) > 0.02


def test_a_runs_flights_are_ballistic_flights_of_its_full_steps_only():
    """The gaps of a run's footstep plan become flights of the full steps (momentum equalities
    in the NLP); a timing step (relaxed dynamics) gets none, a walk has none."""
    from schedules.execution.lower import gait_flights
    from scenegraph.model.footsteps import airborne_gaps
    scn = load_scenario("springy_run")
    scene = build_scene(scn)
    order = compile_schedule(scn).order()
    full = next(s for s in order if s.kind == "full")
    who = scene.characters[0].name
    sp, _ = lower(scene, full, who)
    gaps = airborne_gaps(scene.character(who).footsteps)
    assert gaps and set(gaps) <= set(sp.flights)
    nlp = transcribe(sp, derivatives=False)
    (rows,) = [sl for name, sl, _ in nlp.groups if name == "flight_momentum"]
    # six equalities at every evaluation point in a flight (nodes and midpoints, ends included)
    # but each flight's first: ballistic between the nodes too
    t_ev = sp.motion.time(nlp.s_eval)
    per = [int(np.sum((t_ev > a - 1e-6) & (t_ev < b + 1e-6))) for a, b in sp.flights]
    assert all(n >= 3 for n in per)
    assert rows.stop - rows.start == 6 * sum(n - 1 for n in per)
    timing = [s for s in order if s.kind == "timing"]
    for st in timing:
        assert lower(scene, st, who)[0].flights == ()
    # a jump goal's own flight is not stated twice
    a, b = gaps[0]
    assert gait_flights(scene.character(who).footsteps, ((a - 0.01, b + 0.01),)) == tuple(gaps[1:])
    walk = build_scene(load_scenario("walk"))
    wstep = next(s for s in compile_schedule(load_scenario("walk")).order() if s.kind == "full")
    assert lower(walk, wstep, walk.characters[0].name)[0].flights == ()


def test_the_scene_start_holds_the_planned_entry_speed():
    """A step that contains the scene's start pulls the root's velocity there toward the current
    motion's (the planned gait's speed): with the initial momentum free, bob of two_walkers
    entered falling at 6.3 m/s, caught by 12 body weights of ground force.  A window that starts
    later has no such term; the term costs nothing at the planned speed and grows with the
    squared departure."""
    scn = load_scenario("two_walkers")
    scene = build_scene(scn)
    order = compile_schedule(scn).order()
    full = next(s for s in order if s.kind == "full" and "bob" in s.characters)
    sp, _ = lower(scene, full, "bob")
    (vt,) = sp.velocities
    st = scene.character("bob")
    m = st.motion
    # the centre of mass's velocity by finite differences of its position (momenta_fn's c)
    from scenegraph.problem.flight import momenta_fn
    c = [np.asarray(momenta_fn(st.character)(np.asarray(m.at([t])[0]).ravel(), np.zeros(35))[0]).ravel()
         for t in (m.start, m.start + 1e-5)]
    assert vt.t == m.start
    np.testing.assert_allclose(vt.velocity, (c[1] - c[0]) / 1e-5, atol=2e-3)
    assert np.hypot(*vt.velocity[:2]) > 0.5  # a walk_to walker enters walking
    # 1 m/s off the planned speed costs weight (in E; the objective is OBJ_SCALE² E): w((1 + d)² − d²)
    # with d the departure of the initial motion itself, so |d| < 0.005 m/s there
    with_v = transcribe(sp, derivatives=False)
    off = transcribe(replace(sp, velocities=(replace(vt, velocity=(vt.velocity[0] + 1.0,) + vt.velocity[1:]),)),
                     derivatives=False)
    from scenegraph.problem.transcription import OBJ_SCALE
    gain = float(off.f_fn(off.x0, off.p0)) - float(with_v.f_fn(with_v.x0, with_v.p0))
    assert gain == pytest.approx(OBJ_SCALE**2 * vt.weight, rel=1e-2)
    tackle = load_scenario("tackle_dodge")
    later = [s for s in compile_schedule(tackle).order() if s.kind == "full" and s.window[0] > 0]
    assert later
    sc2 = build_scene(tackle)
    assert lower(sc2, later[0], later[0].characters[0])[0].velocities == ()


def test_the_scene_start_is_held_to_the_plan_in_every_step():
    """After a step has moved the motion (here: the whole motion lowered 0.3 m and sped up 1 m/s
    forward), the next step that contains the scene's start still pulls the pelvis and the
    centre of mass's velocity toward the *planned* entry (the initial motion's), not toward the
    moved motion's: re-anchored on the current motion, each whole-scene step kept the drift of
    the last one, and hopscotch entered its first hop crouched 0.4 m low."""
    from scenegraph.model.motion import Motion
    scn = load_scenario("two_walkers")
    scene = build_scene(scn)
    full = next(s for s in compile_schedule(scn).order() if s.kind == "full" and "bob" in s.characters)
    sp0, _ = lower(scene, full, "bob")
    st = scene.character("bob")
    m = st.motion
    t = np.linspace(m.start, m.end, 200)
    q = np.asarray(m.at(t)[0]).reshape(-1, 35).copy()
    q[:, 2] -= 0.3
    q[:, 0] += 1.0 * (t - m.start)
    moved = scene.with_motion("bob", Motion.from_samples(t, q, m.n_ctrl))
    assert moved.character("bob").plan is m
    sp1, _ = lower(moved, full, "bob")
    start = lambda sp: next(h for h in sp.targets if h.name == "start")
    assert start(sp1).point == pytest.approx(start(sp0).point, abs=1e-9)
    assert sp1.velocities[0].velocity == pytest.approx(sp0.velocities[0].velocity, abs=1e-9)
    # and the moved motion really is elsewhere: what a re-anchoring target would have read
    from schedules.execution.lower import start_velocity
    assert start_velocity(moved.character("bob"), 1.0).velocity[0] > sp0.velocities[0].velocity[0] + 0.5
