"""Synthesis from footprints in one call: initialise, pre-solve kinematics, solve, audit.

This is the paper's basic task (§7): given footprints and a style, the motion that
minimises weighted muscle effort subject to the dynamics.  The schedule executor runs the
same pieces step by step; this module is the direct path used by examples and benchmarks.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .audit import Audit, audit_motion
from .body import Character
from .footsteps import Footstep
from .gait import initial_motion
from .motion import Motion
from .problem import Result, Subproblem, solve
from .style import Style

__all__ = ["Synthesis", "synthesize", "presolve_kinematics"]


@dataclass(frozen=True)
class Synthesis:
    result: Result
    audit: Audit
    presolve: Result | None
    seconds: float


PRESOLVE_TILE = 2.5  # s: longer motions are pre-solved in overlapping windows of this length


def presolve_kinematics(ch: Character, style: Style, motion: Motion, footsteps: tuple[Footstep, ...],
                        tile: float = PRESOLVE_TILE, **kw) -> Result:
    """Make an initial motion satisfy footsteps and ground constraints (no dynamics).

    A motion longer than ``tile`` seconds (world time) is pre-solved window by window, in
    windows of ``tile`` seconds that overlap by half (every control point lies inside one),
    each starting from the previous one's result: the cost grows linearly with the length
    of the motion (one problem over a 4.8 s walk took 41 s; 116 iterations).  The result
    sums iterations and seconds, is a success when every window is, and reports the worst
    violation per constraint group over the windows."""
    label = kw.pop("label", "kinematic")
    if motion.duration <= tile * 1.2:
        return solve(Subproblem(ch, style, motion, footsteps, free=frozenset({"q"}), dynamics="kinematic",
                                label=label, **kw))
    n = int(np.ceil((motion.duration - tile) / (tile / 2))) + 1
    starts = np.linspace(motion.start, motion.end - tile, n)
    parts, cur = [], motion
    for i, t0 in enumerate(starts):
        r = solve(Subproblem(ch, style, cur, footsteps, window=(float(t0), float(t0 + tile)), free=frozenset({"q"}),
                             dynamics="kinematic", label=f"{label}[{i}]", **kw))
        parts.append(r)
        if r.success:
            cur = r.motion
    viol: dict = {}
    for r in parts:
        for k, v in r.violations.items():
            viol[k] = max(viol.get(k, 0.0), v)
    failed = [r.status for r in parts if not r.success]
    return replace(parts[-1], motion=cur, status=failed[0] if failed else parts[-1].status, success=not failed,
                   iterations=sum(r.iterations for r in parts), seconds=sum(r.seconds for r in parts),
                   violations=viol, label=label, timing=None)


def synthesize(ch: Character, style: Style, footsteps: tuple[Footstep, ...], t0: float, t1: float, *,
               free=frozenset({"q"}), run: bool = False, init: Motion | None = None, example=None,
               **subproblem) -> Synthesis:
    """Synthesize a motion over world time [t0, t1] (s) that plants ``footsteps``."""
    m0 = init or initial_motion(ch, footsteps, t0, t1, run=run, example=example, ground=subproblem.get("ground"))
    shared = {k: v for k, v in subproblem.items() if k in ("collocation_hz", "constraint_hz", "cyclic", "ground")}
    pre = presolve_kinematics(ch, style, m0, footsteps, **shared)
    start = pre.motion if pre.success else m0
    res = solve(Subproblem(ch, style, start, footsteps, free=frozenset(free), label="synthesis", **subproblem))
    aud = audit_motion(ch, style, res.motion, res.footsteps, res.contact_forces,
                       **({"ground": subproblem["ground"]} if "ground" in subproblem else {}))
    return Synthesis(res, aud, pre, pre.seconds + res.seconds)
