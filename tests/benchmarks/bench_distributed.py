"""Schedules, sweeps and crowds on Dask: speedups, identity, a killed worker, re-runs after an edit.

Run:  python tests/benchmarks/bench_distributed.py [--quick] [--workdir DIR]

What it does (every run in a fresh temporary folder, step store empty unless said):

1. **Sweep**: 8 variants of ``walk`` (``characters[0].start.heading`` = 0, 0.01, …, 0.07 rad)
   with ``compose sweep`` one after another in this process (``serial_s``) and as Dask
   tasks on a ``LocalCluster`` of 2 worker processes (``dask_s``), no step store;
   ``speedup = serial_s / dask_s``.
2. **Crowd**: ``crowd`` (6 couples, 36 steps) on a LocalCluster of 1 and of 2 workers,
   no step store for the 1-worker run; ``crowd_speedup`` = 1-worker / 2-worker wall time.
3. **Worker killed mid-step**: ``walk`` on an external LocalCluster of 2 workers; as soon
   as a step task runs, its worker process gets SIGKILL; Dask reschedules the task.
   ``worker_kill_recovered`` = 1 when the run finishes with the same step and report
   numbers as sweep variant 0 (the same scene).
4. **Edit, re-run**: couple 3's target in ``crowd`` moved by 10 cm; the edited scene
   re-run on 1 worker with the step store the 2-worker crowd run filled (only couple 3's
   6 steps are solved), over a fresh 1-worker run of the edited scene with an empty
   store: ``edit_rerun_fraction``; the two must give the same numbers.  (With 2 workers the
   fraction is higher — couple 3's 6 steps form one chain — and is printed as well.)

``identical`` = 1 when the serial and Dask sweeps give byte-identical stages and the same
report numbers per variant, the 1- and 2-worker crowd runs the same numbers and stage,
and the edited re-run equals the fresh run.  ``--quick`` caps IPOPT at 8 iterations per
subproblem (COMPOSE_MAX_ITER) in the walk parts (sweep, killed worker) only: the same graph
and work split, much less solve time.  The crowd parts always run uncapped (measured: capped
at 8 iterations, a coupled full step ends with its footsteps violated and the run stops).
A part that fails (a ComposeError) is reported on stderr; its figures print as nan and its
flags as 0, and the last line is still printed.

The last line is exactly
``sweep_n=<int> serial_s=<float> dask_s=<float> speedup=<float> crowd_speedup=<float> identical=<0|1> worker_kill_recovered=<0|1> edit_rerun_fraction=<float>``
"""
from __future__ import annotations

import argparse
import io
import json
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

SWEEP_N = 8


def numbers(rep: dict) -> list:
    """What must not depend on the scheduler: per step status/iterations/energy/violations,
    per character energy and audit figures, every goal and coupling measure."""
    return ([(s["id"], s["status"], s["iterations"], s["energy"], s["violations"]) for s in rep["steps"]]
            + [(w, c["energy"], c["audit"]) for w, c in sorted(rep["characters"].items())]
            + [(n, g["measured"]) for n, g in sorted({**rep["goals"], **rep["couplings"]}.items())])


def run(name: str, work: Path, tag: str, log, **kw) -> tuple[float, dict, bytes]:
    from schedules.cli.run import run_scenario

    out = work / f"{tag}.usda"
    t0 = time.perf_counter()
    rep = run_scenario(name, out=str(out), run_dir=str(work / f"run_{tag}"), log=log, **kw)
    return time.perf_counter() - t0, rep, out.read_bytes()


def sweep(work: Path, tag: str, log, **kw) -> tuple[float, list]:
    from schedules.cli.sweep import run_sweep

    out = work / tag
    t0 = time.perf_counter()
    run_sweep("walk", [f"characters[0].start.heading=0:0.07:0.01"], str(out), contact_sheet=False, log=log, **kw)
    dt = time.perf_counter() - t0
    got = []
    for i in range(SWEEP_N):
        v = out / f"v{i:03d}"
        rep = json.loads((v / "report.json").read_text())
        stage = (v / "stage.usda").read_text()
        stage = re.sub(r'"[^"]*v00\d/scenario.yaml"', '"<variant file>"', stage)  # the only path in it
        got.append((numbers(rep), stage))
    return dt, got


