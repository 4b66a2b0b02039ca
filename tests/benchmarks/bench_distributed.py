"""Schedules, sweeps and crowds on Dask: speedups, identity, a killed worker, re-runs after an edit.

Run:  python tests/benchmarks/bench_distributed.py [--quick] [--parts sweep,kill,crowd,edit]
                                                    [--workdir DIR] [--quiet]

Expected wall time (2 free cores, estimated from CPU seconds measured under load): about
35-40 min in full -- sweep ~8 min (8 + 4 walk solves of ~35 s), killed worker ~2 min, crowd on
2 workers ~5 min, edited crowd re-run ~2 min and fresh ~9 min, crowd on 1 worker ~9 min (the
crowd is ~480 CPU s of solving + ~25 s of output), plus ~1 min of warm-up per cluster;
``--quick`` saves ~4 min of the sweep.  On a loaded machine, several times that.  Progress: one ``bench [mm:ss]`` line per
phase and compose's own progress/ETA lines on stderr (``--quiet``: phase lines only); the
same lines go to ``DIR/bench.log`` when ``--workdir`` is given.

What it does (every run in a fresh folder, step stores empty unless said):

0. **Same conditions for both sides.**  ``OMP_NUM_THREADS`` (and the OpenBLAS/MKL
   equivalents) are set to 1 in this process before numpy loads; the benchmark's own
   ``LocalCluster`` workers are processes (one thread each) that inherit that environment
   (checked: pid of each worker ≠ this process's, ``OMP_NUM_THREADS=1`` in each).  Before
   any timing, this process *and every worker* solve each character and step kind of the
   scene once at one IPOPT iteration (``warm``): kernels compiled or loaded from the disk
   cache, symbolic functions built.  Cluster start and warm-up are reported, not timed.
1. **Sweep**: 8 variants of ``walk`` (``characters[0].start.heading`` = 0, 0.01, …, 0.07 rad)
   with ``compose sweep`` one after another in this process (``serial_s``) and as Dask tasks
   on a ``LocalCluster`` of 2 worker processes (``dask_s``); no step store on either side,
   so both solve every step of every variant with the same code (``run_variant``, plain
   executor): the same work.  ``speedup = serial_s / dask_s``.
2. **Worker killed mid-step**: ``walk`` on a LocalCluster of 2 workers; when the scheduler
   shows a step task processing on a worker, 2 s later (IPOPT running) that worker process
   gets SIGKILL.  ``worker_kill_recovered`` = 1 when the scheduler's story of that task shows
   it processing again after the kill and finishing, and the run's step and report numbers
   equal the serial sweep's variant 0 (the same scene; a plain run when the sweep is skipped).
3. **Crowd**: ``crowd`` (12 characters, 6 couples, 24 steps since round 14: no timing steps) on a LocalCluster of 2 and
   (after part 4) of 1 worker, each with its own empty step store (same hashing and writing
   on both sides); ``crowd_speedup`` = 1-worker / 2-worker wall time.
4. **Edit, re-run**: couple 3's target in ``crowd`` moved 10 cm; the edited scene re-run on
   1 worker with (a copy of) the store the 2-worker crowd run filled, over a fresh 1-worker
   run of the edited scene with an empty store: ``edit_rerun_fraction``; the two must give
   the same stage bytes and numbers, and the re-run must take 20 of 24 steps from the store.

``identical`` = 1 when the serial and Dask sweeps give byte-identical stages and the same
report numbers per variant, the 1- and 2-worker crowd runs the same numbers and stage bytes,
and the edited re-run equals the fresh run (for the parts run).  ``--quick`` caps IPOPT at
8 iterations per subproblem (COMPOSE_MAX_ITER) in the walk parts (sweep, killed worker): the
same graph and work split, less solve time.  The crowd parts always run uncapped.  A part
that fails prints its traceback on stderr; its figures print as nan and its flags as 0, and
the last line is still printed.

The last line is exactly
``sweep_n=<int> serial_s=<float> dask_s=<float> speedup=<float> crowd_speedup=<float> identical=<0|1> worker_kill_recovered=<0|1> edit_rerun_fraction=<float>``
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads
    os.environ[_v] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
# worker processes import this checkout too
os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])

SWEEP_N = 8  # variants: characters[0].start.heading = 0, 0.01, ... (SWEEP_N - 1) / 100 rad
PARTS = ("sweep", "kill", "crowd", "edit")
EDIT_FROM = "dx: [1.1, 1.2, 1.15, 1.1, 1.2, 1.15]"
EDIT_TO = "dx: [1.1, 1.2, 1.25, 1.1, 1.2, 1.15]"  # couple 3's targets 10 cm further
T0 = time.perf_counter()


class Out:
    """Where progress goes: stderr (unless quiet) and a log file (with --workdir)."""

    def __init__(self, quiet: bool, path: Path | None):
        self.quiet = quiet
        self.file = open(path, "a", encoding="utf-8") if path else None  # noqa: SIM115 - closed at exit

    def write(self, s: str) -> int:
        if not self.quiet:
            sys.stderr.write(s)
        if self.file:
            self.file.write(s)
        return len(s)

    def flush(self) -> None:
        sys.stderr.flush()
        if self.file:
            self.file.flush()

    def say(self, msg: str) -> None:
        m, s = divmod(int(time.perf_counter() - T0), 60)
        line = f"bench [{m:02d}:{s:02d}] {msg}\n"
        sys.stderr.write(line)
        sys.stderr.flush()
        if self.file:
            self.file.write(line)
            self.file.flush()


def numbers(rep: dict) -> list:
    """What must not depend on the scheduler: per step status/iterations/energy/violations,
    per character energy and audit figures, every goal and coupling measure."""
    return ([(s["id"], s["status"], s["iterations"], s["energy"], s["violations"]) for s in rep["steps"]]
            + [(w, c["energy"], c["audit"]) for w, c in sorted(rep["characters"].items())]
            + [(n, g["measured"]) for n, g in sorted({**rep["goals"], **rep["couplings"]}.items())])


# --- functions that also run in worker processes (cloudpickled by value from __main__) ---------


def worker_facts() -> tuple[int, str | None, int]:
    """(pid, OMP_NUM_THREADS, threads of this worker's task executor) of the calling process."""
    import os as _os
    import threading as _th

    return _os.getpid(), _os.environ.get("OMP_NUM_THREADS"), _th.active_count()


def worker_cpu() -> float:
    """CPU seconds (user + system) this process has used."""
    import time as _time

    return _time.process_time()


WARM_RUN = """
name: warm_up
duration: 0.6
characters:
  - {name: w, body: {preset: adult_male}, style: walk, start: {position: [-0.35, 0.0], heading: 0}}
goals:
  - type: footprints
    character: w
    steps:
      - {foot: r, position: [-0.70, -0.09], time: [0.00, 0.11]}
      - {foot: l, position: [0.00, 0.09], time: [0.00, 0.6]}
      - {foot: r, position: [0.70, -0.09], time: [0.55, 0.6]}
"""


def warm(scenario: str) -> float:
    """Warm this process for runs of ``scenario``: (1) once per process, a whole run (solve,
    audits, USD stage, stage audit, report) of a 0.6 s walk capped at 10 IPOPT iterations, so
    the output pipeline's imports and caches are loaded; (2) at one IPOPT iteration, the first
    step of each (characters, kind) of the schedule's first branch, after the pre-solve of its
    characters: kernels compiled or loaded, symbolic functions of every body built.  Seconds."""
    import io as _io
    import os as _os
    import tempfile as _tf
    import time as _time

    import networkx as nx

    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene
    from schedules.plan.compiler import compile_schedule
    from schedules.execution.executor import presolve_character, solve_step
    from schedules.execution.graph_tasks import apply_results

    from scenarios.errors import ComposeError
    from schedules.cli.run import run_scenario

    t0 = _time.perf_counter()
    old = _os.environ.get("COMPOSE_MAX_ITER")
    try:
        if not getattr(warm, "pipeline_done", False):
            _os.environ["COMPOSE_MAX_ITER"] = "10"
            with _tf.TemporaryDirectory(prefix="bench_warm_") as d:
                f = _os.path.join(d, "warm_up.yaml")
                with open(f, "w", encoding="utf-8") as fh:
                    fh.write(WARM_RUN)
                try:
                    run_scenario(f, out=_os.path.join(d, "w.usda"), run_dir=_os.path.join(d, "run"), log=_io.StringIO())
                except ComposeError:
                    pass  # a capped solve may fail its goals: only the code paths matter here
            warm.pipeline_done = True
        _os.environ["COMPOSE_MAX_ITER"] = "1"
        scn = load_scenario(scenario)
        schedule = compile_schedule(scn)
        scene = build_scene(scn)
        order = schedule.order()
        branch = nx.node_connected_component(schedule.graph.to_undirected(), order[0].id)
        steps = [s for s in order if s.id in branch]
        who = sorted({w for s in steps for w in (*s.characters, *s.observes)})
        scene, _ = apply_results(scene, {w: presolve_character(scene, w) for w in who}, [])
        seen = set()
        for s in steps:
            if (s.characters, s.kind) in seen:
                continue
            seen.add((s.characters, s.kind))
            scene, _ = apply_results(scene, {}, [(s.kind, solve_step(scene, s, ()))])
    finally:
        if old is None:
            _os.environ.pop("COMPOSE_MAX_ITER", None)
        else:
            _os.environ["COMPOSE_MAX_ITER"] = old
    return _time.perf_counter() - t0


# --- the driver ------------------------------------------------------------------------------------


@contextlib.contextmanager
def local_cluster(n: int, out: Out, warm_for: tuple[str, ...] = ()):
    """A LocalCluster of n worker processes (one thread each, this process's environment),
    checked and warmed; yields (cluster, client)."""
    import dask
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    dask.config.set({"distributed.nanny.pre-spawn-environ": {}})  # inherit OMP_NUM_THREADS=1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=50)
    client = Client(cluster)
    try:
        client.wait_for_workers(n)
        facts = client.run(worker_facts)
        pids = {a: f[0] for a, f in facts.items()}
        ok = (len(facts) == n and len(set(pids.values())) == n and os.getpid() not in pids.values()
              and all(f[1] == "1" for f in facts.values())
              and all(w["nthreads"] == 1 for w in client.scheduler_info(n_workers=-1)["workers"].values()))
        if not ok:
            raise RuntimeError(f"cluster workers are not {n} single-threaded processes with OMP_NUM_THREADS=1: "
                               f"{facts}")
        out.say(f"LocalCluster of {n} worker process(es) up in {time.perf_counter() - t0:.1f} s: pids "
                f"{sorted(pids.values())}, 1 thread each, OMP_NUM_THREADS=1")
        for name in warm_for:
            t1 = time.perf_counter()
            secs = client.run(warm, name)
            out.say(f"  workers warmed for {name} in {time.perf_counter() - t1:.1f} s "
                    f"({', '.join(f'{s:.1f}' for s in secs.values())} s each; not timed)")
        yield cluster, client, pids
    finally:
        client.close()
        cluster.close()


def run(name: str, work: Path, tag: str, log, **kw) -> tuple[float, dict, bytes]:
    from schedules.cli.run import run_scenario

    out = work / f"{tag}.usda"
    t0 = time.perf_counter()
    rep = run_scenario(name, out=str(out), run_dir=str(work / f"run_{tag}"), log=log, **kw)
    return time.perf_counter() - t0, rep, out.read_bytes()


def sweep(work: Path, tag: str, log, n: int, **kw) -> tuple[float, list]:
    from schedules.cli.sweep import run_sweep

    out = work / tag
    vary = f"characters[0].start.heading={','.join(str(i / 100) for i in range(n))}"
    t0 = time.perf_counter()
    run_sweep("walk", [vary], str(out), contact_sheet=False, store="", log=log, **kw)
    dt = time.perf_counter() - t0
    got = []
    for i in range(n):
        v = out / f"v{i:03d}"
        rep = json.loads((v / "report.json").read_text())
        stage = (v / "stage.usda").read_text()
        stage = re.sub(r'"[^"]*v\d{3}/scenario.yaml"', '"<variant file>"', stage)  # the only path in it
        got.append((numbers(rep), stage))
    return dt, got


def _task_story(dask_scheduler, key):  # runs in the scheduler
    ts = dask_scheduler.tasks.get(key)
    return ([(str(t[1]), str(t[2])) for t in dask_scheduler.story(key)],
            None if ts is None else ts.state,
            None if ts is None or ts.processing_on is None else ts.processing_on.address)


def kill_run(work: Path, log, out: Out) -> tuple[bool, dict | None]:
    """walk on a 2-worker LocalCluster; SIGKILL the worker processing the first step task."""
    killed: list = []
    stop = threading.Event()
    with local_cluster(2, out) as (cluster, watcher, pids):
        def killer():
            while not stop.is_set():
                for addr, keys in watcher.processing().items():
                    steps = [str(k) for k in keys if str(k).startswith("step:")]
                    if not steps:
                        continue
                    time.sleep(2.0)  # the task is deserialised and IPOPT runs
                    _, state, where = watcher.run_on_scheduler(_task_story, key=steps[0])
                    if state != "processing" or where != addr:
                        break  # finished meanwhile: wait for the next step
                    os.kill(pids[addr], signal.SIGKILL)
                    killed.append((addr, pids[addr], steps[0]))
                    out.say(f"killed worker {addr} (pid {pids[addr]}) while it processed {steps[0]}")
                    return
                time.sleep(0.2)

        th = threading.Thread(target=killer, daemon=True)
        th.start()
        try:
            _, rep, _ = run("walk", work, "killed", log, scheduler=cluster.scheduler_address, store="")
        finally:
            stop.set()
            th.join(timeout=10)
        if not killed:
            out.say("no step was killed (the run ended first)")
            return False, rep
        story, _, _ = watcher.run_on_scheduler(_task_story, key=killed[0][2])
        ends = [finish for _, finish in story]
        n_proc = ends.count("processing")
        last = len(ends) - 1 - ends[::-1].index("processing") if n_proc else len(ends)
        done = "memory" in ends[last:]
        out.say(f"scheduler's story of {killed[0][2]}: processing {n_proc} time(s), then "
                f"{'finished (memory)' if done else 'not finished'}; transitions {' > '.join(ends)}")
        return n_proc >= 2 and done, rep


def edited_crowd(work: Path) -> Path:
    from scenarios.bundled import find_scenario

    text = Path(find_scenario("crowd")).read_text()
    new = text.replace(EDIT_FROM, EDIT_TO)
    if new == text:
        raise RuntimeError("crowd.yaml changed: update EDIT_FROM/EDIT_TO in the benchmark")
    p = work / "crowd_edited.yaml"
    p.write_text(new)
    return p


class _Capture:
    """A log that also keeps its text (to read the step-store count of a run)."""

    def __init__(self, out: Out):
        self.out, self.parts = out, []

    def write(self, s):
        self.parts.append(s)
        return self.out.write(s)

    def flush(self):
        self.out.flush()

    def text(self):
        return "".join(self.parts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="cap IPOPT at 8 iterations per subproblem in the walk parts")
    ap.add_argument("--parts", default=",".join(PARTS), help=f"comma list of {', '.join(PARTS)} (default: all)")
    ap.add_argument("--workdir", help="keep the runs and bench.log here (default: a temporary folder, removed)")
    ap.add_argument("--quiet", action="store_true", help="phase lines only, not compose's progress lines")
    ap.add_argument("--sweep-n", type=int, default=SWEEP_N, metavar="N",
                    help=f"variants in the sweep (default {SWEEP_N}; fewer only to try the benchmark out)")
    args = ap.parse_args()
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    bad = [p for p in parts if p not in PARTS]
    if bad:
        ap.error(f"--parts: unknown {bad}; choose from {PARTS}")
    cap = {"COMPOSE_MAX_ITER": "8"} if args.quick else {}
    work = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="bench_distributed_"))
    work.mkdir(parents=True, exist_ok=True)
    out = Out(args.quiet, work / "bench.log" if args.workdir else None)
    nan = float("nan")
    serial_s = dask_s = t1 = t2 = frac = nan
    checks: dict[str, bool] = {}
    kill_ok = False
    serial = None
    try:
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else nan
        out.say(f"parts {parts}{' (quick: walk parts capped at 8 iterations)' if args.quick else ''}; "
                f"{os.cpu_count()} CPUs, load average {load:.1f}; work folder {work}")
        t = time.perf_counter()
        for name in (["walk"] if {"sweep", "kill"} & set(parts) else []) + \
                    (["crowd"] if {"crowd", "edit"} & set(parts) else []):
            out.say(f"warming this process for {name} ({warm(name):.1f} s; not timed)")
        out.say(f"warm-up done in {time.perf_counter() - t:.1f} s")

        os.environ.update(cap)
        try:
            if "sweep" in parts:
                try:
                    out.say(f"sweep of {args.sweep_n} walk variants one after another in this process ...")
                    c0 = time.process_time()
                    serial_s, serial = sweep(work, "sweep_serial", out, args.sweep_n)
                    cpu_s = time.process_time() - c0
                    out.say(f"sweep one after another: {serial_s:.1f} s wall, {cpu_s:.1f} CPU s "
                            f"({cpu_s / serial_s:.2f} cores busy)")
                    with local_cluster(2, out, ("walk",)) as (cluster, client, _):
                        out.say("the same sweep on the LocalCluster of 2 workers ...")
                        w0, c0 = client.run(worker_cpu), time.process_time()
                        dask_s, dasked = sweep(work, "sweep_dask", out, args.sweep_n,
                                               scheduler=cluster.scheduler_address)
                        cpu_d = sum(client.run(worker_cpu).values()) - sum(w0.values())
                        cpu_drv = time.process_time() - c0
                    out.say(f"sweep on 2 workers: {dask_s:.1f} s wall, workers {cpu_d:.1f} CPU s + driver "
                            f"{cpu_drv:.1f} CPU s ({cpu_d / dask_s:.2f} of 2 cores busy); speedup "
                            f"{serial_s / dask_s:.3f}; CPU-time ratio serial/Dask {cpu_s / (cpu_d + cpu_drv):.3f} "
                            "(1 = the same work; on 2 free cores the speedup approaches 2 x that)")
                    it_s = sum(s[2] for n, _ in serial for s in n if isinstance(s, tuple) and len(s) == 5)
                    it_d = sum(s[2] for n, _ in dasked for s in n if isinstance(s, tuple) and len(s) == 5)
                    checks["sweep"] = serial == dasked
                    out.say(f"same work: Σ IPOPT iterations of the step solves {it_s} (serial) / {it_d} (Dask); "
                            f"stages and numbers identical: {checks['sweep']}")
                except Exception:
                    checks["sweep"] = False
                    out.say("sweep part failed:\n" + traceback.format_exc())
            if "kill" in parts:
                try:
                    ref = serial[0][0] if serial else None
                    if ref is None:
                        out.say("reference run of walk (plain executor) for the killed-worker part ...")
                        ref = numbers(run("walk", work, "kill_ref", out)[1])
                    out.say("walk on 2 workers, one killed mid-step ...")
                    recovered, krep = kill_run(work, out, out)
                    same = krep is not None and numbers(krep) == ref
                    kill_ok = recovered and same
                    out.say(f"worker killed mid-step: task re-run {recovered}, same numbers as the reference {same}")
                except Exception:
                    out.say("killed-worker part failed:\n" + traceback.format_exc())
        finally:
            for k in cap:
                os.environ.pop(k, None)

        # order: the 2-worker crowd first (it fills the store the edit re-run uses), then the
        # edit part, then the 1-worker crowd, so a long run shows the cheaper results first
        store2 = work / "store_crowd2"
        crowd2 = None
        if {"crowd", "edit"} & set(parts):
            try:
                with local_cluster(2, out, ("crowd",)) as (cluster, client, _):
                    out.say("crowd on 2 workers (its step store is the edit part's) ...")
                    w0 = client.run(worker_cpu)
                    t2_, rep2, st2 = run("crowd", work, "crowd2", out, scheduler=cluster.scheduler_address,
                                         store=str(store2))
                    cpu2 = sum(client.run(worker_cpu).values()) - sum(w0.values())
                crowd2 = (rep2, st2, cpu2)
                if "crowd" in parts:
                    t2 = t2_
                out.say(f"crowd on 2 workers: {t2_:.1f} s wall, workers {cpu2:.1f} CPU s ({cpu2 / t2_:.2f} of 2 cores "
                        f"busy); passes: {rep2['passes']}")
            except Exception:
                checks["crowd"] = False
                out.say("crowd on 2 workers failed:\n" + traceback.format_exc())
        if "edit" in parts and crowd2 is not None:
            try:
                edited = edited_crowd(work)
                with local_cluster(1, out, ("crowd",)) as (cluster, _, _):
                    addr = cluster.scheduler_address
                    shutil.copytree(store2, work / "store_edit")
                    cap_log = _Capture(out)
                    out.say("edited crowd (couple 3's targets +10 cm) re-run on 1 worker with the crowd's step store ...")
                    te, repe, ste = run(str(edited), work, "edit_rerun", cap_log, scheduler=addr,
                                        store=str(work / "store_edit"))
                    m = re.search(r"(\d+) of (\d+) step\(s\) came from the step store", cap_log.text())
                    reused = f"{m.group(1)} of {m.group(2)}" if m else "0"
                    out.say(f"re-run: {te:.1f} s, {reused} step(s) from the store")
                    out.say("edited crowd, fresh run on 1 worker (empty store) ...")
                    tf, repf, stf = run(str(edited), work, "edit_fresh", out, scheduler=addr,
                                        store=str(work / "store_edit_fresh"))
                same = numbers(repe) == numbers(repf) and ste == stf
                checks["edit"] = same and reused == "20 of 24"
                frac = te / tf
                out.say(f"edited crowd: re-run {te:.1f} s, fresh {tf:.1f} s: fraction {frac:.3f}; "
                        f"re-run equals fresh run (numbers, stage bytes): {same}; steps from the store: {reused} "
                        "(expected 20 of 24)")
            except Exception:
                checks["edit"] = False
                out.say("edit part failed:\n" + traceback.format_exc())
        if "crowd" in parts and crowd2 is not None:
            try:
                rep2, st2, cpu2 = crowd2
                with local_cluster(1, out, ("crowd",)) as (cluster, client, _):
                    out.say("crowd on 1 worker ...")
                    w0 = client.run(worker_cpu)
                    t1, rep1, st1 = run("crowd", work, "crowd1", out, scheduler=cluster.scheduler_address,
                                        store=str(work / "store_crowd1"))
                    cpu1 = sum(client.run(worker_cpu).values()) - sum(w0.values())
                checks["crowd"] = numbers(rep1) == numbers(rep2) and st1 == st2
                out.say(f"crowd on 1 worker: {t1:.1f} s wall, worker {cpu1:.1f} CPU s; crowd_speedup {t1 / t2:.3f}; "
                        f"CPU-time ratio 1/2 workers {cpu1 / cpu2:.3f} (1 = the same work); 1- and 2-worker "
                        f"results identical (numbers, stage bytes): {checks['crowd']}")
            except Exception:
                checks["crowd"] = False
                out.say("crowd on 1 worker failed:\n" + traceback.format_exc())
    finally:
        ident = bool(checks) and all(checks.values())
        out.say(f"checks {checks}; total {time.perf_counter() - T0:.0f} s")
        if not args.workdir:
            shutil.rmtree(work, ignore_errors=True)
        print(f"sweep_n={args.sweep_n} serial_s={serial_s:.2f} dask_s={dask_s:.2f} speedup={serial_s / dask_s:.3f} "
              f"crowd_speedup={t1 / t2:.3f} identical={int(ident)} worker_kill_recovered={int(kill_ok)} "
              f"edit_rerun_fraction={frac:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
