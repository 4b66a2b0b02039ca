"""Benchmark (issue #7): the bundled ``tackle`` and ``handhold`` runs, and ``handhold`` solved
as ONE simultaneous NLP over both characters with the hard hand-hold (scenegraph/problem/joint.py).

    python tests/benchmarks/bench_scenarios.py [--skip-tackle] [--skip-handhold] [--skip-monolithic]
                                               [--mono-max-iter N]

Each scenario runs as ``compose run NAME --report r.json`` would (``run_scenario``) in a
temporary folder.  The monolithic problem starts from the same initial motions as the
schedule (``build_scene`` + the executor's kinematic pre-solve) and has the same terms as the
schedule's last full steps (walk_to goals, start, soft footprints, ground, same tolerances,
stall rule and Gauss–Newton Hessian), with the rubber band replaced by the hard coupling
palm_adult(t) = palm_child(t) at 30 Hz over the interval and the hand force F(t) as NLP
variables (equal and opposite).  It "reaches its tolerance" when IPOPT succeeds (or stalls,
the executor's rule), the hand gap of ``goal_report`` is <= 1 cm and both physics audits
pass with the hand force counted.

monolithic_ratio = (monolithic time: pre-solve + build + solve, or its time at the
iteration limit) / (handhold schedule time: the whole ``run_scenario``).  Printed before
the last line: ``monolithic: converged|iteration limit|failed ...``.  Last line, exactly:
tackle_s=<float> handhold_s=<float> monolithic_ratio=<float>
(nan for a part that was skipped or a run that failed: a step did not converge.)
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def run_bundled(name: str, tmp: Path) -> tuple[float, dict | None]:
    """(wall seconds, report); report None when the run failed (a step did not converge)."""
    from scenarios.errors import ComposeError
    from schedules.cli.run import run_scenario

    t = time.perf_counter()
    try:
        rep = run_scenario(name, out=str(tmp / f"{name}.usda"), report=str(tmp / f"{name}.report.json"),
                           run_dir=str(tmp / "runs" / name), log=sys.stderr)
    except ComposeError as exc:
        print(f"{name}: FAILED after {time.perf_counter() - t:.1f} s: {exc}", flush=True)
        return time.perf_counter() - t, None
    return time.perf_counter() - t, rep


def scenario_line(name: str, seconds: float, rep: dict) -> str:
    goals = ", ".join(f"{n} {'holds' if e['holds'] else 'FAILS'} ({e['measured']:.3g})"
                      for n, e in rep["goals"].items() if isinstance(e.get("measured"), (int, float)))
    cpl = ", ".join(f"{n} gap {e['measured'] * 100:.2f} cm ({'holds' if e['holds'] else 'FAILS'})"
                    for n, e in rep["couplings"].items())
    aud = ", ".join(f"{w} {'pass' if c['audit']['passes'] else 'FAIL'}" for w, c in rep["characters"].items())
    return f"{name}: {seconds:.1f} s; audits {aud}; goals {goals}" + (f"; {cpl}" if cpl else "")


def monolithic(max_iter: int) -> dict:
    """Solve handhold as one NLP; returns timings, status and the checks."""
    from scenarios.loader import load_scenario
    from scenegraph.model.audit import audit_motion
    from scenegraph.problem.joint import JointCoupling, coupling_times, solve_joint
    from scenegraph.world.scene import build_scene
    from scenegraph.model.residual import compiled_kernel
    from schedules.cli.run import AUDIT_TOLERANCES, goal_report
    from schedules.plan.compiler import compile_schedule
    from schedules.execution.executor import _subproblem, presolve_character
    from schedules.plan.step import FULL
    from scenegraph.model.motion import Motion

    scn = load_scenario("handhold")
    scene = build_scene(scn)
    schedule = compile_schedule(scn)
    for c in scene.characters:  # kernels compiled/loaded outside the timing (the schedule run did it too)
        compiled_kernel(c.character)
    t0 = time.perf_counter()
    for who in scene.names:  # the executor's pre-solve: the schedule's initial motions
        d = presolve_character(scene, who)
        if d["success"]:
            scene = scene.with_motion(who, Motion(np.asarray(d["ctrl"]), np.asarray(d["warp"])))
    t_pre = time.perf_counter() - t0
    cpl = scene.couplings[0]
    (a, ha), (b, hb) = cpl.handles
    sps = []
    for who in (a, b):  # the terms of the schedule's last full step of each character ...
        step = max((s for s in schedule.steps_of(who) if s.kind == FULL), key=lambda s: s.cycle)
        sp, _ = _subproblem(scene, step, who)
        # ... without the rubber band (soft targets and spring): the hard coupling replaces it
        sps.append(replace(sp, targets=tuple(t for t in sp.targets if not t.name.startswith("coupling:")),
                           springs=(), max_iter=max_iter, label=f"monolithic_{who}"))
    coupling = JointCoupling(ha, hb, coupling_times(cpl.interval, 30.0), name=cpl.name)
    jr = solve_joint(sps[0], sps[1], coupling)
    seconds = t_pre + jr.seconds
    final = scene
    audits = {}
    for who, r, sp in zip((a, b), jr.results, sps):
        final = final.with_motion(who, r.motion, r.footsteps)
        aud = audit_motion(sp.character, sp.style, r.motion, r.footsteps, r.contact_forces, ground=scene.ground)
        audits[who] = aud.to_dict() | {"passes": aud.passes(**AUDIT_TOLERANCES)}
    goals, couplings = goal_report(final, audits)
    gap = couplings[cpl.name]["measured"]
    t_dense = np.linspace(cpl.interval[0], cpl.interval[1], int(round((cpl.interval[1] - cpl.interval[0]) * 120)) + 1)
    from scenegraph.world.scene import handle_track
    dense_gap = float(np.linalg.norm(handle_track(final.character(a), ha, t_dense)
                                     - handle_track(final.character(b), hb, t_dense), axis=1).max())
    ok = (jr.success and couplings[cpl.name]["holds"] and all(v["passes"] for v in audits.values())
          and all(g["holds"] for g in goals.values()))
    capped = jr.status == "Maximum_Iterations_Exceeded"
    return {"result": jr, "seconds": seconds, "presolve_s": t_pre, "converged": ok, "capped": capped,
            "gap": gap, "gap_120hz": dense_gap, "audits": audits, "goals": goals,
            "force_max": float(np.linalg.norm(jr.force, axis=1).max()),
            "force_max_t": float(jr.force_times[int(np.argmax(np.linalg.norm(jr.force, axis=1)))]),
            "force_median": float(np.median(np.linalg.norm(jr.force, axis=1)))}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-tackle", action="store_true")
    ap.add_argument("--skip-handhold", action="store_true")
    ap.add_argument("--skip-monolithic", action="store_true")
    ap.add_argument("--mono-max-iter", type=int, default=1000, help="IPOPT iteration limit of the monolithic NLP")
    args = ap.parse_args(argv)
    tackle_s = handhold_s = ratio = math.nan
    with tempfile.TemporaryDirectory(prefix="bench_scenarios_") as d:
        tmp = Path(d)
        # a run that fails (exit 1: a step did not converge) reports nan: it has no time to a result
        if not args.skip_tackle:
            tackle_s, rep = run_bundled("tackle", tmp)
            if rep is None:
                tackle_s = math.nan
            else:
                print(scenario_line("tackle", tackle_s, rep), flush=True)
        if not args.skip_handhold:
            handhold_s, rep = run_bundled("handhold", tmp)
            if rep is None:
                handhold_s = math.nan
            else:
                print(scenario_line("handhold", handhold_s, rep), flush=True)
                hh_ok = rep["all_audits_pass"] and rep["all_goals_hold"]
                print(f"handhold schedule reaches its tolerance: {'yes' if hh_ok else 'NO'}", flush=True)
    if not args.skip_monolithic:
        m = monolithic(args.mono_max_iter)
        jr = m["result"]
        kind = "converged" if m["converged"] else ("iteration limit" if m["capped"] else "failed")
        aud = ", ".join(f"{w} {'pass' if v['passes'] else 'FAIL'} (root {v['root_residual_rel']:.2g} mg, "
                        f"feet {v['footstep_error_max'] * 1000:.2f} mm, pen {v['penetration_max'] * 1000:.2f} mm)"
                        for w, v in m["audits"].items())
        goals = ", ".join(f"{n} {'holds' if e['holds'] else 'FAILS'} ({e['measured']:.3g} m)"
                          for n, e in m["goals"].items() if isinstance(e.get("measured"), (int, float)))
        print(jr.summary(), flush=True)
        print(f"monolithic details: pre-solve {m['presolve_s']:.1f} s, build {jr.seconds_build:.1f} s, "
              f"IPOPT {jr.seconds_solve:.1f} s; hand gap {m['gap'] * 100:.3f} cm at 30 Hz, "
              f"{m['gap_120hz'] * 100:.3f} cm at 120 Hz; hand force max {m['force_max']:.1f} N (at t = {m['force_max_t']:.3f} s), median {m['force_median']:.1f} N; audits {aud}; "
              f"goals {goals}", flush=True)
        if not math.isnan(handhold_s):
            ratio = m["seconds"] / handhold_s
        print(f"monolithic: {kind} ({jr.status}, {jr.iterations} iterations, {m['seconds']:.1f} s, "
              f"limit {args.mono_max_iter})", flush=True)
    print(f"tackle_s={tackle_s:.3f} handhold_s={handhold_s:.3f} monolithic_ratio={ratio:.3f}", flush=True)


if __name__ == "__main__":
    main()
