"""The critical path of a Schedule and the largest speedup its graph allows.

With step times w (seconds; 1 per step when nothing was measured) the critical path is the
heaviest path through the DAG; no number of workers finishes faster than its weight, so
the largest speedup over one worker is Σw / w(critical path) (Brent's bound: with P
workers the makespan is at most Σw/P + w(critical path)).  The kinematic pre-solves (one
per character, all independent) are not part of the Schedule and are left out.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import networkx as nx

from scenarios.errors import InputError, Location

from schedules.plan.step import Schedule

__all__ = ["CriticalPath", "critical_path", "step_times_from_report", "projected_makespan"]


@dataclass(frozen=True)
class CriticalPath:
    steps: tuple[str, ...]  # step ids along the path
    length: float           # s (or steps, unit times)
    total: float            # Σ step times, s (or the number of steps)
    measured: bool          # times from a report (True) or one per step (False)

    @property
    def max_speedup(self) -> float:
        return self.total / self.length if self.length > 0 else 1.0

    def to_text(self) -> str:
        fmt = (lambda x: f"{x:.1f} s") if self.measured else (lambda x: f"{x:g} steps")  # noqa: E731
        head = (f"critical path: {len(self.steps)} steps, {fmt(self.length)} of {fmt(self.total)} in all; "
                f"largest speedup the graph allows: {self.max_speedup:.2f}x "
                f"({'measured step times' if self.measured else 'every step counted as 1; --times R.json for measured ones'})")
        return head + "\n  " + " -> ".join(self.steps) + "\n"


def critical_path(schedule: Schedule, times: dict[str, float] | None = None) -> CriticalPath:
    """The heaviest path (ties: the schedule's deterministic order)."""
    w = {s.id: float(times.get(s.id, 0.0)) if times else 1.0 for s in schedule.order()}
    best: dict[str, tuple[float, str | None]] = {}
    for s in schedule.order():  # a topological order
        preds = list(schedule.graph.predecessors(s.id))
        if preds:
            p = max(preds, key=lambda x: (best[x][0], x))
            best[s.id] = (best[p][0] + w[s.id], p)
        else:
            best[s.id] = (w[s.id], None)
    if not best:
        return CriticalPath((), 0.0, 0.0, bool(times))
    end = max(best, key=lambda x: (best[x][0], x))
    path = [end]
    while best[path[-1]][1] is not None:
        path.append(best[path[-1]][1])
    assert nx.is_directed_acyclic_graph(schedule.graph)
    return CriticalPath(tuple(reversed(path)), best[end][0], sum(w.values()), bool(times))


def step_times_from_report(path: str | Path) -> dict[str, float]:
    """{step id: seconds} from a ``compose run`` report (its ``steps`` list)."""
    p = Path(path)
    try:
        rep = json.loads(p.read_text(encoding="utf-8"))
        return {s["id"]: float(s["seconds"]) for s in rep["steps"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"--times: not a compose run report ({type(exc).__name__}: {exc})", Location(str(p))) from None


def projected_makespan(total: float, critical: float, workers: int) -> tuple[float, float]:
    """(lower, upper) bound of the wall time on ``workers`` workers: max(Σw/P, critical) and Σw/P + critical."""
    return max(total / workers, critical), total / workers + critical
