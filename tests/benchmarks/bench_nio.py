"""Benchmark: learn the walk style from one gait cycle of CMU 07_01 by NIO, then re-synthesise.

    python tests/benchmarks/bench_nio.py [--frames 64:201] [--max-iter 200] [--out scenarios/styles/walk.yaml]

X_T: the clip's smooth reconstruction moved onto its own footsteps
(``schedules.cli.learn.clip_target``).  Timed: NIO only (``nio_s``; loading, reconstruction
and the target projection are reported separately).  Re-synthesis
(``NIO.resynthesize``): the spacetime solve with the clip's own footsteps started at X_T
with its contact forces, the same budget (300 IPOPT iterations) for each of the learned style, the default
style and the learned style with springs off (paper §7 ablations); joint-angle RMS (deg) of
each against X_T.  Twice: the ordinary solve and the warm-started one (X_T's own contact
forces, IPOPT warm-start options).  The last line's ``resynth_rms_deg`` is the warm-started
one: it continues from X_T itself down to the nearest minimum of the style's energy, which
is what "X_T is optimal under the learned style" predicts; the ordinary solve starts with
the barrier's push off λ = 0 and a constant contact guess, which moves the motion before the
energy has any say (both are printed and stored).  A third measure is the paper's own
protocol (``resynthesize_from_example``: the initial motion copies X_T's poses by leg phase,
then the ordinary synthesis), printed and stored as well.  Last line, exactly:
``nio_s=<float> iterations=<int> g_initial=<float> g_final=<float> resynth_rms_deg=<float>``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from schedules.cli.learn import clip_target, parse_frames, save_learned  # noqa: E402
from scenegraph.model.body import N_JOINT  # noqa: E402
from scenegraph.nio import joint_rms_deg, learn_style, resynthesize_from_example  # noqa: E402
from scenegraph.model.style import default_style  # noqa: E402

CLIP = ROOT / "scenarios" / "clips" / "walk_neutral_cmu_07_01.bvh"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clip", default=str(CLIP))
    ap.add_argument("--frames", default="64:201")
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--resynth-iter", type=int, default=300)
    ap.add_argument("--out", default=None, help="also write the learned style here")
    ap.add_argument("--hessian", default="gauss_newton", choices=("gauss_newton", "exact"),
                    help="spacetime Hessian of the IPOPT solves: re-syntheses, ipopt counterexamples (Subproblem.hessian)")
    ap.add_argument("--counterexamples", default="local", choices=("local", "ipopt"),
                    help="local: one Gauss-Newton step from X_T (default); ipopt: spacetime solves (NIO local=False)")
    ap.add_argument("--solve-iter", type=int, default=150, help="IPOPT iterations per ipopt counterexample")
    ap.add_argument("--alpha-floor", type=float, default=0.0, help="lower bound of every alpha_j in units of 1/M (NIO.alpha_floor; an experiment, README)")
    args = ap.parse_args()
    frames = parse_frames(args.frames)

    def progress(r):
        print(f"iter {r.iteration} G={r.G:.6g} D={r.D:.3g} E_T={r.E_target:.6g} E_S={r.E_counter:.6g} "
              f"beta={r.beta:g} t={r.seconds:.1f}s", flush=True)

    t = time.perf_counter()
    ch, XT, steps, clip = clip_target(args.clip, frames, "adult_male")
    print(f"clip, reconstruction and target: {time.perf_counter() - t:.1f} s", flush=True)
    t = time.perf_counter()
    res = learn_style(ch, XT, steps, name=Path(args.out).stem if args.out else "walk", clip=Path(args.clip).name,
                      frames=args.frames,
                      body="adult_male", callback=progress, max_iter=args.max_iter, hessian=args.hessian,
                      local=args.counterexamples == "local", solve_iter=args.solve_iter,
                      alpha_floor=args.alpha_floor / N_JOINT)
    nio_s = time.perf_counter() - t
    print(f"stop: {res.stop_reason}; evaluations {res.evaluations}", flush=True)

    learned = res.style
    M = len(learned.alpha)
    variants = {
        "learned": learned,
        "default": default_style(ch.total_mass),
        "springs_off": learned.with_(ks1=np.zeros(M), ks2=np.zeros(M), kd=np.zeros(M), name="springs_off"),
    }
    rms, rms_warm, rms_ex = {}, {}, {}
    for name, st in variants.items():
        for warm, out in ((False, rms), (True, rms_warm)):
            r = res.nio.resynthesize(st, max_iter=args.resynth_iter, warm=warm)
            out[name] = joint_rms_deg(r.motion, XT)
            print(f"resynth{' (warm)' if warm else ''} {name}: rms {out[name]:.3f} deg ({r.summary()})", flush=True)
        r = resynthesize_from_example(ch, XT, steps, st, max_iter=args.resynth_iter, hessian=args.hessian)
        rms_ex[name] = joint_rms_deg(r.motion, XT)
        print(f"resynth (paper's initial motion) {name}: rms {rms_ex[name]:.3f} deg ({r.summary()})", flush=True)
    if args.out:
        save_learned(res, args.out, Path(args.clip).name, frames, "adult_male",
                     resynth={k: round(v, 3) for k, v in rms.items()},
                     resynth_warm={k: round(v, 3) for k, v in rms_warm.items()},
                     resynth_example={k: round(v, 3) for k, v in rms_ex.items()})
        print(f"wrote {args.out}", flush=True)
    print("resynth_rms_deg (ordinary / warm-started / paper's initial motion): " + ", ".join(
        f"{k} {rms[k]:.2f} / {rms_warm[k]:.2f} / {rms_ex[k]:.2f}" for k in variants), flush=True)
    print(f"nio_s={nio_s:.3f} iterations={res.iterations} g_initial={res.g_initial:.6g} "
          f"g_final={res.g_final:.6g} resynth_rms_deg={rms_warm['learned']:.4f}")


if __name__ == "__main__":
    main()