def kill_run(work: Path, log) -> tuple[bool, dict | None]:
    """walk on an external 2-worker LocalCluster; SIGKILL the worker of the first step task."""
    import dask
    from distributed import Client, LocalCluster

    dask.config.set({"distributed.nanny.pre-spawn-environ": {}})
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=40)
    watcher = Client(cluster)
    killed: list = []
    stop = threading.Event()

    def killer():
        while not stop.is_set() and not killed:
            for addr, keys in watcher.processing().items():
                if any(str(k).startswith("step:") for k in keys):
                    time.sleep(1.0)  # mid-step: IPOPT is running
                    pid = watcher.run(os.getpid, workers=[addr]).get(addr)
                    if pid:
                        os.kill(pid, signal.SIGKILL)
                        killed.append((addr, pid))
                        print(f"bench: killed worker {addr} (pid {pid}) while it ran a step", file=sys.stderr)
                    return
            time.sleep(0.2)

    th = threading.Thread(target=killer, daemon=True)
    th.start()
    try:
        _, rep, _ = run("walk", work, "killed", log, scheduler=cluster.scheduler_address, store="")
    finally:
        stop.set()
        th.join(timeout=5)
        watcher.close()
        cluster.close()
    return bool(killed), rep


def edited_crowd(work: Path) -> Path:
    from scenarios.bundled import find_scenario

    text = Path(find_scenario("crowd")).read_text()
    new = text.replace("dx: [1.1, 1.2, 1.15, 1.1, 1.2, 1.15]", "dx: [1.1, 1.2, 1.25, 1.1, 1.2, 1.15]")
    assert new != text, "crowd.yaml changed: update the edit in the benchmark"
    p = work / "crowd_edited.yaml"
    p.write_text(new)
    return p


def main() -> int:
    from scenarios.errors import ComposeError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="cap IPOPT at 8 iterations per subproblem")
    ap.add_argument("--workdir", help="keep the runs here (default: a temporary folder, removed)")
    args = ap.parse_args()
    cap = {"COMPOSE_MAX_ITER": "8"} if args.quick else {}
    work = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="bench_distributed_"))
    work.mkdir(parents=True, exist_ok=True)
    log = io.StringIO()
    nan = float("nan")
    serial_s = dask_s = t1 = t2 = frac = nan
    ident, kill_ok = False, False
    try:
        os.environ.update(cap)
        serial_s, serial = sweep(work, "sweep_serial", log)
        print(f"bench: sweep of {SWEEP_N} walk variants one after another: {serial_s:.1f} s", file=sys.stderr)
        dask_s, dasked = sweep(work, "sweep_dask", log, scheduler="local", jobs=2, store="")
        print(f"bench: the same sweep on a LocalCluster of 2 workers: {dask_s:.1f} s", file=sys.stderr)
        ident = serial == dasked
        recovered, krep = kill_run(work, log)
        kill_ok = recovered and krep is not None and numbers(krep) == serial[0][0]
        print(f"bench: worker killed mid-step: {'recovered, same numbers' if kill_ok else 'NOT recovered'}",
              file=sys.stderr)
        for k in cap:
            os.environ.pop(k, None)

        t1, rep1, st1 = run("crowd", work, "crowd1", log, scheduler="local", jobs=1, store="")
        print(f"bench: crowd on 1 worker: {t1:.1f} s", file=sys.stderr)
        store = work / "store"
        t2, rep2, st2 = run("crowd", work, "crowd2", log, scheduler="local", jobs=2, store=str(store))
        print(f"bench: crowd on 2 workers: {t2:.1f} s", file=sys.stderr)
        ident = ident and numbers(rep1) == numbers(rep2) and st1 == st2

        edited = edited_crowd(work)
        shutil.copytree(store, work / "store_copy")
        te, repe, ste = run(str(edited), work, "edit_rerun", log, scheduler="local", jobs=1, store=str(store))
        tf, repf, stf = run(str(edited), work, "edit_fresh", log, scheduler="local", jobs=1, store="")
        te2, _, _ = run(str(edited), work, "edit_rerun2", log, scheduler="local", jobs=2,
                        store=str(work / "store_copy"))
        same_edit = numbers(repe) == numbers(repf) and ste == stf
        ident = ident and same_edit
        frac = te / tf
        print(f"bench: edited crowd: re-run {te:.1f} s (1 worker, step store), fresh {tf:.1f} s; 2-worker re-run "
              f"{te2:.1f} s (fraction {te2 / tf:.3f}); results equal: {same_edit}", file=sys.stderr)
    except ComposeError as exc:
        ident = False
        print(f"bench: a part failed, the rest is not measured: {exc}", file=sys.stderr)
    finally:
        if not args.workdir:
            shutil.rmtree(work, ignore_errors=True)
    print(f"sweep_n={SWEEP_N} serial_s={serial_s:.2f} dask_s={dask_s:.2f} speedup={serial_s / dask_s:.3f} "
          f"crowd_speedup={t1 / t2:.3f} identical={int(ident)} worker_kill_recovered={int(kill_ok)} "
          f"edit_rerun_fraction={frac:.3f}")

    return 0


if __name__ == "__main__":
    sys.exit(main())
