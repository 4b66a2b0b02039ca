"""Clean stops of a run: SIGINT (Ctrl-C) and SIGTERM, and a step's unexpected exception.

A stop request must survive the solver: CasADi catches a ``KeyboardInterrupt`` raised inside
its Python callbacks, prints one ``WARNING("KeyboardInterruptException")`` line and returns
normally with IPOPT status ``NonIpopt_Exception_Thrown`` — the interrupt would be lost and
the step reported as a failed solve (exit 1).  So :func:`catching_interrupts` installs a
handler that *records* the signal before raising ``KeyboardInterrupt`` (which ends IPOPT
within one iteration), and the executor calls :func:`check` after every solve: a recorded
signal raises ``KeyboardInterrupt`` again there, and the run loop turns it into
:class:`RunInterrupted` naming the step (whose result is then not checkpointed).

Exit codes follow the shell convention 128 + signal number: 130 for SIGINT, 143 for SIGTERM.
A second signal while the run is already stopping is recorded but raises nothing (the
clean-up — temporary files removed, pool workers ended — is not cut short).
"""
from __future__ import annotations

import os
import signal
import threading
import traceback
from contextlib import contextmanager
from typing import Iterator

from scenarios.errors import ComposeError

__all__ = ["RunInterrupted", "catching_interrupts", "check", "requested", "crash_message", "debug_enabled",
           "ignore_interrupts_in_worker", "set_phase", "phase"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_IDLE = "loading the scenario"
_state = {"signum": None, "depth": 0, "phase": _IDLE}


class RunInterrupted(ComposeError):
    """The run was stopped by SIGINT/SIGTERM; finished steps' checkpoints are kept.

    ``step``: 1-based step number (0 for a kinematic pre-solve, None after the last step);
    ``name``: the step id (or ``presolve <character>``, ``export``)."""

    def __init__(self, step: int | None, name: str, signum: int | None = None):
        self.step, self.name = step, name
        self.signum = int(signum) if signum else int(signal.SIGINT)
        where = f"at step {step} ({name})" if step is not None else f"during {name}"
        super().__init__(f"interrupted {where}", exit_code=128 + self.signum)


def requested() -> int | None:
    """The signal number recorded since :func:`catching_interrupts` was entered, or None."""
    return _state["signum"]


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a stop was requested (call after a solver returns)."""
    if _state["signum"] is not None:
        raise KeyboardInterrupt


def set_phase(text: str) -> None:
    """What the run does outside its steps (named by an interrupt there), e.g. ``export``."""
    _state["phase"] = text


def phase() -> str:
    return _state["phase"]


def _handler(signum, frame) -> None:
    first = _state["signum"] is None
    _state["signum"] = signum
    if first:
        raise KeyboardInterrupt


@contextmanager
def catching_interrupts() -> Iterator[None]:
    """Install the recording handler for SIGINT and SIGTERM (main thread only; re-entrant).

    On leaving the outermost context the previous handlers are restored and the record is
    cleared.  Off the main thread (where Python cannot install handlers) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _state["depth"] > 0:
        _state["depth"] += 1
        try:
            yield
        finally:
            _state["depth"] -= 1
        return
    old = {s: signal.getsignal(s) for s in _SIGNALS}
    _state["signum"], _state["phase"] = None, _IDLE
    for s in _SIGNALS:
        if old[s] is not signal.SIG_IGN:  # a run started with SIGINT ignored (nohup, `&`) keeps it ignored
            signal.signal(s, _handler)
    _state["depth"] = 1
    try:
        yield
    finally:
        _state["depth"] = 0
        for s in _SIGNALS:
            signal.signal(s, old[s])
        _state["signum"], _state["phase"] = None, _IDLE


def ignore_interrupts_in_worker() -> None:
    """Initializer of ``--jobs`` worker processes: Ctrl-C reaches the whole process group, and
    only the parent stops the run (it ends the workers); a worker must not print its own
    ``KeyboardInterrupt`` traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def debug_enabled() -> bool:
    """``COMPOSE_DEBUG=1`` (or ``compose --debug``): show the traceback of an unexpected error."""
    return os.environ.get("COMPOSE_DEBUG", "").strip() not in ("", "0")


def crash_message(exc: BaseException, limit: int = 400) -> str:
    """``<ExcType>: <message>`` on one line (whitespace runs folded, at most ``limit`` chars)."""
    msg = " ".join(str(exc).split())
    if len(msg) > limit:
        msg = msg[: limit - 1] + "…"
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def format_traceback(exc: BaseException) -> str:
    return "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))


__all__.append("format_traceback")
