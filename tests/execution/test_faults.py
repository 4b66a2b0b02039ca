"""Runs that survive faults (issue #17): SIGINT/SIGTERM stop cleanly, a step's unexpected
exception is that step's named failure, SIGKILL never leaves a half-written file at a final path.

Most tests replace the executor's solves with cheap fakes (like tests/execution/test_checkpoints.py);
one runs the real ``walk`` (iterations capped) and sends SIGINT while its second step solves.
The SIGKILL-and-resume comparison on real solves is ``tests/benchmarks/bench_faults.py``.
"""
from __future__ import annotations

import io
import json
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from schedules.execution import checkpoints as ck
from schedules.execution import executor as ex
from schedules.execution import interrupts
from schedules.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def _interruptible():
    """These tests stop runs with SIGINT, as a terminal's Ctrl-C does.  A process started with
    SIGINT ignored (a shell's background job ``&``, nohup) keeps it ignored on purpose
    (interrupts.catching_interrupts), and so would the test process and its children: restore
    Python's default handler for the test (and SIG_DFL in the children, :func:`_default_sigint`)."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _default_sigint() -> None:
    """Popen ``preexec_fn``: the child starts with SIGINT's default disposition."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _env(**extra) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    for k in ("COMPOSE_STOP_AFTER", "COMPOSE_MAX_ITER", "COMPOSE_DEBUG"):
        env.pop(k, None)
    env.update(extra)
    return env


def _fake_presolve(scene, who):
    m = scene.character(who).motion
    return {"step": f"presolve:{who}", "ctrl": np.asarray(m.ctrl, float) + 0.01, "warp": np.asarray(m.warp, float),
            "status": "ok", "success": True, "iterations": 1, "seconds": 0.01, "violations": {}}


def _fake_solution(scene, step):
    out = {"step": step.id, "characters": {}}
    for who in step.characters:
        st = scene.character(who)
        out["characters"][who] = {
            "ctrl": np.asarray(st.motion.ctrl, float) * 1.001 + 1e-3, "warp": np.asarray(st.motion.warp, float),
            "footsteps": st.footsteps, "mask": None, "status": "Solve_Succeeded", "success": True,
            "iterations": 2, "seconds": 0.01, "energy": 10.0, "violations": {"dynamics": 0.0},
            "presolve": None, "window": None, "timing": {},
            "contact_forces": {"ball_r": (np.array([0.1, 0.2]), np.ones((2, 3)))}}
    return out


# The bundled walk with a timing step asked for (schedule.timewarp: true): two steps, so that a
# fault can hit the second one after the first is checkpointed (by default walk is one full step).
WALK2 = "walk2.yaml"


def _walk2_text() -> str:
    from scenarios import bundled_scenarios
    return bundled_scenarios()["walk"].read_text() + "schedule:\n  timewarp: true\n"


@pytest.fixture()
def walk():
    from scenarios import parse_scenario
    from scenegraph.world.scene import build_scene
    from schedules.plan.compiler import compile_schedule
    scn = parse_scenario(_walk2_text(), WALK2)
    return build_scene(scn), compile_schedule(scn)


@pytest.fixture()
def walk2(tmp_path) -> str:
    """The two-step walk as a scenario file in tmp_path (its path, for ``compose run``)."""
    f = tmp_path / WALK2
    f.write_text(_walk2_text())
    return str(f)


def _committed(run_dir: Path) -> list[str]:
    return sorted(ck.read_all(run_dir))


# --- SIGINT / SIGTERM --------------------------------------------------------------------------------

