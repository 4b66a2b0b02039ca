"""The root residual weighted by the ground force it has to pass through
(transcription.root_force_factor, Subproblem.root_force_ref): its values on constructed forces
and where it appears in the NLP's dynamics residual."""
from dataclasses import replace

import numpy as np
import pytest

from scenegraph.model.body import N_DOF, N_JOINT, make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.residual import CONTACT_HANDLES
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
    """A short walk transcribed with a constructed contact guess: every handle carries 0.01 body
    weight vertically before the middle of the motion and 1 body weight after it."""
    steps = footsteps_for_walk(n_steps=3)
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    m = presolve_kinematics(CH, STYLE, m0, steps).motion
    mg = CH.total_mass * 9.81
    t = np.linspace(m.start, m.end, 400)
    fz = np.where(t < 0.5 * (m.start + m.end), 0.01, 1.0) * mg
    guess = {h: (t, np.stack([0 * fz, 0 * fz, fz], axis=1).ravel()) for h in CONTACT_HANDLES}
    sp = Subproblem(CH, STYLE, m, steps, free=frozenset({"q"}), contact_guess=guess, root_force_ref=0.5)
    return transcribe(sp, derivatives=False), transcribe(replace(sp, root_force_ref=0.0), derivatives=False), mg


def test_root_rows_scaled_where_the_feet_carry_little(walk_nlps):
    on, off, mg = walk_nlps
    r_on = np.asarray(on.rho_dyn_fn(on.x0, on.p0)).reshape(-1, N_DOF).T
    r_off = np.asarray(off.rho_dyn_fn(off.x0, off.p0)).reshape(-1, N_DOF).T
    np.testing.assert_allclose(r_on[:N_JOINT], r_off[:N_JOINT], rtol=1e-9, atol=1e-12)  # joints untouched
    # the expected factor at the nodes (the first evaluation points): the guess's vertical force
    # summed over the handles planted there, touch-down and lift-off nodes (λ held at 0) left out
    N = len(on.s_points)
    fn = np.zeros(N)
    times = on.sp.motion.time(on.s_points)
    for h, k, sl in on.contact_index:
        if on.ubx[sl].max() > 0:
            fn[k] += (0.01 if times[k] < 0.5 * (on.sp.motion.start + on.sp.motion.end) else 1.0) * mg
    want = root_force_factor(fn, mg, 0.5)
    k = np.all(np.abs(r_off[N_JOINT:, :N]) > 1e-6, axis=0)
    ratio = r_on[N_JOINT:, :N][:, k] / r_off[N_JOINT:, :N][:, k]
    np.testing.assert_allclose(ratio, np.tile(want[k], (N_DOF - N_JOINT, 1)), rtol=1e-3)
    assert ratio.max() > 8 and ratio.min() < 1.2  # ≈ 12 at 0.02 bw, ≈ 1.1 at 2 bw: both cases are present


def test_off_by_default():
    assert Subproblem.__dataclass_fields__["root_force_ref"].default == 0.0
