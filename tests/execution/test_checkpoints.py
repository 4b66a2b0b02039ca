"""Run-folder checkpoints (data only, SHA-256 verified) and the run lock — no solves: the
executor runs with ``solve_step`` / ``presolve_character`` replaced by cheap fakes."""
from __future__ import annotations

import io
import json
import os
import pickle
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from scenarios.errors import InputError
from scenegraph.model.footsteps import Footstep
from schedules.execution import checkpoints as ck
from schedules.execution import executor as ex

ROOT = Path(__file__).resolve().parents[2]


def _step_data() -> dict:
    """The shape of what ``solve_step`` returns (and a checkpoint stores)."""
    rng = np.random.default_rng(3)
    return {"step": "walker/c1/whole/full", "fingerprint": "f" * 20, "characters": {"walker": {
        "ctrl": rng.normal(size=(32, 35)), "warp": np.linspace(0.0, 1.2, 6),
        "footsteps": (Footstep("r", (0.1, -0.1), 0.0, 0.4, heading=0.1, free=True),
                      Footstep("l", (0.7 + 1e-17, 0.1), 0.35, 0.8, heel=None)),
        "mask": rng.random(32) > 0.5, "status": "Solve_Succeeded", "success": True, "iterations": 17,
        "seconds": 1.25, "energy": 1234.5678901234567, "violations": {"dynamics": 1e-9, "footsteps": 0.0},
        "presolve": {"status": "ok", "success": True, "iterations": 3, "seconds": 0.1},
        "contact_forces": {"ball_r": (np.linspace(0, 0.4, 5), rng.normal(size=(5, 3)))},
        "window": (0.0, 0.6), "timing": {"build": 0.5, "total": 1.2}}}, "discarded": False}


def _assert_same(a, b):
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    elif isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b)
        for k in a:
            _assert_same(a[k], b[k])
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b)
        for x, y in zip(a, b):
            _assert_same(x, y)
    else:
        assert type(a) is type(b) and a == b, (a, b)


def _manifest(tmp_path) -> ck.Manifest:
    m = ck.Manifest(tmp_path, ex.FORMAT, "f" * 20)
    m.save()
    return m


def test_round_trip_is_exact_and_data_only(tmp_path):
    m = _manifest(tmp_path)
    d = _step_data()
    ck.write_checkpoint(m, "001", d)
    assert sorted(p.name for p in (tmp_path / "steps").iterdir()) == ["001.json", "001.npz"]
    man = json.loads((tmp_path / "manifest.json").read_text())
    assert set(man["checkpoints"]) == {"001.json", "001.npz"}
    got = ck.read_checkpoint(ck.Manifest.load(tmp_path), tmp_path, "001")
    _assert_same(d, got)  # bit-identical arrays and floats, footsteps as Footstep, tuples as tuples
    # the JSON holds footsteps as plain numbers
    doc = json.loads((tmp_path / "steps" / "001.json").read_text())
    fs = doc["data"]["characters"]["walker"]["footsteps"]["$tuple"][0]["$footstep"]
    assert fs["foot"] == "r" and fs["position"] == {"$tuple": [0.1, -0.1]} and fs["free"] is True
    assert ck.read_all(tmp_path)["001"]["step"] == "walker/c1/whole/full"


def test_not_committed_checkpoint_is_ignored(tmp_path):
    m = _manifest(tmp_path)
    ck.write_checkpoint(m, "001", _step_data())
    fresh = ck.Manifest.load(tmp_path)
    fresh["checkpoints"].clear()  # as if killed between writing the files and the commit
    assert ck.read_checkpoint(fresh, tmp_path, "001") is None


def _rejected(tmp_path, name="001", match="") -> str:
    with pytest.raises(InputError) as e:
        ck.read_checkpoint(ck.Manifest.load(tmp_path), tmp_path, name)
    msg = str(e.value)
    assert e.value.exit_code == 2 and "not loaded" in msg and match in msg, msg
    return msg


@pytest.mark.parametrize("which", ["json", "npz"])
def test_truncated_checkpoint_is_rejected_naming_the_file(tmp_path, which):
    ck.write_checkpoint(_manifest(tmp_path), "001", _step_data())
    f = tmp_path / "steps" / f"001.{which}"
    f.write_bytes(f.read_bytes()[:-50])
    assert str(f) in _rejected(tmp_path, match="SHA-256")


