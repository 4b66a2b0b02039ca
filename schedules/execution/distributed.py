"""Running a schedule on Dask: ``compose run FILE --scheduler local|processes|sync|ADDRESS``.

Schedulers (``--jobs N``: the number of local worker processes):

* ``local``: an embedded ``distributed.LocalCluster`` of N worker processes with one thread
  each (IPOPT runs in worker processes, never in threads); its dashboard is not started.
* ``processes``: Dask's multiprocessing scheduler (N processes, no ``distributed`` cluster).
* ``sync``: Dask's synchronous scheduler in this process (debugging; no parallelism).
* ``tcp://host:8786`` (any ``distributed`` address): a running Dask scheduler, e.g. one
  started by dask-jobqueue on SLURM or by the Dask Kubernetes operator (docs/distributed.md).
  Its workers must import this compose version, see the scenario's style files and — for
  the step store to help — share the store folder.  For results equal to the last digit,
  give workers the driver's BLAS thread settings (``OMP_NUM_THREADS`` etc.): the local
  cluster's workers inherit this process's environment for that reason.  An unreachable scheduler is an
  :class:`~scenarios.errors.InputError` (exit 2) raised before anything is written.

The schedule becomes a Dask task graph (:mod:`schedules.execution.graph_tasks`); on a
``distributed`` cluster the driver (this process) hands it over one free worker thread at a
time (:mod:`schedules.execution.dispatch`: Dask cannot estimate how long a compose task
runs and would otherwise place them all up front), collects results as tasks finish
(``as_completed`` on a cluster, scheduler callbacks otherwise), prints the progress and ETA lines of the
plain executor, writes each result to the run folder as a checkpoint (same files and
names: ``--resume`` works across schedulers), and assembles the final Scene by applying
every result in the schedule's order.  A worker that dies mid-step loses its task; the
Dask scheduler runs it again elsewhere (``distributed``'s ``allowed-failures``), and the
result is the same because the task's inputs are explicit data.
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from scenarios.errors import InputError, Location

from schedules.execution.checkpoints import RunLock, write_checkpoint
from schedules.execution.dispatch import dispatch
from schedules.execution.executor import (RunResult, StepFailed, _fmt_s, _record, _resumed, _resumed_step, kept_warning,
                                         prepare_run_dir)
from schedules.execution.graph_tasks import apply_results, presolve_task_key, schedule_graph, step_task_key
from schedules.plan.step import Schedule

__all__ = ["DaskScheduler", "connect", "run_schedule_dask", "SCHEDULERS", "CONNECT_TIMEOUT_S"]

SCHEDULERS = ("local", "processes", "sync")
CONNECT_TIMEOUT_S = 10.0


@dataclass
class DaskScheduler:
    """Where tasks run: a ``distributed`` client, or a local Dask scheduler's ``get``."""

    spec: str
    jobs: int
    client: object = None
    cluster: object = None
    _closed: bool = field(default=False, repr=False)

    @property
    def workers(self) -> int:
        if self.client is not None:
            return len(self.client.scheduler_info(n_workers=-1).get("workers", {})) or self.jobs
        return 1 if self.spec == "sync" else self.jobs

    def describe(self) -> str:
        if self.spec == "local":
            return f"Dask LocalCluster, {self.jobs} worker process(es)"
        if self.spec in ("processes", "sync"):
            return f"Dask {self.spec} scheduler" + (f", {self.jobs} process(es)" if self.spec == "processes" else "")
        return f"Dask scheduler {self.spec}, {self.workers} worker(s)"

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> DaskScheduler:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- execution ------------------------------------------------------------------------------
    def execute(self, dsk: dict, keys: list[str], on_done) -> None:
        """Run ``dsk`` for ``keys``; ``on_done(key, result)`` is called in this process as
        each key finishes (completion order).  Exceptions of ``on_done`` stop the run."""
        if self.client is not None:
            dispatch(self.client, dsk, keys, on_done)  # one task per free worker thread (see dispatch)
            return
        import dask
        from dask.callbacks import Callback

        wanted = set(keys)
        errors: list[BaseException] = []

        class _Progress(Callback):
            def _posttask(self, key, result, dsk_, state, worker_id):
                if key in wanted and not errors:
                    try:
                        on_done(key, result)
                    except BaseException as exc:  # re-raised after the scheduler returns
                        errors.append(exc)
                        raise

        with _Progress():
            try:
                if self.spec == "sync":
                    dask.get(dsk, keys)
                else:
                    import dask.multiprocessing

                    # chunksize 1: dask.multiprocessing batches 6 ready tasks per submission by
                    # default, so a worker got 3 of the crowd's 6 ready steps at once and their
                    # results (progress lines, dependents) arrived together when the last finished
                    dask.multiprocessing.get(dsk, keys, num_workers=self.jobs, chunksize=1)
            except BaseException:
                if errors:
                    raise errors[0] from None
                raise
        if errors:
            raise errors[0]


