"""The best-fit root residual (scenegraph.nio.plausibility) on motions with known answers, and the
initial root path of a window whose first and last stances are cut (scenegraph.model.gait)."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import G, N_DOF, default_character, standing_pose
from scenegraph.model.footsteps import Footstep
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.motion import Motion
from scenegraph.model.style import default_style
from scenegraph.nio.plausibility import best_fit_root_residual


def _motion(q_of_t, dur=1.0, n=61, ctrl=28):
    t = np.linspace(0.0, dur, n)
    return Motion.from_samples(t, np.array([q_of_t(x) for x in t]), ctrl)


def _planted_feet(ch, q, t0=0.0, t1=1.0):
    """Footsteps with heel and ball planted over [t0, t1] where pose q puts them."""
    hp = np.asarray(handle_positions_fn(ch, ("ball_l", "ball_r"))(q)).reshape(3, 2, order="F")
    return tuple(Footstep(f, (float(hp[0, k]), float(hp[1, k])), t0, t1, heading=0.0, heel=(0.0, 1.0), ball=(0.0, 1.0))
                 for k, f in enumerate("lr"))


@pytest.fixture(scope="module")
def ch():
    return default_character()


def test_no_contact_at_rest_leaves_one_body_weight(ch):
    q0 = standing_pose(ch) + np.r_[0, 0, 0.5, np.zeros(N_DOF - 3)]  # held in the air, nothing planted
    b = best_fit_root_residual(ch, default_style(ch.total_mass), _motion(lambda t: q0), (), rate=60)
    assert b.force_bw == pytest.approx(np.ones_like(b.force_bw), abs=1e-6)


def test_free_fall_leaves_nothing(ch):
    q0 = standing_pose(ch) + np.r_[0, 0, 2.0, np.zeros(N_DOF - 3)]

    def fall(t):
        q = q0.copy()
        q[0] += 1.5 * t  # ballistic: constant horizontal speed, parabola in height
        q[2] -= 0.5 * G * t * t
        return q

    b = best_fit_root_residual(ch, default_style(ch.total_mass), _motion(fall), (), rate=60)
    # Motion.from_samples' smoothing term bends the fit's ends toward zero acceleration (1.02 bw at
    # the first and last frame, measured), so the parabola is judged inside [0.25, 0.75] s
    inner = (b.times >= 0.25) & (b.times <= 0.75)
    assert b.force_bw[inner].max() < 0.05 and b.moment_bw_m[inner].max() < 0.05
    assert b.force_bw[0] > 0.5  # the end effect itself: the measure sees it


def test_standing_on_planted_feet_is_possible(ch):
    q0 = standing_pose(ch)
    steps = _planted_feet(ch, q0)
    b = best_fit_root_residual(ch, default_style(ch.total_mass), _motion(lambda t: q0), steps, rate=60)
    assert b.force_max_bw < 0.02


def test_a_push_beyond_friction_keeps_the_cone_distance(ch):
    # the body accelerates forward at 2 g on planted feet: with μ = 0.8 no ground force can do
    # that; the smallest force residual is the distance of (2, 1) m g from the cone, 1.2/√1.64 bw
    q0 = standing_pose(ch)
    steps = _planted_feet(ch, q0, -1.0, 2.0)  # planted throughout (the feet move with the body:
    # the fit only uses which handles are planted, not where)

    def push(t):
        q = q0.copy()
        q[0] += G * t * t  # a = 2 g
        return q

    b = best_fit_root_residual(ch, default_style(ch.total_mass), _motion(push), steps, rate=60)
    bound = 1.2 / np.sqrt(1 + 0.8 ** 2)
    assert np.all(b.force_bw[5:-5] >= bound - 1e-3)
    assert np.median(b.force_bw) < bound + 0.3  # and the fit gets near it (moments traded a little)
