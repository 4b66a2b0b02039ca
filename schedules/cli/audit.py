"""``compose audit STAGE``: the independent physics audit of any UsdSkel stage.

Exit 0 when the stage passes every tolerance of docs/audit.md, 1 when it does not (the
report says why), 2 on bad input.  The last line printed is the summary::

    audit: pass|fail frames=<int> fps=<float> penetration_max_mm=<float> stance_slide_max_mm=<float> flight_wrench_rms_bw=<float> cop_outside_max_cm=<float> dense_residual_max_bw=<float> interpenetration_max_cm=<float>
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from scenarios.errors import InputError

__all__ = ["register", "parse_groups"]


def parse_groups(values: list[str] | None) -> tuple:
    """``--group a,b`` (repeatable) → (("a", "b"), ...); ``--group auto`` → ("auto",)."""
    out = []
    for v in values or []:
        names = tuple(n.strip() for n in v.split(",") if n.strip())
        if names == ("auto",):
            return ("auto",)
        if len(names) < 2:
            raise InputError(f"--group {v!r}: name at least two characters, comma-separated (or 'auto')")
        out.append(names)
    return tuple(out)


def _audit(args) -> int:
    from scenegraph.stage_audit import AuditSettings, audit_stage, summary_line
    report = Path(args.report)
    folder = report.parent if str(report.parent) else Path(".")
    if report.is_dir() or not folder.is_dir():
        raise InputError(f"--report {report}: {'is a directory' if report.is_dir() else f'folder {folder} does not exist'}")
    if args.fps is not None and not (args.fps > 0):
        raise InputError(f"--fps must be positive, got {args.fps}")
    settings = AuditSettings(groups=parse_groups(args.group), allowed_contacts=tuple(args.allow or ()))
    rep = audit_stage(args.stage, args.fps, settings)
    from schedules.execution.checkpoints import atomic_write_text
    atomic_write_text(json.dumps(rep, indent=1) + "\n", report)
    for name, s in rep["systems"].items():
        w = s.get("cop_outside_worst")
        where = (f" (at {w['t']:g} s, normal force {w['normal_bw']:.3g} bw: a moment of {w['moment_bw_m']:.3g} bw·m)"
                 if w and s["cop_outside_max_cm"] > 0 else "")
        print(f"  {name}: mass {s['mass_kg']:.2f} kg, {s['contact_frames']} contact / {s['free_flight_frames']} "
              f"flight frames, CoP outside ≤ {s['cop_outside_max_cm']:.3g} cm{where}, friction use ≤ "
              f"{s['friction_use_max']:.3g}, residual ≤ {s['dense_residual_max_bw']:.3g} bw")
    for f in rep["failures"]:
        print(f"  FAILS: {f}")
    for n in rep["notes"]:
        print(f"  note: {n}", file=sys.stderr)
    print(summary_line(rep), flush=True)
    return 0 if rep["passes"] else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("audit", help="check the physics of any UsdSkel stage from its meshes alone",
                       description="Read a UsdSkel stage (joint transforms, skinned meshes; masses from "
                                   "UsdPhysics.MassAPI or 1000 kg/m^3) and check, per character and frame, the "
                                   "external wrench its momenta need, centre of pressure, friction, flight, floor "
                                   "penetration, stance sliding and overlap between characters (docs/audit.md). "
                                   "Exit 0 pass, 1 fail, 2 bad input.")
    p.add_argument("stage", metavar="STAGE", help="a .usda/.usdc/.usdz stage")
    p.add_argument("--fps", type=float, default=None,
                   help="audit rate (default: the stage's time codes per second; 120 or more is advised)")
    p.add_argument("--group", action="append", metavar="a,b",
                   help="characters checked as one system (forces between them cancel); repeatable; "
                        "'auto' groups characters that touch")
    p.add_argument("--allow", action="append", metavar="A/MESH~B/MESH",
                   help="an overlap asked for (fnmatch pattern), e.g. 'adult/*hand_r~child/*hand_l'; repeatable")
    p.add_argument("--report", metavar="R.json", required=True, help="the JSON report to write")
    p.set_defaults(func=_audit)
