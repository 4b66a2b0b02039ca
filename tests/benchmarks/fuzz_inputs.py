"""Benchmark: property-based fuzzing of every input compose parses (Hypothesis).

    python tests/benchmarks/fuzz_inputs.py [--cases 20000] [--seed 0] [--timeout 5] [--jobs 1]

Mutates every bundled scenario (``scenarios/*.yaml``) and every shipped BVH clip
(``scenarios/clips/*.bvh``, and ``../shared/mocap/*.bvh`` next to the repository, or
``$COMPOSE_SHARED_MOCAP``, when present): dropped, duplicated and renamed keys, wrong types,
NaN/inf, 1e300, negative and zero numbers, deep nesting, huge lists and strings, truncated
and corrupted motion lines, wrong frame counts and times, broken hierarchies, non-UTF-8 and
binary bytes.  Each case goes through the real entry points in a worker process:

* scenario: ``load_scenario`` → ``check_scenario`` (style files, schedule compiled, windows
  checked) → ``build_scene`` (footsteps, characters, styles: everything ``compose run`` does
  before its first solve);
* BVH: ``read_clip`` (parse, rig match, T-pose, floor, resampling, stature) and the
  character ``load_clip`` would fit, i.e. everything ``compose learn`` does before retargeting.

Outcomes: *accepted* (no error), *located error* (a :class:`ComposeError` naming the input
file and a line inside it), *crash* (any other exception, or a ComposeError without file and
line), *hang* (the case ran longer than ``--timeout`` s: the worker is killed and restarted),
*wrote files* (anything appeared in the worker's empty working directory or next to the
input file).  Crashes, hangs and writes are printed with a reproducer.  Last line, exactly:
cases=<int> accepted=<int> located_errors=<int> crashes=<int> hangs=<int> wrote_files=<int>
"""
from __future__ import annotations

import argparse
import copy
import math
import multiprocessing as mp
import os
import shutil
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, Phase, given, settings, strategies as st
from hypothesis import seed as hyp_seed

REPO = Path(__file__).resolve().parents[2]
SCENARIO_FILES = sorted((REPO / "scenarios").glob("*.yaml"))
_SHARED = Path(os.environ.get("COMPOSE_SHARED_MOCAP") or REPO.parent / "shared" / "mocap")
_BUNDLED_CLIPS = sorted((REPO / "scenarios" / "clips").glob("*.bvh"))
CLIP_FILES = _BUNDLED_CLIPS + [p for p in (sorted(_SHARED.glob("*.bvh")) if _SHARED.is_dir() else [])
                               if p.name not in {b.name for b in _BUNDLED_CLIPS}]  # the delivery, not copied
PRESETS = ("adult_male", "adult_female", "child")
OUTCOMES = ("accepted", "located_errors", "crashes", "hangs", "wrote_files")


# --- the worker: runs one case through the real entry points ---------------------------------

def _located(exc, path: str, text_lines: int) -> str | None:
    """None when a ComposeError names the input file and a line in it; else why not."""
    loc = exc.location
    if loc.file is None or Path(loc.file).resolve() != Path(path).resolve():
        return f"names file {loc.file!r}, not the input"
    if loc.line is None or not (1 <= loc.line <= text_lines + 1):
        return f"names line {loc.line!r} (the file has {text_lines} lines)"
    return None


