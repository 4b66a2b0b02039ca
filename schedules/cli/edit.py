"""``compose edit CLIP.bvh [--frames A:B] --longer M --higher M --turn DEG -o OUT.usda``: edit
a captured jump keeping its momentum pattern (thesis ch. 4; docs/dynamic-motion.md).

Writes the stage, a BVH (``--bvh``, default next to the stage) and a JSON report
(``--report``, default ``OUT.edit.json``).  Exit 0, or 2 on bad input.  The last line::

    edit: longer=<m> higher=<m> turn_deg=<deg> momentum_corr=<float> parabola_rms_mm=<float> naive_parabola_rms_mm=<float> edit_s=<float>
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register"]


def _edit(args) -> int:
    from scenegraph.export.clip_edit import edit_clip

    from schedules.execution.checkpoints import atomic_write_text
    from schedules.cli.learn import parse_frames
    frames = parse_frames(args.frames) if args.frames else None
    out = Path(args.output)
    rep = edit_clip(args.clip, out, args.bvh, frames, args.longer, args.higher, args.turn)
    report = Path(args.report) if args.report else out.with_suffix(".edit.json")
    atomic_write_text(json.dumps(rep, indent=1) + "\n", report)
    m = rep["measured"]
    print(f"  clip flight {m['clip_flight_s']:.3f} s, com apex +{m['clip_com_apex_rise']:.3f} m, distance "
          f"{m['clip_com_flight_distance']:.3f} m -> flight {m['flight_s']:.3f} s, apex +{m['com_apex_rise']:.3f} m, "
          f"distance {m['com_flight_distance']:.3f} m, turn {m['turn_deg']:.1f} deg; planted feet within "
          f"{m['planted_foot_error_max'] * 100:.1f} cm")
    print(f"  wrote {rep['stage']}, {rep['bvh']}, {report}")
    fl, nv = rep["flight"], rep["naive"]["flight"]
    print(f"edit: longer={args.longer:g} higher={args.higher:g} turn_deg={args.turn:g} "
          f"momentum_corr={m['momentum_corr']['min']:.4f} parabola_rms_mm={fl.get('parabola_rms_mm', float('nan')):.4g} "
          f"naive_parabola_rms_mm={nv.get('parabola_rms_mm', float('nan')):.4g} edit_s={rep['edit_seconds']:.3f}",
          flush=True)
    return 0


DESCRIPTION = ("Fit the clip, pre-fit its momentum curves, and solve for a jump that lands --longer m further, "
               "rises --higher m higher and turns --turn degrees more with the clip's momentum shape "
               "(docs/dynamic-motion.md). Writes a USD stage, a BVH and a JSON report.")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("edit", help="edit a captured jump (longer, higher, turned) keeping its momentum pattern",
                       description=DESCRIPTION)
    p.add_argument("clip", metavar="CLIP.bvh")
    p.add_argument("--frames", metavar="A:B", help="source frames [A, B) of the jump (default: all)")
    p.add_argument("--longer", type=float, default=0.0, metavar="M", help="land this much further (m)")
    p.add_argument("--higher", type=float, default=0.0, metavar="M", help="raise the apex this much (m)")
    p.add_argument("--turn", type=float, default=0.0, metavar="DEG", help="turn this much more in the air (deg)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.usda", help="the edited stage")
    p.add_argument("--bvh", metavar="OUT.bvh", help="the edited motion as BVH (default: next to the stage)")
    p.add_argument("--report", metavar="R.json", help="JSON report (default OUT.edit.json)")
    p.set_defaults(func=_edit)
