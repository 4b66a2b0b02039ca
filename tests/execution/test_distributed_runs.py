"""End-to-end: the same stage and report numbers whatever the scheduler or worker count.

Slow (several short solves of ``walk`` with IPOPT capped at a few iterations: the point is
that every path computes the same numbers, not that they converge).
"""
from __future__ import annotations

import io
import json

import pytest

from schedules.cli.run import run_scenario

pytestmark = pytest.mark.slow


def _numbers(rep: dict) -> list:
    return ([(s["id"], s["status"], s["iterations"], s["energy"], s["violations"]) for s in rep["steps"]]
            + [(w, c["energy"], c["audit"]["footstep_error_max"]) for w, c in sorted(rep["characters"].items())]
            + [(n, g["measured"]) for n, g in sorted(rep["goals"].items())])


def _run(tmp_path, tag, log=None, **kw):
    out = tmp_path / f"{tag}.usda"
    rep = run_scenario("walk", out=str(out), run_dir=str(tmp_path / f"run_{tag}"), log=log or io.StringIO(), **kw)
    return out.read_bytes(), _numbers(rep), rep


def test_identical_results_across_schedulers(tmp_path, monkeypatch):
    monkeypatch.setenv("COMPOSE_MAX_ITER", "4")
    store = str(tmp_path / "store")
    plain_stage, plain, _ = _run(tmp_path, "plain")
    for tag, kw in [("sync", {"scheduler": "sync", "store": ""}),
                    ("processes", {"scheduler": "processes", "jobs": 2, "store": ""}),
                    ("local2", {"scheduler": "local", "jobs": 2, "store": store})]:
        stage, nums, rep = _run(tmp_path, tag, **kw)
        assert rep["scheduler"] == kw["scheduler"]
        assert nums == plain, tag
        assert stage == plain_stage, tag
    # the same scene again on one worker: every step comes from the step store, same stage
    log = io.StringIO()
    stage, nums, _ = _run(tmp_path, "again", log=log, scheduler="local", jobs=1, store=store)
    assert "2 of 2 step(s) came from the step store" in log.getvalue()
    assert nums == plain and stage == plain_stage
    # the run folder written by the Dask path resumes with the plain executor
    _, nums, rep = _run(tmp_path, "local2", resume=True)
    assert rep["resumed_steps"] == 2 and nums == plain
    assert json.loads((tmp_path / "run_local2" / "report.json").read_text())["resumed_steps"] == 2
