"""Every bundled scenario builds (Drake-style smoke test): load → compile → build the Scene →
lower every Step of every character to its Subproblem (or joint problem) → transcribe.

No IPOPT: the lowering of every Step runs (it is cheap), and one Step per distinct shape
(kind, role, free blocks, whole/windowed, springs, open end) is transcribed with
``derivatives=False`` — the variables, objective, constraints and bounds, without the
Hessian and constraint Jacobian, which are ~70 % of a transcription's build time (measured
on walk_to: 6.3 s with them, ~1.5 s without, one core).  The objective and constraints are
then evaluated at the start point and must be finite.  This catches a Step the executor
cannot lower, a term that names a missing goal, a window that frees nothing, and a bad NLP
shape, in every scenario the project ships.  A bundled edit scenario (an ``edit:`` block, no
schedule) is smoke-tested by running its edit (no IPOPT solve of the motion; the clip fit, ~9 s).
"""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.bundled import bundled_syntheses
from scenarios.loader import load_scenario
from scenegraph.problem import transcribe
from scenegraph.world.scene import build_scene
from schedules.plan.compiler import compile_schedule
from schedules.execution.lower import lower, lower_joint


def _shape(step, sp) -> tuple:
    return (step.kind, step.role, tuple(sorted(sp.free)), sp.window is None, bool(sp.springs), sp.open_end,
            sp.fix_end_time, bool(sp.targets))


@pytest.mark.parametrize("name", sorted(bundled_syntheses()))  # an edit scenario has no steps
def test_every_step_of_a_bundled_scenario_lowers_and_transcribes(name):
    scn = load_scenario(name)
    schedule = compile_schedule(scn)
    scene = build_scene(scn)
    assert len(schedule) > 0
    seen: set = set()
    for step in schedule.order():
        joint = lower_joint(scene, step)
        if joint is not None:
            assert set(joint.characters) == set(step.characters) and len(joint.coupling.times) >= 2
        for who in step.characters:
            sp, mask = lower(scene, step, who)
            assert sp.character is scene.character(who).character
            if mask is not None:
                assert mask.any(), f"{step.id}: the window frees no control point of {who}"
            # every goal term of the step that binds this character became springs of its weight
            for n, w in step.terms:
                if n.startswith("goal:") and isinstance(w, float) and scene.goal(n[5:]).character == who:
                    mine = [t for t in sp.targets if t.name == n]
                    assert mine and max(t.weight for t in mine) == w, (step.id, n)
            key = _shape(step, sp)
            if key in seen:
                continue
            seen.add(key)
            nlp = transcribe(sp, derivatives=False)
            assert nlp.hess_lag is None and nlp.x0.size == nlp.lbx.size == nlp.ubx.size
            f = float(nlp.f_fn(nlp.x0, nlp.p0))
            g = np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()
            assert np.isfinite(f) and np.all(np.isfinite(g)), step.id
            assert g.size == nlp.lbg.size


def _bundled_edits() -> list[str]:
    from scenarios.bundled import bundled_scenarios
    return sorted(set(bundled_scenarios()) - set(bundled_syntheses()))


def test_the_edit_scenarios_are_the_ones_without_a_schedule():
    assert _bundled_edits() == ["edit_broad_jump"]


@pytest.mark.parametrize("name", _bundled_edits())
def test_every_bundled_edit_scenario_edits_its_clip(name, tmp_path):
    """An edit scenario (scenarios/edit_block.py) has no steps: its smoke test is the edit itself —
    the clip loads and fits, the edit runs, the stage, BVH and report are written, and the report's
    goals (distance, apex, turn, momentum correlation, ballistic flight) hold."""
    from scenarios.bundled import find_scenario
    from schedules.execution.edit_run import run_edit
    import io
    scn = load_scenario(name)
    assert scn.is_edit
    rep = run_edit(scn, find_scenario(name), tmp_path / "e.usda", tmp_path / "r.json", 120.0, io.StringIO())
    assert (tmp_path / "e.usda").is_file() and (tmp_path / "e.bvh").is_file() and (tmp_path / "r.json").is_file()
    assert rep["passes"], rep["goals"]
