"""Unit tests of the executor's bookkeeping (no solves)."""
from __future__ import annotations

import numpy as np

from schedules.execution.executor import _merge_contacts


def test_windowed_contact_forces_replace_only_their_window():
    # the old forces cover [0, 2] s; a step over the window [0.5, 1.5] reports forces at all its
    # points (also outside its window, where its motion is held): only its window's may enter
    t_old = np.linspace(0.0, 2.0, 11)
    old = {"ball_r": (t_old, np.tile([0.0, 0.0, 100.0], (11, 1)))}
    t_new = np.linspace(0.0, 2.0, 21)
    new = {"ball_r": (t_new, np.tile([0.0, 0.0, 300.0], (21, 1))),
           "heel_l": (np.array([0.2, 1.0]), np.array([[0.0, 0.0, 50.0], [0.0, 0.0, 60.0]]))}
    out = _merge_contacts(old, new, (0.5, 1.5))
    t, f = out["ball_r"]
    assert np.all(np.diff(t) >= 0)
    inside = (t >= 0.5) & (t <= 1.5)
    assert np.all(f[inside, 2] == 300.0) and np.all(f[~inside, 2] == 100.0)
    assert len(np.unique(np.round(t, 9))) == len(t), "no time may carry two forces"
    assert np.count_nonzero(inside) == np.count_nonzero((t_new >= 0.5) & (t_new <= 1.5))
    t, f = out["heel_l"]
    assert t.tolist() == [1.0] and f[:, 2].tolist() == [60.0]


def test_whole_window_contact_forces_replace_everything():
    old = {"ball_r": (np.array([0.0, 1.0]), np.array([[0, 0, 1.0], [0, 0, 2.0]]))}
    new = {"ball_l": (np.array([0.5]), np.array([[0, 0, 3.0]]))}
    assert _merge_contacts(old, new, None) is new
