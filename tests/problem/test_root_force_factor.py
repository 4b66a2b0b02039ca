"""The root residual weighted by the ground force it has to pass through
(transcription.root_force_factor, Subproblem.root_force_ref): its values on constructed forces
and where it appears in the NLP's dynamics residual."""
from dataclasses import replace

import numpy as np
import pytest

from scenegraph.model.body import N_DOF, N_JOINT, make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe
from scenegraph.problem.synthesis import presolve_kinematics
from scenegraph.problem.transcription import F0_ROOT, root_force_factor

CH = make_character()
STYLE = default_style(CH.total_mass)
MG = 700.0


def test_factor_on_constructed_forces():
    fn = np.array([0.0, 0.05, 0.1, 0.5, 1.0, 3.0]) * MG
    f = root_force_factor(fn, MG, 0.5)
    assert np.all(f >= 1.0) and np.all(np.diff(f) < 0)  # ≥ 1, falls as the ground carries more
    assert f[0] == pytest.approx(np.sqrt(1 + (0.5 / F0_ROOT) ** 2))
    # below F_ref the weighted residual tracks residual / (F_n + F_0): the CoP shift's
    assert f[1] * (0.05 + F0_ROOT) == pytest.approx(f[2] * (0.1 + F0_ROOT), rel=0.05)
    assert f[-1] < 1.02  # at several body weights: the paper's w_r
    np.testing.assert_allclose(root_force_factor(fn, MG, 0.5, on=0.0), 1.0)  # off (flight)
    np.testing.assert_allclose(root_force_factor(-fn, MG, 0.5), f[0])  # a negative force counts as none


@pytest.fixture(scope="module")
def walk_nlps():
    steps = footsteps_for_walk(n_steps=3)
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    m = presolve_kinematics(CH, STYLE, m0, steps).motion
    sp = Subproblem(CH, STYLE, m, steps, free=frozenset({"q"}))
    return transcribe(sp, derivatives=False), transcribe(replace(sp, root_force_ref=0.0), derivatives=False)


def test_root_rows_scaled_where_the_feet_carry_little(walk_nlps):
    on, off = walk_nlps
    x = on.x0.copy()
    lam = on.x_layout["lambda"]
    x[lam] = 0.0  # no contact force anywhere: every root row carries the floor's factor
    r_on = np.asarray(on.rho_dyn_fn(x, on.p0)).reshape(-1, N_DOF).T
    r_off = np.asarray(off.rho_dyn_fn(x, off.p0)).reshape(-1, N_DOF).T
    np.testing.assert_allclose(r_on[:N_JOINT], r_off[:N_JOINT], rtol=1e-9, atol=1e-12)  # joints untouched
    fz = np.zeros(r_on.shape[1])  # the shoe's force is the only ground force left; bounded by F_ref here
    big = np.abs(r_off[N_JOINT:]) > 1e-6
    ratio = r_on[N_JOINT:][big] / r_off[N_JOINT:][big]
    assert ratio.min() > 1.0 and ratio.max() == pytest.approx(root_force_factor(fz, 1.0, 0.5)[0], rel=1e-6)
    # with the start's forces (about one body weight in stance) the factor is near 1 at most points
    r_on0 = np.asarray(on.rho_dyn_fn(on.x0, on.p0)).reshape(-1, N_DOF).T[N_JOINT:]
    r_off0 = np.asarray(off.rho_dyn_fn(off.x0, off.p0)).reshape(-1, N_DOF).T[N_JOINT:]
    k = np.abs(r_off0).max(axis=0) > 1e-6
    fac = np.abs(r_on0[:, k]).max(axis=0) / np.abs(r_off0[:, k]).max(axis=0)
    assert np.all(fac >= 1.0 - 1e-9) and np.median(fac) < 1.6
