"""Fast: the same solve results whatever runs the schedule (plain executor, Dask ``sync``,
Dask ``processes`` with 2 worker processes) on a small scene.

A 0.6 s walk (one character, a timing and a full step after the kinematic pre-solve),
IPOPT capped at 25 iterations per subproblem: the point is that every path computes the
same numbers from the same inputs, not that they converge (at 10 the full step, with the
contact terms of round 11, ends with a footstep row 0.26 mm outside tolerance and fails).  Compared: every step record
(status, iterations, energy, violations, the pre-solve summary) and the final Scene —
control points, timewarp and footsteps of the character, bit for bit — which is all the
stage and report are made from.  (The slow test_distributed_runs.py also compares the
written stages and runs the ``local`` cluster.)
"""
from __future__ import annotations

import io

import numpy as np

from scenarios.loader import parse_scenario
from scenegraph.world.scene import build_scene
from schedules.plan.compiler import compile_schedule
from schedules.execution.distributed import connect, run_schedule_dask
from schedules.execution.executor import run_schedule

TINY_WALK = """
name: tiny_walk
duration: 0.6
characters:
  - name: walker
    body: {preset: adult_male}
    style: walk
    start: {position: [-0.35, 0.0], heading: 0}
goals:
  - type: footprints
    character: walker
    steps:
      - {foot: r, position: [-0.70, -0.09], time: [0.00, 0.11]}
      - {foot: l, position: [0.00, 0.09], time: [0.00, 0.6]}
      - {foot: r, position: [0.70, -0.09], time: [0.55, 0.6]}
schedule:
  timewarp: true               # a timing step and a full step: two steps, one depending on the other
"""


def _facts(result) -> tuple:
    recs = [(r.id, r.status, r.iterations, r.energy, r.violations) for r in result.records]
    chars = []
    for c in result.scene.characters:
        chars.append((c.name, np.asarray(c.motion.ctrl, float).tobytes(), np.asarray(c.motion.warp, float).tobytes(),
                      tuple((f.foot, tuple(f.position), f.t0, f.t1, f.heading) for f in c.footsteps)))
    pre = {w: {k: v for k, v in d.items() if k != "seconds"} for w, d in result.presolve.items()}
    return recs, chars, pre


def test_plain_sync_and_processes_give_identical_results(tmp_path, monkeypatch):
    monkeypatch.setenv("COMPOSE_MAX_ITER", "25")
    scn = parse_scenario(TINY_WALK, "tiny.yaml", base_dir=tmp_path)
    schedule = compile_schedule(scn)
    scene = build_scene(scn)
    assert len(schedule) == 2
    plain = _facts(run_schedule(scene, schedule, run_dir=tmp_path / "plain", fingerprint="t", log=io.StringIO()))
    assert plain[0] and all(np.isfinite(r[3]) for r in plain[0])
    for spec, jobs in (("sync", 1), ("processes", 2)):
        log = io.StringIO()
        with connect(spec, jobs) as sched:
            got = run_schedule_dask(scene, schedule, sched, run_dir=tmp_path / spec, fingerprint="t", log=log)
        assert "2 steps, 1 pre-solve(s)" in log.getvalue()
        assert _facts(got) == plain, spec


def _nap_pid(seconds: float) -> int:
    import os
    import time

    time.sleep(seconds)
    return os.getpid()


def test_processes_scheduler_hands_out_one_task_at_a_time():
    """4 independent 1-s tasks on 2 processes: both processes work and results arrive as
    tasks finish (Dask's multiprocessing default sent all 4 to one process in one batch)."""
    import time

    seen: list = []
    dsk = {f"t{i}": (_nap_pid, 1.0) for i in range(4)}
    with connect("processes", 2) as sched:
        sched.execute(dsk, list(dsk), lambda k, pid: seen.append((time.perf_counter(), pid)))
    assert len(seen) == 4
    assert len({pid for _, pid in seen}) == 2
    assert seen[-1][0] - seen[0][0] > 0.5  # two rounds of two tasks, not one lump
