"""What every goal record is: the scene-side half of a goal kind.

A goal kind lives in two places, one per layer: its pydantic model in
:mod:`scenarios.schema` (fields, validation, and the plan facts the compiler needs without
CasADi: ``active(window)``, ``plan_weight``) and its record here, one module per kind, which
owns the rest — the translation from the schema (:meth:`GoalRecord.from_schema`), the solver
terms (:meth:`GoalRecord.targets`), the measure and report entry (:meth:`GoalRecord.entry`)
and the stage markers (:meth:`GoalRecord.markers`).  A record carries its scenario location
(``where``: ``file:line:col goals[j] (name)``), so a goal that does not hold is reported as
``walk_to.yaml:9:5 goals[0] (walk_to_0): … violated by 0.03 m``.

Units: SI (m, s); times are world seconds of the initial motion (canonical seconds).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from scenarios.weights import TARGET_WEIGHT

__all__ = ["GoalRecord", "AdversarialGoal", "Marker", "where_of", "violated_by"]

Marker = tuple[str, tuple[float, float, float], float]  # (name, world position m, radius m)


def where_of(scn, path: tuple, name: str) -> str:
    """``file:line:col field (name)`` of a scenario path, e.g. ``tackle.yaml:14:5 goals[0] (hit)``."""
    loc = scn.location(path)
    prefix = loc.prefix() if loc is not None else ""
    return f"{prefix} ({name})" if prefix else f"({name})"


def violated_by(measured, tolerance, at_least: bool = False) -> float | None:
    """How far (m) a measure misses its tolerance: measured − tolerance (tolerance − measured
    for an ``at_least`` bound); None when it holds or is not measured."""
    if measured is None or tolerance is None:
        return None
    miss = (tolerance - measured) if at_least else (measured - tolerance)
    return float(miss) if miss > 0 else None


@dataclass(frozen=True, kw_only=True)
class GoalRecord:
    """Fields every goal kind has; subclasses add their own and set ``kind``.

    name        the goal's name (``<type>_<index>`` unless given)
    character   whose motion must satisfy it (a tackle's attacker)
    time        s, when it must hold (None for footprints)
    tolerance   the report's bound (m unless the entry says otherwise)
    where       its scenario location, ``file:line:col goals[j] (name)``
    partner     the other character (a tackle's target, an avoid's ``around``)
    plans_last  tackle/avoid: who plans last in the pair (decides the outcome)
    """

    kind: ClassVar[str] = ""
    default_weight: ClassVar[float] = TARGET_WEIGHT  # spring weight without a Step's (scenarios/weights.py)
    name: str
    character: str
    time: float | None = None
    tolerance: float = 0.0
    where: str = ""
    partner: str | None = None
    plans_last: str | None = None

    @property
    def type(self) -> str:
        return self.kind

    @property
    def expected_to_hold(self) -> bool | None:
        """Adversarial goals: True for the side that plans last (it wins by design of the
        decreasing-horizon schedule), False for the other; None for the rest."""
        return None

    def targets(self, scene, me, weight: float, window, hard: bool = False) -> list:
        """Soft (or, with ``hard``, equality) handle targets for the character's subproblem:
        ``weight`` is the Step's ``goal:<name>`` weight, ``window`` the optimised world-time
        window (None: whole).  Default: none (the goal acts through footsteps or styles)."""
        return []

    def entry(self, scene, audits: dict | None) -> dict:
        """The report entry: ``type``, ``what``, ``measured``, ``tolerance``, ``unit``, ``holds``, ``where``."""
        raise NotImplementedError

    def markers(self) -> list[Marker]:
        """Stage markers of the goal (default none)."""
        return []

    def step_rank(self, who: str) -> int | None:
        """This goal's say in planning ``who``'s initial footsteps: among a character's goals
        the lowest rank plans them (:func:`scenegraph.world.footplan.plan_footsteps`); None:
        no say (the default)."""
        return None

    @classmethod
    def plan_steps(cls, goals: list, ctx):
        """A :class:`~scenegraph.world.footplan.StepPlan` for ``ctx.who`` from its goals of this
        kind and rank (file order)."""
        raise NotImplementedError(f"{cls.kind} has a step rank but plans no footsteps")

    def sequence_span(self) -> tuple[float | None, float, float] | None:
        """(begins or None: right after the previous goal, ends, hands off) s when this goal
        plans a time segment of its character's footsteps and can follow or precede goals of
        another such kind (walk_to, jump, hop: :func:`scenegraph.world.footplan.plan_sequence`);
        None (the default) otherwise."""
        return None

    def sequence_entry(self) -> tuple[float, float] | None:
        """Where (x, y) m this goal needs its character when its segment begins (a leap: the
        take-off); the segment before it ends its footsteps there.  None (the default):
        wherever the previous segment leaves it."""
        return None

    def touches(self) -> tuple[str, str] | None:
        """Two characters whose bodies this goal asks to touch (a tackle's attacker and
        target), exempt from the bodies-apart checks; None (the default) for the rest."""
        return None

    def touches_from(self) -> float:
        """World time (s) from which the bodies of :meth:`touches` may meet; before it they
        are kept apart like anybody's (default: from the start)."""
        return float("-inf")

    def gait_change(self, who: str) -> tuple[float, float, str] | None:
        """(time s, blend s, gait) when this goal changes ``who``'s gait (default: None)."""
        return None

    def _entry(self, measured, what: str, unit: str = "m", **extra) -> dict:
        holds = extra.pop("holds", None)
        if holds is None:
            holds = measured is not None and measured <= self.tolerance
        e = {"type": self.kind, "what": what, "measured": measured, "tolerance": self.tolerance, "unit": unit,
             "holds": bool(holds), **extra, "where": self.where}
        return e


@dataclass(frozen=True, kw_only=True)
class AdversarialGoal(GoalRecord):
    """A goal against ``partner`` (tackle, avoid): solved by the decreasing-horizon schedule,
    where the side that plans last wins; its soft springs ask for no more than the reaction
    time left in the window allows (:func:`scenegraph.world.measure.reach_budget`)."""

    @property
    def expected_to_hold(self) -> bool:
        return self.plans_last == self.character

    def springs(self, scene, me, budget: float, weight: float) -> list:
        """The kind's soft targets within ``budget`` (m) of movement."""
        raise NotImplementedError

    def targets(self, scene, me, weight, window, hard: bool = False) -> list:
        from dataclasses import replace

        from scenegraph.world.measure import reach_budget
        out = self.springs(scene, me, reach_budget(self, me, window), weight)
        return [replace(t, hard=True) for t in out] if hard else out

