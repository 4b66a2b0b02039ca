"""Inverse-dynamics timing: compose's generated C code against Pinocchio, same states, same process.

Run:  python tests/benchmarks/bench_dynamics.py [--states 1000] [--repeats 7] [--fresh]

Both sides are timed in batch over the same random states (within the joint limits) so
that Python call overhead does not decide the figure:

* compose: the compiled inverse dynamics ``id_function(ch)`` mapped over the states
  (``f.map(N)``, a C loop over the generated code), inputs already CasADi matrices — the
  way the optimizer calls it.  An earlier line also reports the time including the
  numpy -> CasADi conversion, and a direct ctypes call of the compiled map on numpy memory.
* Pinocchio: ``pin.rneaInParallel`` with one thread (its batched API), and a tight Python
  loop over ``pin.rnea`` for reference; the ratio uses the faster of the two.
* the Jacobian d tau / d(q, qd, qdd) (35 x 105) of ours, compiled and mapped the same way.

Each figure is the best of several repeats, in microseconds per state.  Compile (or
cache-load) times are printed first.  ``--fresh`` compiles into an empty temporary cache.
The last line is exactly
``id_us_compose=<float> id_us_pinocchio=<float> ratio=<float> jac_us_compose=<float>``
with ratio = compose / Pinocchio.
"""
from __future__ import annotations

import argparse
import atexit
import ctypes
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests/ for pinocchio_model


