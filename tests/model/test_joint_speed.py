"""Human joint-speed ceilings (scenegraph/model/joint_speed.py): the control-point rows imply the
ceiling on the curve, and a full-dynamics transcription carries them where its motion is free."""
from dataclasses import replace

import numpy as np
import pytest

from scenegraph.model.body import N_ROOT, make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.joint_speed import max_speed, speed_rows
from scenegraph.model.motion import Motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe


def _random_motion(seed, n_ctrl=20):
    rng = np.random.default_rng(seed)
    ctrl = np.cumsum(rng.normal(0, 0.2, (n_ctrl, 35)), axis=0)
    warp = np.cumsum(rng.uniform(0.5, 1.5, 8)) * 0.2
    return Motion(ctrl, np.sort(warp))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rows_at_their_bound_keep_every_joint_under_its_ceiling(seed):
    m = _random_motion(seed)
    K = m.n_ctrl
    scale, bound = speed_rows(K, m.warp, np.arange(K - 1))
    d = scale[:, None] * np.diff(m.ctrl[:, N_ROOT:], axis=0)
    k = np.max(np.abs(d) / bound)
    ctrl = m.ctrl.copy()
    ctrl[:, N_ROOT:] = ctrl[0, N_ROOT:] + (ctrl[:, N_ROOT:] - ctrl[0, N_ROOT:]) / k  # the worst row at its bound
    m2 = Motion(ctrl, m.warp)
    t = np.linspace(m2.start, m2.end, 4000)
    speed = np.abs(np.asarray(m2.at(t)[1])[:, N_ROOT:])
    assert np.max(speed / max_speed()) <= 1.0 + 1e-6
    assert np.max(speed / max_speed()) > 0.5  # the bound is not vacuous


def test_the_objective_charges_only_speed_over_a_ceiling():
    """A walk far under the ceilings costs nothing extra; the same walk with its joints
    joints (ctrl deviations from the first point × 8) does."""
    ch = make_character()
    steps = footsteps_for_walk()
    m = initial_motion(ch, steps, steps[1].t0, steps[-1].t0)
    t = np.linspace(m.start, m.end, 1000)
    assert np.max(np.abs(np.asarray(m.at(t)[1])[:, N_ROOT:]) / max_speed()) < 0.5
    style = default_style(ch.total_mass)

    def objective(motion, on):
        nlp = transcribe(Subproblem(ch, style, motion, steps, free=frozenset({"q"}), joint_speed_limit=on),
                         derivatives=False)
        return float(nlp.f_fn(nlp.x0, nlp.p0))

    assert objective(m, True) == pytest.approx(objective(m, False), rel=1e-12)
    fast = m.ctrl.copy()
    fast[:, N_ROOT:] = fast[0, N_ROOT:] + 8.0 * (fast[:, N_ROOT:] - fast[0, N_ROOT:])
    m4 = Motion(fast, m.warp)
    assert np.max(np.abs(np.asarray(m4.at(t)[1])[:, N_ROOT:]) / max_speed()) > 1.0
    assert objective(m4, True) > objective(m4, False) + 1.0
