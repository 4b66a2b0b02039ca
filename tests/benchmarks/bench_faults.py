"""Benchmark: runs that survive SIGKILL, and the run lock (issue #17).

    python tests/benchmarks/bench_faults.py [--scenario walk] [--kills 20] [--seed 0]
                                            [--lock-tries 3] [--keep DIR]

1. Runs ``compose run SCENARIO`` once uninterrupted (the reference; ``walk`` takes about a
   minute) and notes when each step and the export (audit, stage, report, plots) happen.
2. ``--kills K`` times: starts the same run in a fresh folder and kills its process group
   with SIGKILL at a random moment — stratified over the reference run's duration, and
   ``ceil(K/5)`` of them inside the export phase (a random fraction of the export's length
   after the last step's line).
   After each kill every file at a final path (stage, report, plots, manifest, checkpoints)
   is checked: it is absent or complete (the stage opens and has every frame, JSON parses,
   a PNG ends with its IEND chunk, a checkpoint's arrays load without pickle, every committed
   checkpoint matches its SHA-256); a file that is not is *half-written*.  Then
   ``compose run … --resume`` finishes the run and its stage's joint world transforms
   (UsdSkel, every joint, every frame) are compared with the reference's: identical to
   1e-9 counts as *resumed identical*.  A kill moment is a fraction of the run's length,
   estimated from the latest run (load changes it); a run that ended before its moment is
   not a kill (counted in ``missed``) and the same fraction is tried again, up to 3 times.
3. ``--lock-tries N``: while a run holds its folder, N more ``compose run`` on that folder
   are started; each must be refused (exit 2, "in use", the holder's PID).  The holder is
   then SIGKILLed and the stale lock must be taken over at once.

Last line, exactly:
kills=<int> resumed_identical=<int> half_written=<int> lock_conflicts_refused=<int>
"""
from __future__ import annotations

import argparse
import io
import json
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
TOL = 1e-9  # max |difference| of a joint world-transform entry (m or rotation-matrix entry)


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    for k in ("COMPOSE_STOP_AFTER", "COMPOSE_MAX_ITER", "COMPOSE_DEBUG"):
        env.pop(k, None)
    return env


