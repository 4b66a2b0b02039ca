"""``compose run NAME|FILE``: scenario → schedule → solved Scene → USD stage + JSON report.

Exit codes: 0 done, every physics audit passes and every goal and coupling expected to hold
holds; 1 a solve failed (the step and its violated constraint groups are named; the run
folder keeps every finished step; no output stage is written), or the outputs were written
but an audit fails or a goal/coupling expected to hold does not (an adversarial goal whose
other side plans last is expected to fail and does not decide it); 2 bad input (scenario,
arguments, a run folder that does not match on ``--resume``, a checkpoint that fails its
SHA-256 check, a run folder locked by another ``compose run``).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from scenarios.errors import InputError, Location
from scenarios.loader import find_scenario, load_scenario
from schedules.cli.options import add_scenario_argument, add_solve_options

__all__ = ["register", "run_scenario", "goal_report", "goal_verdict", "tackle_entry", "avoid_entry",
           "violation_line", "extra_mass_entries"]


def _versions() -> dict:
    from scenarios.versions import package_versions
    return {"python": platform.python_version(),
            **package_versions(("compose-motion", "casadi", "numpy", "usd-core", "networkx", "pydantic"))}


def _check_output(value: str | None, default: Path) -> Path:
    p = Path(value) if value is not None else default
    if p.suffix.lower() not in (".usda", ".usdc", ".usdz"):
        raise InputError(f"-o {p}: the output must end in .usda, .usdc or .usdz", Location(str(p)))
    if p.exists() and p.is_dir():
        raise InputError(f"-o {p}: is a directory", Location(str(p)))
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"-o {p}: folder {parent} does not exist", Location(str(p)))
    return p


# --- goal and coupling checks -------------------------------------------------------------------

# What a run's physics audit must meet (report field "passes"): footsteps and penetration in m
# at the audit's 120 Hz (the solver holds them exactly only at its collocation points), friction
# cone in N, root residual as a fraction of body weight.
AUDIT_TOLERANCES = {"footstep_tol": 5e-3, "penetration_tol": 1e-2, "friction_tol": 1e-2 * 9.81,
                    "residual_rel_tol": 0.02, "dense_tol": 0.05}  # dense_tol: body weights at every 120 Hz frame (issue 15)


def goal_report(scene, contact_audits: dict | None = None) -> tuple[dict, dict]:
    """({goal: {holds, measured, tolerance, unit, what, where}}, {coupling: {...}}) from the final
    Scene: each goal and coupling record measures itself (scenegraph.world.goals)."""
    goals = {g.name: scene.goal_at_world_time(g).entry(scene, contact_audits) for g in scene.goals}
    couplings = {c.name: c.entry(scene) for c in scene.couplings}
    return goals, couplings


def tackle_entry(g, m: dict) -> dict:
    """Report entry of a tackle goal (:func:`scenegraph.world.goals.tackle.tackle_entry`)."""
    from scenegraph.world.goals.tackle import tackle_entry as entry
    return entry(g, m)


def avoid_entry(g, clearance: float) -> dict:
    """Report entry of an avoid goal (:func:`scenegraph.world.goals.avoid.avoid_entry`)."""
    from scenegraph.world.goals.avoid import avoid_entry as entry
    return entry(g, clearance)


def goal_verdict(goals: dict, couplings: dict) -> dict:
    """Run-level verdict over the goal entries.

    ``all_goals_hold`` (kept for other tools) is literal: every goal and coupling holds — in
    an adversarial scene the loser's goal fails by design, so it is False there.
    ``winners_goals_hold``: every tackle/avoid goal expected to hold (its side plans last) holds
    (True without adversarial goals); ``goals_as_expected``: every goal and coupling holds
    except those expected to fail; ``expected_failures``: the goals expected to fail, with
    whether they did."""
    adv = {n: e for n, e in goals.items() if "expected_to_hold" in e}
    winners = all(e["holds"] for e in adv.values() if e["expected_to_hold"])
    expected_fail = {n: {"holds": e["holds"], "plans_last": e["plans_last"]}
                     for n, e in adv.items() if not e["expected_to_hold"]}
    as_expected = (all(e["holds"] for n, e in goals.items() if n not in expected_fail)
                   and all(c["holds"] for c in couplings.values()))
    return {"all_goals_hold": bool(all(e["holds"] for e in goals.values()) and
                                   all(c["holds"] for c in couplings.values())),
            "winners_goals_hold": bool(winners), "goals_as_expected": bool(as_expected),
            "expected_failures": expected_fail}


# --- the command -------------------------------------------------------------------------------

def run_scenario(name_or_file: str, *, out: str | None = None, report: str | None = None, jobs: int = 1,
                 resume: bool = False, run_dir: str | None = None, fps: float = 30.0, fail_capped: bool = False,
                 scheduler: str | None = None, store: str | None = None, log=None) -> dict:
    """Run a scenario end to end; returns the report dict.  Raises ComposeError on failure."""
    from schedules.cli.scenario import check_scenario
    from schedules.plan.compiler import compile_schedule

    log = sys.stderr if log is None else log  # bound at call time (a test may swap sys.stderr)
    t0 = time.perf_counter()
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    if not (0 < fps <= 1000):
        raise InputError(f"--fps must be in (0, 1000], got {fps}")
    scn = load_scenario(name_or_file)
    if not scn.is_edit:
        check_scenario(scn)
    source = Path(find_scenario(name_or_file))
    out_path = _check_output(out, Path(f"{scn.name}.usda"))
    rdir = Path(run_dir) if run_dir else Path("runs") / scn.name
    report_path = Path(report) if report else rdir / "report.json"
    if report_path.exists() and report_path.is_dir():
        raise InputError(f"--report {report_path}: is a directory")
    if report and not (report_path.parent if str(report_path.parent) else Path(".")).is_dir():
        raise InputError(f"--report {report_path}: folder {report_path.parent} does not exist")
    if scn.is_edit:  # an edit of a captured clip (scenarios/edit_block.py): no schedule, no solver
        from schedules.execution.checkpoints import RunLock
        from schedules.execution.edit_run import run_edit
        with RunLock(rdir):
            return run_edit(scn, source, out_path, report_path, fps, log)

    schedule = compile_schedule(scn)
    sched = _open_scheduler(scheduler, jobs)  # before anything is written: unreachable -> exit 2
    try:
        return _run_locked(scn, schedule, source, out_path, rdir, report_path, t0, jobs, resume, fps, fail_capped,
                           sched, store, log)
    finally:
        if sched is not None:
            sched.close()


def _open_scheduler(scheduler: str | None, jobs: int):
    """``--scheduler``: None runs the plain executor; else a Dask scheduler (schedules.execution.distributed)."""
    if scheduler is None:
        return None
    from schedules.execution.distributed import connect
    return connect(scheduler, jobs)


def _solve(scene, schedule, rdir, fp, jobs, resume, fail_capped, sched, store, log):
    from schedules.execution.executor import run_schedule
    if sched is None:
        return run_schedule(scene, schedule, run_dir=rdir, fingerprint=fp, jobs=jobs, resume=resume,
                            fail_capped=fail_capped, log=log)
    from schedules.execution.distributed import run_schedule_dask
    from schedules.execution.step_store import default_store
    store = None if store == "" else (store or default_store())
    return run_schedule_dask(scene, schedule, sched, run_dir=rdir, fingerprint=fp, resume=resume,
                             fail_capped=fail_capped, store=store, log=log)


def _run_locked(scn, schedule, source, out_path, rdir, report_path, t0, jobs, resume, fps, fail_capped, sched, store,
                log) -> dict:
    from scenegraph.model.audit import audit_motion
    from scenegraph.world.scene import build_scene
    from scenegraph.export.usd import CharacterTrack, Marker, export_usd

    from schedules.execution.checkpoints import RunLock, atomic_write_text
    from schedules.execution.executor import run_fingerprint
    from schedules.execution.run_audit import allowed_contacts, audit_run_stage

    with RunLock(rdir):  # one writer per run folder, held until the report is written
        scene = build_scene(scn)
        fp = run_fingerprint(source.read_text(encoding="utf-8"), schedule)
        print(f"compose: running {scn.name!r}: {len(schedule)} steps, {len(schedule.generations())} generation(s), "
              f"jobs {jobs}, run folder {rdir}", file=log, flush=True)
        for st in scn.sketch_stages:
            print(f"compose: {st['sketch']}: flight detected {st['t'][0]:g}-{st['t'][1]:g} s (keys {st['keys']}): "
                  f"{'; '.join(st['why'])} -> jump goal {st['goal']!r}", file=log, flush=True)
        result = _solve(scene, schedule, rdir, fp, jobs, resume, fail_capped, sched, store, log)
        final = result.scene

        audits = {}
        for c in final.characters:
            a = audit_motion(c.character, c.style, c.motion, c.footsteps, result.contact_forces.get(c.name),
                             ground=final.ground)
            audits[c.name] = a.to_dict()
            audits[c.name]["tolerances"] = dict(AUDIT_TOLERANCES)
            audits[c.name]["passes"] = a.passes(**AUDIT_TOLERANCES)
            print(f"compose: {c.name}: equations of motion at 120 Hz: root residual max "
                  f"{a.dense_residual_max:.3g} body weight at {a.dense_residual_time:.3f} s (in flight "
                  f"{a.dense_flight_residual_max:.3g}), RMS {a.dense_residual_rms:.3g}", file=log, flush=True)
        goals, couplings = goal_report(final, audits)

        # --- outputs: the stage, then the report (the stage is what a failure must not half-write)
        tracks, markers = [], []
        for c in final.characters:
            times, q = c.motion.sample(fps)
            tracks.append(CharacterTrack(c.name, c.character, np.asarray(q, float), float(times[0])))
            for i, f in enumerate(c.footsteps):
                markers.append(Marker(f"{c.name}_footprint_{i}", "footprint",
                                      (f.position[0], f.position[1], final.ground.height(*f.position)),
                                      (f.t0, f.t1), character=c.name))
        for g in final.goals:
            for name, position, radius in g.markers():
                markers.append(Marker(name, "goal", position, None, radius, g.character))
        # the energy of the final motion (the audit's Σ α Q_m² dt at the solver's contact-force
        # times): a windowed step's own energy covers its window only
        energies = {c.name: float(audits[c.name]["energy"]) for c in final.characters}
        metadata = {"scenario": scn.name, "scenario_file": str(source),
                    "styles": {ref: where for ref, where in final.style_refs},
                    "versions": _versions(), "energies": energies,
                    "allowedContacts": allowed_contacts(final)}  # hook (issue #15): contacts asked for
        export_usd(out_path, tracks, fps, markers=markers, metadata=metadata, ground=final.ground)
        stage_audit = audit_run_stage(final, out_path, fps, rdir, metadata, log,  # hook (issue #15)
                                      result.contact_forces)

        rep = {
            "scenario": scn.name, "scenario_file": str(source), "output": str(out_path), "run_dir": str(rdir),
            "jobs": jobs, "resumed_steps": result.resumed, "fps": fps, "presolve": result.presolve,
            "scheduler": sched.spec if sched is not None else None,
            "steps": [r.to_dict() for r in result.records],
            "characters": {c.name: {"audit": audits[c.name], "energy": energies[c.name],
                                    "styles": [ref for ref, _ in c.styles], "footsteps": len(c.footsteps),
                                    "extra_masses": extra_mass_entries(scn, c.name)}
                           for c in final.characters},
            "goals": goals, "couplings": couplings,
            "sketch_stages": scn.sketch_stages,  # flights detected in keyframe sketches (their jump goals above)
            **goal_verdict(goals, couplings),
            "all_audits_pass": all(a["passes"] for a in audits.values()),
            "stage_audit": stage_audit,  # compose audit of the written stage at 120 Hz (not in "passes")
            "total_seconds": round(time.perf_counter() - t0, 3), "solve_seconds": round(result.seconds, 3),
            "versions": _versions(),
        }
        # passes: every audit and every goal/coupling expected to hold (goals_as_expected implies
        # winners_goals_hold; the losers' adversarial goals are expected to fail)
        rep["passes"] = bool(rep["all_audits_pass"] and rep["goals_as_expected"])
        atomic_write_text(json.dumps(rep, indent=1, default=_json_default) + "\n", report_path)
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            pass
        else:
            try:
                from scenegraph.export.preview import write_report_plots
                per_cycle: dict = {}
                for r in result.records:
                    if r.kind == "full":
                        for who, pc in r.per_character.items():
                            per_cycle.setdefault(who, {})[r.cycle] = per_cycle.get(who, {}).get(r.cycle, 0.0) + pc["energy"]
                energy = {who: [v for _, v in sorted(d.items())] for who, d in per_cycle.items()}
                fps_ = [{"position": m.position, "character": m.character, "interval": m.interval}
                        for m in markers if m.kind == "footprint"]
                traj = {tr.name: np.asarray(tr.q)[:, :2] for tr in tracks}
                write_report_plots(report_path.parent, energy=energy, footprints=fps_, trajectories=traj,
                                   prefix=report_path.stem)
            except Exception as exc:  # plots are a convenience; never fail a finished run on them
                print(f"compose: warning: report plots not written: {exc}", file=log)
        print(f"compose: wrote {out_path} and {report_path} in {rep['total_seconds']:.1f} s"
              + ("" if rep["all_goals_hold"] else "; some goals/couplings do not hold (see the report)"),
              file=log, flush=True)
        for n, e in goals.items():
            if "expected_to_hold" in e:
                print(f"compose: {e['type']} goal {n!r} ({e['plans_last']} plans last): "
                      f"{'holds' if e['holds'] else 'does NOT hold'}"
                      + (" (expected to hold)" if e["expected_to_hold"] else
                         " (expected to fail by design: the other side plans last)"), file=log, flush=True)
        failed = [(f"{e['type']} goal {n!r}", e) for n, e in goals.items()
                  if not e["holds"] and e.get("expected_to_hold", True)]
        failed += [(f"{c['type']} coupling {n!r}", c) for n, c in couplings.items() if not c["holds"]]
        for what, e in failed:
            print(f"compose: {violation_line(what, e)}", file=log, flush=True)
        for who, a in audits.items():
            if not a["passes"]:
                print(f"compose: physics audit FAILED for {who!r}: root residual {a['root_residual_rel']:.3g} body "
                      f"weight, footstep error {a['footstep_error_max'] * 1000:.1f} mm, penetration "
                      f"{a['penetration_max'] * 1000:.1f} mm, friction {a['friction_violation_max']:.3g} N "
                      f"(tolerances {AUDIT_TOLERANCES}); outputs written for inspection", file=log, flush=True)
        return rep


def extra_mass_entries(scn, character: str) -> list[dict]:
    """The point masses a character carries, as the report lists them: handle, mass (kg) and
    the scenario's ``label`` (what it is)."""
    return [{"handle": em.handle, "mass": float(em.mass), "label": em.label}
            for em in scn.character(character).body.extra_masses]


