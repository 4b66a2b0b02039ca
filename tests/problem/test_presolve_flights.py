"""The kinematic pre-solve with a jump's flights (``presolve_kinematics(flights=…)``, round 13).

Off in the executor by default (``executor.PRESOLVE_FLIGHTS``; measured in docs/dynamic-motion.md):
the pre-solve then states the full step's ballistic momentum rows (scenegraph/problem/flight.py) on
its own grid.  Fast: the rows are in the kinematic transcription exactly when flights are given.
Slow: the pre-solve of ``broad_jump`` ends with its flight rows held, where the plain pre-solve's
motion is metres per second (per kg) away from ballistic.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.loader import load_scenario
from scenegraph.problem import Subproblem
from scenegraph.problem.synthesis import presolve_kinematics
from scenegraph.problem.transcription import transcribe
from scenegraph.world.scene import build_scene
from schedules.execution.lower import leap_flights_of


@pytest.fixture(scope="module")
def jumper():
    scene = build_scene(load_scenario("broad_jump"))
    return scene, scene.character("jumper")


def test_leap_flights_of_gives_the_jump_goals_flights(jumper):
    scene, _ = jumper
    assert leap_flights_of(scene, "jumper") == ((0.8, 1.28),)
    assert leap_flights_of(scene, "nobody") == ()


def test_kinematic_transcription_has_flight_rows_only_with_flights(jumper):
    scene, st = jumper
    base = Subproblem(st.character, st.style, st.motion, st.footsteps, free=frozenset({"q"}), dynamics="kinematic")
    names = lambda nlp: {n for n, _, _ in nlp.groups}  # noqa: E731
    assert "flight_momentum" not in names(transcribe(base, derivatives=False))
    with_fl = transcribe(Subproblem(st.character, st.style, st.motion, st.footsteps, free=frozenset({"q"}),
                                    dynamics="kinematic", flights=leap_flights_of(scene, "jumper")), derivatives=False)
    (sl,) = [s for n, s, _ in with_fl.groups if n == "flight_momentum"]
    assert sl.stop - sl.start >= 6 * 10  # 6 rows per flight point after the first, ≥ 11 points in 0.48 s at 30 Hz


def _flight_violation(scene, st, motion):
    """Worst flight-row violation (kg·m/s, kg·m²/s) of ``motion`` on the kinematic grid."""
    sp = Subproblem(st.character, st.style, motion, st.footsteps, free=frozenset({"q"}), dynamics="kinematic",
                    flights=leap_flights_of(scene, "jumper"))
    nlp = transcribe(sp, derivatives=False)
    (sl,) = [s for n, s, _ in nlp.groups if n == "flight_momentum"]
    return float(np.max(np.abs(np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()[sl])))


@pytest.mark.slow
def test_presolve_with_flights_holds_them(jumper):
    scene, st = jumper
    plain = presolve_kinematics(st.character, st.style, st.motion, st.footsteps, ground=scene.ground)
    flown = presolve_kinematics(st.character, st.style, st.motion, st.footsteps, ground=scene.ground,
                                flights=leap_flights_of(scene, "jumper"))
    assert plain.success and flown.success
    assert _flight_violation(scene, st, plain.motion) > 10.0  # measured 250 kg·m/s (the initial motion: 78)
    assert _flight_violation(scene, st, flown.motion) < 1e-6
    assert max(flown.violations.values()) < 1e-6  # footsteps and ground still held
