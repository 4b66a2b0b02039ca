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

__all__ = ["register", "run_scenario", "goal_report", "goal_verdict", "tackle_entry", "avoid_entry"]


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version
    out = {"python": platform.python_version()}
    for pkg in ("compose-motion", "casadi", "numpy", "usd-core", "networkx", "pydantic"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


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
                    "residual_rel_tol": 0.02}


def goal_report(scene, contact_audits: dict | None = None) -> tuple[dict, dict]:
    """({goal: {holds, measured, tolerance, unit, what}}, {coupling: {...}}) from the final Scene."""
    from scenegraph.scene import avoid_measure, handle_track, tackle_measure

    from .measures import transition_entry

    goals = {}
    for g in scene.goals:
        me = scene.character(g.character)
        if g.type == "footprints":
            val = (contact_audits or {}).get(g.character, {}).get("footstep_error_max")
            tol = 0.025
            goals[g.name] = {"type": g.type, "what": "max distance of a planted handle from its footprint, "
                             "sampled at 120 Hz (solver enforces it exactly at collocation points)",
                             "measured": val, "tolerance": tol, "unit": "m",
                             "holds": bool(val is not None and val <= tol)}
        elif g.type == "walk_to":
            (x, y), _ = g.data
            p = handle_track(me, "pelvis", [g.time])[0]
            d = float(np.hypot(p[0] - x, p[1] - y))
            goals[g.name] = {"type": g.type, "what": "horizontal pelvis distance from the target at the time",
                             "measured": d, "tolerance": g.tolerance, "unit": "m", "holds": d <= g.tolerance}
        elif g.type == "reach":
            handle, point = g.data
            d = float(np.linalg.norm(handle_track(me, handle, [g.time])[0] - np.asarray(point)))
            goals[g.name] = {"type": g.type, "what": f"{handle} distance from the target at the time",
                             "measured": d, "tolerance": g.tolerance, "unit": "m", "holds": d <= g.tolerance}
        elif g.type == "tackle":
            goals[g.name] = tackle_entry(g, tackle_measure(me, scene.character(g.partner), g.time))
        elif g.type == "avoid":
            goals[g.name] = avoid_entry(g, avoid_measure(me, scene.character(g.partner), g.time))
        elif g.type == "style_change" and g.data[1] is not None:
            goals[g.name] = transition_entry(g, me, scene.duration)
        elif g.type == "style_change":
            goals[g.name] = {"type": g.type, "what": "style timeline applied (θ blended across the seam)",
                             "measured": None, "tolerance": None, "holds": True}
    couplings = {}
    for c in scene.couplings:
        t = np.linspace(c.interval[0], c.interval[1], max(2, int((c.interval[1] - c.interval[0]) * 30) + 1))
        tracks = [handle_track(scene.character(w), h, t) for w, h in c.handles]
        centre = np.mean(tracks, axis=0)
        d = float(max(np.linalg.norm(tr - centre, axis=1).max() for tr in tracks)) * (2 if len(tracks) == 2 else 1)
        couplings[c.name] = {"type": c.type, "what": "max distance between the held handles over the interval"
                             if len(tracks) == 2 else "max distance of a holder's handle from their centre",
                             "measured": d, "tolerance": c.tolerance, "unit": "m", "holds": d <= c.tolerance}
    return goals, couplings


def _adversarial(g, entry: dict) -> dict:
    """The outcome fields every tackle/avoid entry carries: who plans last, whether this goal
    is expected to hold (its side plans last and wins by design), and a plain note."""
    expected = bool(g.expected_to_hold)
    entry.update({"plans_last": g.plans_last, "expected_to_hold": expected,
                  "note": (f"{g.character} plans last: expected to hold" if expected else
                           f"expected to FAIL by design: {g.plans_last} plans last and wins")})
    return entry