class Run:
    """A ``compose run`` child in its own process group; stderr lines collected with their times."""

    def __init__(self, args: list[str], cwd: Path):
        self.t0 = time.perf_counter()
        self.proc = subprocess.Popen([sys.executable, "-m", "schedules.cli.main", "run", *args], cwd=cwd, env=_env(),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines: list[tuple[float, str]] = []
        self.cond = threading.Condition()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self.cond:
                self.lines.append((time.perf_counter() - self.t0, line.rstrip("\n")))
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def wait_line(self, pred, timeout: float) -> float | None:
        """Time (s since start) of the first line matching ``pred``, waiting up to ``timeout``."""
        end = time.perf_counter() + timeout
        with self.cond:
            while True:
                for t, line in self.lines:
                    if pred(line):
                        return t
                left = end - time.perf_counter()
                if left <= 0 or (self.proc.poll() is not None and not self.reader.is_alive()):
                    return None
                self.cond.wait(min(left, 0.2))

    def kill_at(self, t: float) -> bool:
        """SIGKILL the process group ``t`` s after the start; False if it had already ended."""
        while True:
            if self.proc.poll() is not None:
                return False
            left = t - (time.perf_counter() - self.t0)
            if left <= 0:
                break
            time.sleep(min(left, 0.01))
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            return False
        self.proc.wait()
        return True

    def finish(self) -> int:
        rc = self.proc.wait()
        self.reader.join()
        return rc

    @property
    def text(self) -> str:
        return "\n".join(line for _, line in self.lines)


# --- what a final path may hold -------------------------------------------------------------------

def joint_transforms(path: Path) -> dict[str, np.ndarray]:
    """{SkelRoot path: joint world transforms (frames, joints, 4, 4)} of every character."""
    from pxr import Usd, UsdGeom, UsdSkel
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise ValueError("not a USD stage")
    t0, t1 = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    cache = UsdSkel.Cache()
    out = {}
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            sq = cache.GetSkelQuery(binding.GetSkeleton())
            frames = []
            xf = UsdGeom.XformCache()
            for k in range(t0, t1 + 1):
                xf.SetTime(Usd.TimeCode(k))
                frames.append(np.array(sq.ComputeJointWorldTransforms(xf), float))
            out[f"{prim.GetPath()}:{binding.GetSkeleton().GetPath()}"] = np.stack(frames)
    if not out:
        raise ValueError("no skeleton in the stage")
    return out


def _max_diff(a: dict, b: dict) -> float:
    if set(a) != set(b):
        return math.inf
    return max((float(np.abs(a[k] - b[k]).max()) if a[k].shape == b[k].shape else math.inf) for k in a)


def _png_complete(data: bytes) -> bool:
    return data.startswith(b"\x89PNG\r\n\x1a\n") and data[-12:-8] == b"\x00\x00\x00\x00" and data[-8:-4] == b"IEND"


def usd_frames(folder: Path) -> dict[Path, dict[str, int]]:
    """Frames per joint track of every USD stage under ``folder`` (the output stage and the run's
    120 Hz audit stage), by path relative to ``folder``."""
    return {p.relative_to(folder): {k: v.shape[0] for k, v in joint_transforms(p).items()}
            for p in sorted(folder.rglob("*.usd[acz]")) if not p.name.startswith(".")}


def half_written(folder: Path, ref_frames: dict[Path, dict[str, int]]) -> list[str]:
    """Files at final paths of a killed run's folder that are not complete (see the module doc).

    ``ref_frames``: :func:`usd_frames` of the uninterrupted run; a stage must have the frames of
    the same stage there (a stage the reference lacks must read back whole)."""
    from schedules.execution.checkpoints import CheckpointError, read_all
    bad = []
    for p in sorted(folder.rglob("*")):
        if not p.is_file() or p.name.startswith(".") or p.suffix == ".log":
            continue  # temporaries (".name.XXXX.tmp") and the lock are not final paths
        try:
            if p.suffix in (".usda", ".usdc", ".usdz"):
                got = {k: v.shape[0] for k, v in joint_transforms(p).items()}
                want = ref_frames.get(p.relative_to(folder))
                if want is not None and got != want:
                    raise ValueError(f"frames {sorted(got.values())} where the reference has {sorted(want.values())}")
            elif p.suffix == ".json":
                doc = json.loads(p.read_text(encoding="utf-8"))
                if p.parent.name == "steps" and not {"format", "fingerprint", "name", "npz_sha256", "data"} <= set(doc):
                    raise ValueError("not a whole checkpoint")
                if p.name == "manifest.json" and "checkpoints" not in doc:
                    raise ValueError("not a whole manifest")
                if p.name == "rep.json" and "passes" not in doc:
                    raise ValueError("not a whole report")
            elif p.suffix == ".npz":
                with np.load(io.BytesIO(p.read_bytes()), allow_pickle=False) as z:
                    for k in z.files:
                        z[k]
            elif p.suffix == ".png":
                if not _png_complete(p.read_bytes()):
                    raise ValueError("PNG without its IEND chunk")
        except Exception as exc:  # noqa: BLE001 - any failure to read it back is a half-written file
            bad.append(f"{p}: {type(exc).__name__}: {exc}")
    run = folder / "run"
    if (run / "manifest.json").exists():
        try:
            read_all(run)  # every committed checkpoint against its SHA-256
        except (CheckpointError, Exception) as exc:  # noqa: BLE001
            bad.append(f"{run}: committed checkpoint: {exc}")
    return bad


def temporaries(folder: Path) -> int:
    return sum(1 for p in folder.rglob(".*") if p.name != ".lock")


# --- the benchmark ---------------------------------------------------------------------------------

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="walk")
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lock-tries", type=int, default=3)
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep it (default: a temporary folder, removed)")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_faults_"))
    work.mkdir(parents=True, exist_ok=True)
    outs = ["-o", "out.usda", "--report", "rep.json", "--run-dir", "run"]
    try:
        # 1. the reference
        d = work / "ref"
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir()
        ref = Run([args.scenario, *outs], d)
        ref_rc = ref.finish()
        wall = time.perf_counter() - ref.t0
        if ref_rc not in (0, 1) or not (d / "out.usda").exists():
            print(ref.text)
            raise SystemExit(f"the reference run failed (exit {ref_rc})")
        steps = [(t, line) for t, line in ref.lines if line.startswith("[") and "] " in line]
        last = steps[-1][1].split("]")[0] + "]"
        t_last = steps[-1][0]
        t_wrote = next(t for t, line in ref.lines if line.startswith("compose: wrote"))
        ref_tf = joint_transforms(d / "out.usda")
        ref_frames = usd_frames(d)
        ref_bytes = (d / "out.usda").read_bytes()
        print(f"reference: exit {ref_rc}, {wall:.1f} s wall; last step line at {t_last:.1f} s, outputs written at "
              f"{t_wrote:.1f} s (export {t_wrote - t_last:.2f} s); {sum(v.shape[0] for v in ref_tf.values())} frames", flush=True)

        # 2. kills
        k_export = math.ceil(args.kills / 5) if args.kills else 0
        k_time = args.kills - k_export
        # a moment is a fraction of the run up to its last step line; the run's length is estimated
        # from the latest run seen (machine load changes it): a run that ends before its kill moment
        # is a miss, and the same fraction is tried again on the new estimate (up to 3 times)
        plan = [("time", (i + rng.random()) / max(k_time, 1) * 0.97) for i in range(k_time)]
        plan += [("export", rng.random()) for _ in range(k_export)]
        est, est_export = t_last, t_wrote - t_last
        kills = identical = half = missed = same_bytes = temps = 0
        for i, (kind, x) in enumerate(plan):
            d = work / f"kill{i:02d}"
            for attempt in range(3):
                shutil.rmtree(d, ignore_errors=True)
                d.mkdir()
                r = Run([args.scenario, *outs], d)
                if kind == "export":
                    t_ev = r.wait_line(lambda line: line.startswith(last), timeout=20 * wall)
                    t_kill = (t_ev or 0.0) + x * est_export
                    killed = t_ev is not None and r.kill_at(t_kill)
                else:
                    t_kill = x * est
                    killed = r.kill_at(t_kill)
                r.finish()
                if killed:
                    break
                missed += 1
                t_end = next((t for t, line in r.lines if line.startswith(last)), None)
                t_out = next((t for t, line in r.lines if line.startswith("compose: wrote")), None)
                if t_end is not None:
                    est = t_end
                    if t_out is not None:
                        est_export = t_out - t_end
                print(f"kill {i:2d} ({kind}, {t_kill:.2f} s): missed, the run had ended (exit {r.proc.returncode}); "
                      f"estimates now: steps {est:.1f} s, export {est_export:.2f} s", flush=True)
            if not killed:
                continue
            kills += 1
            phase = r.lines[-1][1][:60] if r.lines else "(no output yet)"
            bad = half_written(d, ref_frames)
            half += len(bad)
            for b in bad:
                print(f"    HALF-WRITTEN {b}", flush=True)
            temps += temporaries(d)
            res = Run([args.scenario, *outs, "--resume"], d)
            rc = res.finish()
            diff = math.inf
            if rc == ref_rc and (d / "out.usda").exists():
                diff = _max_diff(ref_tf, joint_transforms(d / "out.usda"))
                same_bytes += (d / "out.usda").read_bytes() == ref_bytes
            ok = diff <= TOL
            identical += ok
            resumed = json.loads((d / "rep.json").read_text()).get("resumed_steps") if (d / "rep.json").exists() else None
            print(f"kill {i:2d} ({kind}) at {t_kill:6.2f} s after '{phase}': {len(bad)} half-written; resume exit "
                  f"{rc}, {resumed} steps from checkpoints, {time.perf_counter() - res.t0:.1f} s, max |dT| = "
                  f"{diff:.3g} -> {'identical' if ok else 'DIFFERENT'}", flush=True)
            if not ok:
                print("    " + "\n    ".join(res.text.splitlines()[-8:]), flush=True)

        # 3. the run lock
        refused = 0
        if args.lock_tries:
            d = work / "lock"
            shutil.rmtree(d, ignore_errors=True)
            d.mkdir()
            holder = Run([args.scenario, *outs], d)
            if holder.wait_line(lambda line: line.startswith("compose: running"), timeout=10 * wall) is None:
                raise SystemExit("the lock holder did not start:\n" + holder.text)
            for j in range(args.lock_tries):
                other = Run([args.scenario, "-o", f"other{j}.usda", "--report", f"other{j}.json", "--run-dir", "run"], d)
                rc = other.finish()
                alive = holder.proc.poll() is None
                ok = alive and rc == 2 and "in use" in other.text and f"pid {holder.proc.pid}" in other.text
                refused += ok
                print(f"lock try {j}: exit {rc}, holder alive {alive}: {'refused' if ok else 'NOT refused'}: "
                      f"{other.text.strip().splitlines()[-1][:160] if other.text.strip() else ''}", flush=True)
            holder.kill_at(0.0)
            holder.finish()
            probe = subprocess.run([sys.executable, "-c", "import sys; from schedules.execution.checkpoints import RunLock; "
                                    "RunLock(sys.argv[1]).acquire(); print('taken over')", str(d / "run")],
                                   env=_env(), capture_output=True, text=True)
            print(f"stale lock after SIGKILL of the holder: {(probe.stdout + probe.stderr).strip()[-160:]}", flush=True)
        print(f"missed={missed} bytes_identical={same_bytes} leftover_temporaries={temps} tolerance={TOL:g}")
        print(f"kills={kills} resumed_identical={identical} half_written={half} lock_conflicts_refused={refused}")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
