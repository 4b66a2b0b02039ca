"""What the NIO optimisers read and return: an evaluation of G at one θ, the per-iteration
records, the result, and the history that collects records for a progress callback.

Energies are in the solver's normalised units (E of :mod:`.energy`); times in seconds."""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

from scenegraph.model.motion import Motion
from scenegraph.problem import Result
from scenegraph.model.style import Style

__all__ = ["IterationRecord", "NIOResult", "Evaluation", "History", "Problem"]


@dataclass(frozen=True)
class IterationRecord:
    iteration: int
    G: float  # G(θ) = E(X_T; θ) − E(X_S; θ) at the iterate
    D: float  # D(θ), Eq. 18
    E_target: float  # E(X_T; θ)
    E_counter: float  # E(X_S; θ)
    beta: float  # step accepted (line-search β or trust radius); 0: no step taken
    evaluations: int  # G evaluations in this iteration
    seconds: float  # since the start of the run


@dataclass(frozen=True)
class NIOResult:
    style: Style  # α normalised
    theta: np.ndarray  # raw θ (147) at the end
    history: list[IterationRecord]
    g_initial: float
    g_final: float
    iterations: int
    evaluations: int
    seconds: float
    stop_reason: str
    counterexample: Motion | None = None
    nio: Any = field(default=None, compare=False)  # the NIO problem that produced it (learn_style sets it)


@dataclass(frozen=True)
class Evaluation:
    """G(θ), D(θ), the energies of X_T and X_S, the Eq. 21 gradient of G + D, X_S with its
    forces, and the IPOPT result of the last counterexample solve (None for local ones)."""

    theta: np.ndarray
    G: float
    D: float
    E_T: float
    E_S: float
    grad: np.ndarray  # dG̃/dθ + dD/dθ
    motion_S: Motion
    FS: np.ndarray
    solve: Result | None


class History:
    """The iteration records of one run, each passed to ``callback`` as it is added."""

    def __init__(self, callback: Callable[[IterationRecord], None] | None):
        self.t_start = _time.perf_counter()
        self.records: list[IterationRecord] = []
        self.callback = callback

    def elapsed(self) -> float:
        return _time.perf_counter() - self.t_start

    def add(self, iteration: int, G: float, cur: Evaluation, beta: float, evaluations: int) -> None:
        """Record iteration ``iteration`` at the current evaluation ``cur`` with its G."""
        rec = IterationRecord(iteration, G, cur.D, cur.E_T, cur.E_S, beta, evaluations, self.elapsed())
        self.records.append(rec)
        if self.callback:
            self.callback(rec)

    def result(self, style: Style, cur: Evaluation, g_initial: float, g_final: float, evaluations: int,
               reason: str) -> NIOResult:
        """The run's result; ``iterations`` counts the records with a step taken."""
        return NIOResult(style, cur.theta, self.records, g_initial, g_final,
                         sum(1 for h in self.records[1:] if h.beta > 0), evaluations, self.elapsed(),
                         reason, cur.motion_S)


class Problem(Protocol):
    """What the optimisers need of an NIO problem (:class:`scenegraph.nio.NIO`)."""

    target: Motion  # X_T
    alpha_floor: float  # lower bound of every α_j in the bundle's LP
    verbose: bool

    def evaluate(self, theta: np.ndarray, candidates: tuple[Motion, ...] = ()) -> Evaluation: ...

    def measure(self, theta: np.ndarray, motion: Motion) -> tuple: ...
