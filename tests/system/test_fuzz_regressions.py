"""Inputs the fuzzer (tests/benchmarks/fuzz_inputs.py) found that were accepted but broke later."""
from __future__ import annotations

import numpy as np

from scenarios.loader import parse_scenario
from scenegraph.model.footsteps import Footstep
from scenegraph.model.gait import _root_path
from scenegraph.world.scene import build_scene


def test_root_path_with_knots_at_the_same_time_is_finite():
    """Three footprints whose outer two have the same t0 + t1 put two root-path knots at the
    same time; the path divided by their zero time difference and was NaN before the start."""
    steps = (Footstep("r", (0.0, -0.1), 0.0, 0.6), Footstep("l", (0.3, 0.1), 0.05, 0.1),
             Footstep("l", (0.6, 0.1), 0.1, 0.5))
    times = np.linspace(0.0, 1.0, 61)
    xy, heading = _root_path(steps, times)
    assert np.all(np.isfinite(xy)) and np.all(np.isfinite(heading))


def test_scene_of_such_footprints_has_a_finite_initial_motion():
    text = """name: knots
duration: 1.0
characters:
  - name: a
goals:
  - type: footprints
    character: a
    steps:
      - {foot: r, position: [0.0, -0.1], time: [0.0, 0.6]}
      - {foot: l, position: [0.3, 0.1], time: [0.05, 0.1]}
      - {foot: l, position: [0.6, 0.1], time: [0.1, 0.5]}
"""
    scene = build_scene(parse_scenario(text, "knots.yaml"))
    m = scene.characters[0].motion
    assert np.all(np.isfinite(m.ctrl)) and np.all(np.isfinite(m.warp))