def test_edited_checkpoint_is_rejected(tmp_path):
    ck.write_checkpoint(_manifest(tmp_path), "001", _step_data())
    f = tmp_path / "steps" / "001.json"
    f.write_text(f.read_text().replace('"iterations":17', '"iterations":18'))
    assert str(f) in _rejected(tmp_path, match="differs from the manifest")


def test_missing_checkpoint_file_is_rejected(tmp_path):
    ck.write_checkpoint(_manifest(tmp_path), "001", _step_data())
    (tmp_path / "steps" / "001.npz").unlink()
    assert "001.npz" in _rejected(tmp_path, match="missing")


def test_foreign_checkpoint_with_matching_manifest_is_rejected(tmp_path):
    """A checkpoint of another run copied in with its hashes (manifest edited to match)."""
    other = tmp_path / "other"
    ck.write_checkpoint(ck.Manifest(other, ex.FORMAT, "o" * 20), "001", _step_data())
    mine = tmp_path / "mine"
    m = _manifest(mine)
    for suf in ("json", "npz"):
        (mine / "steps").mkdir(exist_ok=True)
        (mine / "steps" / f"001.{suf}").write_bytes((other / "steps" / f"001.{suf}").read_bytes())
        m.checkpoints[f"001.{suf}"] = ck.sha256_file(mine / "steps" / f"001.{suf}")[0]
    m.save()
    assert "001.json" in _rejected(mine, match="belongs to another run")


def test_pickle_payloads_are_never_loaded(tmp_path):
    """An object array (a pickle inside the npz) and a plain pickle as the npz are refused even
    when the manifest is edited to carry their hashes; the payload never runs."""
    marker = tmp_path / "pwned"

    class Boom:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    for payload in ("object_array", "raw_pickle"):
        d = tmp_path / payload
        m = _manifest(d)
        ck.write_checkpoint(m, "001", _step_data())
        npz = d / "steps" / "001.npz"
        if payload == "object_array":
            buf = io.BytesIO()
            np.savez(buf, a0=np.array([Boom()], dtype=object))
            npz.write_bytes(buf.getvalue())
        else:
            npz.write_bytes(pickle.dumps(Boom()))
        m.checkpoints["001.npz"] = ck.sha256_file(npz)[0]
        # a forger who also rewrites the JSON's own record of the npz hash
        doc = json.loads((d / "steps" / "001.json").read_text())
        doc["npz_sha256"] = m.checkpoints["001.npz"]
        (d / "steps" / "001.json").write_text(json.dumps(doc))
        m.checkpoints["001.json"] = ck.sha256_file(d / "steps" / "001.json")[0]
        m.save()
        assert "001.npz" in _rejected(d, match="unreadable arrays")
        assert not marker.exists()


