"""The Dask executor's pieces: graph translation, the step store, scheduler errors, content keys.

Fast tests only (no solve); the cross-scheduler identity test is in test_distributed_runs.py.
"""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from dask.core import get_dependencies

from scenarios.errors import InputError
from scenarios.loader import load_scenario, parse_scenario
from scenegraph.model.footsteps import Footstep
from schedules.cli import main as cli
from schedules.plan.compiler import compile_schedule
from schedules.plan.critical_path import critical_path
from schedules.execution.graph_tasks import (SCENE_KEY, presolve_task_key, schedule_graph, step_key, step_task_key)

TWO_COUPLES = """
name: two_couples
duration: 0.8
characters: []
schedule: {cycles: 2}
repeat:
  - for: {i: [1, 2], y: [0.0, 4.0], tx: [1.0, 1.1]}
    characters:
      - {name: "a${i}", body: {preset: adult_male}, style: walk, start: {position: [0.0, "${y + 0.4}"], heading: 0}}
      - {name: "c${i}", body: {preset: child}, style: walk_person2, start: {position: [0.0, "${y - 0.3}"], heading: 0}}
    goals:
      - {type: walk_to, character: "a${i}", target: ["${tx}", "${y + 0.25}"], time: 0.8}
      - {type: walk_to, character: "c${i}", target: ["${tx}", "${y - 0.2}"], time: 0.8}
    couplings:
      - type: hand_hold
        name: hold${i}
        between: [{character: "a${i}", handle: palm_r}, {character: "c${i}", handle: palm_l}]
        interval: [0.0, 0.8]
"""


@pytest.mark.parametrize("name", ["crowd", "handhold", "tackle", "walk_to_run"])
def test_step_task_depends_exactly_on_its_ancestors(name):
    schedule = compile_schedule(load_scenario(name))
    dsk = schedule_graph(object(), schedule)
    solved = {w for s in schedule.order() for w in s.characters}
    assert set(dsk) == {SCENE_KEY} | {presolve_task_key(w) for w in solved} | {step_task_key(s.id) for s in schedule}
    for s in schedule:
        deps = get_dependencies(dsk, step_task_key(s.id))
        steps = {d for d in deps if d.startswith("step:")}
        assert steps == {step_task_key(a) for a in nx.ancestors(schedule.graph, s.id)}, s.id
        assert SCENE_KEY in deps
        # the pre-solves of every character the step (or an ancestor) frees or observes, no others
        anc = [schedule.step(a) for a in nx.ancestors(schedule.graph, s.id)] + [s]
        who = {w for a in anc for w in (*a.characters, *a.observes)} & solved
        assert {d for d in deps if d.startswith("presolve:")} == {presolve_task_key(w) for w in who}


def test_crowd_couples_are_independent_branches():
    schedule = compile_schedule(load_scenario("crowd"))
    dsk = schedule_graph(object(), schedule)
    for s in schedule:
        couple = s.group
        for d in get_dependencies(dsk, step_task_key(s.id)):
            if d.startswith("step:"):
                assert schedule.step(d.split(":", 1)[1]).group == couple
    cp = critical_path(schedule)
    assert len(schedule) == 24 and cp.length == 4 and cp.max_speedup == pytest.approx(6.0)  # 4 full steps a couple


def test_resumed_step_is_data_without_dependencies():
    schedule = compile_schedule(load_scenario("handhold"))
    first, second = schedule.order()[:2]
    dsk = schedule_graph(object(), schedule, given={step_task_key(first.id): {"step": first.id, "characters": {}}})
    assert get_dependencies(dsk, step_task_key(first.id)) == set()
    assert step_task_key(first.id) in get_dependencies(dsk, step_task_key(second.id))


def test_critical_path_uses_measured_times():
    schedule = compile_schedule(load_scenario("crowd"))
    times = {s.id: (10.0 if s.group.startswith("adult3") else 1.0) for s in schedule}
    cp = critical_path(schedule, times)
    assert all(sid.split("/")[0].endswith("3") for sid in cp.steps)
    # each couple: 4 full steps (2 cycles × 2 characters; no timing step with a fixed duration)
    assert cp.length == pytest.approx(40.0)
    assert cp.max_speedup == pytest.approx((40.0 + 20.0) / 40.0)


