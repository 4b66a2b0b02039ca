"""Dense-dynamics nodes around contact ends (Subproblem.end_node_dt): where they are on a walk."""
from dataclasses import replace

import numpy as np

from scenegraph.model.body import make_character
from scenegraph.model.footsteps import contact_points, footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem
from scenegraph.problem.transcription import _node_grid

CH = make_character()


def test_nodes_before_and_after_every_contact_end():
    steps = footsteps_for_walk(n_steps=3)
    m = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    sp = Subproblem(CH, default_style(CH.total_mass), m, steps, end_node_dt=1 / 120)
    on, off = _node_grid(sp, CH, 30.0), _node_grid(replace(sp, end_node_dt=0.0), CH, 30.0)
    t_on, t_off = m.time(on), m.time(off)
    ends = [t for st in steps for _, (ta, tb), _ in contact_points(CH, st) for t in (ta, tb) if m.start < t < m.end]
    assert ends
    for te in ends:
        for v in (te - 1 / 120, te + 1 / 120):
            if m.start < v < m.end:
                assert np.min(np.abs(t_on - v)) < 2.5e-3  # a node there (or an end/knot within 2.5 ms)
    assert set(np.round(off, 9)) <= set(np.round(on, 9)) and len(on) > len(off)  # only added
    assert np.all(np.diff(on) > 0)
