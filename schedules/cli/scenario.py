"""``compose validate``, ``compose schema``, ``compose list`` and ``compose schedule``."""
from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from scenarios.bundled import bundled_scenarios, bundled_styles, describe_scenario
from scenarios.errors import ComposeError, InputError, Location
from scenarios.loader import load_scenario, scenario_json_schema
from scenarios.schema import Scenario, StyleChangeGoal

__all__ = ["register", "check_scenario"]


def check_scenario(scn: Scenario) -> None:
    """Checks beyond the schema that need the world model: referenced style files load and the
    schedule compiles (every Step's window at least ``compiler.MIN_WINDOW`` wide)."""
    from scenegraph.model.style import load_style  # schedules may import scenegraph

    if scn.is_edit:  # the clip was checked by the language (scenarios/edit_block.py); nothing to compile
        return

    refs = [(("characters", i, "style"), c.style) for i, c in enumerate(scn.characters)]
    refs += [(("goals", j, "style"), g.style) for j, g in enumerate(scn.goals) if isinstance(g, StyleChangeGoal)]
    checked: set[Path] = set()
    for path, ref in refs:
        f = scn.style_file(ref)
        if f is None or f in checked:
            continue
        checked.add(f)
        try:
            load_style(f)
        except InputError as exc:
            raise InputError(f"style {ref!r} is invalid: {exc}", scn.location(path)) from None
    # the schedule must be compilable: every window wide enough (a style change too close to the
    # start or end of the scene leaves no room for its seam window), located at the cause
    from schedules.plan.compiler import compile_schedule
    compile_schedule(scn)


def _validate(args) -> int:
    bad = 0
    for name in args.files:
        try:
            scn = load_scenario(name)
            check_scenario(scn)
        except ComposeError as exc:
            bad += 1
            print(f"compose: error: {exc}", file=sys.stderr)
            continue
        if not args.quiet:
            if scn.is_edit:
                print(f"ok: {name} (scenario {scn.name!r}: an edit of {scn.edit.clip})")
            else:
                print(f"ok: {name} (scenario {scn.name!r}: {len(scn.characters)} character(s), "
                      f"{len(scn.goals)} goal(s), {len(scn.couplings)} coupling(s), {scn.duration:g} s)")
    return 2 if bad else 0


def _schema(args) -> int:
    json.dump(scenario_json_schema(), sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


def _list(args) -> int:
    scenarios = bundled_scenarios()
    width = max([len(n) for n in scenarios] + [len(n) for n in bundled_styles()] + [8])
    print("bundled scenarios (compose run NAME):")
    for name, path in scenarios.items():
        print(f"  {name:<{width}}  {describe_scenario(path)}")
    print("bundled styles (style: NAME):")
    for name, path in bundled_styles().items():
        where = "built-in" if path is None else str(path.name)
        print(f"  {name:<{width}}  {where}")
    return 0


def _output_path(value: str | None, flag: str) -> Path | None:
    if value is None:
        return None
    p = Path(value)
    if p.exists() and p.is_dir():
        raise InputError(f"{flag} {value}: is a directory", Location(value))
    if not p.parent.exists():
        raise InputError(f"{flag} {value}: folder {p.parent} does not exist", Location(value))
    return p


def _schedule(args) -> int:
    from schedules.plan.compiler import compile_schedule

    dot = _output_path(args.dot, "--dot")
    png = _output_path(args.png, "--png")
    if png is not None and shutil.which("dot") is None:
        raise InputError("--png needs graphviz `dot`, which is not installed (use --dot and render it elsewhere)")
    scn = load_scenario(args.file)
    schedule = compile_schedule(scn)
    if args.json:
        sys.stdout.write(schedule.to_json() + "\n")
    else:
        sys.stdout.write(schedule.to_text())
        from schedules.plan.critical_path import critical_path, step_times_from_report
        times = step_times_from_report(args.times) if getattr(args, "times", None) else None
        sys.stdout.write(critical_path(schedule, times).to_text())
    if dot is not None:
        schedule.write_dot(dot)
        print(f"wrote {dot}", file=sys.stderr)
    if png is not None:
        schedule.write_png(png)
        print(f"wrote {png}", file=sys.stderr)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check scenario files (exit 2 if any is invalid)",
                       description="Validate scenario files or bundled scenario names; every error names "
                                   "file:line:col and the field.")
    p.add_argument("files", nargs="+", metavar="FILE", help="scenario file or bundled scenario name")
    p.add_argument("-q", "--quiet", action="store_true", help="print errors only")
    p.set_defaults(func=_validate)

    p = sub.add_parser("schema", help="print the JSON Schema of scenario files",
                       description="Print the JSON Schema of scenario files (for editors).")
    p.set_defaults(func=_schema)

    p = sub.add_parser("list", help="list bundled scenarios and styles",
                       description="List the bundled scenarios and styles.")
    p.set_defaults(func=_list)

    p = sub.add_parser("schedule", help="show the schedule compiled from a scenario",
                       description="Compile a scenario into its schedule and print the graph as text.")
    p.add_argument("file", metavar="FILE", help="scenario file or bundled scenario name")
    p.add_argument("--dot", metavar="OUT.dot", help="also write the graph in graphviz DOT")
    p.add_argument("--png", metavar="OUT.png", help="also render a PNG (needs graphviz `dot`)")
    p.add_argument("--json", action="store_true", help="print the schedule as JSON instead of text")
    p.add_argument("--times", metavar="R.json", help="weigh the critical path with the step seconds of a run report")
    p.set_defaults(func=_schedule)
