"""Knots on flight ends (scenegraph/model/knot_warp.py): the warp puts a knot on each event and
the motion stays the same motion in world time."""
import numpy as np
import pytest

from scenarios.loader import load_scenario
from scenegraph.model.footsteps import airborne_gaps
from scenegraph.model.knot_warp import align_knots, knot_times
from scenegraph.model.motion import Motion
from scenegraph.world.scene import build_scene


def _smooth_motion(t0=0.0, t1=1.1, n_ctrl=29):
    t = np.linspace(t0, t1, 400)
    q = np.stack([np.sin(2 * np.pi * (0.5 + 0.04 * k) * t + k) * (0.1 + 0.02 * k) for k in range(35)], axis=1)
    return Motion.from_samples(t, q, n_ctrl)


@pytest.mark.parametrize("events", [(0.1357, 0.2214, 0.4929, 0.5786, 0.85, 0.9357), (0.31,), (0.05, 0.52, 1.07)])
def test_every_event_is_a_knot_and_the_motion_is_unchanged(events):
    m = _smooth_motion()
    a = align_knots(m, events)
    kt = knot_times(a)
    for e in events:
        assert np.min(np.abs(kt - e)) < 1e-9, (e, kt)
    t = np.linspace(m.start, m.end, 777)
    assert np.max(np.abs(a.at(t)[0] - m.at(t)[0])) < 2e-3  # rad or m
    assert np.all(np.diff(a.warp) > 0)
    assert a.start == pytest.approx(m.start) and a.end == pytest.approx(m.end)
    # knot spacing stays within a fifth of the uniform one
    h = m.duration / (m.n_ctrl - 3)
    assert np.all(np.abs(np.diff(kt) - h) < 0.6 * h)


def test_no_event_inside_leaves_the_motion_alone():
    m = _smooth_motion()
    assert align_knots(m, ()) is m
    assert align_knots(m, (m.start, m.end, m.end + 1.0)) is m


def test_events_sharing_a_knot_keep_the_first():
    m = _smooth_motion()
    h = m.duration / (m.n_ctrl - 3)
    e1, e2 = 10 * h + 0.1 * h, 10 * h + 0.3 * h  # both nearest to knot 10
    a = align_knots(m, (e1, e2))
    kt = knot_times(a)
    assert np.min(np.abs(kt - e1)) < 1e-9
    assert np.min(np.abs(kt - e2)) > 0.1 * h


@pytest.mark.parametrize("name,who", [("tackle_dodge", "tackler"), ("springy_run", None), ("broad_jump", None)])
def test_a_bundled_plan_has_knots_on_its_flight_ends(name, who):
    scene = build_scene(load_scenario(name))
    c = scene.character(who) if who else scene.characters[0]
    gaps = airborne_gaps(c.footsteps)
    assert gaps, "the plan has flights"
    kt = knot_times(c.motion)
    for a, b in gaps:
        for e in (a, b):
            assert np.min(np.abs(kt - e)) < 1e-6, (e, kt)
    assert c.plan is c.motion
