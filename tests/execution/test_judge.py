"""The one acceptance rule for a solved Step (``executor.judge``), as a table: step kind ×
IPOPT status per character × held constraints × ``fail_capped`` → accepted / kept unconverged
(``capped``) / discarded / failed."""
from __future__ import annotations

import pytest

from schedules.execution.executor import UNCONVERGED, VIOLATION_TOL, judge, kept_warning
from schedules.plan.step import Step

OK, CAP, RESTO, INF = "Solve_Succeeded", "Maximum_Iterations_Exceeded", "Restoration_Failed", "Infeasible_Problem_Detected"
HELD, BROKEN = {"dynamics": VIOLATION_TOL / 10}, {"dynamics": VIOLATION_TOL * 10}


def _data(statuses, viol):
    return {"characters": {f"c{i}": {"status": s, "success": s == OK, "iterations": 10, "seconds": 1.0,
                                     "energy": 1.0, "violations": dict(viol), "presolve": None}
                           for i, s in enumerate(statuses)}}


def _step(kind):
    return Step(id=f"a/c0/w0/{kind}", kind=kind, characters=("c0",), window=(0.0, 1.0), free=("q",), terms=(),
                cycle=0)


@pytest.mark.parametrize("kind, statuses, viol, fail_capped, outcome", [
    ("full", [OK], HELD, False, "accepted"),
    ("full", [CAP], HELD, False, "capped"),
    ("full", [RESTO], HELD, False, "capped"),
    ("full", ["Error_In_Step_Computation"], HELD, False, "capped"),
    ("full", [OK, RESTO], HELD, False, "capped"),          # one character of a joint step
    ("full", [RESTO], BROKEN, False, "failed"),             # unconverged and infeasible
    ("full", [CAP], HELD, True, "failed"),                  # --fail-capped
    ("full", [INF], HELD, False, "failed"),                 # not a numerical stop
    ("full", [OK], BROKEN, False, "failed"),
    ("timing", [OK], HELD, False, "accepted"),
    ("timing", [CAP], HELD, False, "discarded"),            # a warm start is used only converged
    ("timing", [RESTO], HELD, False, "discarded"),
    ("timing", [OK], BROKEN, False, "discarded"),
])
def test_judge(kind, statuses, viol, fail_capped, outcome):
    d = judge(_step(kind), _data(statuses, viol), fail_capped)
    got = ("failed" if d.get("failed") else "discarded" if d.get("discarded") else
           "capped" if d.get("capped") else "accepted")
    assert got == outcome, d


def test_a_failure_names_the_step_the_status_and_the_groups():
    d = judge(_step("full"), _data([RESTO], BROKEN), False)
    assert "a/c0/w0/full" in d["failed"] and RESTO in d["failed"] and "dynamics=" in d["failed"]


def test_the_warning_says_why_the_step_was_kept():
    assert "failed restoration" in kept_warning("s", RESTO)
    assert "iteration cap" in kept_warning("s", f"{OK};{CAP}")
    assert set(UNCONVERGED) >= {CAP, RESTO}
