"""Which body pairs of a scene's characters a full step keeps apart, and when (issue #15, item 5).

:func:`scene_clearance` gives the clearance constraints (:class:`~scenegraph.model.clearance.BodyClearance`)
of one character against every other one, each held at its current motion, on a grid of
``rate`` Hz over a window (world s); the spheres and the pair test are in
:mod:`scenegraph.model.clearance`.  Contacts a scene asks for are left out: held hands (each
against the partner's held hand and the forearm next to it — the spheres of a held hand
reach past the wrist of the hand it holds; the rest of the partner's body stays
constrained) and the two characters a goal asks to touch (:meth:`GoalRecord.touches`) from
the time it allows it on (:meth:`GoalRecord.touches_from`, e.g. a tackle 0.15 s before the hit).
"""
from __future__ import annotations

import math

import numpy as np

from scenegraph.model.clearance import CLEARANCE_HZ, CLEARANCE_MARGIN, BodyClearance, body_spheres, clearance_pairs

__all__ = ["scene_clearance"]


def _with_forearm(hands: set) -> set:
    """Held hand bodies ("hand_l") with their forearms ("forearm_l")."""
    return set(hands) | {"forearm_" + h.rsplit("_", 1)[1] for h in hands if h.startswith("hand_")}


def scene_clearance(scene, who: str, window: tuple[float, float], rate: float = CLEARANCE_HZ,
                    margin: float = CLEARANCE_MARGIN) -> tuple[BodyClearance, ...]:
    """Clearance constraints of character ``who`` against every other character of ``scene``
    (held at its current motion) at ``rate`` Hz over ``window`` (world s); see the module
    docstring for what is left out."""
    me = scene.character(who)
    a, b = float(window[0]), float(window[1])
    times = np.linspace(a, b, max(2, int(math.ceil((b - a) * rate)) + 1))
    out: list[BodyClearance] = []
    for other in scene.characters:
        if other.name == who:
            continue
        held_me, held_other = set(), set()
        for cpl in scene.couplings:
            names = {w for w, _ in cpl.handles}
            if who in names and other.name in names:
                held_me |= {me.character.handle(h).body for w, h in cpl.handles if w == who}
                held_other |= {other.character.handle(h).body for w, h in cpl.handles if w == other.name}
        t_end = min([g.touches_from() for g in scene.goals if g.touches() is not None
                     and set(g.touches()) == {who, other.name}], default=np.inf)
        ts = times[times <= t_end + 1e-9]
        ts = ts[(ts >= other.motion.start - 1e-9) & (ts <= other.motion.end + 1e-9)]
        if not len(ts):
            continue
        skip = frozenset((x.body, y.body) for x in body_spheres(me.character) for y in body_spheres(other.character)
                         if (x.body in held_me and y.body in _with_forearm(held_other))
                         or (y.body in held_other and x.body in _with_forearm(held_me)))
        qa, _, _ = me.motion.at(ts)
        qb, _, _ = other.motion.at(ts)
        out += clearance_pairs(me.character, np.atleast_2d(qa), other.character, np.atleast_2d(qb), ts, skip,
                               other.name, margin)
    return tuple(out)
