"""Spacetime synthesis from footprints, checked by the independent physics audit."""
from dataclasses import replace

import numpy as np
import pytest

from scenegraph.body import make_character
from scenegraph.footsteps import footsteps_for_walk
from scenegraph.gait import initial_motion
from scenegraph.spacetime import Subproblem, solve
from scenegraph.style import default_style
from scenegraph.synthesis import presolve_kinematics, synthesize

CH = make_character()
STYLE = default_style(CH.total_mass)


@pytest.fixture(scope="module")
def walk():
    steps = footsteps_for_walk()  # four footprints, 0.7 m steps at 1.85 steps/s ≈ 1.3 m/s
    # soft footprint springs and a one-sided soft ground at 120 Hz keep planted feet still and
    # swinging toes above the ground between the collocation points
    return steps, synthesize(CH, STYLE, steps, steps[1].t0, steps[-1].t0, soft_pin_hz=120.0,
                             soft_ground_hz=120.0, soft_ground_weight=1e4)


def test_walk_cycle_converges_and_passes_the_audit(walk):
    steps, syn = walk
    res, aud = syn.result, syn.audit
    assert res.success, res.summary()
    # constraints hold at the collocation points (solver's own check) ...
    assert res.violations["footstep"] <= 1e-6
    assert res.violations["penetration"] <= 1e-6
    # ... and the independent audit re-evaluates between them at 120 Hz
    assert aud.footstep_error_max <= 1e-3, aud
    assert aud.penetration_max <= 1e-3, aud
    assert aud.foot_sliding_max <= 0.05, aud
    assert aud.friction_violation_max <= 1e-6
    assert aud.root_residual_rel <= 1e-3, aud     # root residual vs body weight
    assert aud.joint_limit_violation_max <= 1e-6
    speed = (res.motion.canonical([1.0])[0, 0] - res.motion.canonical([0.0])[0, 0]) / res.motion.duration
    assert 1.1 < speed < 1.5


def test_walk_energy_is_far_below_the_initial_guess(walk):
    steps, syn = walk
    assert syn.result.energy < 0.05 * syn.presolve.energy


@pytest.mark.slow
def test_free_footprint_moves_to_a_lower_energy_spot():
    """A footprint placed 15 cm too wide, then freed: warm-started at the fixed optimum (motion
    and contact forces), the solver moves it and lowers the energy while every constraint
    holds.  It does not converge within 300 iterations (it keeps drifting, see README), so
    only feasibility and the energy decrease are asserted."""
    steps = list(footsteps_for_walk())
    wide = replace(steps[2], position=(steps[2].position[0], steps[2].position[1] - 0.15))
    steps[2] = wide
    fixed = synthesize(CH, STYLE, tuple(steps), steps[1].t0, steps[-1].t0)
    assert fixed.result.success, fixed.result.summary()
    steps[2] = replace(wide, free=True)
    free = solve(Subproblem(CH, STYLE, fixed.result.motion, tuple(steps), free=frozenset({"q", "footprints"}),
                            contact_guess=fixed.result.contact_forces))
    moved = np.subtract(free.footsteps[2].position, wide.position)
    assert np.linalg.norm(moved) > 0.02
    assert free.energy < fixed.result.energy
    assert free.violations["footstep"] <= 1e-5 and free.violations["penetration"] <= 1e-5


@pytest.mark.slow
def test_timewarp_moves_a_hurried_footstep_later():
    steps = list(footsteps_for_walk())
    steps[2] = replace(steps[2], t0=steps[2].t0 - 0.12, t1=steps[2].t1 - 0.12)  # lands 0.12 s early
    steps = tuple(steps)
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    pre = presolve_kinematics(CH, STYLE, m0, steps)
    res = solve(Subproblem(CH, STYLE, pre.motion, steps, free=frozenset({"q", "warp"})))
    assert res.success, res.summary()
    s_land = pre.motion.to_canonical([steps[2].t0])[0]
    landed = res.motion.time([s_land])[0]
    assert landed > steps[2].t0 + 0.03  # later in world time: only the warp can do that
    assert res.motion.start == pytest.approx(pre.motion.start) and res.motion.end == pytest.approx(pre.motion.end)
    assert np.all(np.diff(res.motion.warp) > 0)
    assert res.violations["footstep"] <= 1e-6


