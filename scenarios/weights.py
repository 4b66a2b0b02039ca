"""Default weights of the soft terms a scenario's goals and starts become (a leaf module).

The compiler writes them into each Step (``goal:<name>``, ``start``), and the scene's
goal→term translation and the executor use them when they build a subproblem.  They live in
the language package, the one layer that both :mod:`schedules` (the plan, which must stay
free of CasADi and of the character model) and :mod:`scenegraph` may import.

Units: 1/m² of the normalised objective (a weight times a squared distance in metres).
"""
from __future__ import annotations

__all__ = ["TARGET_WEIGHT", "START_WEIGHT", "AVOID_WEIGHT"]

TARGET_WEIGHT = 300.0  # soft goal springs (walk_to, reach, tackle)
START_WEIGHT = 100.0   # soft spring holding the pelvis at the character's start position
AVOID_WEIGHT = 300.0   # soft escape springs (1000 made IPOPT oscillate)