@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_swallowed_by_the_solver_still_stops_the_run(tmp_path, walk, monkeypatch, signum):
    """CasADi catches the KeyboardInterrupt raised inside IPOPT and returns normally; the
    recorded signal must still stop the run, and the interrupted step must not be kept."""
    scene, schedule = walk
    order = schedule.order()
    seen = []

    def solve(scene, step, presolve, contacts=None):
        seen.append(step.id)
        if step.id == order[1].id:
            try:  # what CasADi does with an exception raised in its callbacks
                os.kill(os.getpid(), signum)
                time.sleep(5)  # the handler raises here
                raise AssertionError("the signal handler did not raise")
            except KeyboardInterrupt:
                pass
        return _fake_solution(scene, step)

    monkeypatch.setattr(ex, "presolve_character", _fake_presolve)
    monkeypatch.setattr(ex, "solve_step", solve)
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with pytest.raises(interrupts.RunInterrupted) as e:
        ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", log=io.StringIO())
    assert (e.value.step, e.value.name) == (2, order[1].id)
    assert e.value.exit_code == 128 + signum
    assert seen == [order[0].id, order[1].id]
    assert _committed(tmp_path) == ["000_walker", "001"]  # the interrupted step's result is not kept
    assert not list(tmp_path.rglob(".*.tmp"))
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before  # handlers restored
    with ck.RunLock(tmp_path):  # and the lock released
        pass

    # --resume then solves only the interrupted step and ends like an uninterrupted run
    monkeypatch.setattr(ex, "solve_step", lambda scene, step, presolve, contacts=None:
                        seen.append(step.id) or _fake_solution(scene, step))
    seen.clear()
    b = ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", resume=True, log=io.StringIO())
    assert seen == [order[1].id] and b.resumed == 1
    a = ex.run_schedule(scene, schedule, run_dir=tmp_path / "fresh", fingerprint="fp", log=io.StringIO())
    for c in a.scene.characters:
        np.testing.assert_array_equal(c.motion.ctrl, b.scene.character(c.name).motion.ctrl)


def test_sigint_during_a_real_solve_exits_130_with_a_resume_hint(tmp_path, walk2):
    """The real walk (IPOPT capped at 20 iterations per step to keep it short): SIGINT as soon
    as step 1 is reported, i.e. while step 2 is being built or solved."""
    p = subprocess.Popen([sys.executable, "-m", "schedules.cli.main", "run", WALK2, "-o", "w.usda", "--run-dir", "run"],
                         cwd=tmp_path, env=_env(COMPOSE_MAX_ITER="20"), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, preexec_fn=_default_sigint)
    lines = []
    for line in p.stdout:
        lines.append(line)
        if line.startswith("[1/2]"):
            time.sleep(1.5)  # past step 1's checkpoint: step 2's build (seconds) or IPOPT
            p.send_signal(signal.SIGINT)
            break
    out = "".join(lines) + p.stdout.read()
    rc = p.wait(timeout=120)
    assert rc == 130, out
    assert "Traceback" not in out
    hint = [line for line in out.splitlines() if "interrupted" in line and "compose:" in line]
    assert len(hint) == 1, out
    m = re.fullmatch(r"compose: interrupted at step (\d) \(([^)]+)\); resume with: "
                     r"compose run walk2\.yaml --resume --run-dir run -o w\.usda", hint[0])
    assert m, hint
    n = int(m.group(1))
    assert m.group(2) == ["presolve walker", "walker/c1/whole/timing", "walker/c1/whole/full"][n]
    # the steps before the interrupted one are kept, the interrupted one is not
    assert _committed(tmp_path / "run") == ["000_walker", "001", "002"][:n]
    assert not (tmp_path / "w.usda").exists() and not (tmp_path / "run" / "report.json").exists()
    assert not [q for q in tmp_path.rglob(".*") if q.name != ".lock"], "temporaries left behind"


def test_resume_command_repeats_the_run_arguments():
    from schedules.cli.main import build_parser
    from schedules.cli.run import resume_command
    args = build_parser().parse_args(["run", "my scene.yaml", "-o", "o.usdc", "--jobs", "2", "--fps", "24",
                                      "--report", "r.json", "--fail-capped"])
    assert resume_command(args) == ("compose run 'my scene.yaml' --resume -o o.usdc --report r.json --jobs 2 "
                                    "--fps 24 --fail-capped")


def test_interrupt_during_export_names_the_phase(tmp_path, monkeypatch, capfd, walk2):
    monkeypatch.setattr(ex, "presolve_character", _fake_presolve)
    monkeypatch.setattr(ex, "solve_step", lambda scene, step, presolve, contacts=None: _fake_solution(scene, step))
    import scenegraph.export.usd as ue

    def export(*a, **k):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)
        raise AssertionError("the signal handler did not raise")

    monkeypatch.setattr(ue, "export_usd", export)
    rc = main(["run", walk2, "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run")])
    err = capfd.readouterr().err
    assert rc == 130
    assert f"interrupted during the audit and export (all 2 steps are checkpointed); resume with: compose run {walk2} " \
           "--resume" in err
    assert _committed(tmp_path / "run") == ["000_walker", "001", "002"]
    assert not (tmp_path / "w.usda").exists()


