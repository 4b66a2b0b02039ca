"""The dispatcher: dependencies read from a Dask graph, priority order, and one task per free
worker thread on a real LocalCluster (Dask's own ``client.get`` placed every ready task up
front: an 8-variant sweep left one of two workers idle for 19 % of the run)."""
from __future__ import annotations

import threading
import time

import pytest

from schedules.execution.dispatch import dispatch, priority_order, task_dependencies


def _add(*xs):
    return sum(sum(x) if isinstance(x, list) else x for x in xs)


def _nap(i: int, seconds: float) -> tuple:
    import time as _t

    start = _t.time()
    _t.sleep(seconds)
    return i, start, _t.time()


GRAPH = {
    "data": 10,
    "a": (_add, "data", 1),
    "b": (_add, "a", ["data", "a"]),  # keys inside a list are references
    "c": (_add, "data", 2),
    "d": (_add, "b", "c"),
    "t": (len, ("a", "b")),  # a tuple that is not a task is passed as it is
}


def test_dependencies_are_the_keys_a_task_reads():
    deps = task_dependencies(GRAPH)
    assert deps == {"data": set(), "a": {"data"}, "b": {"a", "data"}, "c": {"data"}, "d": {"b", "c"}, "t": set()}


def test_priority_order_puts_each_wanted_key_after_what_it_needs():
    assert priority_order(GRAPH, ["d"]) == ["data", "a", "b", "c", "d"]
    assert priority_order(GRAPH, ["c", "d"]) == ["data", "c", "a", "b", "d"]
    assert priority_order(GRAPH, ["t", "a"]) == ["t", "data", "a"]


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=50)
    c = distributed.Client(cluster)
    c.wait_for_workers(2)
    yield c
    c.close()
    cluster.close()


def test_results_and_callbacks_follow_the_graph(client):
    got = {}
    dispatch(client, GRAPH, ["d", "t"], lambda k, r: got.__setitem__(k, r))
    assert got == {"d": (11 + 10 + 11) + 12, "t": 2}


def test_each_worker_holds_at_most_one_task_and_order_is_kept(client):
    """Polls the scheduler while 8 independent 0.4 s tasks run on 2 single-threaded workers:
    no worker is ever given a second task while it runs one, and tasks start in key order."""
    dsk = {f"v-{i}": (_nap, i, 0.4) for i in range(8)}
    seen, stop = [], threading.Event()

    def poll():
        while not stop.is_set():
            seen.append(max((len(v) for v in client.processing().values()), default=0))
            time.sleep(0.05)

    th = threading.Thread(target=poll, daemon=True)
    th.start()
    finished = []
    try:
        dispatch(client, dsk, list(dsk), lambda k, r: finished.append(r))
    finally:
        stop.set()
        th.join(5)
    assert sorted(r[0] for r in finished) == list(range(8))
    assert seen and max(seen) == 1, seen
    # greedy in key order: task i starts only after i - 1 tasks have ended (2 slots)
    spans = {i: (start, end) for i, start, end in finished}
    for i, (start, _) in spans.items():
        assert sum(end <= start for j, (_, end) in spans.items() if j != i) >= i - 1, (i, spans)


def test_a_failing_task_raises_and_nothing_keeps_running(client):
    dsk = {"ok": (_nap, 1, 2.0), "bad": (_add, "x", 1)}  # str + int
    with pytest.raises(TypeError):
        dispatch(client, dsk, ["bad", "ok"], lambda k, r: None)
    deadline = time.time() + 10
    while time.time() < deadline and any(client.processing().values()):
        time.sleep(0.1)
    assert not any(client.processing().values())


def _pid() -> int:
    import os as _os

    return _os.getpid()


def _slow_sum(data: list, seconds: float) -> int:
    import time as _t

    _t.sleep(seconds)
    return sum(data)


def test_a_killed_worker_s_task_and_the_data_it_held_are_recomputed():
    """SIGKILL the worker running a task (which also holds the graph's data node): the task is
    run again elsewhere and its result arrives — data must be recomputable, not scattered."""
    import os
    import signal

    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=50)
    c = distributed.Client(cluster)
    try:
        c.wait_for_workers(2)
        pids = c.run(_pid)
        dsk = {"data": [1, 2, 3], "slow": (_slow_sum, "data", 3.0), "after": (_add, "slow", 10)}
        killed = []

        def killer():
            deadline = time.time() + 20
            while time.time() < deadline and not killed:
                for addr, keys in c.processing().items():
                    if "slow" in {str(k) for k in keys}:
                        time.sleep(0.5)
                        os.kill(pids[addr], signal.SIGKILL)
                        killed.append(addr)
                        return
                time.sleep(0.05)

        th = threading.Thread(target=killer, daemon=True)
        th.start()
        got = {}
        dispatch(c, dsk, ["after"], lambda k, r: got.__setitem__(k, r))
        th.join(5)
        assert killed, "the task finished before it could be killed"
        assert got == {"after": 16}
    finally:
        c.close()
        cluster.close()