def connect(spec: str, jobs: int = 1) -> DaskScheduler:
    """Open the scheduler named by ``--scheduler`` (see the module docstring).

    Raises InputError (exit 2) for an unknown name or an unreachable address."""
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    if spec in ("processes", "sync"):
        return DaskScheduler(spec, jobs)
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - distributed is a dependency
        raise InputError(f"--scheduler {spec}: dask.distributed is not installed ({exc}); "
                         "install compose-motion with its dependencies") from None
    if spec == "local":
        # workers inherit this process's environment: distributed's nanny would otherwise set
        # OMP/MKL/OPENBLAS_NUM_THREADS=1 in them, which changes BLAS summation order and the
        # results in their last digits (1e-12) against the plain executor and `processes`
        import dask

        dask.config.set({"distributed.nanny.pre-spawn-environ": {}})
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=50)  # task errors arrive through the futures; the close-time heartbeat noise does not
        return DaskScheduler(spec, jobs, Client(cluster), cluster)
    if "://" not in spec:
        raise InputError(f"{spec!r}: expected local, processes, sync or a Dask scheduler address "
                         "such as tcp://host:8786", Location(None, field="--scheduler"))
    try:
        client = Client(spec, timeout=f"{CONNECT_TIMEOUT_S}s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"{spec}: cannot reach the Dask scheduler within {CONNECT_TIMEOUT_S:g} s "
                         f"({type(exc).__name__}: {exc}); nothing was written. Start one with "
                         "`dask scheduler` (see docs/distributed.md) or use --scheduler local",
                         Location(None, field="--scheduler")) from None
    return DaskScheduler(spec, jobs, client)


def run_schedule_dask(scene, schedule: Schedule, sched: DaskScheduler, *, run_dir: str | os.PathLike,
                      fingerprint: str, resume: bool = False, fail_capped: bool = False,
                      store: str | os.PathLike | None = None, log=sys.stderr) -> RunResult:
    """Run every Step of ``schedule`` over ``scene`` on ``sched``; same contract and run-folder
    files as :func:`schedules.execution.executor.run_schedule` (see the module docstring)."""
    run_dir = Path(run_dir)
    with RunLock(run_dir):
        return _run(scene, schedule, sched, run_dir, fingerprint, resume, fail_capped, store, log)