def test_step_key_changes_only_for_the_edited_couple():
    from scenegraph.world.scene import build_scene

    a = parse_scenario(TWO_COUPLES, "two_couples.yaml")
    # the edited copy lives in another file, and a comment line moves every goal one line down:
    # the goals' scenario locations (file:line, for messages) are not read by a solve
    b = parse_scenario(TWO_COUPLES.replace("tx: [1.0, 1.1]", "tx: [1.0, 1.3]").replace(
        "characters: []", "# edited\ncharacters: []"), "edited/two_couples_v2.yaml")
    assert a.goals and all(g.where != h.where for g, h in zip(build_scene(a).goals, build_scene(b).goals))
    sa, sb = build_scene(a), build_scene(b)
    sched_a, sched_b = compile_schedule(a), compile_schedule(b)
    assert [s.id for s in sched_a] == [s.id for s in sched_b]
    first = [s for s in sched_a if s.cycle == 1]
    assert {s.group for s in first} == {"a1+c1", "a2+c2"}
    for s in first:
        ka, kb = step_key(sa, s, {}, False), step_key(sb, sched_b.step(s.id), {}, False)
        if s.group == "a2+c2":  # couple 2's target moved: its steps read other data
            assert ka != kb, s.id
        else:
            assert ka == kb, s.id
        assert step_key(sa, s, {}, True) != ka  # fail_capped changes what is accepted


def test_step_store_round_trip_and_damage(tmp_path, capsys):
    from schedules.execution.step_store import StepStore

    st = StepStore(tmp_path / "store")
    key = "ab" * 32
    fs = Footstep("r", (0.1, -0.09), 0.0, 0.5)
    data = {"step": "x", "characters": {"w": {"ctrl": np.arange(6.0).reshape(2, 3), "footsteps": (fs,),
                                              "energy": 1.5, "status": "Solve_Succeeded"}}}
    assert st.get(key) is None
    st.put(key, data)
    got = st.get(key)
    assert np.array_equal(got["characters"]["w"]["ctrl"], data["characters"]["w"]["ctrl"])
    assert got["characters"]["w"]["footsteps"] == data["characters"]["w"]["footsteps"]
    assert got["characters"]["w"]["energy"] == 1.5
    npz = next((tmp_path / "store").rglob("001.npz"))
    npz.write_bytes(npz.read_bytes()[:-7] + b"garbage")
    assert st.get(key) is None
    assert "damaged" in capsys.readouterr().err
    st.put(key, data)  # a damaged entry is replaced
    assert st.get(key) is not None
    with pytest.raises(InputError):
        st.get("../../etc")


def test_unreachable_scheduler_is_exit_2_and_writes_nothing(tmp_path, monkeypatch, capsys):
    from schedules.execution import distributed

    monkeypatch.setattr(distributed, "CONNECT_TIMEOUT_S", 1.0)
    monkeypatch.chdir(tmp_path)
    rc = cli.main(["run", "walk", "--scheduler", "tcp://127.0.0.1:9", "-o", "w.usda", "--run-dir", "r"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "cannot reach the Dask scheduler" in err and "nothing was written" in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_scheduler_name_is_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "walk", "--scheduler", "bogus", "-o", "w.usda"]) == 2
    assert "expected local, processes, sync" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_sync_scheduler_runs_a_graph_and_reports_progress():
    from schedules.execution.distributed import connect

    seen = []
    dsk = {"x": 1, "y": (lambda v: v + 1, "x"), "z": (lambda a, b: a * b, "x", "y")}
    with connect("sync") as sched:
        sched.execute(dsk, ["y", "z"], lambda k, v: seen.append((k, v)))
    assert sorted(seen) == [("y", 2), ("z", 2)]


def test_sweep_with_an_unreachable_scheduler_is_exit_2_and_writes_nothing(tmp_path, monkeypatch, capsys):
    from schedules.execution import distributed

    monkeypatch.setattr(distributed, "CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "sw"
    rc = cli.main(["sweep", "walk", "--vary", "characters[0].start.heading=0,0.1", "--scheduler", "tcp://127.0.0.1:9",
                   "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "tcp://127.0.0.1:9: cannot reach the Dask scheduler" in err and "nothing was written" in err
    assert list(tmp_path.iterdir()) == []
