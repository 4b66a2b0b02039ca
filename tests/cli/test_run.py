"""End-to-end tests of ``compose run``: scenario → schedule → executor → USD stage + report.

The default run keeps one real end-to-end solve (the bundled ``walk``, about 45 s on two
cores) plus cheap failure paths; everything longer is marked ``slow``.
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


def compose(*args, cwd, env=None, timeout=1500):
    e = dict(os.environ)
    e.pop("COMPOSE_STOP_AFTER", None)
    e.pop("COMPOSE_MAX_ITER", None)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "schedules.cli.main", "run", *map(str, args)], cwd=cwd, env=e,
                          capture_output=True, text=True, timeout=timeout)


def final_motions(run_dir: Path) -> dict:
    """{character: (ctrl, warp)} after the last checkpoint that touched each character."""
    from schedules.execution.checkpoints import read_all

    out = {}
    for name, d in read_all(run_dir).items():  # verified against the manifest's SHA-256
        if name.startswith("000_"):  # not the 000_<who> pre-solves
            continue
        for who, c in d["characters"].items():
            out[who] = (np.asarray(c["ctrl"]), np.asarray(c["warp"]))
    return out


def tracks_from_run(name: str, run_dir: Path, fps: float):
    from scenarios.loader import load_scenario
    from scenegraph.model.motion import Motion
    from scenegraph.world.scene import build_scene
    from scenegraph.export.usd import CharacterTrack

    scene = build_scene(load_scenario(name))
    tracks = []
    for who, (ctrl, warp) in final_motions(run_dir).items():
        times, q = Motion(ctrl, warp).sample(fps)
        tracks.append(CharacterTrack(who, scene.character(who).character, np.asarray(q), float(times[0])))
    return tracks


@pytest.fixture(scope="module")
def walk_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("walk")
    (d / "tmp").mkdir()
    res = compose("walk", "-o", "tmp/walk.usda", "--report", "tmp/r.json", "--run-dir", "run", cwd=d)
    return d, res


def test_walk_end_to_end(walk_run):
    from scenegraph.export.usd import readback_errors

    d, res = walk_run
    assert res.returncode == 0, res.stderr[-3000:]
    assert "[1/1] walker/c1/whole/full" in res.stderr  # no timing step: the duration is fixed
    assert "ETA" in res.stderr
    stage = d / "tmp" / "walk.usda"
    assert stage.is_file()
    dp, dr, n = readback_errors(stage, tracks_from_run("walk", d / "run", 30.0), 30.0)
    assert n >= 30 and dp <= 1e-5 and dr <= 1e-4
    rep = json.loads((d / "tmp" / "r.json").read_text())
    assert rep["scenario"] == "walk"
    assert [s["id"] for s in rep["steps"]] == ["walker/c1/whole/full"]
    for s in rep["steps"]:
        assert _accepted(s) and s["iterations"] > 0 and s["seconds"] > 0 and np.isfinite(s["energy"])
    audit = rep["characters"]["walker"]["audit"]
    for k in ("root_residual_rms", "footstep_error_max", "penetration_max", "friction_violation_max",
              "planted_speed_max", "joint_limit_violation_max", "energy"):
        assert k in audit
    assert audit["root_residual_rel"] < 0.05
    g = rep["goals"]["footprints_0"]
    assert set(g) >= {"holds", "measured", "tolerance"} and g["holds"]
    assert rep["total_seconds"] > 0 and rep["versions"]["casadi"]
    # the stage carries provenance
    text = stage.read_text()
    assert "walker" in text and "energies" in text
    # report artefacts: named after the report (two reports in one folder keep their plots),
    # written with the umask's mode (not mkstemp's 0600)
    import stat
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((d / "tmp" / "r.json").stat().st_mode) == 0o666 & ~umask
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        pass
    else:
        plot = d / "tmp" / "r.energy_per_cycle.png"
        assert plot.is_file() and stat.S_IMODE(plot.stat().st_mode) == 0o666 & ~umask
        assert not (d / "tmp" / "energy_per_cycle.png").exists()
    # checkpoints: data only, each file's SHA-256 in the manifest
    man = json.loads((d / "run" / "manifest.json").read_text())
    assert man["format"] == 2 and set(man["checkpoints"]) == {
        "000_walker.json", "000_walker.npz", "001.json", "001.npz"}
    assert not list((d / "run").rglob("*.pkl"))


def _accepted(step: dict) -> bool:
    """The executor's policy, read from the report: a full step succeeds or is kept, stopped
    unconverged (its iteration cap or a numerical breakdown), with every hard constraint held;
    a timing step (a warm start) succeeds or is reported as discarded."""
    from schedules.execution.executor import UNCONVERGED, VIOLATION_TOL
    if step["kind"] == "full":
        return step["success"] or (all(s in UNCONVERGED or s == "Solve_Succeeded" for s in step["status"].split(";"))
                                   and all(v <= VIOLATION_TOL for v in step["violations"].values()))
    return step["success"] or step["status"].startswith("discarded:")


def test_bad_scenario_exits_2_and_writes_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nduration: -1\ncharacters: []\n")
    res = compose(bad, "-o", "out.usda", "--report", "r.json", cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert "bad.yaml" in res.stderr
    assert not (tmp_path / "out.usda").exists() and not (tmp_path / "r.json").exists()
    assert not (tmp_path / "runs").exists()


def test_bad_output_extension_exits_2(tmp_path):
    res = compose("walk", "-o", "out.obj", cwd=tmp_path)
    assert res.returncode == 2 and ".usda" in res.stderr
    assert not list(tmp_path.iterdir())


def test_failing_step_exits_1_names_step_and_constraints(tmp_path):
    res = compose("walk", "-o", "out.usda", "--report", "r.json", "--run-dir", "run", cwd=tmp_path,
                  env={"COMPOSE_MAX_ITER": "1"})
    assert res.returncode == 1, res.stderr[-3000:]
    assert "step 'walker/c1/whole/" in res.stderr and "violated constraint groups" in res.stderr
    assert "Maximum_Iterations_Exceeded" in res.stderr
    assert not (tmp_path / "out.usda").exists() and not (tmp_path / "r.json").exists()
    assert (tmp_path / "run" / "manifest.json").exists()  # the run folder (last good state) is kept


@pytest.mark.slow
def test_resume_after_kill_gives_the_same_result(walk_run, tmp_path):
    d, full = walk_run
    assert full.returncode == 0
    res = compose("walk", "-o", "w.usda", "--run-dir", "run", cwd=tmp_path, env={"COMPOSE_STOP_AFTER": "1"})
    assert res.returncode == 75, res.stderr[-3000:]
    assert not (tmp_path / "w.usda").exists()
    assert len(list((tmp_path / "run" / "steps").glob("[0-9][0-9][0-9].npz"))) == 1
    assert len(list((tmp_path / "run" / "steps").glob("[0-9][0-9][0-9].json"))) == 1
    assert (tmp_path / "run" / "steps" / "000_walker.json").exists()
    assert not list((tmp_path / "run").rglob("*.pkl"))
    res = compose("walk", "-o", "w.usda", "--run-dir", "run", "--resume", cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "resumed" in res.stderr
    a, b = final_motions(d / "run"), final_motions(tmp_path / "run")
    for who in a:
        np.testing.assert_array_equal(a[who][0], b[who][0])
        np.testing.assert_array_equal(a[who][1], b[who][1])


@pytest.mark.slow
def test_resume_rejects_a_foreign_run_folder(walk_run, tmp_path):
    d, full = walk_run
    res = compose("walk_to", "-o", "x.usda", "--run-dir", d / "run", "--resume", cwd=tmp_path)
    assert res.returncode == 2 and "different scenario" in res.stderr


@pytest.mark.slow
def test_two_walkers_jobs_2_equals_jobs_1(tmp_path):
    r1 = compose("two_walkers", "-o", "a.usda", "--report", "a.json", "--run-dir", "r1", "--jobs", "1", cwd=tmp_path)
    assert r1.returncode == 0, r1.stderr[-3000:]
    r2 = compose("two_walkers", "-o", "b.usda", "--report", "b.json", "--run-dir", "r2", "--jobs", "2", cwd=tmp_path)
    assert r2.returncode == 0, r2.stderr[-3000:]
    a, b = final_motions(tmp_path / "r1"), final_motions(tmp_path / "r2")
    assert set(a) == {"alice", "bob"} == set(b)
    for who in a:
        np.testing.assert_array_equal(a[who][0], b[who][0])
        np.testing.assert_array_equal(a[who][1], b[who][1])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["walk_to", "two_walkers", "walk_to_run"])
def test_bundled_scenarios_run_end_to_end(name, tmp_path):
    from scenegraph.export.usd import readback_errors

    res = compose(name, "-o", f"{name}.usda", "--report", "r.json", "--run-dir", "run", cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-3000:]
    dp, dr, n = readback_errors(tmp_path / f"{name}.usda", tracks_from_run(name, tmp_path / "run", 30.0), 30.0)
    assert n > 0 and dp <= 1e-5 and dr <= 1e-4
    rep = json.loads((tmp_path / "r.json").read_text())
    assert all(_accepted(s) for s in rep["steps"])
    for who, c in rep["characters"].items():
        assert c["audit"]["root_residual_rel"] < 0.05, who
        assert c["audit"]["passes"], (who, c["audit"])
    assert all(g["holds"] for g in rep["goals"].values()), rep["goals"]
    if name == "walk_to_run":  # thesis §6.4.2: it reaches the run's speed, dipping and leaning forward
        g = rep["goals"]["style_change_0"]
        assert g["measured"] >= 0.9 * g["target_speed"] and g["reached_at"] is not None, g
        assert g["lean_during_deg"] > g["lean_before_deg"] + 3.0, g
        assert g["dip_m"] > 0.01, g


def test_scene_units_and_edits():
    """Scenario degrees become radians; body edits reach the character; walk_to footsteps are free."""
    import math

    from scenarios.loader import load_scenario
    from scenegraph.model.footsteps import walk_footsteps
    from scenegraph.world.scene import build_scene

    scene = build_scene(load_scenario("tackle"))
    assert scene.character("dodger").start[2] == pytest.approx(math.pi / 2)
    steps = scene.character("dodger").footsteps
    assert steps and all(f.free for f in steps)
    assert all(abs(f.heading - math.pi / 2) < 1e-9 for f in steps)
    fs = walk_footsteps((0, 0), (1.5, 0), 0.0, 1.4)
    assert fs[0].t0 == 0.0 and fs[-1].t1 == pytest.approx(1.4)
    assert [f.foot for f in fs] == ["r", "l", "r", "l"][:len(fs)]
    assert all(f.free for f in fs)


def test_exit_code_follows_every_goal_expected_to_hold(monkeypatch):
    """Exit 1 when a non-adversarial goal (walk_to, reach) or a coupling does not hold; an
    adversarial goal expected to fail by design (the other side plans last) does not decide it."""
    import argparse

    from schedules.cli import run as cli_run

    ok = {"holds": True}
    walk_fail = {"type": "walk_to", "holds": False, "measured": 0.4, "tolerance": 0.05}
    loser = {"type": "avoid", "holds": False, "expected_to_hold": False, "plans_last": "attacker"}
    winner = {"type": "tackle", "holds": True, "expected_to_hold": True, "plans_last": "attacker"}
    v = cli_run.goal_verdict({"w": walk_fail, "f": ok}, {})
    assert not v["goals_as_expected"] and v["winners_goals_hold"]  # the old exit rule said 0 here
    assert cli_run.goal_verdict({"t": winner, "a": loser}, {})["goals_as_expected"]
    assert not cli_run.goal_verdict({"t": winner}, {"hold": {"type": "hand_hold", "holds": False}})["goals_as_expected"]

    def fake(passes):
        return lambda *a, **k: {"passes": passes}

    args = argparse.Namespace(file="x", output=None, report=None, jobs=1, resume=False, run_dir=None, fps=30.0,
                              fail_capped=False)
    monkeypatch.setattr(cli_run, "run_scenario", fake(False))
    assert cli_run._run(args) == 1
    monkeypatch.setattr(cli_run, "run_scenario", fake(True))
    assert cli_run._run(args) == 0