def violation_line(what: str, e: dict) -> str:
    """``<file>:<line>:<col> goals[j] (<name>): <type> goal '<name>' does NOT hold: measured …,
    tolerance … <unit>[, violated by … m]`` for a report entry that does not hold."""
    from scenegraph.world.goals import violated_by
    at_least = "must be >=" in str(e.get("unit") or "")
    miss = violated_by(e.get("measured"), e.get("tolerance"), at_least=at_least)
    unit = str(e.get("unit") or "").split(" ")[0]
    text = (f"{what} does NOT hold: measured {_num(e.get('measured'))}, tolerance {_num(e.get('tolerance'))} "
            f"{e.get('unit') or ''}").rstrip()
    if miss is not None:
        text += f"; violated by {miss:.3g} {unit}".rstrip()
    return f"{e['where']}: {text}" if e.get("where") else text


def _num(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.bool_,)):
        return bool(o)
    raise TypeError(type(o).__name__)


def resume_command(args) -> str:
    """The ``compose run … --resume`` command line that continues the run of ``args``."""
    import shlex
    words = ["compose", "run", args.file, "--resume"]
    for flag, value in (("--run-dir", args.run_dir), ("-o", args.output), ("--report", args.report)):
        if value is not None:
            words += [flag, str(value)]
    if args.jobs != 1:
        words += ["--jobs", str(args.jobs)]
    if args.fps != 30.0:
        words += ["--fps", f"{args.fps:g}"]
    if args.fail_capped:
        words.append("--fail-capped")
    if getattr(args, "scheduler", None):
        words += ["--scheduler", str(args.scheduler)]
    return " ".join(shlex.quote(w) for w in words)


