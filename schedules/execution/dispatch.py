"""Handing a task graph to a Dask cluster one free worker slot at a time.

Why not ``client.get(dsk, keys)``: Dask places every ready task on a worker when it is
submitted, using an estimate of its duration.  A compose task (a Step, a sweep variant)
runs for seconds to minutes, but each has its own key prefix, so Dask knows no duration
for it and estimates half a second (``distributed.scheduler.unknown-task-duration``): an
8-variant sweep on 2 workers was placed 4 + 4 up front, and work stealing, which also
reasons from those estimates, moved nothing.  Measured (2026-12-02, ``walk`` × 8 headings,
LocalCluster of 2): one worker stood idle for 75 s and 56 s while the other still held
queued variants — 19 % of the run.

:func:`dispatch` keeps that decision here: a task is submitted only when its dependencies
have finished **and** a worker thread is free, in a fixed priority order (the order of
``keys``, then the graph's), so the next task always goes to the first worker that frees
up — greedy list scheduling, the same order on every run.  Dask still places, runs,
transfers and recovers: a task lost with a killed worker is resubmitted by Dask's
scheduler from its futures, and the dispatcher's count of busy slots follows the
cluster's current number of worker threads (an elastic cluster grows or shrinks it).

Graph form: Dask's classic dict — ``key → (callable, *args)`` is a task, any other value
is data.  An argument that equals a key, or a list whose items are keys, refers to that
key's result (as in Dask's own graphs; tuples that are not tasks are passed as they are).
"""
from __future__ import annotations

from collections.abc import Callable, Hashable

__all__ = ["is_task", "task_dependencies", "priority_order", "dispatch"]


def is_task(value) -> bool:
    """A graph value that is a task ``(callable, *args)``."""
    return isinstance(value, tuple) and bool(value) and callable(value[0])


def _refs(arg, keys) -> list:
    if isinstance(arg, list):
        return [k for a in arg for k in _refs(a, keys)]
    if isinstance(arg, Hashable) and not isinstance(arg, tuple) and arg in keys:
        return [arg]
    return []


def task_dependencies(dsk: dict) -> dict:
    """key → the set of keys its task reads (empty for data)."""
    keys = set(dsk)
    return {k: ({d for a in v[1:] for d in _refs(a, keys)} if is_task(v) else set()) for k, v in dsk.items()}


def priority_order(dsk: dict, keys: list) -> list:
    """Every key needed for ``keys``: ``keys`` in their order, each preceded by what it needs
    (depth first, in argument order); keys that nothing wanted needs are dropped."""
    pos = {k: i for i, k in enumerate(dsk)}
    deps = {k: sorted(d, key=pos.__getitem__) for k, d in task_dependencies(dsk).items()}
    out, seen = [], set()

    def visit(k) -> None:
        stack = [(k, iter(deps[k]))]
        while stack:
            node, it = stack[-1]
            nxt = next((d for d in it if d not in seen), None)
            if nxt is not None:
                seen.add(nxt)
                stack.append((nxt, iter(deps[nxt])))
                continue
            stack.pop()
            out.append(node)

    for k in keys:
        if k not in seen:
            seen.add(k)
            visit(k)
    return out


def _value(x):
    return x


def _slots(client) -> int:
    workers = client.scheduler_info(n_workers=-1).get("workers", {})
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


def dispatch(client, dsk: dict, keys: list, on_done: Callable[[Hashable, object], None]) -> None:
    """Run ``dsk`` for ``keys`` on ``client`` (a ``distributed.Client``), submitting a task when
    its dependencies are done and a worker thread is free; ``on_done(key, result)`` is called
    in this process for each of ``keys`` as it finishes.  A task's exception (or one of
    ``on_done``) cancels what is still running and propagates."""
    from distributed import as_completed

    order = priority_order(dsk, keys)
    deps = task_dependencies(dsk)
    wanted = set(keys)
    futures: dict = {}  # key -> future of its task (data nodes too)
    waiting = [k for k in order if is_task(dsk[k])]
    for k in order:
        if not is_task(dsk[k]):  # data as a task that returns it: the scheduler can recompute it when the
            # worker holding it dies (scattered data would be lost, and every task reading it cancelled)
            futures[k] = client.submit(_value, dsk[k], key=k, pure=False)
    done = {k for k in futures}
    readers = dict.fromkeys(order, 0)  # tasks still to read k's result
    for t in waiting:
        for d in deps[t]:
            readers[d] += 1
    running = as_completed()
    by_future: dict = {}

    def arg(a):
        if isinstance(a, list):
            return [arg(x) for x in a]
        if isinstance(a, Hashable) and not isinstance(a, tuple) and a in futures:
            return futures[a]
        return a

    def submit_ready() -> None:
        free = _slots(client) - running.count()
        for k in list(waiting):
            if free <= 0:
                break
            if deps[k] <= done:
                fn, *args = dsk[k]
                fut = client.submit(fn, *[arg(a) for a in args], key=k, pure=False)
                futures[k], by_future[fut] = fut, k
                running.add(fut)
                waiting.remove(k)
                free -= 1

    try:
        submit_ready()
        while running.count() or waiting:
            if not running.count():  # nothing runs and nothing is ready: a broken graph
                raise RuntimeError(f"tasks {waiting[:3]} wait for keys that no task produces")
            fut = next(running)
            k = by_future.pop(fut)
            result = fut.result()
            done.add(k)
            if k in wanted:
                on_done(k, result)
            for d in deps[k]:
                readers[d] -= 1
                if readers[d] == 0 and d not in wanted:
                    futures.pop(d, None)  # its data is no longer needed on the cluster
            submit_ready()
    finally:
        pending = [f for f in futures.values() if hasattr(f, "done") and not f.done()]
        if pending:
            client.cancel(pending)
