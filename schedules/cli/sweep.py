"""``compose sweep FILE --vary PATH=VALUES … -o DIR``: one scenario, many variants.

Every combination of the ``--vary`` values is built and validated first
(:mod:`schedules.plan.sweep`; a bad one is an error, exit 2, before anything runs or is
written).  Then each variant runs as its own schedule: without ``--scheduler`` one after
another in this process; with ``--scheduler local|processes|sync|ADDRESS`` each variant is
one Dask task (a worker process runs that variant's schedule through the Dask task graph
in-process, with the content-addressed step store so steps shared by variants are solved
once).  Output in DIR:

* ``sweep.json``: the scenario, the ``--vary`` arguments, every variant's values and the
  SHA-256 of its scenario text (what ``--resume`` checks);
* ``vNNN/scenario.yaml``, ``vNNN/stage.usda``, ``vNNN/report.json``, ``vNNN/run/`` (run
  folder), ``vNNN/log.txt`` per variant;
* ``summary.csv`` (+ ``summary.parquet`` with pyarrow) and ``contact_sheet.png`` (with
  matplotlib), see :mod:`schedules.execution.sweep_outputs`.

``--resume`` continues a sweep in DIR: variants with a report are kept, the others run
(continuing their run folder).  Exit 0 when every variant passes, 1 when one fails or
errs, 2 on bad input (also: DIR holds a different sweep, or a sweep without ``--resume``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

from scenarios.bundled import find_scenario
from scenarios.atomic import append_log
from scenarios.errors import ComposeError, InputError, Location

from schedules.execution.checkpoints import atomic_write_text
from schedules.plan.sweep import build_variants, parse_vary
from schedules.execution.sweep_outputs import summary_row, write_contact_sheet, write_summary
from schedules.cli.options import add_scenario_argument, add_solve_options

__all__ = ["register", "run_sweep", "run_variant"]

FORMAT = 1


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def run_variant(vdir: str, fps: float, fail_capped: bool, store: str | None, resume: bool) -> dict:
    """Run one variant folder's ``scenario.yaml`` (in whichever process calls it); returns
    ``{"report", "exit_code"}`` or ``{"error", "exit_code"}`` — never raises ComposeError."""
    from schedules.cli.run import run_scenario

    v = Path(vdir)
    t0 = time.perf_counter()
    where = {"pid": os.getpid(), "started": time.time()}  # when and where it ran (load-balance traces)
    with append_log(v / "log.txt") as log:
        try:
            rep = run_scenario(str(v / "scenario.yaml"), out=str(v / "stage.usda"), report=str(v / "report.json"),
                               run_dir=str(v / "run"), fps=fps, fail_capped=fail_capped,
                               resume=resume and (v / "run" / "manifest.json").is_file(),
                               scheduler="sync" if store else None, store=store, log=log)
        except ComposeError as exc:
            print(f"compose: error: {exc}", file=log)
            return {"error": str(exc), "exit_code": exc.exit_code, "seconds": time.perf_counter() - t0,
                    **where, "ended": time.time()}
    return {"report": rep, "exit_code": 0 if rep["passes"] else 1, "seconds": time.perf_counter() - t0,
            **where, "ended": time.time()}


def _check_dir(out: Path, meta: dict, resume: bool) -> None:
    f = out / "sweep.json"
    if f.exists():
        if not resume:
            raise InputError(f"-o {out}: already holds a sweep; use --resume to continue it or another folder",
                             Location(str(f)))
        try:
            old = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"--resume: cannot read {f}: {exc}", Location(str(f))) from None
        if old.get("format") != FORMAT or old.get("variants") != meta["variants"]:
            raise InputError(f"--resume: {out} holds a different sweep (other scenario text or --vary values); "
                             "use another -o", Location(str(f)))
    elif out.exists() and any(out.iterdir()) and not resume:
        raise InputError(f"-o {out}: folder exists and is not empty", Location(str(out)))


def run_sweep(file: str, varies: list[str], out: str, *, scheduler: str | None = None, jobs: int = 1,
              resume: bool = False, fps: float = 30.0, fail_capped: bool = False, store: str | None = None,
              contact_sheet: bool = True, log=sys.stderr) -> list[dict]:
    """Run a sweep (see the module docstring); returns the summary rows."""
    if not varies:
        raise InputError("give at least one --vary PATH=VALUES", Location(None, field="--vary"))
    source = find_scenario(file)
    parsed = [parse_vary(a) for a in varies]
    variants = build_variants(file, parsed)  # every combination validated before anything runs
    out_dir = Path(out)
    meta = {"format": FORMAT, "scenario": str(source), "vary": list(varies),
            "variants": [{"index": v.index, "values": {p: val for p, val in v.assignment},
                          "scenario_sha256": _sha(v.yaml_text)} for v in variants]}
    _check_dir(out_dir, meta, resume)
    sched = None
    if scheduler is not None:
        from schedules.execution.distributed import connect

        sched = connect(scheduler, jobs)  # unreachable: exit 2 before anything is written
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(json.dumps(meta, indent=1) + "\n", out_dir / "sweep.json")
        if sched is not None and store is None:
            from schedules.execution.step_store import default_store

            store = str(default_store())
        store = store or None
        todo, outcomes = [], {}
        for v in variants:
            vdir = out_dir / f"v{v.index:03d}"
            rep = vdir / "report.json"
            if resume and rep.is_file() and (vdir / "scenario.yaml").is_file() \
                    and _sha((vdir / "scenario.yaml").read_text(encoding="utf-8")) == _sha(v.yaml_text):
                outcomes[v.index] = {"report": json.loads(rep.read_text(encoding="utf-8")), "resumed": True}
                outcomes[v.index]["exit_code"] = 0 if outcomes[v.index]["report"].get("passes") else 1
                print(f"compose: sweep variant {v.index} ({v.label}): kept from the interrupted sweep", file=log)
                continue
            vdir.mkdir(exist_ok=True)
            atomic_write_text(v.yaml_text, vdir / "scenario.yaml")
            todo.append(v)
        print(f"compose: sweep of {len(variants)} variant(s) of {source}: {len(todo)} to run"
              + (f" on {sched.describe()}" if sched else " one after another"), file=log, flush=True)
        t0 = time.perf_counter()

        def done(key: str, o: dict) -> None:
            i = int(key.split(":", 1)[1])
            outcomes[i] = o
            v = variants[i]
            what = (("passes" if o["report"]["passes"] else "fails") if "report" in o
                    else f"error: {o['error'].splitlines()[0]}")
            took = f" in {o['seconds']:.0f} s (process {o['pid']})" if "seconds" in o and "pid" in o else ""
            print(f"compose: sweep [{len(outcomes)}/{len(variants)}] variant {i} ({v.label}): {what}{took}; "
                  f"elapsed {time.perf_counter() - t0:.0f} s", file=log, flush=True)

        args = {v.index: (str(out_dir / f"v{v.index:03d}"), fps, fail_capped, store, resume) for v in todo}
        if sched is None:
            for v in todo:
                done(f"variant:{v.index}", run_variant(*args[v.index]))
        else:
            dsk = {f"variant:{i}": (run_variant, *a) for i, a in args.items()}
            sched.execute(dsk, list(dsk), done)
    finally:
        if sched is not None:
            sched.close()
    rows = [summary_row(v.index, v.assignment, outcomes[v.index]) for v in variants]
    for f in write_summary(rows, out_dir):
        print(f"compose: wrote {f}", file=log)
    if contact_sheet:
        try:
            p = write_contact_sheet([(v.label, out_dir / f"v{v.index:03d}" / "stage.usda") for v in variants],
                                    out_dir / "contact_sheet.png")
            if p:
                print(f"compose: wrote {p}", file=log)
        except ComposeError as exc:  # matplotlib missing: the sheet is a convenience
            print(f"compose: contact sheet skipped: {exc}", file=log)
    return rows


def _sweep(args) -> int:
    rows = run_sweep(args.file, args.vary or [], args.output, scheduler=args.scheduler, jobs=args.jobs,
                     resume=args.resume, fps=args.fps, fail_capped=args.fail_capped,
                     store="" if args.no_store else args.store, contact_sheet=not args.no_contact_sheet)
    return 0 if all(r["status"] == "passes" for r in rows) else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sweep", help="run every combination of varied scenario fields",
                       description="Vary scenario fields (--vary PATH=VALUES, several allowed), validate every "
                                   "combination, run each one and write per-variant stages and reports, a "
                                   "summary CSV and a contact sheet. Exit 2 on bad input, 1 if a variant fails.")
    add_scenario_argument(p)
    p.add_argument("--vary", action="append", metavar="PATH=VALUES",
                   help="a field path and its values: START:STOP:STEP or a comma list, "
                        "e.g. characters[0].start.heading=0:180:20")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="sweep folder")
    p.add_argument("--no-contact-sheet", action="store_true", help="do not draw contact_sheet.png")
    add_solve_options(p, what="variants")
    p.set_defaults(func=_sweep)
