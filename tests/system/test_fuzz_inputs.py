"""A fast subset of the input fuzzing campaign (tests/benchmarks/fuzz_inputs.py).

A few hundred Hypothesis-generated mutations of the bundled scenarios and shipped BVH clips
go through the real entry points in a worker process; every one must be accepted or fail
with a compose error naming the file and a line, within 5 s, writing nothing.  The harness's
own classification is checked too (a crash, an unlocated error, a hang and a write are each
recognised), so a harness that counted everything as fine would fail here.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path


_spec = importlib.util.spec_from_file_location("fuzz_inputs", Path(__file__).resolve().parents[1] / "benchmarks" / "fuzz_inputs.py")
fuzz = importlib.util.module_from_spec(_spec)
sys.modules["fuzz_inputs"] = fuzz  # dataclasses look their module up by name
_spec.loader.exec_module(fuzz)


def test_seeds_are_found_relative_to_the_repository():
    assert len(fuzz.SCENARIO_FILES) >= 10 and all(p.is_relative_to(fuzz.REPO) for p in fuzz.SCENARIO_FILES)
    assert any(p.parent == fuzz.REPO / "scenarios" / "clips" for p in fuzz.CLIP_FILES)


def test_harness_recognises_crashes_hangs_and_writes():
    w = fuzz.Worker(timeout=1.0)
    try:
        assert w.run("selftest", b"", {})[0] == "accepted"
        assert w.run("selftest", b"", {"raise": True})[0] == "crashes"
        assert w.run("selftest", b"", {"unlocated": True})[0] == "crashes"
        assert w.run("selftest", b"", {"write": True})[0] == "wrote_files"
        assert w.run("selftest", b"", {"spin": 0.3})[0] == "accepted"  # below the CPU limit
        assert w.run("selftest", b"", {"spin": 30.0})[0] == "hangs"
        assert w.run("selftest", b"", {})[0] == "accepted"  # a fresh worker after the hang
        # a real located error: a scenario with a wrong type
        out, detail = w.run("scenario", b"name: x\nduration: abc\ncharacters: [{name: a}]\n", {})
        assert out == "located_errors" and ":2:" in detail and "duration" in detail, detail
    finally:
        w.close()


def test_fuzzed_inputs_never_crash_hang_or_write():
    tally = fuzz.campaign(320, seed=0, timeout=5.0, bvh_share=0.3)
    report = "\n".join(f"{o} {k} from {s} {p}: {d}" for o, k, s, d, p, _ in tally.failures[:10])
    assert tally.cases == 320
    assert tally.counts["crashes"] == tally.counts["hangs"] == tally.counts["wrote_files"] == 0, report
    # the mutations reach both sides: some inputs still validate, most are rejected with a place
    assert tally.counts["accepted"] >= 10 and tally.counts["located_errors"] >= 100, tally.line()