def run_case(kind: str, data: bytes, params: dict, in_dir: Path, work_dir: Path) -> tuple[str, str]:
    """(outcome, detail) of one case; ``work_dir`` is the (empty) current directory."""
    from scenarios.errors import ComposeError

    name = "fuzz.yaml" if kind == "scenario" else "fuzz.bvh"
    path = in_dir / name
    path.write_bytes(data)
    # any line-break convention counts (\r alone, U+2028 …: YAML and str.splitlines honour them)
    n_lines = max(data.count(b"\n"), data.count(b"\r"), len(data.decode("utf-8", "replace").splitlines())) + 1
    try:
        if kind == "selftest":  # the harness's own checks: a slow, a writing or a crashing "parser"
            if params.get("spin"):  # compute for that many seconds
                end = time.process_time() + params["spin"]
                while time.process_time() < end:
                    pass
            if params.get("write"):
                (work_dir / "stray.txt").write_text("x")
            if params.get("raise"):
                raise ValueError("boom")
            if params.get("unlocated"):
                raise ComposeError("an error without a place")
        elif kind == "scenario":
            from scenarios.loader import load_scenario
            from scenegraph.world.scene import build_scene
            from schedules.cli.scenario import check_scenario

            scn = load_scenario(str(path))
            check_scenario(scn)
            scene = build_scene(scn)
            for c in scene.characters:  # an accepted scene must be finite: NaN would reach the solver
                if not (np.all(np.isfinite(c.motion.ctrl)) and np.all(np.isfinite(c.motion.warp))):
                    raise FloatingPointError(f"the initial motion of {c.name} is not finite")
        else:
            from scenegraph.model.body import PRESETS as BODY_PRESETS, make_character
            from scenegraph.mocap.clip import read_clip

            preset = params.get("preset", "adult_male")
            clip = read_clip(str(path), frames=params.get("frames"), preset=preset)
            p = BODY_PRESETS[preset]  # the character load_clip fits to the clip
            H = clip.performer_height
            make_character(preset, height=H, mass=p.mass * (H / p.height) ** 2)
        outcome, detail = "accepted", ""
    except ComposeError as exc:
        why = _located(exc, str(path), n_lines)
        outcome, detail = ("located_errors", str(exc).splitlines()[0]) if why is None else \
            ("crashes", f"unlocated {type(exc).__name__} ({why}): {exc}")
    except Exception as exc:  # noqa: BLE001 - a crash is exactly what is being looked for
        tb = traceback.extract_tb(exc.__traceback__)
        where = "; ".join(f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in tb[-3:])
        outcome, detail = "crashes", f"{type(exc).__name__}: {str(exc)[:300]} at {where}"
    left = sorted(x.name for x in in_dir.iterdir() if x.name != name) + sorted(x.name for x in work_dir.iterdir())
    path.unlink(missing_ok=True)
    if left:
        for x in list(in_dir.iterdir()) + list(work_dir.iterdir()):
            shutil.rmtree(x) if x.is_dir() else x.unlink()
        return "wrote_files", f"wrote {left} ({outcome}: {detail})"
    return outcome, detail


def _worker_main(conn, root: str) -> None:
    import resource

    try:  # a runaway allocation becomes a MemoryError (a crash), not the machine swapping
        resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))
    except (ValueError, OSError):
        pass
    in_dir, work_dir = Path(root) / "in", Path(root) / "cwd"
    in_dir.mkdir(exist_ok=True)
    work_dir.mkdir(exist_ok=True)
    os.chdir(work_dir)
    import scenarios.loader  # noqa: F401  (warm imports before the first timed case)
    import scenegraph.mocap.clip  # noqa: F401
    import scenegraph.world.scene  # noqa: F401
    import schedules.cli.scenario  # noqa: F401
    conn.send("ready")
    while True:
        msg = conn.recv()
        if msg is None:
            return
        kind, data, params = msg
        outcome, detail = run_case(kind, data, params, in_dir, work_dir)
        conn.send((outcome, detail[:2000]))