def _run(args) -> int:
    """``compose run``; SIGINT/SIGTERM stop it with one line naming the step and the
    ``--resume`` command (exit 130/143), the finished steps' checkpoints kept."""
    from schedules.execution import interrupts
    with interrupts.catching_interrupts():
        try:
            rep = run_scenario(args.file, out=args.output, report=args.report, jobs=args.jobs, resume=args.resume,
                               run_dir=args.run_dir, fps=args.fps, fail_capped=args.fail_capped,
                               scheduler=getattr(args, "scheduler", None),
                               store="" if getattr(args, "no_store", False) else getattr(args, "store", None))
        except interrupts.RunInterrupted as exc:
            print(f"compose: {exc.message}; resume with: {resume_command(args)}", file=sys.stderr, flush=True)
            return exc.exit_code
        except KeyboardInterrupt:  # outside the steps: loading, or the audit and export after the last step
            signum = interrupts.requested() or 2
            print(f"compose: interrupted during {interrupts.phase()}; resume with: {resume_command(args)}",
                  file=sys.stderr, flush=True)
            return 128 + signum
    # exit 0: every physics audit passes and every goal and coupling expected to hold holds
    # (walk_to, reach, footprints, couplings, the winners' tackle/avoid goals); in adversarial
    # scenes the goals of the side that does not plan last are expected to fail and do not decide it
    return 0 if rep["passes"] else 1


RUN_DESCRIPTION = ("Compile a scenario into its schedule, solve every step (with checkpoints in the run folder) and "
                   "write a USD stage plus a JSON report. Exit 2 on bad input, 1 when a solve fails.")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="solve a scenario and write a USD stage and a report", description=RUN_DESCRIPTION)
    add_scenario_argument(p)
    p.add_argument("-o", "--output", metavar="OUT.usda", help="USD stage (.usda, .usdc, .usdz); "
                                                              "default <scenario name>.usda here")
    p.add_argument("--report", metavar="R.json", help="JSON report; default <run folder>/report.json")
    p.add_argument("--run-dir", metavar="DIR", help="checkpoint folder; default runs/<scenario name>")
    add_solve_options(p, what="steps")
    p.set_defaults(func=_run)