def tackle_entry(g, m: dict) -> dict:
    """Report entry of a tackle goal from :func:`scenegraph.scene.tackle_measure` numbers.

    Holds when the attacker's contact point (front of its chest) is within the goal's
    tolerance (5 cm) of the target's torso surface (either side: touching, not buried) and
    the closing speed is within ±10 % of the goal's ``speed`` (or, without one, at least
    ``min_speed``).  The palms' distances from the torso are reported for the hands-around
    part (``hands_around_torso``), which does not decide ``holds``."""
    from scenegraph.scene import TACKLE_SPEED_TOL

    min_speed, hands, goal_speed = g.data
    d, v = m["contact_distance"], m["closing_speed"]
    contact_ok = abs(d) <= g.tolerance
    if goal_speed is not None:
        speed_ok = abs(v - goal_speed) <= TACKLE_SPEED_TOL * goal_speed
        speed_what = f"within ±{TACKLE_SPEED_TOL:.0%} of {goal_speed:g} m/s"
    else:
        speed_ok = v >= min_speed
        speed_what = f">= min_speed {min_speed:g} m/s"
    palms = m["palm_distances"]
    return _adversarial(g, {
        "type": g.type,
        "what": "distance of the attacker's contact point (front of its chest) from the target's torso "
                f"surface at the impact (|d| <= tolerance), and closing speed {speed_what}",
        "measured": abs(d), "tolerance": g.tolerance, "unit": "m",
        "contact_distance": d, "contact_holds": bool(contact_ok),
        "speed": v, "closing_speed": v, "goal_speed": goal_speed, "min_speed": min_speed,
        "speed_tolerance": TACKLE_SPEED_TOL * goal_speed if goal_speed is not None else None,
        "speed_holds": bool(speed_ok),
        "chest_to_chest": m["chest_to_chest"], "contact_point": m["contact_point"],
        "hands_around_torso": bool(hands), "palm_torso_distances": palms,
        "holds": bool(contact_ok and speed_ok)})