class Worker:
    """One worker process; a case that overruns ``timeout`` s is a hang and the worker is
    replaced (a hang is never waited out)."""

    def __init__(self, timeout: float):
        self.timeout = timeout
        self.root = tempfile.mkdtemp(prefix="compose-fuzz-")
        self.proc = None
        self.conn = None

    def _start(self):
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, self.root), daemon=True)
        self.proc.start()
        child.close()
        if not self.conn.poll(120):
            raise RuntimeError("fuzz worker did not start")
        self.conn.recv()

    def _cpu(self) -> float | None:
        """CPU seconds (user + system) the worker has used; None where /proc is missing."""
        try:
            fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, ValueError, IndexError):
            return None

    def run(self, kind: str, data: bytes, params: dict) -> tuple[str, str]:
        """Run one case.  A hang is a case that used more than ``timeout`` s of the worker's CPU
        time (wall time on a machine shared with other jobs would count their load), or more
        than ten times that in wall time (a case blocked without computing)."""
        if self.proc is None or not self.proc.is_alive():
            self._start()
        cpu0, t0 = self._cpu(), time.monotonic()
        self.conn.send((kind, data, params))
        while not self.conn.poll(0.05):
            cpu = self._cpu()
            used = (cpu - cpu0) if cpu is not None and cpu0 is not None else time.monotonic() - t0
            if used > self.timeout or time.monotonic() - t0 > 10 * self.timeout:
                self._stop(kill=True)
                return "hangs", f"no answer within {self.timeout:g} s of CPU time"
        try:
            return self.conn.recv()
        except EOFError:
            self._stop(kill=True)
            return "crashes", "the worker process died"

    def _stop(self, kill: bool = False):
        if self.proc is not None:
            if kill:
                self.proc.kill()
            else:
                try:
                    self.conn.send(None)
                except (BrokenPipeError, OSError):
                    pass
            self.proc.join(10)
            if self.proc.is_alive():
                self.proc.kill()
                self.proc.join()
        self.proc = None
        for d in ("in", "cwd"):  # leftovers of a killed case
            p = Path(self.root) / d
            if p.exists():
                shutil.rmtree(p)

    def close(self):
        self._stop()
        shutil.rmtree(self.root, ignore_errors=True)


# --- mutations ---------------------------------------------------------------------------------

_DEEP, _HUGE, _BIGINT = "@@DEEP@@", "@@HUGE@@", "@@BIGINT@@"
SPECIAL_NUMBERS = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0, 0.0, -0.0, -1, -1.0, -1e-9, 1e-300, 5e-324,
                   2 ** 63, -2 ** 63, 10 ** 30, 1e6, 0.001, 0.05, 0.1, 0.19, 0.2, 3600.0, 601.0, 1e4, 10001.0, 12.5]
WEIRD_STRINGS = ["", " ", "1e6", "nan", ".inf", "~", "null", "true", "yes", "no", "on", "0x1F", "0o17", "1_000",
                 "walk", "run", "default", "../../etc/passwd", "/etc/passwd", "C:\\x", "styles/walk.yaml",
                 "adult_male", "palm_r", "l", "r", "a" * 100, "é✓😀", "\t", "a\nb", "{", "[", "- x", "&a", "*a",
                 "!!python/object:os.system", "<<", "%YAML 1.1", "---", "..."]


def _any_value():
    scalars = st.one_of(st.sampled_from(SPECIAL_NUMBERS), st.sampled_from(WEIRD_STRINGS), st.booleans(), st.none(),
                        st.integers(-10 ** 6, 10 ** 6), st.floats(allow_nan=True, allow_infinity=True),
                        st.text(max_size=20), st.sampled_from([_DEEP, _HUGE, _BIGINT]))
    return st.one_of(scalars, st.lists(scalars, max_size=4), st.dictionaries(st.text(max_size=8), scalars, max_size=4),
                     st.lists(st.lists(scalars, max_size=3), max_size=3))


def _paths(node, prefix=()):
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, prefix + (i,))
    return out


def _get(node, path):
    for p in path:
        node = node[p]
    return node


def _mutate_data(draw, data):
    """One structural mutation of parsed scenario data, in place (returns the new root)."""
    paths = _paths(data)
    path = draw(st.sampled_from(paths))
    op = draw(st.sampled_from(["drop", "replace", "number", "scale", "rename", "insert", "dup_item", "swap",
                               "empty"]))
    if not path:
        return draw(_any_value()) if op == "replace" else data
    parent, key = _get(data, path[:-1]), path[-1]
    value = parent[key]
    if op == "drop":
        del parent[key]
    elif op == "replace":
        parent[key] = draw(_any_value())
    elif op == "number":
        parent[key] = draw(st.sampled_from(SPECIAL_NUMBERS))
    elif op == "scale":
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            parent[key] = value * draw(st.sampled_from([-1, 0, 1e-6, 0.01, 0.5, 2, 10, 100, 1e6, 1e300]))
        elif isinstance(value, list) and value:  # copies, not aliases (a later swap would make a cycle)
            parent[key] = [copy.deepcopy(v) for _ in range(draw(st.sampled_from([2, 10, 100, 2000]))) for v in value]
    elif op == "rename" and isinstance(parent, dict):
        new = draw(st.one_of(st.sampled_from(["", "name", "type", "time", "target", "character", "steps", "x",
                                              "Name", "time ", "duration"]), st.text(max_size=10)))
        parent[new] = parent.pop(key)
    elif op == "insert":
        if isinstance(value, dict):
            value[draw(st.text(max_size=10))] = draw(_any_value())
        elif isinstance(value, list):
            value.insert(draw(st.integers(0, len(value))), draw(_any_value()))
    elif op == "dup_item" and isinstance(parent, list):
        parent.insert(key, copy.deepcopy(value))
    elif op == "swap":
        other = draw(st.sampled_from(paths))
        if other and other[:len(path)] != path and path[:len(other)] != other:
            op_parent, ok = _get(data, other[:-1]), other[-1]
            parent[key], op_parent[ok] = op_parent[ok], value
    elif op == "empty":
        parent[key] = type(value)() if isinstance(value, (dict, list, str)) else None
    return data