def best_time(fn, repeats: int) -> float:
    fn()  # warm up
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def ctypes_batch(fmap: ca.Function, lib: str):
    """Call the compiled map function in ``lib`` directly on Fortran-ordered numpy arrays."""
    so = ctypes.CDLL(lib)
    name = fmap.name()
    ci = ctypes.c_longlong
    sz = [ci() for _ in range(4)]
    getattr(so, f"{name}_work")(*[ctypes.byref(s) for s in sz])
    iw = (ci * max(sz[2].value, 1))()
    w = np.zeros(max(sz[3].value, 1))
    fun = getattr(so, name)
    dptr = ctypes.POINTER(ctypes.c_double)

    def call(args, res):
        argv = (dptr * max(sz[0].value, len(args)))(*[a.ctypes.data_as(dptr) for a in args])
        resv = (dptr * max(sz[1].value, len(res)))(*[r.ctypes.data_as(dptr) for r in res])
        return fun(argv, resv, iw, w.ctypes.data_as(dptr), 0)
    return call


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--preset", default="adult_male")
    ap.add_argument("--fresh", action="store_true", help="compile into an empty temporary cache")
    args = ap.parse_args(argv)
    if args.fresh:
        fresh = tempfile.mkdtemp(prefix="compose-bench-")
        atexit.register(shutil.rmtree, fresh, True)
        os.environ["COMPOSE_CACHE_DIR"] = fresh

    import pinocchio as pin

    from pinocchio_model import build_pinocchio, random_states
    from scenegraph.model import codegen
    from scenegraph.model.body import make_character

    N, R = args.states, args.repeats
    ch = make_character(args.preset)
    q, qd, qdd = random_states(ch, N, seed=1)

    for label, build in (("id", codegen.id_function), ("jac", codegen.id_jacobian_function)):
        before = dict(codegen.STATS)
        t0 = time.perf_counter()
        f = build(ch)
        dt = time.perf_counter() - t0
        how = ("compiled" if codegen.STATS["compiled"] > before["compiled"] else
               "loaded from cache" if codegen.STATS["loaded"] > before["loaded"] else "CasADi VM (no codegen)")
        print(f"{label}: {how} in {dt:.2f} s ({f.n_instructions() if f.class_name() == 'SXFunction' else f.class_name()})"
              f", cache {codegen.cache_dir()}")
    f_id, f_jac = codegen.id_function(ch), codegen.id_jacobian_function(ch)
    f_vm = codegen.id_function(ch, compile=False)

    # Same states for everybody: CasADi column-major (35 x N), Pinocchio Fortran arrays.
    Qn, Vn, An = (np.asfortranarray(x.T) for x in (q, qd, qdd))
    Qd, Vd, Ad = ca.DM(Qn), ca.DM(Vn), ca.DM(An)
    id_map, jac_map, vm_map = f_id.map(N), f_jac.map(N), f_vm.map(N)

    ours = np.array(id_map(Qd, Vd, Ad))
    pm = build_pinocchio(ch, aligned=True)  # its fastest joint types; depth-first numbering: permute
    # the states once, outside the timing
    model, data = pm.model, pm.data
    qp, qdp, qddp = pm.to_pin(q), pm.to_pin(qd), pm.to_pin(qdd)
    Qp, Vp, Ap = (np.asfortranarray(x.T) for x in (qp, qdp, qddp))
    pool = pin.ModelPool(model, 1)
    tau_pin = np.zeros((model.nv, N), order="F")
    pin.rneaInParallel(1, pool, Qp, Vp, Ap, tau_pin)
    ref = pm.from_pin(tau_pin.T).T
    err = np.max(np.linalg.norm(ours - ref, axis=0) / np.linalg.norm(ref, axis=0))
    print(f"states: {N} ({args.preset}), max relative difference compose vs Pinocchio: {err:.2e}")

    us = 1e6 / N
    t_ours = best_time(lambda: id_map(Qd, Vd, Ad), R) * us
    t_ours_np = best_time(lambda: id_map(Qn, Vn, An), R) * us
    t_vm = best_time(lambda: vm_map(Qd, Vd, Ad), R) * us
    t_jac = best_time(lambda: jac_map(Qd, Vd, Ad), R) * us
    t_pin_batch = best_time(lambda: pin.rneaInParallel(1, pool, Qp, Vp, Ap, tau_pin), R) * us

    def pin_loop():
        for i in range(N):
            pin.rnea(model, data, qp[i], qdp[i], qddp[i])
    t_pin_loop = best_time(pin_loop, R) * us
    t_pin = min(t_pin_batch, t_pin_loop)

    def pin_derivatives_loop():
        for i in range(N):
            pin.computeRNEADerivatives(model, data, qp[i], qdp[i], qddp[i])
    t_pin_jac = best_time(pin_derivatives_loop, max(1, R // 2)) * us

    # Cross-check without CasADi's numpy conversion: the compiled map called through ctypes.
    t_ctypes = float("nan")
    try:
        fmap = f_vm.map(N)
        codegen.compiled(fmap)
        so = codegen.library_path(fmap)
        if so is not None and so.exists():
            out = np.zeros((35, N), order="F")
            call = ctypes_batch(fmap, str(so))
            call([Qn, Vn, An], [out])
            if np.allclose(out, ours, rtol=1e-12, atol=1e-9):
                t_ctypes = best_time(lambda: call([Qn, Vn, An], [out]), R) * us
    except (OSError, AttributeError) as exc:  # no compiler, or an unexpected library layout
        print(f"ctypes cross-check skipped: {exc}")

    print(f"compose id, compiled, CasADi inputs : {t_ours:8.3f} us/state")
    print(f"compose id, compiled, numpy inputs  : {t_ours_np:8.3f} us/state (includes numpy<->CasADi conversion)")
    print(f"compose id, compiled map via ctypes : {t_ctypes:8.3f} us/state (numpy memory, no conversion)")
    print(f"compose id, CasADi VM               : {t_vm:8.3f} us/state")
    print(f"pinocchio rneaInParallel(1 thread)  : {t_pin_batch:8.3f} us/state")
    print(f"pinocchio rnea, Python loop         : {t_pin_loop:8.3f} us/state")
    print(f"compose jacobian (35x105), compiled : {t_jac:8.3f} us/state")
    print(f"pinocchio RNEA derivatives, loop    : {t_pin_jac:8.3f} us/state (reference for the Jacobian)")
    print(f"id_us_compose={t_ours:.4f} id_us_pinocchio={t_pin:.4f} ratio={t_ours / t_pin:.4f} jac_us_compose={t_jac:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
