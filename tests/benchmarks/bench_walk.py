"""Benchmark: synthesise the one-cycle walk from its initialisation with the default style.

    python tests/benchmarks/bench_walk.py [--hessian gauss_newton|exact]

Times the kinematic pre-solve plus the full spacetime solve (the compiled residual kernel
is built or loaded from the cache before timing starts).  Last line, exactly:
walk_cycle_s=<float> iterations=<int> converged=<0|1> root_residual_rms=<float> footstep_err_max_m=<float>
"""
from __future__ import annotations

import argparse
import time

from scenegraph.model.body import make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.residual import compiled_kernel, kernel_hessian
from scenegraph.model.style import default_style
from scenegraph.problem.synthesis import synthesize


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hessian", default="gauss_newton", choices=("gauss_newton", "exact"),
                    help="Subproblem.hessian of the full solve")
    args = ap.parse_args()
    ch = make_character()
    style = default_style(ch.total_mass)
    t = time.perf_counter()
    compiled_kernel(ch)
    if args.hessian == "exact":
        kernel_hessian(ch)
    print(f"kernel compile/load: {time.perf_counter() - t:.2f} s")
    steps = footsteps_for_walk()
    t = time.perf_counter()
    syn = synthesize(ch, style, steps, steps[1].t0, steps[-1].t0, soft_pin_hz=120.0, hessian=args.hessian)
    wall = time.perf_counter() - t
    print(syn.presolve.summary())
    print(syn.result.summary())
    print(f"audit: {syn.audit.to_dict()}")
    iters = syn.presolve.iterations + syn.result.iterations
    print(f"walk_cycle_s={wall:.3f} iterations={iters} converged={int(syn.result.success)} "
          f"root_residual_rms={syn.audit.root_residual_rms:.6g} footstep_err_max_m={syn.audit.footstep_error_max:.6g}")


if __name__ == "__main__":
    main()
