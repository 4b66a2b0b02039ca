"""Shared fixtures.  ``tests/`` is on ``sys.path`` (pytest's rootdir-conftest import mode), so
test modules can ``import pinocchio_model``.  ``tests/benchmarks/bench_*.py`` are timing
scripts, not tests: pytest does not collect them (they do not match ``test_*.py``)."""
from __future__ import annotations

import os

# One OpenMP thread for IPOPT's MUMPS in every test (and the subprocesses they start), set
# before CasADi loads its IPOPT plugin: IPOPT's iterates depend on MUMPS's thread count, so
# with the machine's default (one thread per core) a test's outcome depends on the core count.
# Measured: test_exact_hessian_solves_a_window converged with 1 thread (and, per its author,
# multithreaded on a larger machine) but hit its 100-iteration cap with 2 threads on a 2-core one.
os.environ["OMP_NUM_THREADS"] = "1"

import functools  # noqa: E402

import pytest  # noqa: E402

from scenegraph.model.body import make_character  # noqa: E402

# (preset, height m, mass kg): the presets at their own size and scaled to other bodies.
BODIES = [("adult_male", None, None), ("adult_female", 1.80, 80.0), ("child", 1.40, 35.0),
          ("adult_male", 2.00, 120.0)]


@functools.lru_cache(maxsize=None)
def character(preset: str = "adult_male", height: float | None = None, mass: float | None = None):
    return make_character(preset, height, mass)


@pytest.fixture(scope="session")
def adult():
    return character()
