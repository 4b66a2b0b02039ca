"""The ``repeat`` construct: many similar characters, goals and couplings from one template.

A scenario may have a top-level ``repeat`` list.  Each block has a ``for`` mapping of
variable names to equally long lists of values, and template lists ``characters``,
``goals`` and/or ``couplings``.  For every index k the templates are copied with the
variables bound to their k-th values and appended to the scenario's own lists (block by
block, k by k, item by item)::

    repeat:
      - for: {i: [1, 2], y: [-1.0, 1.0]}
        characters:
          - name: walker${i}                   # text: walker1, walker2
            start: {position: [0.0, "${y}"]}   # a whole "${...}" keeps the value's type
        goals:
          - {type: walk_to, character: "walker${i}", target: [2.0, "${y + 0.5}"], time: 1.0}

Inside ``${...}``: variable names, numbers, ``+ - * /``, unary minus and parentheses.
The expansion happens before validation, so the expanded scenario is validated like any
other, and an error in an expanded item is reported at the template's file:line:col (the
field path names the expanded item, e.g. ``characters[3].start``).  Errors in the
construct itself (an unknown variable, lists of different lengths, a bad expression) are
:class:`~scenarios.errors.InputError` located at the offending node.
"""
from __future__ import annotations

import ast
import copy
import re
from typing import Any

from scenarios.errors import InputError
from scenarios.yamlio import Positions, error_location

__all__ = ["expand_repeats", "SECTIONS", "MAX_REPEAT", "REPEAT_JSON_SCHEMA"]

SECTIONS = ("characters", "goals", "couplings")
MAX_REPEAT = 100  # values per variable
_VAR = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,31}$")
_EXPR = re.compile(r"\$\{([^{}]*)\}")

REPEAT_JSON_SCHEMA = {
    "type": "array", "description": "template blocks expanded before validation (docs/scenario-language.md)",
    "items": {"type": "object", "additionalProperties": False, "required": ["for"],
              "properties": {"for": {"type": "object", "description": "variable -> list of values (equal lengths)",
                                     "additionalProperties": {"type": "array", "minItems": 1,
                                                              "maxItems": MAX_REPEAT}},
                             **{s: {"type": "array", "items": {"type": "object"}} for s in SECTIONS}}}}


def _err(msg: str, file, positions: Positions, path: tuple) -> InputError:
    return InputError(msg, error_location(file, positions, path))


