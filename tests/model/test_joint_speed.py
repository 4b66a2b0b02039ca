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


def test_a_walk_is_far_under_the_ceilings_and_its_transcription_has_the_rows():
    ch = make_character()
    steps = footsteps_for_walk()
    m = initial_motion(ch, steps, steps[1].t0, steps[-1].t0)
    t = np.linspace(m.start, m.end, 1000)
    assert np.max(np.abs(np.asarray(m.at(t)[1])[:, N_ROOT:]) / max_speed()) < 0.5
    sp = Subproblem(ch, default_style(ch.total_mass), m, steps, free=frozenset({"q"}))
    nlp = transcribe(sp, derivatives=False)
    rows = [sl for name, sl, _ in nlp.groups if name == "joint_speed"]
    assert len(rows) == 1 and rows[0].stop - rows[0].start == (m.n_ctrl - 1) * (35 - N_ROOT)
    g = np.asarray(nlp.g_fn(nlp.x0, nlp.p0)).ravel()[rows[0]]
    assert np.all(g >= nlp.lbg[rows[0]]) and np.all(g <= nlp.ubg[rows[0]])
    off = transcribe(replace(sp, joint_speed_limit=False), derivatives=False)
    assert not any(name == "joint_speed" for name, _, _ in off.groups)