def _dump(data) -> str:
    text = yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper), sort_keys=False, allow_unicode=True,
                     width=120)
    return text


def _expand_sentinels(draw, text: str) -> str:
    for token in (_DEEP, _HUGE, _BIGINT):
        for quoted in (f"'{token}'", f'"{token}"', token):
            while quoted in text:
                if token == _DEEP:
                    n = draw(st.sampled_from([50, 65, 200, 1000, 20000]))
                    rep = "[" * n + "1" + "]" * n
                elif token == _HUGE:
                    n = draw(st.sampled_from([1001, 5000, 100_000, 300_000]))
                    rep = "[" + ", ".join(["0.5"] * n) + "]"
                else:
                    rep = "9" * draw(st.sampled_from([20, 400, 5000, 100_000]))
                text = text.replace(quoted, rep, 1)
    return text


def _mutate_bytes(draw, raw: bytes) -> bytes:
    """One byte- or line-level mutation (syntax, encoding, truncation)."""
    op = draw(st.sampled_from(["truncate", "delete_range", "insert_bytes", "flip", "dup_line", "drop_line",
                               "repeat_line", "tabs", "crlf", "yaml_feature", "binary", "long_line", "nul",
                               "bom", "empty"]))
    n = len(raw)
    at = draw(st.integers(0, max(n, 0)))
    lines = raw.split(b"\n")
    li = draw(st.integers(0, max(len(lines) - 1, 0)))
    if op == "truncate":
        return raw[:at]
    if op == "delete_range":
        return raw[:at] + raw[at + draw(st.integers(1, 200)):]
    if op == "insert_bytes":
        return raw[:at] + draw(st.one_of(st.binary(min_size=1, max_size=8),
                                         st.sampled_from([b"\xff", b"\xfe\xff", b"\xc3", b"\xed\xa0\x80", b"\x80",
                                                          b"\xe2\x82", b"\x00", b"\x1b[31m", b"\x85", "\u2028".encode()])
                                         )) + raw[at:]
    if op == "flip" and n:
        i = min(at, n - 1)
        return raw[:i] + bytes([raw[i] ^ (1 << draw(st.integers(0, 7)))]) + raw[i + 1:]
    if op == "dup_line":
        return b"\n".join(lines[:li + 1] + [lines[li]] + lines[li + 1:])
    if op == "drop_line":
        return b"\n".join(lines[:li] + lines[li + 1:])
    if op == "repeat_line":  # at most ~4 MB more: beyond that it only tests how fast the harness writes
        times = min(draw(st.sampled_from([10, 1000, 50_000])), 4_000_000 // (len(lines[li]) + 1))
        return b"\n".join(lines[:li + 1] + [lines[li]] * times + lines[li + 1:])
    if op == "tabs":
        return raw.replace(b"  ", b"\t", draw(st.integers(1, 5)))
    if op == "crlf":
        return raw.replace(b"\n", draw(st.sampled_from([b"\r\n", b"\r"])))
    if op == "yaml_feature":
        feat = draw(st.sampled_from([b"&a ", b"*a", b"!!python/object/apply:os.system ['true'] ", b"!custom ",
                                     b"<<: {}\n", b"---\n", b"...\n", b"%YAML 1.1\n", b"? ", b"|\n  x\n", b">-\n",
                                     b"{", b"}", b"[", b"]", b"- ", b": ", b"#", b"'", b'"', b"\\", b"@", b"`"]))
        return raw[:at] + feat + raw[at:]
    if op == "binary":
        return draw(st.sampled_from([b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)),
                                     b"PK\x03\x04" + bytes(64), b"\x7fELF" + bytes(range(200)), b"#usda 1.0\n(\n)\n",
                                     b"PXR-USDC" + bytes(100)])) + (raw[:at] if draw(st.booleans()) else b"")
    if op == "long_line":
        return raw[:at] + b"x" * draw(st.sampled_from([10_000, 1_000_000])) + raw[at:]
    if op == "nul":
        return raw.replace(b" ", b"\x00", 1)
    if op == "bom":
        return b"\xef\xbb\xbf" + raw
    if op == "empty":
        return draw(st.sampled_from([b"", b"\n", b"   \n\t\n", b"#\n", b"~\n", b"[]\n", b"{}\n", b"0\n"]))
    return raw


