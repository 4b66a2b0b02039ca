"""The dynamics' Gauss–Newton term assembled point by point (scenegraph/problem/gram.py) is the
JᵀJ of CasADi's own AD Jacobian of the residuals, to round-off, away from the start too."""
import casadi as ca
import numpy as np

from scenegraph.model.body import make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.style import default_style
from scenegraph.problem import Subproblem, transcribe
from scenegraph.problem.synthesis import presolve_kinematics

CH = make_character()
STYLE = default_style(CH.total_mass)


def test_lagrangian_hessian_equals_the_ad_gauss_newton_matrix():
    steps = footsteps_for_walk(n_steps=3)
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    m = presolve_kinematics(CH, STYLE, m0, steps).motion
    nlp = transcribe(Subproblem(CH, STYLE, m, steps, free=frozenset({"q"})))
    x, p = nlp.x, nlp.p
    Jd, Jx = ca.jacobian(nlp.rho_dyn_fn(x, p), x), ca.jacobian(nlp.rho_extra_fn(x, p), x)
    ref = ca.Function("ref", [x, p], [ca.triu(2 * (ca.mtimes(Jd.T, Jd) + ca.mtimes(Jx.T, Jx)))])
    rng = np.random.default_rng(3)
    for x0 in (nlp.x0, nlp.x0 + 1e-2 * rng.standard_normal(nlp.x0.shape)):
        H = np.array(ca.densify(nlp.hess_lag(x0, nlp.p0, 1.0, np.zeros(nlp.g.shape[0]))))
        R = np.array(ca.densify(ref(x0, nlp.p0)))
        assert np.abs(R).max() > 1.0
        assert np.abs(H - R).max() <= 1e-9 * np.abs(R).max()
