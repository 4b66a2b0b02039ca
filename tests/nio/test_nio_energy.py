"""NIO's energy is the spacetime solver's objective (issue #18, item 1): E(X; θ) read from the
NIO problem's own transcription, so the energy NIO learns with and the one the synthesis
minimises cannot drift apart (the round-10 re-implementation overstated E(X_T) by 21.5 %)."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import N_JOINT, make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.model.residual import residual_kernel
from scenegraph.nio import NIO
from scenegraph.nio.energy import nlp_params, nonneg_lsq
from scenegraph.nio.theta import ALPHA, KERNEL, project


@pytest.fixture(scope="module")
def case():
    """A synthesized (initial-motion) walk of a non-default duration, its NIO problem and a random θ."""
    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3, step_length=0.62)
    m = initial_motion(ch, fs, 0.0, 1.45)
    nio = NIO(ch, m, fs, local=True)
    rng = np.random.default_rng(7)
    th = nio.initial_theta()
    th[ALPHA] = rng.uniform(0.2, 3.0, N_JOINT)
    th[ALPHA] /= th[ALPHA].sum()
    th[KERNEL] *= rng.uniform(0.5, 1.5, th[KERNEL].size)
    return ch, m, nio, project(th)


def test_energy_equals_the_nlp_objective(case):
    """E(X; θ) with its profiled λ is IPOPT's objective f(x, p) at that point (rel 1e-9), for
    the target and for a perturbed motion."""
    ch, m, nio, th = case
    nlp = nio.nlp
    for motion in (m, m.__class__(np.asarray(m.ctrl) * 1.0 + 1e-3, m.warp)):
        E, _, _, lam = nio.measure(th, motion)
        x = nlp.x0.copy()
        x[nlp.x_layout["ctrl"]] = np.asarray(motion.ctrl, float).ravel()
        x[nlp.x_layout["lambda"]] = lam
        f = float(nlp.f_fn(x, nlp_params(nlp, th)))
        assert E == pytest.approx(f, rel=1e-9)


def test_energy_differs_from_a_node_only_reimplementation(case):
    """The check above can fail: the round-10 energy (trapezoid sum of the ungated kernel at the
    nodes, same forces) is a different number on this motion — by more than 5 %."""
    ch, m, nio, th = case
    E, _, F, _ = nio.measure(th, m)
    q, qd, qdd = nio.states(m)
    Q = np.asarray(residual_kernel(ch).map(nio.N)(q, qd, qdd, F, np.tile(th[KERNEL, None], (1, nio.N))))
    from scenegraph.model.residual import W_ROOT
    from scenegraph.problem import OBJ_SCALE
    per = th[ALPHA] @ Q[:N_JOINT] ** 2 + W_ROOT * (Q[N_JOINT:] ** 2).sum(axis=0)
    old = (OBJ_SCALE / nio.model.mg) ** 2 * per @ nio.model.wT
    assert abs(old - E) > 0.05 * E


def test_alpha_gradient_is_exact_at_zero_alpha(case):
    """E is linear in α (constant per-point style): ∂E/∂α_j is exact, also where α_j = 0."""
    ch, m, nio, th = case
    _, lam = nio.forces(m, th)
    th0 = th.copy()
    th0[ALPHA][:3] = 0.0
    E0, g0 = nio.energy(th0, m, lam)
    for j in (0, 1, 10):
        t1 = th0.copy()
        t1[j] += 0.01
        assert nio.energy(t1, m, lam)[0] - E0 == pytest.approx(0.01 * g0[j], rel=1e-8, abs=1e-10 * E0)


def test_nonneg_lsq_matches_lawson_hanson():
    """The active-set λ solve gives NNLS's answer on a random sparse problem."""
    import scipy.sparse as sps
    from scipy.optimize import nnls

    rng = np.random.default_rng(0)
    A = sps.random(300, 80, density=0.1, random_state=1, format="csc") + sps.vstack(
        [sps.csr_matrix((220, 80)), 0.1 * sps.identity(80)])
    b = rng.normal(size=300)
    x, it = nonneg_lsq(A.tocsc(), b)
    ref, _ = nnls(A.toarray(), -b)
    assert it > 0 and np.abs(x - ref).max() < 1e-8 and (ref == 0).any()