@dataclass(frozen=True)
class _Seed:
    name: str
    text: str
    data: object = None


def _scenario_seeds() -> list[_Seed]:
    out = []
    for p in SCENARIO_FILES:
        text = p.read_text(encoding="utf-8")
        out.append(_Seed(p.name, text, yaml.safe_load(text)))
    return out


def _short_clip(text: str, frames: int) -> str:
    """The clip with only its first ``frames`` motion lines (a cheap seed that still walks)."""
    head, _, motion = text.partition("MOTION")
    lines = motion.strip("\n").splitlines()
    body = [ln for ln in lines[2:] if ln.strip()][:frames]
    return f"{head}MOTION\nFrames: {len(body)}\n{lines[1]}\n" + "\n".join(body) + "\n"


def _clip_seeds() -> list[_Seed]:
    out = []
    for p in CLIP_FILES:
        text = p.read_text(encoding="utf-8")
        out.append(_Seed(p.name, text))
        out.append(_Seed(f"{p.name}[:90]", _short_clip(text, 90)))
    return out


@st.composite
def scenario_cases(draw, seeds):
    seed = draw(st.sampled_from(seeds))
    data = copy.deepcopy(seed.data)
    for _ in range(draw(st.integers(0, 3))):
        data = _mutate_data(draw, data)
    text = _expand_sentinels(draw, _dump(data)) if draw(st.integers(0, 9)) else seed.text
    raw = text.encode("utf-8", "surrogatepass")
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 2]))):
        raw = _mutate_bytes(draw, raw)
        if len(raw) > 8_000_000:
            raw = raw[:8_000_000]
    return "scenario", seed.name, raw, {}


_BVH_NUMBERS = ["nan", "inf", "-inf", "1e300", "-1e300", "1e309", "0", "-0", "1e-300", "abc", "1,5", "--1", "0x10",
                "", "1.2.3", "+", "1e", "١٢", "NaN", "Infinity"]


