"""Synthesis from footprints in one call: initialise, pre-solve kinematics, solve, audit.

This is the paper's basic task (§7): given footprints and a style, the motion that
minimises weighted muscle effort subject to the dynamics.  The schedule executor runs the
same pieces step by step; this module is the direct path used by examples and benchmarks.
"""
from __future__ import annotations

from dataclasses import dataclass

from scenegraph.model.audit import Audit, audit_motion
from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.gait import initial_motion
from scenegraph.model.motion import Motion
from scenegraph.problem import Result, Subproblem, solve
from scenegraph.model.style import Style

__all__ = ["Synthesis", "synthesize", "presolve_kinematics"]


@dataclass(frozen=True)
class Synthesis:
    result: Result
    audit: Audit
    presolve: Result | None
    seconds: float


def presolve_kinematics(ch: Character, style: Style, motion: Motion, footsteps: tuple[Footstep, ...],
                        **kw) -> Result:
    """Make an initial motion satisfy footsteps and ground constraints (no dynamics).

    With ``flights`` (world s (take-off, landing)) the ballistic momentum rows of the full step
    (:mod:`.flight`) are held too, with their exact curvature: a jump's full step then starts with its
    flight rows satisfied (broad_jump: 2.05 instead of 290 kg·m/s, docs/dynamic-motion.md round 13);
    without that curvature this pre-solve ran to its 300-iteration cap (126 iterations with it).  The
    executor does not pass flights (``executor.PRESOLVE_FLIGHTS``: measured, the iteration count did not fall)."""
    if kw.get("flights"):
        kw.setdefault("flight_curvature", True)
    return solve(Subproblem(ch, style, motion, footsteps, free=frozenset({"q"}), dynamics="kinematic",
                            label="kinematic", **kw))


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
