"""Does a style rank the real held-out trial cheaper than the flailing syntheses? (issue #18 item 2)

    python tests/benchmarks/energy_rank.py prepare [--trial speed|turn] [--cache DIR] [--rival NAME=STYLE.yaml ...]
    python tests/benchmarks/energy_rank.py rank STYLE.yaml [STYLE.yaml ...] [--trial speed|turn] [--cache DIR]

No synthesis is needed to judge a θ: under the shipped ``walk`` θ the real 07_12 trial (moved
onto its own footsteps) has NIO energy 9.24 and the flailing synthesis 0.40 — the prediction
flails because flailing is the style's optimum.  ``prepare`` computes, once per trial, the
real trial projected onto its footsteps (X_real: ``feasible_target``, the 200-iteration cap of
``compose learn``) and "rival" motions: syntheses of the same task (the trial's footsteps and
timing, ``compose evaluate-style``'s initial motion and pre-solve, 300 IPOPT iterations) under
given styles; they are written to ``--cache`` as .npz.  ``rank`` reads them and prints, for every
style file, :func:`scenegraph.nio.ranking.rank_report`: E(X_real; θ), E(rival; θ) for every
rival, their log ratio (< 0: the real motion is cheaper, as a style that predicts it must
make it), the energy split by joint group, and the held-out G (E(X_real) minus the energy
of one Gauss–Newton step from X_real under θ, the local counterexample NIO trains with).

The trials are bench_heldout.py's (speed: 07_12 2:264; turn: 16_18 209:430).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_heldout import TRIALS, _mocap_dir  # noqa: E402


def _trial(name: str):
    for n, train, tframes, test, sframes in TRIALS:
        if n == name:
            return train, tframes, test, sframes
    raise SystemExit(f"unknown trial {name!r}")


def _test_task(mocap: Path, name: str):
    from schedules.cli.learn import clip_target

    _, _, test, sframes = _trial(name)
    ch, mot, steps, clip = clip_target(mocap / test, sframes, "adult_male", reconstruct=False, feasible=False,
                                       onesided=True)
    return ch, mot, steps, clip


def _save(path: Path, motion, **meta) -> None:
    np.savez(path, ctrl=np.asarray(motion.ctrl), warp=np.asarray(motion.warp), meta=json.dumps(meta))


def _load(path: Path):
    from scenegraph.model.motion import Motion

    z = np.load(path)
    return Motion(np.asarray(z["ctrl"]), np.asarray(z["warp"])), json.loads(str(z["meta"]))


def prepare(args) -> None:
    from scenegraph.model.style import default_style, load_style
    from scenegraph.nio import feasible_target, joint_rms_deg, resample
    from scenegraph.nio.heldout import group_rms_deg
    from scenegraph.problem.synthesis import synthesize

    mocap, cache = _mocap_dir(args.mocap), Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    ch, mot, steps, clip = _test_task(mocap, args.trial)
    t = np.asarray(clip.times, float)
    qr = np.asarray(clip.q, float)
    real = cache / f"{args.trial}_real.npz"
    if not real.exists():
        t0 = time.perf_counter()
        res = feasible_target(ch, resample(mot), steps, max_iter=200)
        x = res.motion
        rms = group_rms_deg(x.canonical(x.to_canonical(t)), qr)
        _save(real, x, what="real trial projected onto its footsteps", status=res.status,
              violation=max(res.violations.values(), default=0.0), rms_vs_ik=rms,
              seconds=time.perf_counter() - t0)
        print(f"{args.trial} real: {res.summary()} ({joint_rms_deg(x, mot):.2f} deg from the IK fit) "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    for spec in args.rival:
        rname, _, path = spec.partition("=")
        out = cache / f"{args.trial}_rival_{rname}.npz"
        if out.exists():
            continue
        st = default_style(ch.total_mass) if path == "default" else load_style(path)
        ex_style = load_style(args.example) if args.example else (st if st.example is not None else None)
        ex = ex_style.example.arrays() if ex_style is not None and ex_style.example is not None else None
        t0 = time.perf_counter()
        syn = synthesize(ch, st, steps, float(t[0]), float(t[-1]), example=ex, max_iter=300)
        x = syn.result.motion
        rms = group_rms_deg(x.canonical(x.to_canonical(t)), qr)
        _save(out, x, what=f"synthesis under {path}", status=syn.result.status, iterations=syn.result.iterations,
              rms_vs_ik=rms, seconds=time.perf_counter() - t0)
        print(f"{args.trial} rival {rname}: {syn.result.summary()} all {rms['all']:.2f} trunk+arms "
              f"{rms['trunk_arms']:.2f} deg, {time.perf_counter() - t0:.0f} s", flush=True)


def rank(args) -> None:
    from scenegraph.model.style import load_style
    from scenegraph.nio.problem import NIO
    from scenegraph.nio.ranking import rank_report

    mocap, cache = _mocap_dir(args.mocap), Path(args.cache)
    ch, _, steps, _ = _test_task(mocap, args.trial)
    real, meta = _load(cache / f"{args.trial}_real.npz")
    rivals = {p.stem.split("_rival_", 1)[1]: _load(p)[0] for p in sorted(cache.glob(f"{args.trial}_rival_*.npz"))}
    nio = NIO(ch, real, steps, local=True)
    for path in args.styles:
        th = load_style(path).vector()
        rep = rank_report(nio, th, real, rivals)
        print(json.dumps({"style": path, "trial": args.trial, **rep}) if args.json else
              f"{args.trial} {Path(path).name}: " + rep["line"], flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--rival", action="append", default=[], help="NAME=STYLE.yaml (or NAME=default)")
    p.add_argument("--example", default=None, help="style file whose example poses start every rival synthesis")
    r = sub.add_parser("rank")
    r.add_argument("styles", nargs="+")
    r.add_argument("--json", action="store_true")
    for q in (p, r):
        q.add_argument("--trial", choices=[t[0] for t in TRIALS], default="speed")
        q.add_argument("--cache", default="/tmp/energy_rank")
        q.add_argument("--mocap", default=None)
    args = ap.parse_args()
    (prepare if args.cmd == "prepare" else rank)(args)


if __name__ == "__main__":
    main()
