"""Sweep variants: ``--vary PATH=VALUES`` arguments, their combinations, each one validated.

``PATH`` is a field path in the scenario as written (after ``repeat`` blocks are
expanded), e.g. ``characters[0].start.heading``, ``goals[1].target``, ``duration``.
``VALUES`` is either a range ``START:STOP:STEP`` (numbers; STOP included when the steps
land on it, e.g. ``0:180:20`` is 0, 20, …, 180) or a comma list ``2.5,3.0,3.5`` /
``walk,walk_person2`` (each item read as a YAML scalar: numbers stay numbers).  Several
``--vary`` give every combination (the first one varies slowest).

Every combination is built and validated before anything runs: a path that does not
exist, a bad value, or a combination the scenario language rejects is an
:class:`~scenarios.errors.InputError` (exit 2) naming the scenario file, the line of the
field, the field path and the variant.
"""
from __future__ import annotations

import copy
import itertools
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from scenarios.bundled import find_scenario
from scenarios.errors import InputError, Location
from scenarios.loader import validate_scenario
from scenarios.repeat import expand_repeats
from scenarios.yamlio import error_location, format_path, load_yaml

__all__ = ["Vary", "Variant", "parse_vary", "parse_path", "parse_values", "combinations", "build_variants",
           "MAX_VARIANTS"]

MAX_VARIANTS = 10000
_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


@dataclass(frozen=True)
class Vary:
    """One ``--vary``: the field path (as parts and as written) and its values."""

    text: str
    path: tuple
    values: tuple


@dataclass(frozen=True)
class Variant:
    """One combination: index, (path text, value) pairs, the scenario data as YAML text."""

    index: int
    assignment: tuple[tuple[str, Any], ...]
    yaml_text: str

    @property
    def label(self) -> str:
        return ", ".join(f"{p}={v}" for p, v in self.assignment)


def _arg_error(msg: str) -> InputError:
    return InputError(msg, Location(None, field="--vary"))


def parse_path(text: str) -> tuple:
    """``characters[0].start.heading`` → ``('characters', 0, 'start', 'heading')``."""
    parts: list = []
    if not text:
        raise _arg_error("empty field path")
    for seg in text.split("."):
        m = _PART.fullmatch(seg)
        if not m:
            raise _arg_error(f"bad field path {text!r} at {seg!r} (expected e.g. characters[0].start.heading)")
        parts.append(m.group(1))
        parts += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return tuple(parts)


def _scalar(item: str, arg: str) -> Any:
    item = item.strip()
    if not item:
        raise _arg_error(f"{arg}: empty value in the list")
    try:
        v = yaml.safe_load(item)
    except yaml.YAMLError:
        return item
    if isinstance(v, (dict, list)) or v is None:
        raise _arg_error(f"{arg}: value {item!r} is not a number or a word")
    return v


def parse_values(text: str, arg: str = "--vary") -> tuple:
    """A ``START:STOP:STEP`` range or a comma list (see the module docstring)."""
    if text.count(":") == 2 and "," not in text:
        try:
            a, b, s = (float(x) for x in text.split(":"))
        except ValueError:
            raise _arg_error(f"{arg}: range {text!r} must be START:STOP:STEP numbers") from None
        if not all(math.isfinite(x) for x in (a, b, s)) or s == 0 or (b - a) / s < 0:
            raise _arg_error(f"{arg}: range {text!r} has a zero step or steps away from STOP")
        n = int(math.floor((b - a) / s + 1e-9)) + 1
        if n > MAX_VARIANTS:
            raise _arg_error(f"{arg}: range {text!r} has {n} values (at most {MAX_VARIANTS})")
        ints = all(float(x).is_integer() and "." not in x for x in text.split(":"))
        vals = [a + k * s for k in range(n)]
        return tuple(int(round(v)) if ints else round(v, 12) for v in vals)
    return tuple(_scalar(x, arg) for x in text.split(","))


def parse_vary(arg: str) -> Vary:
    """``PATH=VALUES`` → :class:`Vary`."""
    if "=" not in arg:
        raise _arg_error(f"{arg!r}: expected PATH=VALUES, e.g. characters[0].start.heading=0:180:20")
    path, values = arg.split("=", 1)
    path = path.strip()
    return Vary(path, parse_path(path), parse_values(values, f"--vary {path}"))


def combinations(varies: list[Vary]) -> list[tuple[tuple[str, Any], ...]]:
    """Every combination (the first ``--vary`` varies slowest)."""
    n = math.prod(len(v.values) for v in varies)
    if n > MAX_VARIANTS:
        raise _arg_error(f"{n} combinations (at most {MAX_VARIANTS})")
    paths = [v.text for v in varies]
    if len(set(paths)) != len(paths):
        raise _arg_error(f"a field is varied twice: {', '.join(sorted(p for p in paths if paths.count(p) > 1))}")
    return [tuple(zip(paths, combo)) for combo in itertools.product(*(v.values for v in varies))]


def _set(data: Any, path: tuple, value: Any, file: str, positions: dict, label: str) -> None:
    cur = data
    for i, part in enumerate(path):
        last = i == len(path) - 1
        here = format_path(path[:i]) or "the scenario"

        def err(msg: str) -> InputError:
            loc = error_location(file, positions, path[:i])
            loc = Location(loc.file, loc.line, loc.column, format_path(path))
            return InputError(f"--vary {format_path(path)} ({label}): {msg}", loc)

        if isinstance(part, int):
            if not isinstance(cur, list):
                raise err(f"{here} is not a list")
            if part >= len(cur):
                raise err(f"{here} has {len(cur)} item(s), no [{part}]")
        else:
            if not isinstance(cur, dict):
                raise err(f"{here} is not a mapping (no field {part!r})")
            if part not in cur and not last:
                raise err(f"{here} has no field {part!r}")
        if last:
            cur[part] = value
        else:
            cur = cur[part]


def _absolute_styles(data: dict, base: Path) -> None:
    """Relative style file and edit clip references → absolute (a variant file lives in the sweep folder)."""
    e = data.get("edit")
    if isinstance(e, dict) and isinstance(e.get("clip"), str) and not Path(e["clip"]).is_absolute():
        e["clip"] = str((base / e["clip"]).resolve())
    for c in data.get("characters", []) or []:
        if isinstance(c, dict):
            for key in ("style", "styles"):
                v = c.get(key)
                if isinstance(v, str) and v.endswith((".yaml", ".yml")) and not Path(v).is_absolute():
                    c[key] = str((base / v).resolve())


def build_variants(file: str, varies: list[Vary]) -> list[Variant]:
    """Every combination applied to the scenario and validated (see the module docstring)."""
    path = find_scenario(file)
    data, positions = load_yaml(path)
    if not isinstance(data, dict):
        raise InputError("a scenario must be a mapping of fields", Location(str(path), 1, 1))
    data, positions = expand_repeats(data, positions, str(path))
    base = Path(path).resolve().parent
    out = []
    for i, combo in enumerate(combinations(varies)):
        label = f"variant {i}: " + ", ".join(f"{p}={v}" for p, v in combo)
        d = copy.deepcopy(data)
        for (p, v), vary in zip(combo, varies):
            _set(d, vary.path, v, str(path), positions, label)
        try:
            validate_scenario(d, positions, str(path), base)
        except InputError as exc:
            raise InputError(f"{label}: {exc.message}", exc.location, details=exc.details) from None
        _absolute_styles(d, base)
        out.append(Variant(i, combo, yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=100)))
    return out