# --- an unexpected exception inside a step --------------------------------------------------------------

def _raise_in(monkeypatch, step_no: int):
    def solve(scene, step, presolve, contacts=None):
        if step.id.endswith("full" if step_no == 2 else "timing"):
            raise RuntimeError("boom\n   at line 2 of the solver")
        return _fake_solution(scene, step)
    monkeypatch.setattr(ex, "presolve_character", _fake_presolve)
    monkeypatch.setattr(ex, "solve_step", solve)


def test_exception_in_the_solve_is_the_steps_named_failure(tmp_path, monkeypatch, capfd, walk2):
    """The real ``solve_step`` with ``solve`` (scenegraph.problem) raising."""
    monkeypatch.setattr(ex, "presolve_character", _fake_presolve)

    def solve(sp, *a, **k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(ex, "solve", solve)
    monkeypatch.delenv("COMPOSE_DEBUG", raising=False)
    rc = main(["run", walk2, "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run")])
    err = capfd.readouterr().err
    assert rc == 1, err
    assert f"compose: error: step 1 (walker/c1/whole/timing) failed: ZeroDivisionError: float division by zero; " \
           f"finished steps are kept in {tmp_path / 'run'}\n" in err
    assert "Traceback" not in err
    assert _committed(tmp_path / "run") == ["000_walker"]
    assert not (tmp_path / "w.usda").exists()


def test_a_later_steps_crash_keeps_the_earlier_steps(tmp_path, monkeypatch, capfd, walk2):
    _raise_in(monkeypatch, 2)
    rc = main(["run", walk2, "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run")])
    err = capfd.readouterr().err
    assert rc == 1
    failed = [line for line in err.splitlines() if "failed" in line]
    assert len(failed) == 1 and "step 2 (walker/c1/whole/full) failed: RuntimeError: boom at line 2 of the solver;" \
        in failed[0], err
    assert "Traceback" not in err
    assert _committed(tmp_path / "run") == ["000_walker", "001"]
    # the kept steps resume: only the crashed step is solved again
    calls = []
    monkeypatch.setattr(ex, "solve_step", lambda scene, step, presolve, contacts=None:
                        calls.append(step.id) or _fake_solution(scene, step))
    assert main(["run", walk2, "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run"),
                 "--resume"]) in (0, 1)
    assert calls == ["walker/c1/whole/full"]
    assert (tmp_path / "w.usda").exists()


@pytest.mark.parametrize("how", ["env", "flag"])
def test_debug_shows_the_traceback(tmp_path, monkeypatch, capfd, how, walk2):
    _raise_in(monkeypatch, 1)
    argv = ["run", walk2, "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run")]
    if how == "env":
        monkeypatch.setenv("COMPOSE_DEBUG", "1")
    else:
        monkeypatch.delenv("COMPOSE_DEBUG", raising=False)
        argv.insert(0, "--debug")
    assert main(argv) == 1
    err = capfd.readouterr().err
    assert "Traceback (most recent call last)" in err and "RuntimeError: boom" in err
    assert "step 1 (walker/c1/whole/timing) failed: RuntimeError: boom at line 2 of the solver" in err


def test_a_crash_in_the_presolve_is_step_0(tmp_path, monkeypatch, capfd):
    def presolve(scene, who):
        raise IndexError("list index out of range")
    monkeypatch.setattr(ex, "presolve_character", presolve)
    rc = main(["run", "walk", "-o", str(tmp_path / "w.usda"), "--run-dir", str(tmp_path / "run")])
    err = capfd.readouterr().err
    assert rc == 1 and "step 0 (presolve walker) failed: IndexError: list index out of range" in err
    assert "Traceback" not in err


def test_an_unexpected_error_outside_the_steps_is_one_line(tmp_path, monkeypatch, capfd):
    import schedules.cli.run as cr

    def boom(*a, **k):
        raise KeyError("scene")
    monkeypatch.setattr(cr, "run_scenario", boom)
    monkeypatch.delenv("COMPOSE_DEBUG", raising=False)
    assert main(["run", "walk"]) == 1
    err = capfd.readouterr().err
    assert err.strip().splitlines() == ["compose: internal error: KeyError: 'scene' (run with --debug or "
                                        "COMPOSE_DEBUG=1 for the traceback)"]


