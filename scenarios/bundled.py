"""Bundled scenarios and styles, and how style references resolve to files.

Bundled scenarios are ``scenarios/*.yaml``; bundled styles are ``scenarios/styles/*.yaml``
(``walk.yaml`` or ``walk.style.yaml`` both give the style ``walk``) plus the built-in
``default`` style, which has no file.

A style reference in a scenario is either a *name* (``walk``) or a *path*
(``styles/mine.yaml``, anything with a folder part or a ``.yaml``/``.yml`` suffix).  Paths
are resolved relative to the scenario file's folder and must stay inside the allowed roots:
that folder and the bundled styles folder (symlinks are followed before the check).
"""
from __future__ import annotations

import os
from pathlib import Path

from scenarios.errors import InputError, Location
from scenarios.names import is_style_path, suggest

__all__ = ["BUNDLED_DIR", "STYLES_DIR", "BUILTIN_STYLES", "bundled_scenarios", "bundled_syntheses", "bundled_styles",
           "find_scenario", "resolve_style", "style_problem", "allowed_roots", "describe_scenario"]

BUNDLED_DIR = Path(__file__).resolve().parent
STYLES_DIR = BUNDLED_DIR / "styles"
BUILTIN_STYLES = ("default",)


def _style_name(p: Path) -> str:
    name = p.name
    for suffix in (".style.yaml", ".style.yml", ".yaml", ".yml"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return p.stem


def bundled_scenarios() -> dict[str, Path]:
    """Name → file of every bundled scenario, sorted by name."""
    files = sorted(p for p in BUNDLED_DIR.glob("*.yaml") if p.is_file())
    return {p.stem: p for p in files}


def bundled_syntheses() -> dict[str, Path]:
    """Name → file of every bundled scenario that synthesises characters (every one without a
    top-level ``edit:`` block, which edits a captured clip instead: scenarios/edit_block.py)."""
    from scenarios.yamlio import load_yaml
    out = {}
    for name, p in bundled_scenarios().items():
        data, _ = load_yaml(p)
        if not (isinstance(data, dict) and "edit" in data):
            out[name] = p
    return out


def bundled_styles() -> dict[str, Path | None]:
    """Name → file of every bundled style (None for the built-in ``default``), sorted by name."""
    out: dict[str, Path | None] = {n: None for n in BUILTIN_STYLES}
    if STYLES_DIR.is_dir():
        for p in sorted(STYLES_DIR.iterdir()):
            if p.is_file() and p.suffix in (".yaml", ".yml"):
                out[_style_name(p)] = p
    return dict(sorted(out.items()))


def find_scenario(name_or_path: str | os.PathLike) -> Path:
    """A scenario file: an existing path, else a bundled scenario name (``tackle``, no suffix)."""
    s = str(name_or_path)
    p = Path(s)
    if p.exists():
        return p
    looks_like_path = "/" in s or os.sep in s or s.endswith((".yaml", ".yml"))
    if looks_like_path:
        raise InputError("file not found", Location(s))
    bundled = bundled_scenarios()
    if s in bundled:
        return bundled[s]
    raise InputError(suggest(s, list(bundled), "scenario") + " (and no such file)", Location(s))


def allowed_roots(base_dir: Path | None) -> list[Path]:
    """Folders a style path may point into: the scenario's folder and the bundled styles."""
    roots = [(base_dir or Path.cwd()).resolve(), STYLES_DIR.resolve()]
    return list(dict.fromkeys(roots))


def _style_path(ref: str, base_dir: Path | None) -> Path:
    p = Path(ref).expanduser() if ref.startswith("~") else Path(ref)
    if not p.is_absolute():
        p = (base_dir or Path.cwd()) / p
    return p.resolve()


def style_problem(ref: str, context: dict | None = None) -> str | None:
    """Why a style reference is not acceptable, or None.  ``context``: base_dir, styles."""
    ctx = context or {}
    base_dir = ctx.get("base_dir")
    base_dir = Path(base_dir) if base_dir is not None else None
    if not is_style_path(ref):
        styles = ctx.get("styles")
        known = list(styles if styles is not None else bundled_styles())
        return None if ref in known else suggest(ref, known, "style")
    if not ref.endswith((".yaml", ".yml")):
        return f"style file {ref!r} must be a .yaml file"
    p = _style_path(ref, base_dir)
    roots = allowed_roots(base_dir)
    if not any(p.is_relative_to(r) for r in roots):
        return (f"style path {ref!r} leaves the allowed folders (the scenario's folder {roots[0]} "
                f"and the bundled styles {roots[-1]})")
    if not p.is_file():
        return f"style file {ref!r} not found (looked at {p})"
    return None


def resolve_style(ref: str, base_dir: Path | None = None) -> Path | None:
    """The file of a style reference (None for a built-in style).  Raises InputError if invalid."""
    msg = style_problem(ref, {"base_dir": base_dir})
    if msg:
        raise InputError(msg)
    if not is_style_path(ref):
        return bundled_styles()[ref]
    return _style_path(ref, base_dir)


def describe_scenario(path: Path) -> str:
    """The one-line ``description`` of a scenario file, without validating it."""
    from scenarios.yamlio import load_yaml
    try:
        data, _ = load_yaml(path)
    except InputError as exc:
        return f"(unreadable: {exc.message})"
    d = data.get("description", "") if isinstance(data, dict) else ""
    return str(d).strip().splitlines()[0] if d else ""