@pytest.mark.slow
def test_run_with_flight_phases():
    """A cyclic run cycle (1 m steps at 2.8 steps/s ≈ 2.8 m/s, stance 38 % of a stride, so
    both feet are off the ground between stances) converges from the initialisation."""
    steps = footsteps_for_walk(step_length=1.0, cadence=2.8, stance_fraction=0.38, gait="run")
    flights = [(a.t1, b.t0) for a, b in zip(steps, steps[1:])]
    assert all(b - a > 0.05 for a, b in flights)
    syn = synthesize(CH, STYLE, steps, steps[1].t0, steps[-1].t0, run=True, max_iter=600, cyclic=True,
                     soft_pin_hz=120.0, soft_ground_hz=120.0, soft_ground_weight=1e4)
    res, aud = syn.result, syn.audit
    assert res.success, res.summary()
    assert aud.root_residual_rel <= 1e-3, aud
    assert aud.footstep_error_max <= 1e-3, aud
    assert aud.penetration_max <= 1e-3, aud
    assert aud.friction_violation_max <= 1e-6, aud
    assert aud.joint_limit_violation_max <= 1e-6, aud
    # no contact force in flight: the forces exist only inside stances
    for times, _ in res.contact_forces.values():
        for a, b in flights:
            assert not np.any((times > a + 1e-6) & (times < b - 1e-6))
    # the cycle ends where it began, one stride further
    q0, q1 = res.motion.canonical([0.0, 1.0])
    assert q1[0] - q0[0] == pytest.approx(2.0, abs=1e-3)
    np.testing.assert_allclose(q1[2:], q0[2:], atol=1e-6)


def test_spring_force_enters_the_dynamics():
    """A physical spring (rubber-band coupling) pulls the right palm toward a moving anchor:
    the solver's force is k (anchor − palm) at every collocation point, and the independent
    audit balances the equations of motion only when that force is counted."""
    from scenegraph.audit import audit_motion
    from scenegraph.kinematics import handle_positions_fn
    from scenegraph.spacetime import Spring

    steps = footsteps_for_walk()
    t0, t1 = steps[1].t0, steps[-1].t0
    m0 = initial_motion(CH, steps, t0, t1)
    times = np.linspace(t0, t1, 40)
    q, _, _ = m0.state_at_s(m0.to_canonical(times))
    palm = np.asarray(handle_positions_fn(CH, ("palm_r",)).map(len(times))(q.T)).T
    anchor = palm + np.array([0.0, -0.08, 0.0])  # 8 cm to the right of the initial palm path
    k = 400.0
    spring = Spring("palm_r", tuple(times), tuple(map(tuple, anchor)), k)
    syn = synthesize(CH, STYLE, steps, t0, t1, springs=(spring,))
    res = syn.result
    assert res.success, res.summary()
    ft, ff = res.contact_forces["palm_r"]
    qs, _, _ = res.motion.state_at_s(res.motion.to_canonical(ft))
    pos = np.asarray(handle_positions_fn(CH, ("palm_r",)).map(len(ft))(qs.T)).T
    expect = k * (np.stack([np.interp(ft, times, anchor[:, c]) for c in range(3)], axis=1) - pos)
    np.testing.assert_allclose(ff, expect, atol=1e-6)
    assert np.abs(ff).max() > 5.0  # a real pull, not a vanishing one
    with_force = syn.audit
    without = audit_motion(CH, STYLE, res.motion, res.footsteps,
                           {h: v for h, v in res.contact_forces.items() if h != "palm_r"})
    assert with_force.root_residual_rel <= 1e-3, with_force
    assert without.root_residual_max > 3 * with_force.root_residual_max + 1.0