def test_unknown_tag_and_non_mapping_manifest_are_rejected(tmp_path):
    with pytest.raises(InputError, match="unknown tag"):
        ck.decode({"$eval": "print(1)"}, {})
    (tmp_path / "manifest.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="manifest"):
        ck.Manifest.load(tmp_path)


def test_atomic_write_mode_follows_umask_and_leaves_no_temporaries(tmp_path, monkeypatch):
    old = os.umask(0o022)
    try:
        p = ck.atomic_write_text("hello\n", tmp_path / "sub" / "a.txt")
    finally:
        os.umask(old)
    assert p.read_text() == "hello\n"
    assert stat.S_IMODE(p.stat().st_mode) == 0o644
    assert [x.name for x in p.parent.iterdir()] == ["a.txt"]

    class Stop(Exception):
        pass

    def fail(fd):
        raise Stop()

    monkeypatch.setattr(os, "fsync", fail)  # a failure (or signal) while writing ...
    with pytest.raises(Stop):
        ck.atomic_write(p, b"new")
    monkeypatch.undo()
    # ... leaves the old content and no temporary file
    assert p.read_text() == "hello\n" and [x.name for x in p.parent.iterdir()] == ["a.txt"]


# --- the executor with fake solves ------------------------------------------------------------------

@pytest.fixture()
def fake_run(monkeypatch):
    """(scene, schedule, calls) with the executor's solves replaced by deterministic fakes."""
    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene
    from schedules.plan.compiler import compile_schedule

    from scenarios import bundled_scenarios, parse_scenario
    # two steps (a timing and a full step, asked for): the tests edit the second one's checkpoint
    scn = parse_scenario(bundled_scenarios()["walk"].read_text() + "schedule:\n  timewarp: true\n", "walk.yaml")
    scene, schedule = build_scene(scn), compile_schedule(scn)
    assert len(schedule) == 2
    calls = []

    def presolve(scene, who):
        calls.append(f"presolve:{who}")
        m = scene.character(who).motion
        return {"step": f"presolve:{who}", "ctrl": np.asarray(m.ctrl, float) + 0.01,
                "warp": np.asarray(m.warp, float), "status": "ok", "success": True, "iterations": 1,
                "seconds": 0.01, "violations": {}}

    def solve(scene, step, presolve, contacts=None):
        calls.append(step.id)
        out = {"step": step.id, "characters": {}}
        for who in step.characters:
            st = scene.character(who)
            out["characters"][who] = {
                "ctrl": np.asarray(st.motion.ctrl, float) * 1.001, "warp": np.asarray(st.motion.warp, float),
                "footsteps": st.footsteps, "mask": None, "status": "Solve_Succeeded", "success": True,
                "iterations": 2, "seconds": 0.01, "energy": 10.0, "violations": {"dynamics": 0.0},
                "presolve": None, "window": None, "timing": {},
                "contact_forces": {"ball_r": (np.array([0.1, 0.2]), np.ones((2, 3)))}}
        return out

    monkeypatch.setattr(ex, "presolve_character", presolve)
    monkeypatch.setattr(ex, "solve_step", solve)
    return scene, schedule, calls


def test_resume_replays_verified_checkpoints(tmp_path, fake_run):
    scene, schedule, calls = fake_run
    log = io.StringIO()
    a = ex.run_schedule(scene, schedule, run_dir=tmp_path / "r", fingerprint="fp", log=log)
    n = len(calls)
    assert n == 1 + len(schedule)
    assert not list((tmp_path / "r").rglob("*.pkl"))
    b = ex.run_schedule(scene, schedule, run_dir=tmp_path / "r", fingerprint="fp", resume=True, log=log)
    assert len(calls) == n, "a resumed run solves nothing again"
    assert b.resumed == len(schedule)
    for c in a.scene.characters:
        np.testing.assert_array_equal(c.motion.ctrl, b.scene.character(c.name).motion.ctrl)
    # an edited checkpoint is rejected (never loaded), named, and its step and the later ones re-solved
    f = tmp_path / "r" / "steps" / "002.json"
    f.write_text(f.read_text().replace('"energy":10.0', '"energy":1.0'))
    log = io.StringIO()
    c = ex.run_schedule(scene, schedule, run_dir=tmp_path / "r", fingerprint="fp", resume=True, log=log)
    assert str(f) in log.getvalue() and "never loaded" in log.getvalue()
    assert calls[n:] == [s.id for s in schedule.order()[1:]]
    for ch in a.scene.characters:
        np.testing.assert_array_equal(ch.motion.ctrl, c.scene.character(ch.name).motion.ctrl)


def _recommit(run_dir, name, npz_bytes=None, json_text=None):
    """Rewrite a checkpoint's files and make the manifest (and the JSON's own npz hash) agree, as
    someone crafting a run folder would: only the content checks are left to catch it."""
    import hashlib
    steps = run_dir / "steps"
    if npz_bytes is not None:
        (steps / f"{name}.npz").write_bytes(npz_bytes)
        doc = json.loads((steps / f"{name}.json").read_text())
        doc["npz_sha256"] = hashlib.sha256(npz_bytes).hexdigest()
        (steps / f"{name}.json").write_text(json.dumps(doc))
    if json_text is not None:
        (steps / f"{name}.json").write_text(json_text)
    man = json.loads((run_dir / "manifest.json").read_text())
    for ext in ("json", "npz"):
        man["checkpoints"][f"{name}.{ext}"] = hashlib.sha256((steps / f"{name}.{ext}").read_bytes()).hexdigest()
    (run_dir / "manifest.json").write_text(json.dumps(man))


@pytest.mark.parametrize("craft", ["pickle_payload", "pickle_file", "truncated", "checksum_mismatch", "foreign_json"])
def test_crafted_checkpoint_is_rejected_and_its_step_solved_again(tmp_path, fake_run, craft):
    import pickle
    scene, schedule, calls = fake_run
    a = ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", log=io.StringIO())
    n = len(calls)
    npz = tmp_path / "steps" / "002.npz"
    if craft == "pickle_payload":  # an object array: np.load would unpickle it if allowed to
        buf = io.BytesIO()
        np.savez(buf, payload=np.array([{"__reduce__": "os.system"}], dtype=object))
        _recommit(tmp_path, "002", npz_bytes=buf.getvalue())
    elif craft == "pickle_file":  # a pickle where the arrays belong, with every hash made to agree
        _recommit(tmp_path, "002", npz_bytes=pickle.dumps({"ctrl": [1, 2, 3]}))
    elif craft == "truncated":  # cut in half, hashes made to agree: the archive itself is broken
        _recommit(tmp_path, "002", npz_bytes=npz.read_bytes()[: npz.stat().st_size // 2])
    elif craft == "checksum_mismatch":  # one byte changed, the manifest left alone
        raw = bytearray(npz.read_bytes())
        raw[len(raw) // 2] ^= 0xFF
        npz.write_bytes(bytes(raw))
    else:  # a well-formed checkpoint of another step and run
        doc = json.loads((tmp_path / "steps" / "002.json").read_text())
        doc["fingerprint"] = "another-run"
        _recommit(tmp_path, "002", json_text=json.dumps(doc))
    log = io.StringIO()
    b = ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", resume=True, log=log)
    assert "002" in log.getvalue() and "never loaded" in log.getvalue()
    assert calls[n:] == [s.id for s in schedule.order()[1:]], "the rejected step and the later ones are solved again"
    assert b.resumed == 1
    for ch in a.scene.characters:
        np.testing.assert_array_equal(ch.motion.ctrl, b.scene.character(ch.name).motion.ctrl)
    # and the folder is whole again: a second resume solves nothing
    ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", resume=True, log=io.StringIO())
    assert len(calls) == n + len(schedule) - 1


def test_uncommitted_checkpoint_is_solved_again(tmp_path, fake_run):
    scene, schedule, calls = fake_run
    ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", log=io.StringIO())
    man = json.loads((tmp_path / "manifest.json").read_text())
    del man["checkpoints"]["002.json"], man["checkpoints"]["002.npz"]
    (tmp_path / "manifest.json").write_text(json.dumps(man))
    calls.clear()
    log = io.StringIO()
    ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", resume=True, log=log)
    assert calls == [schedule.order()[1].id]
    assert "not committed" in log.getvalue()


def test_old_pickle_run_folder_is_refused_on_resume(tmp_path, fake_run):
    scene, schedule, calls = fake_run
    (tmp_path / "steps").mkdir()
    (tmp_path / "manifest.json").write_text(json.dumps({"format": 1, "fingerprint": "fp"}))
    (tmp_path / "steps" / "001.pkl").write_bytes(b"not loaded")
    with pytest.raises(InputError, match="format 1"):
        ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", resume=True, log=io.StringIO())
    assert calls == []


# --- the run lock ---------------------------------------------------------------------------------

_HOLD = textwrap.dedent("""
    import sys, time
    from schedules.execution.checkpoints import RunLock
    with RunLock(sys.argv[1]):
        print("locked", flush=True)
        time.sleep(60)
""")


def test_lock_refuses_a_second_writer_and_is_reentrant(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.Popen([sys.executable, "-c", _HOLD, str(tmp_path)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert p.stdout.readline().strip() == "locked"
        with pytest.raises(ck.RunFolderBusy) as e:
            ck.RunLock(tmp_path).acquire()
        assert f"pid {p.pid}" in str(e.value) and e.value.exit_code == 2
    finally:
        p.kill()
        p.wait()
    # the holder died (SIGKILL): its lock file stays, but does not block
    assert (tmp_path / ck.LOCK_NAME).exists()
    with ck.RunLock(tmp_path):
        with ck.RunLock(tmp_path):  # re-entrant in one process
            assert (tmp_path / ck.LOCK_NAME).read_text().strip() == str(os.getpid())
    with ck.RunLock(tmp_path):
        pass


def test_compose_run_in_a_locked_folder_exits_2(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.Popen([sys.executable, "-c", _HOLD, str(tmp_path / "run")], stdout=subprocess.PIPE, text=True,
                         env=env)
    try:
        assert p.stdout.readline().strip() == "locked"
        res = subprocess.run([sys.executable, "-m", "schedules.cli.main", "run", "walk", "-o", "w.usda", "--run-dir",
                              "run"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    finally:
        p.kill()
        p.wait()
    assert res.returncode == 2, res.stderr[-2000:]
    assert "in use by another compose run" in res.stderr and f"pid {p.pid}" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "w.usda").exists()
