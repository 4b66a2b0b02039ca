"""The held-out audit's foot sliding (scenegraph.nio.slide): a distance per stance, checked on
motions whose sliding is known — a still foot, a steady drift and a millimetre wobble (the
last reads 0.17 m/s as a speed, what ``Audit.planted_speed_max`` reports, while it never
leaves a 2 mm radius)."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import N_DOF, make_character
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.nio.slide import slide_summary, stance_slides

CH = make_character()
RATE = 120.0


def _standing(x_of_t, dur=0.6):
    """A body standing with both feet planted over [0, dur] s, its root x = x_of_t(t) (m),
    nothing else moving; footsteps where the handles are at t = 0 (on the ground under them)."""
    t = np.linspace(0.0, dur, int(round(dur * RATE)) + 1)
    q = np.zeros((t.size, N_DOF))
    q[:, 2] = 0.95
    q[:, 0] = x_of_t(t)
    names = ("ball_l", "ball_r")
    p0 = np.asarray(handle_positions_fn(CH, names)(q[0])).reshape(3, 2, order="F")
    steps = tuple(Footstep(f, (float(p0[0, k]), float(p0[1, k])), 0.0, dur, ball=(0.0, 1.0), heel=None)
                  for k, f in enumerate("lr"))
    return t, q, steps


def test_a_still_foot_does_not_slide():
    t, q, steps = _standing(lambda t: 0.0 * t)
    s = stance_slides(CH, t, q, steps)
    assert [r["handle"] for r in s] == ["ball_l", "ball_r"]
    assert all(r["samples"] == t.size for r in s)
    assert max(r["slide_m"] for r in s) == pytest.approx(0.0, abs=1e-12)
    assert max(r["speed_max_m_s"] for r in s) == pytest.approx(0.0, abs=1e-12)


def test_a_steady_drift_slides_speed_times_duration():
    v, dur = 0.04, 0.6
    t, q, steps = _standing(lambda t: v * t, dur)
    s = slide_summary(stance_slides(CH, t, q, steps))
    assert s["stance_slide_max_m"] == pytest.approx(v * dur, rel=1e-9)
    assert s["planted_speed_max_m_s"] == pytest.approx(v, rel=1e-9)
    assert s["stance_slide_where"]["t_to"] == pytest.approx(dur)
    # the footprints are on the ground under where the balls were at t = 0 (z0 above it): the
    # error is largest at the end, hypot(v · dur, z0)
    z0 = float(np.asarray(handle_positions_fn(CH, ("ball_l",))(q[0])).ravel()[2])
    assert s["footprint_error_where"]["error_m"] == pytest.approx(np.hypot(v * dur, z0), rel=1e-6)
    assert s["footprint_error_where"]["t"] == pytest.approx(dur)


def test_a_millimetre_wobble_is_fast_but_does_not_slide_far():
    """2 mm at 15 Hz (the 30 Hz constraint points' half period): the speed the audit reports is
    A·120·sin(π/4) = 0.17 m/s, the distance from where it planted A = 2 mm (the stage audit's
    limit is 5 mm)."""
    A = 0.002
    t, q, steps = _standing(lambda t: A * np.sin(2 * np.pi * 15.0 * t))
    s = slide_summary(stance_slides(CH, t, q, steps))
    assert s["planted_speed_max_m_s"] == pytest.approx(A * RATE * np.sin(np.pi / 4), rel=1e-6)
    assert s["planted_speed_max_m_s"] > 0.1
    assert s["stance_slide_max_m"] == pytest.approx(A, rel=1e-9)  # from where it planted (x = 0)


def test_only_the_planted_interval_counts():
    """A heel planted for the first half only: a drift in the second half is not its slide."""
    dur = 0.6
    t, q, steps = _standing(lambda t: np.where(t > 0.3, 0.1 * (t - 0.3), 0.0), dur)
    st = Footstep("l", steps[0].position, 0.0, dur, ball=None, heel=(0.0, 0.5))
    (r,) = stance_slides(CH, t, q, (st,))
    (_, (ta, tb), _), = contact_points(CH, st)
    assert (ta, tb) == (0.0, 0.3) and r["handle"] == "heel_l"
    assert r["slide_m"] == pytest.approx(0.0, abs=1e-12)
    ball = Footstep("l", steps[0].position, 0.0, dur, ball=(0.0, 1.0), heel=None)
    assert stance_slides(CH, t, q, (ball,))[0]["slide_m"] == pytest.approx(0.1 * 0.3, rel=1e-9)


def test_bad_shapes_and_no_samples():
    t, q, steps = _standing(lambda t: 0.0 * t)
    with pytest.raises(ValueError, match="N_DOF"):
        stance_slides(CH, t, q[:-1], steps)
    late = (Footstep("l", (0.0, 0.0), 5.0, 6.0),)
    assert stance_slides(CH, t, q, late) == []
    assert slide_summary([])["stance_slide_max_m"] == 0.0


def test_the_audits_sliding_figure_is_this_speed_not_a_distance():
    """``Audit.planted_speed_max`` on a motion drifting 0.04 m/s for 0.6 s reads 0.04 (m/s), the
    slide is 24 mm: the 0.11–0.41 of the round-13 held-out reports were speeds."""
    from scenegraph.model.audit import audit_motion
    from scenegraph.model.motion import Motion
    from scenegraph.model.style import default_style

    t, q, steps = _standing(lambda t: 0.04 * t)
    m = Motion.from_samples(t, q, 20)
    a = audit_motion(CH, default_style(CH.total_mass), m, steps)
    s = slide_summary(stance_slides(CH, t, m.canonical(m.to_canonical(t)), steps))
    assert a.planted_speed_max == pytest.approx(0.04, rel=1e-6)
    assert s["planted_speed_max_m_s"] == pytest.approx(a.planted_speed_max, rel=1e-6)
    assert s["stance_slide_max_m"] == pytest.approx(0.024, rel=1e-6)


def test_evaluate_style_judges_with_the_run_tolerances_and_the_slide():
    """The held-out verdict (``evaluate.audit_entry``): a 3 mm footstep miss between constraint
    points passes as in ``compose run`` (5 mm), a 24 mm stance slide fails, and each failing
    check is named."""
    from scenegraph.model.audit import Audit
    from scenegraph.model.motion import Motion

    from schedules.cli.evaluate import audit_entry

    ok = Audit(root_residual_rms=1.0, root_residual_max=2.0, root_residual_rel=1e-3, footstep_error_max=0.003,
               penetration_max=0.003, friction_violation_max=0.0, planted_speed_max=0.3,
               joint_limit_violation_max=0.0, energy=1.0, dense_residual_max=0.005)
    t, q, steps = _standing(lambda t: 0.0 * t)
    e = audit_entry(CH, ok, Motion.from_samples(t, q, 20), steps)
    assert e["passes"] and e["fails_on"] == [] and e["stance_slide_max_m"] < 1e-9
    assert not ok.passes()  # the old verdict: Audit.passes()'s 1 mm defaults
    t, q, steps = _standing(lambda t: 0.04 * t)
    e = audit_entry(CH, ok, Motion.from_samples(t, q, 20), steps)
    assert not e["passes"] and e["fails_on"] == ["stance_slide"]
    assert e["stance_slide_max_m"] == pytest.approx(0.024, rel=1e-6)
    from dataclasses import replace
    e = audit_entry(CH, replace(ok, footstep_error_max=0.006, dense_residual_max=0.06), Motion.from_samples(t, q, 20), steps)
    assert e["fails_on"] == ["footstep", "dense_residual", "stance_slide"]
