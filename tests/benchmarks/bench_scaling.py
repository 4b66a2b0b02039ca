"""Benchmark (issue #14): how wall time grows with scene length and cast size, and whether
every step converges.

    python tests/benchmarks/bench_scaling.py [--skip-bundled] [--keep DIR]

Every run is ``compose run FILE -o S.usda --report R.json --run-dir D`` in a fresh process
(the compiled kernels come from the disk cache, which the first run fills: the benchmark
warms it before timing anything), in this order:

* ``walk``: the bundled one-cycle walk (the README's main job), warm;
* walks to a point straight ahead at 1.3 m/s with the ``walk`` style, lasting 1.2, 2.4, 4.8
  and 9.6 s (scenarios written into a temporary folder);
* hand-in-hand chains of 2, 3 and 4 adults (``walk`` style, 0.65 m apart, each holding the
  next one's left palm with the right) walking 1.4 m ahead in 1.2 s;
* every bundled scenario (unless ``--skip-bundled``).

Per run it prints one line: wall seconds, exit code, steps, capped or stalled steps, audits,
and energy per second (Σ over characters of the audit's energy of the final motion, J-like
units of Σ α Q_m² dt, divided by the duration).  Last line, exactly:

``walk_s=<float> t_1_2=<float> t_2_4=<float> t_4_8=<float> t_9_6=<float> duration_exponent=<float>
energy_per_s_spread=<float> chain_exponent=<float> capped_steps=<int> audits_pass=<0|1>``

(one line) where ``duration_exponent`` is the least-squares slope of log wall time against log
duration over the four walks, ``energy_per_s_spread`` the largest over the smallest energy
per second among them, ``chain_exponent`` the slope of log wall time against log cast size
over the chains, ``capped_steps`` the number of steps over all runs that ended at an
iteration cap or stalled (discarded ones included), and ``audits_pass`` 1 when every run
wrote a report and every character's audit passed.  A run that fails (no report) counts as
an audit failure and its time still enters the slopes.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DURATIONS = (1.2, 2.4, 4.8, 9.6)
CHAINS = (2, 3, 4)
SPEED = 1.3  # m/s


def walk_to_yaml(duration: float) -> str:
    tag = str(duration).replace(".", "_")
    return f"""name: walk_{tag}
description: walk {SPEED * duration:.2f} m straight ahead in {duration} s
duration: {duration}
characters:
  - name: walker
    style: walk
    start: {{position: [0.0, 0.0], heading: 0}}
goals:
  - type: walk_to
    character: walker
    target: [{SPEED * duration:.3f}, 0.0]
    time: {duration}
    tolerance: 0.05
