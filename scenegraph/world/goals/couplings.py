"""Couplings as typed records: ``hand_hold`` (two handles coincide) and ``carry`` (holders
share an object's weight).  Each owns its translation from the schema, its solver terms
(a rubber band: :meth:`Coupling.targets` and, for a hand-hold, the physical spring
:meth:`Coupling.springs`; a hard hand-hold is a joint solve, ``scenegraph.problem.joint``) and its
report entry (:meth:`Coupling.entry`).  Times are world seconds; positions m; stiffness N/m.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from scenegraph.world.measure import handle_track
from scenegraph.problem import HandleTarget, Spring
from scenegraph.world.goals.base import where_of

__all__ = ["Coupling", "HandHold", "Carry", "coupling_targets", "coupling_springs", "COUPLING_KINDS",
           "HAND_HOLD_TOL", "CARRY_TOL"]

HAND_HOLD_TOL = 0.01  # m: hands within this distance count as holding (issue #7: ≤ 1 cm)
CARRY_TOL = 0.05  # m: a holder's hand within this of the holders' centre's path


@dataclass(frozen=True, kw_only=True)
class Coupling:
    """handles: ((character, handle), ...); interval: (t0, t1) s; mass: kg (carry);
    where: its scenario location ``file:line:col couplings[i] (name)``."""

    kind: ClassVar[str] = ""
    name: str
    handles: tuple[tuple[str, str], ...]
    interval: tuple[float, float]
    tolerance: float = HAND_HOLD_TOL
    mass: float = 0.0
    where: str = ""

    @property
    def type(self) -> str:
        return self.kind

    def targets(self, scene, character: str, stiffness: float, window, rate: float = 10.0) -> tuple:
        """Rubber-band target points of ``character`` (:func:`coupling_targets`)."""
        return coupling_targets(scene, character, self, stiffness, window, rate)

    def springs(self, scene, character: str, stiffness: float, window, rate: float = 60.0) -> tuple:
        """Physical springs of ``character`` (a hand-hold's; none for a carry)."""
        return ()

    def loads(self, character: str) -> tuple[tuple[str, float], ...]:
        """(handle, kg) this coupling hangs on ``character``'s body (default none)."""
        return ()

    def entry(self, scene) -> dict:
        """Report entry: the largest distance between the held handles (two holders) or of a
        holder's handle from their centre, over the interval at 30 Hz (m), within ``tolerance``."""
        c = self
        t = np.linspace(c.interval[0], c.interval[1], max(2, int((c.interval[1] - c.interval[0]) * 30) + 1))
        tracks = [handle_track(scene.character(w), h, t) for w, h in c.handles]
        centre = np.mean(tracks, axis=0)
        d = float(max(np.linalg.norm(tr - centre, axis=1).max() for tr in tracks)) * (2 if len(tracks) == 2 else 1)
        return {"type": c.type, "what": "max distance between the held handles over the interval"
                if len(tracks) == 2 else "max distance of a holder's handle from their centre",
                "measured": d, "tolerance": c.tolerance, "unit": "m", "holds": d <= c.tolerance, "where": c.where}


def _common(name: str, refs, c, scn, i: int) -> dict:
    """The fields every coupling record takes from its schema model ``couplings[i]``."""
    return {"name": name, "handles": tuple((r.character, r.handle) for r in refs),
            "interval": (float(c.interval[0]), float(c.interval[1])), "where": where_of(scn, ("couplings", i), name)}


@dataclass(frozen=True, kw_only=True)
class HandHold(Coupling):
    kind = "hand_hold"

    @classmethod
    def from_schema(cls, name: str, c, scn, i: int) -> "HandHold":
        return cls(**_common(name, c.between, c, scn, i))

    def springs(self, scene, character: str, stiffness: float, window, rate: float = 60.0) -> tuple:
        return coupling_springs(scene, character, self, stiffness, window, rate)


@dataclass(frozen=True, kw_only=True)
class Carry(Coupling):
    kind = "carry"

    @classmethod
    def from_schema(cls, name: str, c, scn, i: int) -> "Carry":
        return cls(**_common(name, c.holders, c, scn, i), mass=float(c.mass), tolerance=CARRY_TOL)

    def loads(self, character: str) -> tuple[tuple[str, float], ...]:
        """The carried mass shared equally by its holders (a static share)."""
        return tuple((h, self.mass / len(self.handles)) for who, h in self.handles if who == character)


COUPLING_KINDS = {k.kind: k for k in (HandHold, Carry)}


def coupling_targets(scene, character: str, coupling: Coupling, stiffness: float,
                     window: tuple[float, float], rate: float = 10.0) -> tuple[HandleTarget, ...]:
    """Rubber-band springs of a coupling for ``character``: its handle toward the partners' held
    handles (their current motion) at ~``rate`` Hz inside the coupling interval ∩ window.

    The weight grows with the stiffness (N/m): w = stiffness / (m g) · 10 per point.
    """
    c = coupling
    mine = [h for who, h in c.handles if who == character]
    others = [(who, h) for who, h in c.handles if who != character]
    if not mine or not others:
        return ()
    a, b = max(c.interval[0], window[0]), min(c.interval[1], window[1])
    if b <= a:
        return ()
    n = max(2, int(math.ceil((b - a) * rate)) + 1)
    times = np.linspace(a, b, n)
    me = scene.character(character)
    w = float(stiffness) / (me.character.total_mass * 9.81) * 10.0
    out = []
    for who, h in others:
        track = handle_track(scene.character(who), h, times)
        for t, p in zip(times, track):
            out.append(HandleTarget(mine[0], float(t), tuple(float(v) for v in p), w, name=f"coupling:{c.name}"))
    return tuple(out)


def coupling_springs(scene, character: str, coupling: Coupling, stiffness: float,
                     window: tuple[float, float], rate: float = 60.0) -> tuple[Spring, ...]:
    """The physical rubber band of a hand-hold for ``character``: a spring of ``stiffness``
    (N/m) from its handle to each partner's held handle (their current motion), sampled at
    ``rate`` Hz over the coupling interval ∩ window.  Solved in turn, each partner feels the
    equal and opposite force k (p_other − p_own) (thesis §6.4.3)."""
    c = coupling
    mine = [h for who, h in c.handles if who == character]
    others = [(who, h) for who, h in c.handles if who != character]
    a, b = max(c.interval[0], window[0]), min(c.interval[1], window[1])
    if not mine or not others or b <= a:
        return ()
    times = np.linspace(a, b, max(2, int(math.ceil((b - a) * rate)) + 1))
    return tuple(Spring(mine[0], tuple(float(t) for t in times),
                        tuple(tuple(float(v) for v in p) for p in handle_track(scene.character(who), h, times)),
                        float(stiffness), name=f"coupling:{c.name}")
                 for who, h in others)