def _eval(expr: str, env: dict, where) -> Any:
    """Value of a ``${...}`` expression (names, numbers, + - * /, unary minus)."""
    try:
        tree = ast.parse(expr.strip(), mode="eval")
    except SyntaxError:
        raise where(f"bad expression ${{{expr}}} (allowed: variables, numbers, + - * / and parentheses)") from None

    def ev(n):
        if isinstance(n, ast.Expression):
            return ev(n.body)
        if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
            return n.value
        if isinstance(n, ast.Name):
            if n.id not in env:
                raise where(f"unknown variable {n.id!r} in ${{{expr}}} (this block's variables: "
                            f"{', '.join(sorted(env)) or 'none'})")
            return env[n.id]
        if isinstance(n, ast.UnaryOp) and isinstance(n.op, (ast.USub, ast.UAdd)):
            v = ev(n.operand)
            _number(v, expr, where)
            return -v if isinstance(n.op, ast.USub) else v
        if isinstance(n, ast.BinOp) and isinstance(n.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            a, b = ev(n.left), ev(n.right)
            _number(a, expr, where)
            _number(b, expr, where)
            if isinstance(n.op, ast.Add):
                return a + b
            if isinstance(n.op, ast.Sub):
                return a - b
            if isinstance(n.op, ast.Mult):
                return a * b
            if b == 0:
                raise where(f"division by zero in ${{{expr}}}")
            return a / b
        raise where(f"bad expression ${{{expr}}} (allowed: variables, numbers, + - * / and parentheses)")

    return ev(tree)


def _number(v, expr, where) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise where(f"arithmetic on a non-number ({v!r}) in ${{{expr}}}")


def _text(v) -> str:
    if isinstance(v, float):
        return repr(round(v, 12))
    return str(v)


def _substitute(node: Any, env: dict, path: tuple, file, positions: Positions) -> Any:
    if isinstance(node, dict):
        return {k: _substitute(v, env, path + (k,), file, positions) for k, v in node.items()}
    if isinstance(node, list):
        return [_substitute(v, env, path + (i,), file, positions) for i, v in enumerate(node)]
    if not isinstance(node, str) or "${" not in node:
        return node

    def where(msg: str) -> InputError:
        return _err(msg, file, positions, path)

    m = _EXPR.fullmatch(node.strip())
    if m:
        v = _eval(m.group(1), env, where)
        return round(v, 12) if isinstance(v, float) else v
    out = _EXPR.sub(lambda mm: _text(_eval(mm.group(1), env, where)), node)
    if "${" in out:
        raise where(f"unterminated ${{...}} in {node!r}")
    return out


def expand_repeats(data: Any, positions: Positions, file: str | None = None) -> tuple[Any, Positions]:
    """``data`` with its ``repeat`` blocks expanded (a new dict; ``data`` is not changed) and
    ``positions`` extended so expanded items point at their templates."""
    if not isinstance(data, dict) or "repeat" not in data:
        return data, positions
    blocks = data["repeat"]
    if not isinstance(blocks, list) or not blocks:
        raise _err("'repeat' must be a non-empty list of blocks (each with 'for' and templates)", file, positions,
                   ("repeat",))
    out = {k: (copy.deepcopy(v) if k in SECTIONS else v) for k, v in data.items() if k != "repeat"}
    pos = dict(positions)
    for b, block in enumerate(blocks):
        bp = ("repeat", b)
        if not isinstance(block, dict):
            raise _err("a repeat block must be a mapping with 'for' and templates", file, positions, bp)
        unknown = sorted(set(block) - {"for", *SECTIONS})
        if unknown:
            raise _err(f"unknown field {unknown[0]!r} (a repeat block has 'for', "
                       f"{', '.join(repr(s) for s in SECTIONS)})", file, positions, bp + (unknown[0],))
        if "for" not in block:
            raise _err("missing required field 'for' (variable -> list of values)", file, positions, bp + ("for",))
        loop = block["for"]
        if not isinstance(loop, dict) or not loop:
            raise _err("'for' must map variable names to lists of values", file, positions, bp + ("for",))
        n = None
        for var, vals in loop.items():
            vp = bp + ("for", var)
            if not isinstance(var, str) or not _VAR.match(var):
                raise _err(f"variable name {var!r} must be a letter or _ then letters, digits, _", file, positions, vp)
            if not isinstance(vals, list) or not vals or len(vals) > MAX_REPEAT:
                raise _err(f"variable {var!r}: expected a list of 1 to {MAX_REPEAT} values", file, positions, vp)
            for i, v in enumerate(vals):
                if isinstance(v, (dict, list)) or v is None:
                    raise _err(f"variable {var!r}: values must be numbers or strings", file, positions, vp + (i,))
            if n is None:
                n = len(vals)
            elif len(vals) != n:
                first = next(iter(loop))
                raise _err(f"variable {var!r} has {len(vals)} values but {first!r} has {n}: every variable of a "
                           "block needs one value per repetition", file, positions, vp)
        if not any(s in block for s in SECTIONS):
            raise _err(f"a repeat block needs at least one of {', '.join(SECTIONS)}", file, positions, bp)
        for sec in SECTIONS:
            if sec not in block:
                continue
            templates = block[sec]
            if not isinstance(templates, list) or not templates:
                raise _err(f"'{sec}' in a repeat block must be a non-empty list of templates", file, positions,
                           bp + (sec,))
            target = out.get(sec)
            if target is None:
                target = out[sec] = []
                pos.setdefault((sec,), positions.get(bp + (sec,), (1, 1)))
            elif not isinstance(target, list):
                raise _err(f"'{sec}' must be a list", file, positions, (sec,))
            for k in range(n):
                env = {var: vals[k] for var, vals in loop.items()}
                for j, tpl in enumerate(templates):
                    tp = bp + (sec, j)
                    new = (sec, len(target))
                    item = _substitute(tpl, env, tp, file, positions)
                    target.append(item)
                    for p, lc in positions.items():  # the expanded item's nodes point at the template's
                        if p[:len(tp)] == tp:
                            pos[new + p[len(tp):]] = lc
    return out, pos
