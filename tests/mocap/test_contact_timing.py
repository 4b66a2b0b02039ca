"""One-sided contact speeds (scenegraph.mocap.contacts.point_speed) and the half-frame widening of
clip contacts (schedules.cli.learn._widen): a brisk walk keeps its double support at 30 fps."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.mocap.contacts import contact_mask, point_speed


def _landing(fps=30.0, v=2.0, land=10, lift=20, T=30):
    """A point that moves at v m/s at floor height, rests on frames land..lift, then leaves."""
    x = np.zeros(T)
    for k in range(1, T):
        x[k] = x[k - 1] + (0.0 if land < k <= lift else v / fps)
    return np.column_stack([x, np.zeros(T), np.zeros(T)])


def test_onesided_speed_is_zero_on_the_touchdown_and_liftoff_frames():
    P = _landing()
    central = point_speed(P, 30.0)
    one = point_speed(P, 30.0, onesided=True)
    assert central[10] == pytest.approx(1.0) and central[20] == pytest.approx(1.0)  # half the approach speed
    assert one[10] == pytest.approx(0.0) and one[20] == pytest.approx(0.0)
    assert one[5] == pytest.approx(2.0) and one[25] == pytest.approx(2.0)  # moving frames stay moving
    assert np.all(one <= central + 1e-12)


def test_onesided_mask_holds_the_whole_rest():
    P = _landing()
    m_c = contact_mask(P, 30.0, min_duration=0.0)
    m_o = contact_mask(P, 30.0, min_duration=0.0, onesided=True)
    assert np.flatnonzero(m_o).tolist() == list(range(10, 21))
    assert np.flatnonzero(m_c).tolist() == list(range(11, 20))  # central: touchdown and lift-off lost


@pytest.mark.slow
def test_brisk_walk_has_no_flight_with_onesided_contacts():
    """07_12 (1.9 m/s) at 30 fps: central differences find 0.07–0.1 s "flight" gaps (a run),
    one-sided speeds widened by half a frame find overlapping stances."""
    from pathlib import Path

    from schedules.cli.evaluate import find_training_clip
    from schedules.cli.learn import _has_flight, clip_target

    clip = find_training_clip("walk_brisk_cmu_07_12.bvh", Path("."))
    if clip is None:
        pytest.skip("the shared validation trial 07_12 is not available")
    _, _, st_c, c = clip_target(clip, (2, 264), reconstruct=False, feasible=False)
    _, _, st_o, _ = clip_target(clip, (2, 264), reconstruct=False, feasible=False, onesided=True)
    t0, t1 = c.times[0], c.times[-1]
    assert all(s.heel is None for s in st_c)  # classified as a run
    assert not _has_flight(st_o, t0, t1) and any(s.heel is not None for s in st_o)
    spans = sorted((s.t0, s.t1) for s in st_o)
    assert all(b[0] <= a[1] + 1e-9 for a, b in zip(spans, spans[1:]))
