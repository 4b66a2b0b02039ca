"""Goals and couplings as typed records, one module per kind (see :mod:`.base`).

``GOAL_KINDS`` maps a goal ``type`` of the scenario language to its record class; a test
checks that it names exactly the schema's goal kinds (``scenarios.schema.Goal``), and the
same for ``COUPLING_KINDS``.  :func:`goal_records` and :func:`coupling_records` translate a
validated Scenario.  Adding a goal kind: its pydantic model in ``scenarios/schema.py`` (the
language and the plan facts) and one module here (everything the scene, the solver and the
report need).
"""
from __future__ import annotations

from scenegraph.world.goals.avoid import Avoid
from scenegraph.world.goals.base import GoalRecord, violated_by, where_of
from scenegraph.world.goals.couplings import COUPLING_KINDS, Carry, Coupling, HandHold
from scenegraph.world.goals.footprints import Footprints
from scenegraph.world.goals.jump import Hop, Jump
from scenegraph.world.goals.keyframes import Keyframes
from scenegraph.world.goals.reach import Reach
from scenegraph.world.goals.style_change import StyleChange
from scenegraph.world.goals.tackle import Tackle
from scenegraph.world.goals.walk_to import WalkTo

__all__ = ["GOAL_KINDS", "COUPLING_KINDS", "GoalRecord", "Coupling", "WalkTo", "Reach", "Tackle", "Avoid",
           "Footprints", "StyleChange", "Jump", "Hop", "Keyframes", "HandHold", "Carry", "goal_records", "coupling_records", "where_of",
           "violated_by"]

GOAL_KINDS: dict[str, type[GoalRecord]] = {k.kind: k for k in (Footprints, WalkTo, Reach, Tackle, Avoid, StyleChange,
                                                          Jump, Hop, Keyframes)}


def goal_records(scn, plans_last: dict[frozenset, str]) -> tuple[GoalRecord, ...]:
    """The goal records of a Scenario, in file order; ``plans_last`` per adversarial pair."""
    out = []
    for j, (name, g) in enumerate(scn.named_goals()):
        cls = GOAL_KINDS[g.type]
        pair = getattr(g, "opponents", None)
        out.append(cls.from_schema(name, g, scn, j, plans_last.get(frozenset(pair)) if pair else None))
    return tuple(out)


def coupling_records(scn) -> tuple[Coupling, ...]:
    return tuple(COUPLING_KINDS[c.type].from_schema(name, c, scn, i) for i, (name, c) in enumerate(scn.named_couplings()))