"""


def chain_yaml(n: int, gap: float = 0.65, duration: float = 1.2, ahead: float = 1.4) -> str:
    chars, goals, couplings = [], [], []
    for i in range(n):
        y = gap * ((n - 1) / 2 - i)  # person i+1 walks on person i's right (−y)
        chars.append(f"  - name: p{i}\n    style: walk\n    start: {{position: [0.0, {y:.3f}], heading: 0}}")
        goals.append(f"  - type: walk_to\n    character: p{i}\n    target: [{ahead}, {y:.3f}]\n    time: {duration}")
    for i in range(n - 1):
        couplings.append(f"  - type: hand_hold\n    name: hold{i}\n    between:\n"
                         f"      - {{character: p{i}, handle: palm_r}}\n      - {{character: p{i + 1}, handle: palm_l}}\n"
                         f"    interval: [0.0, {duration}]")
    return (f"name: chain_{n}\ndescription: {n} people walk hand in hand\nduration: {duration}\ncharacters:\n"
            + "\n".join(chars) + "\ngoals:\n" + "\n".join(goals) + "\ncouplings:\n" + "\n".join(couplings) + "\n")


def compose_cmd() -> list[str]:
    exe = shutil.which("compose")
    return [exe] if exe else [sys.executable, "-c", "import sys; from schedules.cli.main import main; sys.exit(main())"]


CAPPED = ("Maximum_Iterations_Exceeded", "Stalled", "Restoration_Failed", "Error_In_Step_Computation",
          "Search_Direction_Becomes_Too_Small")  # stopped unconverged (kept when feasible: executor.UNCONVERGED)


def run(label: str, target: str, tmp: Path) -> dict:
    """Run one scenario in a fresh process; returns wall seconds, exit code and report figures."""
    rep_path = tmp / f"{label}.report.json"
    cmd = compose_cmd() + ["run", target, "-o", str(tmp / f"{label}.usda"), "--report", str(rep_path),
                           "--run-dir", str(tmp / "runs" / label)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
    wall = time.perf_counter() - t0
    out = {"label": label, "seconds": wall, "exit": proc.returncode, "report": None, "steps": 0, "capped": 0,
           "audits_pass": False, "energy_per_s": math.nan}
    if rep_path.exists() and proc.returncode in (0, 1):
        rep = json.loads(rep_path.read_text())
        out["report"] = rep
        out["steps"] = len(rep["steps"])
        out["capped"] = sum(any(c in r["status"] for c in CAPPED) for r in rep["steps"])
        out["audits_pass"] = bool(rep.get("all_audits_pass"))
        dur = float(rep.get("duration") or 0.0) or _duration(target)
        energy = sum(float(c["audit"]["energy"]) for c in rep["characters"].values())
        out["energy_per_s"] = energy / dur if dur > 0 else math.nan
    else:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [""]
        out["error"] = tail[0]
    capped = f"{out['capped']}/{out['steps']} capped or stalled"
    audits = "audits pass" if out["audits_pass"] else ("AUDIT FAIL" if out["report"] else f"FAILED: {out.get('error')}")
    print(f"{label}: {wall:.1f} s, exit {proc.returncode}, {capped}, {audits}, "
          f"energy/s {out['energy_per_s']:.4g}", flush=True)
    return out


def _duration(target: str) -> float:
    from scenarios.loader import load_scenario
    return float(load_scenario(target).duration)


def slope(x, y) -> float:
    x, y = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    return float(np.polyfit(x, y, 1)[0])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-bundled", action="store_true", help="leave out the bundled scenarios")
    ap.add_argument("--keep", metavar="DIR", help="write stages, reports and run folders here (kept)")
    args = ap.parse_args(argv)
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_scaling."))
    tmp.mkdir(parents=True, exist_ok=True)
    from scenarios.bundled import bundled_syntheses
    from scenegraph.model.body import make_character
    from scenegraph.model.residual import compiled_kernel
    compiled_kernel(make_character())  # fill the compiled-code cache before timing anything
    runs = [run("walk", "walk", tmp)]
    walks = []
    for d in DURATIONS:
        f = tmp / f"walk_{str(d).replace('.', '_')}.yaml"
        f.write_text(walk_to_yaml(d))
        walks.append(run(f.stem, str(f), tmp))
    chains = []
    for n in CHAINS:
        f = tmp / f"chain_{n}.yaml"
        f.write_text(chain_yaml(n))
        chains.append(run(f.stem, str(f), tmp))
    runs += walks + chains
    if not args.skip_bundled:
        runs += [run(name, name, tmp) for name in bundled_syntheses()]
    eps = [w["energy_per_s"] for w in walks]
    spread = max(eps) / min(eps) if all(np.isfinite(eps)) and min(eps) > 0 else math.nan
    capped = sum(r["capped"] for r in runs)
    audits = int(all(r["audits_pass"] for r in runs))
    t = [w["seconds"] for w in walks]
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"walk_s={runs[0]['seconds']:.3f} t_1_2={t[0]:.3f} t_2_4={t[1]:.3f} t_4_8={t[2]:.3f} t_9_6={t[3]:.3f} "
          f"duration_exponent={slope(DURATIONS, t):.3f} energy_per_s_spread={spread:.3f} "
          f"chain_exponent={slope(CHAINS, [c['seconds'] for c in chains]):.3f} capped_steps={capped} "
          f"audits_pass={audits}", flush=True)


if __name__ == "__main__":
    main()
