"""Safe YAML loading that remembers where every value came from.

``load_yaml`` parses with PyYAML's safe composer, refuses tags, anchors and aliases (a
scenario is plain data; aliases enable "billion laughs" expansion), reads numbers as a
person writes them (YAML 1.2: ``1e6`` and ``1.0e300`` are numbers, where PyYAML's YAML 1.1
resolver makes them strings; a quoted ``"1e6"`` stays a string), and returns the plain
Python data together with a map from field path (a tuple of keys and indices) to the
1-based (line, column) of the value.  ``validate`` runs a pydantic model over that data
and turns the first validation error into an :class:`InputError` that names the file,
line, column and field path.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from .atomic import atomic_write
from .errors import InputError, Location

__all__ = ["load_yaml", "parse_yaml", "read_text", "validate", "load_model", "format_path", "dump_yaml_atomic"]

MAX_BYTES = 2_000_000
_PLAIN_TAGS = {
    "tag:yaml.org,2002:map", "tag:yaml.org,2002:seq", "tag:yaml.org,2002:str",
    "tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:bool",
    "tag:yaml.org,2002:null",
}
Positions = dict[tuple, tuple[int, int]]
# YAML 1.2 core schema floats that the YAML 1.1 resolver leaves as strings: an exponent
# without a dot or without a sign ("1e6", "1.0e300", ".5e3")
_FLOAT_12 = re.compile(r"[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+")
M = TypeVar("M", bound=BaseModel)


def format_path(path: tuple) -> str:
    """('characters', 1, 'style') -> 'characters[1].style'."""
    out = ""
    for p in path:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + str(p)
    return out


def _loc(file: str | None, mark, path: tuple = ()) -> Location:
    return Location(file, mark.line + 1, mark.column + 1, format_path(path) or None)


def _construct(node, file, path, positions: Positions):
    positions[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
    if node.tag not in _PLAIN_TAGS:
        raise InputError(f"YAML tag {node.tag!r} is not allowed (plain data only)", _loc(file, node.start_mark, path))
    if isinstance(node, yaml.MappingNode):
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                raise InputError("mapping keys must be plain strings (no merge keys)", _loc(file, key_node.start_mark, path))
            key = key_node.value
            if key in out:
                raise InputError(f"duplicate key {key!r}", _loc(file, key_node.start_mark, path + (key,)))
            out[key] = _construct(value_node, file, path + (key,), positions)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(v, file, path + (i,), positions) for i, v in enumerate(node.value)]
    return _scalar(node)


def _scalar(node: yaml.ScalarNode):
    if node.tag == "tag:yaml.org,2002:str" and node.style is None and _FLOAT_12.fullmatch(node.value):
        return float(node.value)  # plain (unquoted) 1e6: a number, as YAML 1.2 reads it
    loader = yaml.SafeLoader("")
    return loader.construct_object(node, deep=True)


def parse_yaml(text: str, file: str | None = None) -> tuple[Any, Positions]:
    """Parse YAML text into plain data plus a field-path → (line, column) map."""
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None):
                raise InputError("YAML anchors and aliases are not allowed", _loc(file, event.start_mark))
        docs = list(yaml.compose_all(text, Loader=yaml.SafeLoader))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        loc = _loc(file, mark) if mark else Location(file)
        raise InputError(f"invalid YAML: {exc.problem or exc.context}", loc) from None
    except yaml.YAMLError as exc:  # pragma: no cover - PyYAML always marks its errors
        raise InputError(f"invalid YAML: {exc}", Location(file)) from None
    if len(docs) != 1 or docs[0] is None:
        raise InputError("expected exactly one YAML document with content", Location(file, 1, 1))
    positions: Positions = {}
    return _construct(docs[0], file, (), positions), positions


def read_text(path: str | os.PathLike, kind: str, max_bytes: int) -> str:
    """A UTF-8 input file's text; every failure is an InputError naming the file."""
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > max_bytes:
            raise InputError(f"file is {size} bytes, more than the {max_bytes} allowed", Location(str(path)))
        return p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("file not found", Location(str(path))) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected a {kind} file", Location(str(path))) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"file is not UTF-8 text (byte {exc.start})", Location(str(path))) from None


def load_yaml(path: str | os.PathLike) -> tuple[Any, Positions]:
    """Read and parse a YAML file (at most 2 MB)."""
    return parse_yaml(read_text(path, "YAML", MAX_BYTES), str(path))


def _nearest(positions: Positions, path: tuple) -> tuple[tuple, tuple[int, int] | None]:
    p = tuple(path)
    while p and p not in positions:
        p = p[:-1]
    return p, positions.get(p)


def error_location(file: str | None, positions: Positions, path: tuple) -> Location:
    _, pos = _nearest(positions, path)
    line, col = pos if pos else (None, None)
    return Location(file, line, col, format_path(path) or None)


def validate(model: type[M], data: Any, positions: Positions, file: str | None = None,
             context: dict | None = None) -> M:
    """Validate ``data`` with ``model``; the first error becomes an InputError with its location."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        first = errors[0]
        path = tuple(x for x in first["loc"] if not (isinstance(x, str) and x.startswith("function-")))
        msg = first["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if first["type"] == "extra_forbidden":
            msg = f"unknown field {path[-1]!r}"
        more = [f"{format_path(tuple(e['loc']))}: {e['msg']}" for e in errors[1:6]]
        raise InputError(msg, error_location(file, positions, path), details=more) from None


def load_model(model: type[M], path: str | os.PathLike, context: dict | None = None) -> M:
    data, positions = load_yaml(path)
    return validate(model, data, positions, str(path), context=context)


def dump_yaml_atomic(data: Any, path: str | os.PathLike, header: str = "") -> None:
    """Write plain data as YAML (UTF-8) through the atomic writer (no half-written file)."""
    text = header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    atomic_write(path, text)