def _run(scene, schedule, sched, run_dir, fingerprint, resume, fail_capped, store, log) -> RunResult:
    manifest, old = prepare_run_dir(run_dir, fingerprint, resume)
    order = schedule.order()
    index = {s.id: i for i, s in enumerate(order)}
    n = len(order)
    chars = sorted({w for s in order for w in s.characters})
    given: dict[str, dict] = {}
    for who in chars:
        d = _resumed(old, run_dir, f"000_{who}", log)
        if d is not None:
            if d.get("fingerprint") != fingerprint or d.get("step") != f"presolve:{who}":
                raise InputError(f"--resume: checkpoint of the pre-solve of {who!r} does not belong to this run",
                                 Location(str(run_dir / "steps" / f"000_{who}.json")))
            given[presolve_task_key(who)] = d
    for s in order:
        d = _resumed_step(old, run_dir, index[s.id] + 1, s.id, fingerprint, log)
        if d is not None:
            given[step_task_key(s.id)] = d
    dsk = schedule_graph(scene, schedule, store=str(store) if store else None, fail_capped=fail_capped,
                         given=given)
    pre_keys = [presolve_task_key(w) for w in chars]
    step_keys = [step_task_key(s.id) for s in order]
    by_key = {step_task_key(s.id): s for s in order}
    results: dict[str, dict] = {}
    t_start = time.perf_counter()
    counts = {"done": 0, "new": 0, "stored": 0}
    resumed = sum(1 for k in step_keys if k in given)
    print(f"compose: {sched.describe()}: {n} steps, {len(pre_keys)} pre-solve(s)"
          + (f", {resumed} step(s) resumed" if resumed else "")
          + (f", step store {store}" if store else ""), file=log, flush=True)

    def on_done(key: str, d: dict) -> None:
        results[key] = d
        if key in given:
            if key in by_key:
                counts["done"] += 1
                s = by_key[key]
                print(f"[{index[s.id] + 1}/{n}] {s.id}: resumed from {run_dir / 'steps'}/{index[s.id] + 1:03d}.json",
                      file=log, flush=True)
            else:
                print(f"[0/{n}] presolve {key.split(':', 1)[1]}: {d['status']}, {d['iterations']} it, "
                      f"{d['seconds']:.1f} s (resumed)", file=log, flush=True)
            return
        stored = " (from the step store)" if d.get("stored") else ""
        if key not in by_key:  # a pre-solve
            who = key.split(":", 1)[1]
            d["fingerprint"] = fingerprint
            write_checkpoint(manifest, f"000_{who}", d)
            print(f"[0/{n}] presolve {who}: {d['status']}, {d['iterations']} it, {d['seconds']:.1f} s{stored}",
                  file=log, flush=True)
            return
        s = by_key[key]
        if d.get("skipped"):
            return
        if d.get("failed"):
            raise StepFailed(f"{d['failed']}; finished steps are kept in {run_dir}")
        d["fingerprint"] = fingerprint
        write_checkpoint(manifest, f"{index[s.id] + 1:03d}", d)
        counts["done"] += 1
        counts["new"] += 1
        counts["stored"] += bool(stored)
        rec = _record(index[s.id], s, d)
        elapsed = time.perf_counter() - t_start
        eta = elapsed / max(1, counts["new"]) * (n - counts["done"])  # wall time per finished step so far
        print(f"[{index[s.id] + 1}/{n}] {s.id} (cycle {s.cycle}, {s.kind}): {rec.status}, "
              f"{rec.iterations} it, E={rec.energy:.4g}, {rec.seconds:.1f} s{stored}; "
              f"elapsed {_fmt_s(elapsed)}, ETA {_fmt_s(eta)}", file=log, flush=True)
        if d.get("capped"):
            print(kept_warning(s.id, rec.status), file=log, flush=True)
        if d.get("discarded"):
            print(f"    {s.id}: timing result discarded ({d.get('discard_reason', '')})", file=log, flush=True)

    sched.execute(dsk, pre_keys + step_keys, on_done)
    for k in step_keys:  # a failure whose completion event came after a skipped descendant's
        if results[k].get("failed"):
            raise StepFailed(f"{results[k]['failed']}; finished steps are kept in {run_dir}")
    presolves = {k.split(":", 1)[1]: results[k] for k in pre_keys}
    final, contacts = apply_results(scene, presolves, [(s.kind, results[step_task_key(s.id)]) for s in order])
    records = [_record(index[s.id], s, results[step_task_key(s.id)]) for s in order]
    presolved = {w: {k: d[k] for k in ("status", "success", "iterations", "seconds", "violations")}
                 for w, d in presolves.items()}
    if counts["stored"]:
        print(f"compose: {counts['stored']} of {counts['new']} step(s) came from the step store (unchanged inputs)",
              file=log, flush=True)
    return RunResult(final, records, time.perf_counter() - t_start, contacts, resumed, presolved)
