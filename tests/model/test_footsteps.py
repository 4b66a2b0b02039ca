"""One footstep generator (scenegraph/model/footsteps.py) with one foot width: every plan it makes —
a straight walk or run, a walk along a path, a walk→run change, standing — puts the feet
FOOT_WIDTH apart, and nothing else in the package generates footsteps."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from scenegraph.model.footsteps import (FOOT_WIDTH, GAITS, footsteps_for_walk, gait_footsteps, standing_footsteps,
                                  walk_footsteps)

ROOT = Path(__file__).resolve().parents[2]


def _lateral(steps, heading=(1.0, 0.0)) -> set[float]:
    """|lateral offset| (m) of each footstep's ball from the line through the origin along ``heading``."""
    lat = np.array([-heading[1], heading[0]])
    return {round(abs(float(np.dot(f.position, lat))), 9) for f in steps}


@pytest.mark.parametrize("steps", [
    footsteps_for_walk(),
    footsteps_for_walk(step_length=1.0, cadence=GAITS["run"].cadence, stance_fraction=GAITS["run"].stance_fraction,
                       gait="run"),
    walk_footsteps((0.0, 0.0), (1.5, 0.0), 0.0, 1.4),
    gait_footsteps((0.0, 0.0), (4.0, 0.0), 0.0, 2.0, (1.0, 0.6, "run")),
    gait_footsteps((0.0, 0.0), (3.0, 0.0), 0.0, 1.4, before="run"),
    standing_footsteps((0.0, 0.0, 0.0), 0.0, 1.0, 0.2),
], ids=["straight walk", "straight run", "walk_to", "walk to run", "run_to", "standing"])
def test_every_generated_plan_puts_the_feet_foot_width_apart(steps):
    assert _lateral(steps) == {round(FOOT_WIDTH / 2, 9)}
    feet = {f.foot for f in steps}
    assert feet == {"l", "r"}


# modules that construct footsteps without generating a plan, and why
NOT_GENERATORS = {
    "scenegraph/world/goals/footprints.py": "Footprints.plan_steps: one Footstep per footprint written in the scenario",
    "scenegraph/mocap/contacts.py": "its own Footstep type: contacts detected in a mocap clip",
    "schedules/execution/checkpoints.py": "reads footsteps stored in a checkpoint",
    "schedules/cli/learn.py": "footsteps measured from a mocap clip (the learning target)",
    "scenegraph/world/footplan.py": "_merge: one stance from two generated stances of a foot meeting at a seam",
}


def test_no_other_module_generates_footsteps():
    """Only scenegraph/model/footsteps.py makes footstep plans; the other places that construct a
    ``Footstep(...)`` copy footsteps from a file, a clip or a checkpoint (NOT_GENERATORS), and
    no module but footsteps.py holds a foot-width constant."""
    makers = {}
    for p in sorted((ROOT / "scenegraph").rglob("*.py")) + sorted((ROOT / "schedules").rglob("*.py")):
        text = p.read_text(encoding="utf-8")
        tree = ast.parse(text)
        n = sum(1 for node in ast.walk(tree) if isinstance(node, ast.Call)
                and getattr(node.func, "id", None) == "Footstep")
        rel = str(p.relative_to(ROOT))
        if n:
            makers[rel] = n
        if rel != "scenegraph/model/footsteps.py":
            assert "FOOT_WIDTH =" not in text and "width: float = 0.1" not in text, rel
    assert set(makers) - {"scenegraph/model/footsteps.py"} <= set(NOT_GENERATORS), makers


def test_airborne_gaps_are_the_runs_flights_and_a_walk_has_none():
    from scenegraph.model.footsteps import Footstep, airborne_gaps
    run = footsteps_for_walk(step_length=1.0, cadence=2.8, stance_fraction=0.38, gait="run")
    gaps = airborne_gaps(run)
    np.testing.assert_allclose(gaps, [(a.t1, b.t0) for a, b in zip(run, run[1:])])
    assert all(b > a for a, b in gaps)
    assert airborne_gaps(footsteps_for_walk()) == ()  # double support: never airborne
    # a heel that lands late or a ball that lifts early shortens the planted interval
    late = Footstep("l", (0.0, 0.0), 1.0, 2.0, heel=None, ball=(0.25, 0.5))
    early = Footstep("r", (0.5, 0.0), 0.0, 1.0, heel=(0.0, 0.5), ball=(0.1, 0.8))
    np.testing.assert_allclose(airborne_gaps((late, early)), [(0.8, 1.25)])
