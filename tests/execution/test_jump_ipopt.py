"""The per-step IPOPT switch of jump full steps (schedules.execution.lower.JUMP_FULL_IPOPT, round 15).

The lowering adds ``JUMP_FULL_IPOPT`` to a full step's Subproblem.ipopt_options when the step holds
a jump goal's flight, and to no other step (a walk, a run's gait flights); solver_options passes
them to IPOPT on top of the project's defaults.  Lowering only: no solve (the measured effect of
the options is in docs/dynamic-motion.md "Speed (round 15)").
"""
from __future__ import annotations

import pytest

from scenarios.loader import load_scenario
from scenegraph.problem.solver import START_AT_GUESS, solver_options
from scenegraph.world.scene import build_scene
from schedules.execution import lower as lowering
from schedules.plan.compiler import compile_schedule


def _full_steps(name: str):
    scn = load_scenario(name)
    scene = build_scene(scn)
    return scene, [s for s in compile_schedule(scn).order() if s.kind == "full"]


@pytest.fixture
def switched(monkeypatch):
    monkeypatch.setattr(lowering, "JUMP_FULL_IPOPT", START_AT_GUESS)


def test_a_jump_full_step_carries_the_switch_to_ipopt(switched):
    scene, fulls = _full_steps("broad_jump")
    sp, _ = lowering.lower(scene, fulls[0], "jumper")
    assert sp.flights and sp.ipopt_options == START_AT_GUESS
    ipopt = solver_options(sp)["ipopt"]
    assert ipopt["warm_start_init_point"] == "yes" and ipopt["mu_init"] == 1e-3
    assert ipopt["mu_strategy"] == "adaptive" and ipopt["max_iter"] == sp.max_iter  # the defaults stay


@pytest.mark.parametrize("name,gait_flights", [("walk", False), ("springy_run", True)])
def test_steps_without_a_jump_goal_do_not(switched, name, gait_flights):
    scene, fulls = _full_steps(name)
    sp, _ = lowering.lower(scene, fulls[0], scene.characters[0].name)
    assert bool(sp.flights) == gait_flights  # a run's flights between strides are no jump goal's
    assert sp.ipopt_options == ()
    assert "warm_start_init_point" not in solver_options(sp)["ipopt"]


def test_the_default_is_the_project_ipopt_defaults():
    assert lowering.JUMP_FULL_IPOPT == ()
    scene, fulls = _full_steps("broad_jump")
    sp, _ = lowering.lower(scene, fulls[0], "jumper")
    assert sp.ipopt_options == () and solver_options(sp)["ipopt"].get("mu_init") is None