# --- SIGKILL while writing ----------------------------------------------------------------------------

_WRITER = textwrap.dedent("""
    import sys, numpy as np
    from pathlib import Path
    from schedules.execution import checkpoints as ck
    d = Path(sys.argv[1]); rng = np.random.default_rng(int(sys.argv[2]))
    m = ck.Manifest(d, 2, "fp"); m.save()
    i = 0
    print("ready", flush=True)
    while True:
        i += 1
        data = {"step": f"s{i}", "ctrl": rng.normal(size=(400, 35)), "n": i}
        ck.write_checkpoint(m, f"{i % 7 + 1:03d}", data)
        ck.atomic_write(d / "report.json", (('{"n": %d, "pad": "' % i) + "x" * 200000 + '"}').encode())
""")


def test_sigkill_while_writing_leaves_only_whole_files(tmp_path):
    """A writer loop of checkpoints, manifest and a report, killed at random moments: every
    file at a final path is whole and every committed checkpoint verifies."""
    rng = random.Random(7)
    for k in range(6):
        d = tmp_path / f"k{k}"
        p = subprocess.Popen([sys.executable, "-c", _WRITER, str(d), str(k)], env=_env(), stdout=subprocess.PIPE,
                             text=True)
        assert p.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.05, 0.6))
        p.kill()
        p.wait()
        p.stdout.close()
        ck.read_all(d)  # every committed checkpoint matches its SHA-256 and loads
        for f in (d / "steps").glob("*.npz"):  # uncommitted ones are whole too
            with np.load(f, allow_pickle=False) as z:
                assert z["a0"].shape == (400, 35)
        for f in [*(d / "steps").glob("*.json"), d / "manifest.json"]:
            json.loads(f.read_text())
        if (d / "report.json").exists():
            assert json.loads((d / "report.json").read_text())["pad"] == "x" * 200000
        # the next run's prepare step removes the temporaries of the killed one
        ex.prepare_run_dir(d, "fp", resume=True)
        assert not list(d.rglob(".*.tmp"))


def _slow_solve(scene, step, presolve, contacts=None):  # runs in a worker process (pickled by name)
    time.sleep(60)
    return _fake_solution(scene, step)


def test_interrupt_with_jobs_ends_the_workers(tmp_path, monkeypatch):
    """--jobs 2: the workers ignore SIGINT (Ctrl-C reaches the whole process group); the parent
    stops at once and terminates the workers instead of waiting for their solves."""
    from scenarios.loader import load_scenario
    from scenegraph.world.scene import build_scene
    from schedules.plan.compiler import compile_schedule
    import threading

    scn = load_scenario("two_walkers")
    scene, schedule = build_scene(scn), compile_schedule(scn)

    monkeypatch.setattr(ex, "presolve_character", _fake_presolve)
    monkeypatch.setattr(ex, "solve_step", _slow_solve)
    timer = threading.Timer(2.0, os.kill, (os.getpid(), signal.SIGINT))
    t0 = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(interrupts.RunInterrupted) as e:
            ex.run_schedule(scene, schedule, run_dir=tmp_path, fingerprint="fp", jobs=2, log=io.StringIO())
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 30, "waited for the workers' solves"
    assert e.value.step == 1 and e.value.exit_code == 130
    assert _committed(tmp_path) == ["000_alice", "000_bob"]


def test_run_outputs_get_the_umask_mode_and_leave_no_temporaries(tmp_path):
    """BVH and USD go through scenarios.atomic like the checkpoints and the report: the
    file gets the mode of a new file under the umask (``mkstemp`` alone gives 0600)."""
    import stat
    from scenegraph.model.body import N_DOF, make_character
    from scenegraph.export.bvh import export_bvh
    from scenegraph.export.usd import CharacterTrack, export_usd
    tr = CharacterTrack("A", make_character(), np.zeros((4, N_DOF)))
    old = os.umask(0o027)
    try:
        paths = [export_bvh(tmp_path / "a.bvh", tr, 30.0), export_usd(tmp_path / "a.usda", [tr], 30.0)]
    finally:
        os.umask(old)
    for p in paths:
        assert stat.S_IMODE(p.stat().st_mode) == 0o640, p
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bvh", "a.usda"]
