"""The one root error type of compose.

Every error compose raises on purpose is a :class:`ComposeError`.  When the error comes
from a file it carries the source location (file, line, column) and the field path, and
its message reads ``file:line:col field: message`` so that editors can jump to it.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ComposeError", "Location"]


@dataclass(frozen=True)
class Location:
    """A place in a source file; line and column are 1-based."""

    file: str | None = None
    line: int | None = None
    column: int | None = None
    field: str | None = None

    def prefix(self) -> str:
        parts = []
        if self.file:
            where = self.file
            if self.line is not None:
                where += f":{self.line}"
                if self.column is not None:
                    where += f":{self.column}"
            parts.append(where)
        if self.field:
            parts.append(self.field)
        return " ".join(parts)


class ComposeError(Exception):
    """Root of every deliberate compose error.

    ``exit_code`` is what the CLI returns: 2 for bad input (files, arguments), 1 for
    failures while computing (a solve that did not converge, an export that failed).
    """

    exit_code: int = 1

    def __init__(self, message: str, location: Location | None = None, *, exit_code: int | None = None,
                 details: list[str] | None = None):
        self.message = message
        self.location = location or Location()
        self.details = list(details or [])
        if exit_code is not None:
            self.exit_code = exit_code
        super().__init__(str(self))

    def __str__(self) -> str:
        prefix = self.location.prefix()
        head = f"{prefix}: {self.message}" if prefix else self.message
        if self.details:
            head += "\n" + "\n".join(f"  {d}" for d in self.details)
        return head


class InputError(ComposeError):
    """Bad input: a file, a field or an argument that cannot be accepted (exit code 2)."""

    exit_code = 2


__all__.append("InputError")
