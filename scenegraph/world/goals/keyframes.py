"""``keyframes``: a rough sketch — soft springs toward a few keys (thesis ch. 3).

Solver: per key, a pelvis spring toward ``position`` (x, y, z) and a partial pose spring on
the root yaw (``heading``) and the named joint DOFs, each weighted by the Step's
``goal:<name>`` weight × the key's ``weight`` (pose springs per rad², position per m²).
Measure: the largest pelvis distance from a key's position (m), within ``tolerance``;
keys without a position are reported with their largest angle error (deg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenegraph.model.body import N_DOF
from scenegraph.world.measure import handle_track
from scenegraph.problem import HandleTarget, PoseTarget
from scenegraph.world.goals.base import GoalRecord, Marker, where_of

__all__ = ["Keyframes", "Key"]


@dataclass(frozen=True)
class Key:
    """t: s; position: pelvis (x, y, z) m or None; angles: ((dof name, rad), …) incl. root_yaw."""

    t: float
    position: tuple[float, float, float] | None
    angles: tuple[tuple[str, float], ...]
    weight: float


@dataclass(frozen=True, kw_only=True)
class Keyframes(GoalRecord):
    kind = "keyframes"
    keys: tuple[Key, ...]

    @classmethod
    def from_schema(cls, name: str, g, scn, j: int, plans_last=None) -> "Keyframes":
        keys = []
        for k in sorted(g.keys, key=lambda k: k.time):
            ang = [("root_yaw", math.radians(k.heading))] if k.heading is not None else []
            ang += [(d, math.radians(a)) for d, a in sorted(k.joints.items())]
            keys.append(Key(float(k.time), None if k.position is None else tuple(float(x) for x in k.position),
                            tuple(ang), float(k.weight)))
        return cls(name=name, character=g.character, time=keys[-1].t, tolerance=float(g.tolerance),
                   where=where_of(scn, ("goals", j), name), keys=tuple(keys))

    def targets(self, scene, me, weight, window, hard: bool = False) -> list:
        ch = me.character
        out: list = []
        for k in self.keys:
            if k.position is not None:
                out.append(HandleTarget("pelvis", k.t, k.position, weight * k.weight, hard=hard,
                                        name=f"goal:{self.name}"))
            if k.angles:
                q = np.zeros(N_DOF)
                idx = []
                for d, a in k.angles:
                    i = ch.dof_index(d)
                    q[i] = a
                    idx.append(i)
                out.append(PoseTarget(k.t, tuple(q), weight * k.weight, dofs=tuple(idx)))
        return out

    def entry(self, scene, audits) -> dict:
        me = scene.character(self.character)
        dist, ang = [], []
        for k in self.keys:
            if k.position is not None:
                dist.append(float(np.linalg.norm(handle_track(me, "pelvis", [k.t])[0] - np.asarray(k.position))))
            if k.angles:
                q = me.motion.state_at_s(me.motion.to_canonical([k.t]))[0][0]
                ang += [abs(math.degrees(float(q[me.character.dof_index(d)]) - a)) for d, a in k.angles]
        e = self._entry(max(dist) if dist else 0.0, "largest pelvis distance from a key's position")
        e["angle_error_max_deg"] = max(ang) if ang else None
        return e

    def markers(self) -> list[Marker]:
        return [(f"goal_{self.name}_{i}", k.position, 0.04) for i, k in enumerate(self.keys) if k.position is not None]