def _mutate_bvh(draw, text: str) -> str:
    head, sep, motion = text.partition("MOTION")
    hlines = head.split("\n")
    mlines = motion.split("\n")
    op = draw(st.sampled_from(["frames", "frame_time", "value", "drop_value", "add_value", "drop_frames",
                               "offset", "channels", "channel_name", "joint_name", "brace", "deep", "wide",
                               "drop_hier_line", "dup_hier_block", "no_motion"]))
    frame_idx = [i for i, ln in enumerate(mlines) if ln.strip() and not ln.strip().startswith("Frame")]
    if op == "frames":
        new = draw(st.sampled_from(["0", "-1", "1", "2", "3", "10", "1000000", "10000000000", "1e3", "1.5", "x", "",
                                    "99999999999999999999999", str(len(frame_idx) + 1), str(max(len(frame_idx) - 1, 0))]))
        mlines = [f"Frames: {new}" if ln.startswith("Frames:") else ln for ln in mlines]
    elif op == "frame_time":
        new = draw(st.sampled_from(["0", "-0.01", "nan", "inf", "1e300", "1e-300", "1e-6", "11", "x", "", "0.1 0.2"]))
        mlines = [f"Frame Time: {new}" if ln.startswith("Frame Time:") else ln for ln in mlines]
    elif op in ("value", "drop_value", "add_value") and frame_idx:
        i = draw(st.sampled_from(frame_idx))
        toks = mlines[i].split()
        k = draw(st.integers(0, max(len(toks) - 1, 0)))
        if op == "value" and toks:
            toks[k] = draw(st.sampled_from(_BVH_NUMBERS))
        elif op == "drop_value" and toks:
            del toks[k]
        else:
            toks.insert(k, "0.0")
        mlines[i] = " ".join(toks)
    elif op == "drop_frames" and frame_idx:
        cut = draw(st.sampled_from(frame_idx))
        mlines = mlines[:cut]
    elif op in ("offset", "channels", "channel_name", "joint_name", "brace", "drop_hier_line"):
        kw = {"offset": "OFFSET", "channels": "CHANNELS", "channel_name": "CHANNELS", "joint_name": "JOINT",
              "brace": "{", "drop_hier_line": ""}[op]
        idx = [i for i, ln in enumerate(hlines) if kw in ln] or [0]
        i = draw(st.sampled_from(idx))
        toks = hlines[i].split()
        if op == "offset" and len(toks) > 1:
            toks[draw(st.integers(1, len(toks) - 1))] = draw(st.sampled_from(_BVH_NUMBERS))
        elif op == "channels" and len(toks) > 1:
            toks[1] = draw(st.sampled_from(["-1", "0", "1", "7", "100", "3.5", "x", "99999999999"]))
        elif op == "channel_name" and len(toks) > 2:
            toks[draw(st.integers(2, len(toks) - 1))] = draw(st.sampled_from(
                ["Wrotation", "Xposition", "Xrotation", "xrotation", "JOINT", "}", "MOTION"]))
        elif op == "joint_name" and len(toks) > 1:
            toks[1] = draw(st.sampled_from(["Hips", "LeftFoot", "Unknown", "{", "End", "JOINT", "a" * 1000, "é"]))
        elif op == "brace":
            toks = []
        elif op == "drop_hier_line":
            toks = []
        hlines[i] = " ".join(toks)
    elif op == "deep":  # JOINT nested thousands of levels (a recursive parser exhausts the stack)
        n = draw(st.sampled_from([100, 1000, 5000]))
        nest = "".join(f"JOINT j{k}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" for k in range(n))
        nest += "End Site\n{\nOFFSET 0 1 0\n}\n" + "}\n" * n
        i = next((i for i, ln in enumerate(hlines) if "End Site" in ln), len(hlines) - 1)
        hlines.insert(i, nest)
    elif op == "wide":  # thousands of joints or channels
        n = draw(st.sampled_from([500, 5000, 50_000]))
        sib = "JOINT w{k}\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n" \
              "End Site\n{{\nOFFSET 0 1 0\n}}\n}}\n"
        i = next((i for i, ln in enumerate(hlines) if "End Site" in ln), len(hlines) - 1)
        hlines.insert(i, "".join(sib.format(k=k) for k in range(n)))
    elif op == "dup_hier_block":
        idx = [i for i, ln in enumerate(hlines) if "JOINT" in ln] or [0]
        i = draw(st.sampled_from(idx))
        hlines = hlines[:i] + hlines[i:i + 8] + hlines[i:]
    elif op == "no_motion":
        return head
    return "\n".join(hlines) + sep + "\n".join(mlines)


@st.composite
def bvh_cases(draw, seeds):
    seed = draw(st.sampled_from(seeds))
    text = seed.text
    for _ in range(draw(st.integers(0, 2))):
        text = _mutate_bvh(draw, text)
    raw = text.encode("utf-8")
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2]))):
        raw = _mutate_bytes(draw, raw)
        if len(raw) > 8_000_000:  # a 100 MB file is tested by tests/system/test_input_limits.py, not sent 1000 times
            raw = raw[:8_000_000]
    frames = draw(st.one_of(st.none(), st.tuples(st.integers(-5, 200), st.integers(-5, 400)),
                            st.tuples(st.sampled_from([0, 1, None]), st.sampled_from([None, 2, 3, 60, 10 ** 9]))))
    return "bvh", seed.name, raw, {"frames": frames, "preset": draw(st.sampled_from(PRESETS))}


