"""Load a scenario file (or a bundled scenario by name) into a validated :class:`Scenario`.

Every problem becomes an :class:`InputError` (exit code 2) whose message starts with
``file:line:col field.path:`` — for structural errors (wrong type, unknown field, …) and
for cross-field errors (a missing character, a time outside the scenario, an unknown
style, …) alike.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from scenarios.bundled import bundled_styles, find_scenario
from scenarios.errors import InputError, Location
from scenarios.repeat import REPEAT_JSON_SCHEMA, expand_repeats
from scenarios.schema import FieldProblem, Scenario
from scenarios.sketch_stages import add_sketch_stages
from scenarios.yamlio import Positions, error_location, parse_yaml, read_text

__all__ = ["load_scenario", "parse_scenario", "validate_scenario", "validation_context", "scenario_json_schema"]

_TAG_ERRORS = {"union_tag_invalid", "union_tag_not_found"}
# characters of a scenario file (UTF-8 bytes): the bundled ones have about 1 000; 1 000
# footprints written one per line take about 80 000
MAX_SCENARIO_BYTES = 256_000


def validation_context(file: str | os.PathLike | None = None, base_dir: str | os.PathLike | None = None) -> dict:
    """The pydantic context for a scenario: where style paths resolve, which styles exist."""
    if base_dir is None:
        base_dir = Path(file).resolve().parent if file is not None else Path.cwd()
    return {"base_dir": Path(base_dir), "file": str(file) if file is not None else None,
            "styles": bundled_styles()}


def _data_path(loc: tuple, data: Any) -> tuple:
    """Drop pydantic's non-data loc parts (union tags, function names) by walking the data."""
    out: list = []
    cur = data
    for i, part in enumerate(loc):
        last = i == len(loc) - 1
        if isinstance(cur, dict):
            if part in cur:
                out.append(part)
                cur = cur[part]
                continue
            if last and isinstance(part, str) and not part.startswith("function-"):
                out.append(part)  # a missing or extra field
            continue
        if isinstance(cur, (list, tuple)) and isinstance(part, int) and 0 <= part < len(cur):
            out.append(part)
            cur = cur[part]
            continue
        if isinstance(part, int) and last:
            out.append(part)
        # anything else (a tag, a type name) is not a data key: skip it
    return tuple(out)


def _describe(err: dict, data: Any) -> tuple[tuple, str]:
    path = _data_path(tuple(err["loc"]), data)
    msg = err["msg"]
    exc = (err.get("ctx") or {}).get("error")
    if isinstance(exc, FieldProblem):
        path = _data_path(tuple(err["loc"]) + exc.path, data)
        msg = exc.message
    elif msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    if err["type"] == "extra_forbidden":
        key = str(path[-1])
        msg = f"unknown field {key if len(key) <= 60 else key[:57] + '…'!r}"
    elif err["type"] in _TAG_ERRORS:
        path = path + ("type",)
        if err["type"] == "union_tag_not_found":
            msg = "missing 'type'"
        else:
            tag = (err.get("ctx") or {}).get("tag")
            expected = (err.get("ctx") or {}).get("expected_tags", "")
            msg = f"unknown type {tag!r} (known: {expected})"
    elif err["type"] == "missing":
        msg = f"missing required field {path[-1]!r}" if path else msg
    return path, msg


def validate_scenario(data: Any, positions: Positions, file: str | None = None,
                      base_dir: str | os.PathLike | None = None) -> Scenario:
    """Validate parsed YAML data; the first problem becomes an InputError with file:line:col.

    ``repeat`` blocks are expanded first (:mod:`scenarios.repeat`), then the flights of keyframe
    sketches without stated stages become ``jump`` goals (:mod:`scenarios.sketch_stages`)."""
    data, positions = expand_repeats(data, positions, file)
    data, positions, stages = add_sketch_stages(data, positions)  # flights a keyframe sketch implies
    ctx = validation_context(file, base_dir)
    try:
        scn = Scenario.model_validate(data, context=ctx)
        scn._positions = dict(positions)
        scn._sketch_stages = stages
        return scn
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        described = [_describe(e, data) for e in errors]
        for e in errors:
            exc_ = (e.get("ctx") or {}).get("error")
            if isinstance(exc_, FieldProblem) and exc_.more:
                prefix = _data_path(tuple(e["loc"]), data)
                described += [(_data_path(prefix + p, data), m) for p, m in exc_.more]
        # report in file order: the first problem a reader meets comes first
        described.sort(key=lambda d: error_location(file, positions, d[0]).line or 0)
        path, msg = described[0]
        more = []
        for p, m in described[1:6]:
            loc = error_location(file, positions, p)
            more.append(f"{loc.prefix()}: {m}")
        raise InputError(msg, error_location(file, positions, path), details=more) from None


def parse_scenario(text: str, file: str | None = None, base_dir: str | os.PathLike | None = None) -> Scenario:
    """Parse and validate scenario YAML text."""
    data, positions = parse_yaml(text, file)
    return validate_scenario(data, positions, file, base_dir)


def load_scenario(path_or_name: str | os.PathLike) -> Scenario:
    """Load a scenario file, or a bundled scenario by name (``walk``, ``tackle``)."""
    path = find_scenario(path_or_name)
    data, positions = parse_yaml(read_text(path, "scenario", MAX_SCENARIO_BYTES), str(path))
    if not isinstance(data, dict):
        line, col = positions.get((), (1, 1))
        raise InputError("a scenario must be a mapping of fields", Location(str(path), line, col))
    return validate_scenario(data, positions, str(path), Path(path).resolve().parent)


def scenario_json_schema() -> dict:
    """The JSON Schema of scenario files (for editors)."""
    schema = Scenario.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    props = schema.setdefault("properties", {})
    props["repeat"] = REPEAT_JSON_SCHEMA
    # an edit scenario (scenarios/edit_block.py) has an `edit` block and none of a synthesis's fields;
    # a synthesis needs a duration and characters (possibly an empty list when repeat blocks add
    # them: validated after expansion)
    synthesis = {"required": ["duration", "characters"], "not": {"required": ["edit"]},
                 "anyOf": [{"required": ["repeat"]}, {"properties": {"characters": {"minItems": 1}}}]}
    from scenarios.edit_block import EDIT_EXCLUDES
    edit = {"required": ["edit"], "not": {"anyOf": [{"required": [f]} for f in EDIT_EXCLUDES]}}
    schema["oneOf"] = [synthesis, edit]
    return schema