def avoid_entry(g, clearance: float) -> dict:
    """Report entry of an avoid goal: clearance (closest of pelvis and chest to the other's
    chest) must be at least the sphere radius."""
    r = g.data[0]
    return _adversarial(g, {"type": g.type, "what": "closest pelvis/chest distance to the other's chest",
                            "measured": clearance, "clearance": clearance, "tolerance": r, "radius": r,
                            "unit": "m (must be >=)", "holds": bool(clearance >= r - 1e-3)})


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
                 log=None) -> dict:
    """Run a scenario end to end; returns the report dict.  Raises ComposeError on failure."""
    from scenegraph.audit import audit_motion
    from scenegraph.scene import build_scene
    from scenegraph.usd_export import CharacterTrack, Marker, export_usd

    from .cli_scenario import check_scenario
    from .compiler import compile_schedule
    from .checkpoints import RunLock, atomic_write_text
    from .executor import run_fingerprint, run_schedule

    log = sys.stderr if log is None else log  # bound at call time (a test may swap sys.stderr)
    t0 = time.perf_counter()
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    if not (0 < fps <= 1000):
        raise InputError(f"--fps must be in (0, 1000], got {fps}")
    scn = load_scenario(name_or_file)
    check_scenario(scn)
    source = Path(find_scenario(name_or_file))
    out_path = _check_output(out, Path(f"{scn.name}.usda"))
    rdir = Path(run_dir) if run_dir else Path("runs") / scn.name
    report_path = Path(report) if report else rdir / "report.json"
    if report_path.exists() and report_path.is_dir():
        raise InputError(f"--report {report_path}: is a directory")
    if report and not (report_path.parent if str(report_path.parent) else Path(".")).is_dir():
        raise InputError(f"--report {report_path}: folder {report_path.parent} does not exist")

    schedule = compile_schedule(scn)
    with RunLock(rdir):  # one writer per run folder, held until the report is written
        scene = build_scene(scn)
        fp = run_fingerprint(source.read_text(encoding="utf-8"), schedule)
        print(f"compose: running {scn.name!r}: {len(schedule)} steps, {len(schedule.generations())} generation(s), "
              f"jobs {jobs}, run folder {rdir}", file=log, flush=True)
        result = run_schedule(scene, schedule, run_dir=rdir, fingerprint=fp, jobs=jobs, resume=resume,
                              fail_capped=fail_capped, log=log)
        final = result.scene

        audits = {}
        for c in final.characters:
            a = audit_motion(c.character, c.style, c.motion, c.footsteps, result.contact_forces.get(c.name),
                             ground=final.ground)
            audits[c.name] = a.to_dict()
            audits[c.name]["tolerances"] = dict(AUDIT_TOLERANCES)
            audits[c.name]["passes"] = a.passes(**AUDIT_TOLERANCES)
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
            if g.type == "walk_to":
                (x, y), _ = g.data
                markers.append(Marker(f"goal_{g.name}", "goal", (x, y, 0.05), None, 0.08, g.character))
            elif g.type == "reach":
                markers.append(Marker(f"goal_{g.name}", "goal", tuple(g.data[1]), None, 0.04, g.character))
        # the energy of the final motion (the audit's Σ α Q_m² dt at the solver's contact-force
        # times): a windowed step's own energy covers its window only
        energies = {c.name: float(audits[c.name]["energy"]) for c in final.characters}
        metadata = {"scenario": scn.name, "scenario_file": str(source),
                    "styles": {ref: where for ref, where in final.style_refs},
                    "versions": _versions(), "energies": energies}
        export_usd(out_path, tracks, fps, markers=markers, metadata=metadata, ground=final.ground)

        rep = {
            "scenario": scn.name, "scenario_file": str(source), "output": str(out_path), "run_dir": str(rdir),
            "jobs": jobs, "resumed_steps": result.resumed, "fps": fps, "presolve": result.presolve,
            "steps": [r.to_dict() for r in result.records],
            "characters": {c.name: {"audit": audits[c.name], "energy": energies[c.name],
                                    "styles": [ref for ref, _ in c.styles], "footsteps": len(c.footsteps)}
                           for c in final.characters},
            "goals": goals, "couplings": couplings,
            **goal_verdict(goals, couplings),
            "all_audits_pass": all(a["passes"] for a in audits.values()),
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
                from scenegraph.preview import write_report_plots
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
            print(f"compose: {what} does NOT hold: measured {_num(e.get('measured'))}, tolerance "
                  f"{_num(e.get('tolerance'))} {e.get('unit') or ''}".rstrip(), file=log, flush=True)
        for who, a in audits.items():
            if not a["passes"]:
                print(f"compose: physics audit FAILED for {who!r}: root residual {a['root_residual_rel']:.3g} body "
                      f"weight, footstep error {a['footstep_error_max'] * 1000:.1f} mm, penetration "
                      f"{a['penetration_max'] * 1000:.1f} mm, friction {a['friction_violation_max']:.3g} N "
                      f"(tolerances {AUDIT_TOLERANCES}); outputs written for inspection", file=log, flush=True)
        return rep


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
    return " ".join(shlex.quote(w) for w in words)


def _run(args) -> int:
    """``compose run``; SIGINT/SIGTERM stop it with one line naming the step and the
    ``--resume`` command (exit 130/143), the finished steps' checkpoints kept."""
    from . import interrupts
    with interrupts.catching_interrupts():
        try:
            rep = run_scenario(args.file, out=args.output, report=args.report, jobs=args.jobs, resume=args.resume,
                               run_dir=args.run_dir, fps=args.fps, fail_capped=args.fail_capped)
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


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="solve a scenario and write a USD stage and a report",
                       description="Compile a scenario into its schedule, solve every step (with checkpoints in "
                                   "the run folder) and write a USD stage plus a JSON report. Exit 2 on bad "
                                   "input, 1 when a solve fails.")
    p.add_argument("file", metavar="NAME|FILE", help="scenario file or bundled scenario name")
    p.add_argument("-o", "--output", metavar="OUT.usda", help="USD stage (.usda, .usdc, .usdz); "
                                                              "default <scenario name>.usda here")
    p.add_argument("--report", metavar="R.json", help="JSON report; default <run folder>/report.json")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="solve independent steps in N processes")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run from its run folder")
    p.add_argument("--run-dir", metavar="DIR", help="checkpoint folder; default runs/<scenario name>")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate of the exported stage (default 30)")
    p.add_argument("--fail-capped", action="store_true",
                   help="fail the run when a full step stops at its iteration cap, even with every constraint "
                        "satisfied (default: such a step is kept, with its status in the report)")
    p.set_defaults(func=_run)
