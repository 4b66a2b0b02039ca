"""Two small helpers about names, shared by the schema and the bundled-file lookup (a leaf module).

``suggest`` phrases an unknown-name message with a close match; ``is_style_path`` tells a
style *path* from a style *name*.  They live here, below both :mod:`scenarios.schema` and
:mod:`scenarios.bundled`, so that neither has to import the other to use them.
"""
from __future__ import annotations

import difflib

__all__ = ["suggest", "is_style_path"]


def suggest(value: str, known: list[str] | tuple[str, ...], what: str, limit: int = 8) -> str:
    """``unknown style 'rnu' (known: default, run, walk); did you mean 'run'?``"""
    known = sorted(known)
    shown = ", ".join(known[:limit]) + (", …" if len(known) > limit else "")
    msg = f"unknown {what} {value!r} (known: {shown})"
    close = difflib.get_close_matches(str(value), known, n=1, cutoff=0.5)
    if close:
        msg += f"; did you mean {close[0]!r}?"
    return msg


def is_style_path(ref: str) -> bool:
    """A style reference is a file path if it has a folder part or a YAML suffix."""
    return "/" in ref or "\\" in ref or ref.endswith((".yaml", ".yml"))
