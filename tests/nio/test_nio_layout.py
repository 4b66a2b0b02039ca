"""NIO reads the transcription's layout by name: θ substituted through ``NLP.p_layout`` gives
back the transcription's own parameters, and a start set through ``NLP.x_layout`` is the
motion it came from."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.nio import NIO
from scenegraph.nio.counterexamples import nlp_params
from scenegraph.model.style import N_THETA_FULL, THETA_LAYOUT, Style, default_style


@pytest.fixture(scope="module")
def nio():
    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3)
    return NIO(ch, initial_motion(ch, fs, 0.0, 1.3), fs, solve_iter=3)


def test_theta_layout_names_every_style_field():
    st = default_style()
    th = st.vector()
    assert th.size == N_THETA_FULL
    for f in ("alpha", "ks1", "ks2", "kd", "q_rest", "k_shoe", "h_rest"):
        assert np.array_equal(th[THETA_LAYOUT[f]], np.atleast_1d(getattr(st, f)))
    assert Style.from_vector(th).vector().tolist() == th.tolist()


def test_parameters_by_name_reproduce_the_transcription(nio):
    """The NLP was transcribed with the default style: writing that style's θ into p by name
    must give p0 back; another θ changes exactly the θ and sqrt(α) blocks."""
    nlp = nio.nlp
    th = default_style(nio.ch.total_mass).vector()
    assert np.allclose(nlp_params(nlp, th), nlp.p0, rtol=1e-15, atol=0.0)
    th2 = th.copy()
    th2[THETA_LAYOUT["ks1"]] *= 2.0
    n_alpha = th2[THETA_LAYOUT["alpha"]].size
    th2[THETA_LAYOUT["alpha"]] = np.linspace(0.5, 1.5, n_alpha) / n_alpha
    changed = np.flatnonzero(nlp_params(nlp, th2) != nlp.p0)
    inside = np.zeros(nlp.p0.size, bool)
    for name in ("theta", "sqrt_alpha"):
        inside[nlp.p_layout[name]] = True
    assert changed.size > 0 and inside[changed].all()
    assert {"theta", "sqrt_alpha"} <= set(nlp.p_layout)


def test_start_by_name_is_the_motion(nio):
    """A counterexample started at X_T: the ctrl block of x is X_T's control points, and the
    objective the solver evaluates there is finite."""
    nlp = nio.nlp
    x0 = nio.cx._start(nio.target, None)
    assert np.array_equal(x0[nlp.x_layout["ctrl"]], np.asarray(nio.target.ctrl, float).ravel())
    p = nlp_params(nlp, default_style(nio.ch.total_mass).vector())
    assert np.isfinite(float(nlp.f_fn(x0, p)))
