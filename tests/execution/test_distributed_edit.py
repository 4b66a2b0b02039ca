"""Slow: after an edit, a re-run with the step store solves only what changed and gives the
fresh run's results.

Two independent walkers (0.6 s each, a timing and a full step each: two branches of the
schedule), IPOPT capped at 10 iterations (same numbers on every path is the point, not
convergence).  The scene is run once with an empty step store; then walker b's footprints
are moved 5 cm and the edited scene is re-run with that store (walker a's pre-solve and two
steps must come from the store, b's must be solved) and run fresh with an empty store.
The re-run and the fresh run must agree bit for bit: every step record and the final
control points, timewarps and footsteps of both walkers.  (The crowd version, with timing,
is ``tests/benchmarks/bench_distributed.py``'s edit part.)
"""
from __future__ import annotations

import io
import re

import numpy as np
import pytest

from scenarios.loader import parse_scenario
from scenegraph.world.scene import build_scene
from schedules.plan.compiler import compile_schedule
from schedules.execution.distributed import connect, run_schedule_dask

pytestmark = pytest.mark.slow

TWO_TINY_WALKERS = """
name: two_tiny_walkers
duration: 0.6
characters:
  - {name: a, body: {preset: adult_male}, style: walk, start: {position: [-0.35, 0.0], heading: 0}}
  - {name: b, body: {preset: adult_male}, style: walk, start: {position: [-0.35, 3.0], heading: 0}}
goals:
  - type: footprints
    character: a
    steps:
      - {foot: r, position: [-0.70, -0.09], time: [0.00, 0.11]}
      - {foot: l, position: [0.00, 0.09], time: [0.00, 0.6]}
      - {foot: r, position: [0.70, -0.09], time: [0.55, 0.6]}
  - type: footprints
    character: b
    steps:
      - {foot: r, position: [-0.70, 2.91], time: [0.00, 0.11]}
      - {foot: l, position: [0.00, 3.09], time: [0.00, 0.6]}
      - {foot: r, position: [X_LAST, 2.91], time: [0.55, 0.6]}
schedule:
  timewarp: true   # a timing step too (not the default with a fixed duration): two steps per walker
"""


def _facts(result) -> tuple:
    recs = [(r.id, r.status, r.iterations, r.energy, r.violations) for r in result.records]
    chars = [(c.name, np.asarray(c.motion.ctrl, float).tobytes(), np.asarray(c.motion.warp, float).tobytes(),
              tuple((f.foot, tuple(f.position), f.t0, f.t1, f.heading) for f in c.footsteps))
             for c in result.scene.characters]
    return recs, chars


def _run(tmp_path, x_last: str, tag: str, store):
    scn = parse_scenario(TWO_TINY_WALKERS.replace("X_LAST", x_last), f"{tag}.yaml", base_dir=tmp_path)
    schedule = compile_schedule(scn)
    log = io.StringIO()
    with connect("sync") as sched:
        res = run_schedule_dask(build_scene(scn), schedule, sched, run_dir=tmp_path / tag, fingerprint=tag,
                                store=store, log=log)
    return res, log.getvalue()


def test_edit_rerun_solves_the_edited_branch_only_and_equals_a_fresh_run(tmp_path, monkeypatch):
    monkeypatch.setenv("COMPOSE_MAX_ITER", "10")
    store = tmp_path / "store"
    first, log = _run(tmp_path, "0.70", "original", store)
    assert "came from the step store" not in log
    rerun, log = _run(tmp_path, "0.75", "rerun", store)
    assert "2 of 4 step(s) came from the step store" in log
    stored = {re.match(r"\[\d+/\d+\] (presolve \w+|[^ :]+)", line).group(1)
              for line in log.splitlines() if "(from the step store)" in line}
    assert stored == {"presolve a", "a/c1/whole/timing", "a/c1/whole/full"}, log
    fresh, _ = _run(tmp_path, "0.75", "fresh", tmp_path / "empty_store")
    assert _facts(rerun) == _facts(fresh)
    # walker a is the same in all three runs; b changed with the edit
    a_first, a_fresh = _facts(first)[1][0], _facts(fresh)[1][0]
    assert a_first == a_fresh
    assert _facts(first)[1][1] != _facts(fresh)[1][1]
