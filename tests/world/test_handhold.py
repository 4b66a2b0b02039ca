"""Hand-in-hand walking (thesis §6.4.3), end to end (slow): `handhold` and its variant
`handhold_child_adapts`.

Both must exit 0 with the hands within 1 cm over the coupled interval, both walk_to goals
met, both characters' physics audits passing and, outside the held hands, the bodies apart
(the stage auditor's overlap ≤ 0.5 cm).  The asymmetry the thesis describes —
the character solved more often (and first) does the adapting, the other adjusts
minimally — is measured as how far each character's held palm moved from its own
uncoupled plan (the pre-solved initial motion in the run folder).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(name: str, cwd: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("COMPOSE_MAX_ITER", None)
    env.pop("COMPOSE_STOP_AFTER", None)
    res = subprocess.run([sys.executable, "-m", "schedules.cli.main", "run", name, "-o", "out.usda", "--report",
                          "r.json", "--run-dir", "run"], cwd=cwd, env=env, capture_output=True, text=True,
                         timeout=3000)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads((cwd / "r.json").read_text())


def palm_adaptation(name: str, run_dir: Path) -> dict[str, float]:
    """Per character: mean distance (m) of its held palm from where its uncoupled plan (the
    pre-solved initial motion) put it, over the coupled interval."""
    from scenarios import load_scenario
    from scenegraph.model.motion import Motion
    from scenegraph.world.scene import build_scene, handle_track
    from schedules.execution.checkpoints import read_all
    from schedules.execution.executor import _apply

    scene = build_scene(load_scenario(name))
    initial = {}
    for ck, d in read_all(run_dir).items():  # checkpoints in name order: pre-solves, then steps
        if ck.startswith("000_"):
            who = ck[4:]
            scene = scene.with_motion(who, Motion(d["ctrl"], d["warp"]))
            initial[who] = scene.character(who)
        elif not d.get("discarded"):
            scene = _apply(scene, d)
    (c,) = scene.couplings
    t = np.linspace(c.interval[0], c.interval[1], 61)
    return {who: float(np.linalg.norm(handle_track(scene.character(who), h, t) - handle_track(initial[who], h, t),
                                      axis=1).mean())
            for who, h in c.handles}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for name in ("handhold", "handhold_child_adapts"):
        d = tmp_path_factory.mktemp(name)
        out[name] = (_run(name, d), palm_adaptation(name, d / "run"))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", ["handhold", "handhold_child_adapts"])
def test_hands_held_goals_met_audits_pass(runs, name):
    rep, _ = runs[name]
    hold = rep["couplings"]["hold"]
    assert hold["tolerance"] == pytest.approx(0.01)
    assert hold["holds"] and hold["measured"] <= 0.01, hold
    assert all(g["holds"] for g in rep["goals"].values()), rep["goals"]
    for who, c in rep["characters"].items():
        assert c["audit"]["passes"], (who, c["audit"])
    # bodies apart (issue 15 item 5), read from the written stage by the stage auditor: apart from
    # the held hands, the two bodies overlap by at most 0.5 cm (8.6 cm before the clearance rows)
    assert rep["stage_audit"]["summary"]["interpenetration_max_cm"] <= 0.5, rep["stage_audit"]["summary"]


@pytest.mark.slow
def test_the_character_solved_more_often_adapts_more(runs):
    _, sym = runs["handhold"]
    _, child_more = runs["handhold_child_adapts"]
    # handhold: the adult goes first and bends to the child's hand; the variant: the child,
    # solved first and twice per cycle, reaches up to the adult's
    assert sym["adult"] > sym["child"], sym
    assert child_more["child"] > child_more["adult"], child_more
    share = lambda a: a["child"] / (a["child"] + a["adult"])  # noqa: E731
    assert share(child_more) > share(sym) + 0.2, (sym, child_more)