# --- the campaign ------------------------------------------------------------------------------

@dataclass
class Tally:
    counts: dict = field(default_factory=lambda: {k: 0 for k in OUTCOMES})
    failures: list = field(default_factory=list)  # (outcome, kind, seed, detail, reproducer path)
    seconds: float = 0.0

    @property
    def cases(self) -> int:
        return sum(self.counts.values())

    def line(self) -> str:
        c = self.counts
        return (f"cases={self.cases} accepted={c['accepted']} located_errors={c['located_errors']} "
                f"crashes={c['crashes']} hangs={c['hangs']} wrote_files={c['wrote_files']}")


def campaign(n_cases: int, seed: int = 0, timeout: float = 5.0, bvh_share: float = 0.3, keep: Path | None = None,
             log=None) -> Tally:
    """Run ``n_cases`` Hypothesis-generated cases (a share ``bvh_share`` of them BVH clips)."""
    tally = Tally()
    worker = Worker(timeout)
    t0 = time.perf_counter()
    scen_seeds, clip_seeds = _scenario_seeds(), _clip_seeds()

    def record(case):
        kind, seed_name, raw, params = case
        outcome, detail = worker.run(kind, raw, params)
        tally.counts[outcome] += 1
        if outcome in ("crashes", "hangs", "wrote_files"):
            repro = None
            if keep is not None:
                keep.mkdir(parents=True, exist_ok=True)
                repro = keep / f"{outcome}_{len(tally.failures):04d}.{'yaml' if kind == 'scenario' else 'bvh'}"
                repro.write_bytes(raw)
            tally.failures.append((outcome, kind, seed_name, detail, params, repro))
            if log is not None:
                label = {'crashes': 'crash', 'hangs': 'hang'}.get(outcome, outcome)
                print(f"{label}: {kind} from {seed_name} {params or ''}: "
                      f"{detail}" + (f" [{repro}]" if repro else ""), file=log, flush=True)
        if log is not None and tally.cases % 1000 == 0:
            print(f"  {tally.line()} [{time.perf_counter() - t0:.0f} s]", file=log, flush=True)

    n_bvh = int(round(n_cases * bvh_share)) if clip_seeds else 0
    try:
        for kind, n, strat in (("scenario", n_cases - n_bvh, scenario_cases(scen_seeds)),
                               ("bvh", n_bvh, bvh_cases(clip_seeds))):
            if n <= 0:
                continue

            target, round_ = tally.cases + n, 0
            while tally.cases < target and round_ < 5:  # Hypothesis may stop a little early
                left = target - tally.cases

                @settings(max_examples=left, deadline=None, database=None, phases=[Phase.generate],
                          suppress_health_check=list(HealthCheck))
                @hyp_seed(seed * 7919 + round_ * 104729 + len(kind))
                @given(strat)
                def one(case):
                    if tally.cases < target:
                        record(case)

                try:
                    one()
                except Exception as exc:  # noqa: BLE001 - a bug of the generator, not of compose
                    if log is not None:
                        print(f"harness error while generating (round {round_}): {type(exc).__name__}: {exc}"[:500],
                              file=log, flush=True)
                round_ += 1
    finally:
        worker.close()
    tally.seconds = time.perf_counter() - t0
    return tally


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=20_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=5.0, help="seconds per case before it counts as a hang")
    ap.add_argument("--bvh-share", type=float, default=0.3, help="share of the cases that are BVH clips")
    ap.add_argument("--keep", type=Path, help="write the input of every crash, hang or write here")
    args = ap.parse_args(argv)
    print(f"fuzzing {len(SCENARIO_FILES)} scenarios and {len(CLIP_FILES)} clips "
          f"({', '.join(p.name for p in CLIP_FILES)})", file=sys.stderr)
    tally = campaign(args.cases, args.seed, args.timeout, args.bvh_share, args.keep, log=sys.stderr)
    print(f"{tally.seconds:.0f} s, {tally.seconds / max(tally.cases, 1) * 1000:.1f} ms per case")
    print(tally.line())
    return 0 if not (tally.counts["crashes"] or tally.counts["hangs"] or tally.counts["wrote_files"]) else 1


if __name__ == "__main__":
    sys.exit(main())
