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

from scenarios.atomic import atomic_write
from scenarios.errors import InputError, Location

__all__ = ["load_yaml", "parse_yaml", "read_text", "validate", "load_model", "format_path", "dump_yaml_atomic"]

MAX_BYTES = 2_000_000  # any YAML file compose reads (scenarios have their own, smaller limit)
MAX_DEPTH = 64  # nesting levels of mappings and sequences (a scenario needs about 6, a style 4)
MAX_NODES = 200_000  # scalars, mappings and sequences in one file
# libyaml's parser when PyYAML has it (10-20x faster); the pure-Python one otherwise.  Both
# give the same events, nodes and marks; only the composed tree is used, never the constructor.
_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
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
            p = str(p)
            out += ("." if out else "") + (p if len(p) <= 60 else p[:57] + "…")  # a 1 MB key stays one short line
    return out


def _loc(file: str | None, mark, path: tuple = ()) -> Location:
    return Location(file, mark.line + 1, mark.column + 1, format_path(path) or None)


def _construct(node, file, path, positions: Positions, ctor):
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
            out[key] = _construct(value_node, file, path + (key,), positions, ctor)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(v, file, path + (i,), positions, ctor) for i, v in enumerate(node.value)]
    return _scalar(node, file, path, ctor)


def _scalar(node: yaml.ScalarNode, file, path, ctor):
    if node.tag == "tag:yaml.org,2002:str" and not node.style and _FLOAT_12.fullmatch(node.value):
        return float(node.value)  # plain (unquoted) 1e6: a number, as YAML 1.2 reads it
    try:
        return ctor.construct_object(node, deep=True)
    except (yaml.YAMLError, ValueError, OverflowError) as exc:  # e.g. a timestamp out of range
        raise InputError(f"cannot read the value {node.value[:40]!r}: {exc}", _loc(file, node.start_mark, path)) from None


def _reader_location(exc: yaml.YAMLError, text: str, file: str | None) -> Location:
    """Line and column of a ReaderError (it carries a character position, not a mark)."""
    pos = getattr(exc, "position", None)
    if not isinstance(pos, int):
        return Location(file, 1, 1)
    pos = max(0, min(pos, len(text)))
    line = text.count("\n", 0, pos) + 1
    return Location(file, line, pos - (text.rfind("\n", 0, pos) + 1) + 1)


def _check_events(text: str, file: str | None) -> None:
    """One streaming pass over the YAML events (no recursion, nothing built): anchors and
    aliases are refused, and nesting depth and node count are bounded *before* any node tree
    or Python object is built (a 100 000-deep ``[[[[…`` would otherwise exhaust the stack)."""
    depth = nodes = 0
    for event in yaml.parse(text, Loader=_Loader):
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None):
            raise InputError("YAML anchors and aliases are not allowed", _loc(file, event.start_mark))
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                raise InputError(f"nesting deeper than {MAX_DEPTH} levels (a scenario needs about 6)",
                                 _loc(file, event.start_mark))
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
        if isinstance(event, (yaml.ScalarEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            nodes += 1
            if nodes > MAX_NODES:
                raise InputError(f"more than {MAX_NODES} values in one file", _loc(file, event.start_mark))


def parse_yaml(text: str, file: str | None = None) -> tuple[Any, Positions]:
    """Parse YAML text into plain data plus a field-path → (line, column) map."""
    try:
        _check_events(text, file)
        docs = list(yaml.compose_all(text, Loader=_Loader))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        loc = _loc(file, mark) if mark else Location(file, 1, 1)
        if "nesting depth" in str(exc.problem):  # libyaml >= 0.2.5 stops at its own depth (1000),
            # scanning ahead before _check_events sees the 65th level: the same error, located there
            raise InputError(f"nesting deeper than {MAX_DEPTH} levels (a scenario needs about 6)", loc) from None
        raise InputError(f"invalid YAML: {exc.problem or exc.context}", loc) from None
    except yaml.YAMLError as exc:  # a ReaderError: a character YAML does not allow (NUL, …)
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"invalid YAML: {msg}", _reader_location(exc, text, file)) from None
    if len(docs) != 1 or docs[0] is None:
        raise InputError("expected exactly one YAML document with content", Location(file, 1, 1))
    positions: Positions = {}
    return _construct(docs[0], file, (), positions, yaml.SafeLoader("")), positions


# binary formats a user may hand over by mistake (a renamed file): named instead of "not UTF-8"
_MAGIC = ((b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"GIF8", "a GIF image"),
          (b"%PDF", "a PDF document"), (b"PK\x03\x04", "a ZIP archive (or .usdz)"), (b"PXR-USDC", "a binary USD stage"),
          (b"\x7fELF", "an executable"), (b"\x1f\x8b", "a gzip archive"), (b"\x93NUMPY", "a numpy array"),
          (b"\x80\x04", "a Python pickle"), (b"\x80\x05", "a Python pickle"))


def _line_col(data: bytes, at: int) -> tuple[int, int]:
    """1-based (line, column) of byte offset ``at`` (the column counts bytes)."""
    line = data.count(b"\n", 0, at) + 1
    return line, at - (data.rfind(b"\n", 0, at) + 1) + 1


def _line_col_streamed(fh, at: int, chunk: int = 1 << 20) -> tuple[int, int]:
    """(line, column) of byte offset ``at`` of an open file, read in 1 MB chunks (nothing kept)."""
    fh.seek(0)
    line, col, pos = 1, 1, 0
    while pos < at:
        block = fh.read(min(chunk, at - pos))
        if not block:
            break
        nl = block.count(b"\n")
        if nl:
            line += nl
            col = len(block) - block.rfind(b"\n")
        else:
            col += len(block)
        pos += len(block)
    return line, col


def read_text(path: str | os.PathLike, kind: str, max_bytes: int) -> str:
    """A UTF-8 input file's text; every failure is an InputError naming the file (and, for a
    file too large or not UTF-8, the line and column where it goes wrong).  At most
    ``max_bytes + 1`` bytes are ever read, so a huge file costs nothing."""
    p = Path(path)
    try:
        if p.exists() and not p.is_dir() and not p.is_file():  # a FIFO or device would block or never end
            raise InputError(f"not a regular file, expected a {kind} file", Location(str(path)))
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > max_bytes:  # a regular file: refused before its bytes are read
                line, col = _line_col_streamed(fh, max_bytes)
                raise InputError(f"file is {size} bytes, larger than the {max_bytes} bytes a {kind} file may have "
                                 "(see docs/reliability.md, input limits)", Location(str(path), line, col))
            data = fh.read(max_bytes + 1)  # a pipe or a growing file: never more than the limit
    except FileNotFoundError:
        raise InputError("file not found", Location(str(path))) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected a {kind} file", Location(str(path))) from None
    except PermissionError:
        raise InputError("permission denied", Location(str(path))) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", Location(str(path))) from None
    if len(data) > max_bytes:
        line, col = _line_col(data, max_bytes)
        raise InputError(f"file is larger than the {max_bytes} bytes a {kind} file may have "
                         "(see docs/reliability.md, input limits)", Location(str(path), line, col))
    for magic, what in _MAGIC:
        if data.startswith(magic):
            raise InputError(f"file is {what}, not a {kind} file", Location(str(path), 1, 1))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line, col = _line_col(data, exc.start)
        raise InputError(f"file is not UTF-8 text (byte {exc.start}: {data[exc.start:exc.start + 1]!r})",
                         Location(str(path), line, col)) from None
    return text[1:] if text.startswith("\ufeff") else text  # a byte-order mark some editors write


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
