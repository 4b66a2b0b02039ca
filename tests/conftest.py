"""Shared fixtures.  ``tests/`` is on ``sys.path`` (pytest's rootdir-conftest import mode), so
test modules can ``import pinocchio_model``.  ``tests/benchmarks/bench_*.py`` are timing
scripts, not tests: pytest does not collect them (they do not match ``test_*.py``)."""
from __future__ import annotations

import functools

import pytest

from scenegraph.body import make_character

# (preset, height m, mass kg): the presets at their own size and scaled to other bodies.
BODIES = [("adult_male", None, None), ("adult_female", 1.80, 80.0), ("child", 1.40, 35.0),
          ("adult_male", 2.00, 120.0)]


@functools.lru_cache(maxsize=None)
def character(preset: str = "adult_male", height: float | None = None, mass: float | None = None):
    return make_character(preset, height, mass)


@pytest.fixture(scope="session")
def adult():
    return character()
