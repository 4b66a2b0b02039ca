"""NIO priors and tying (scenegraph.nio.prior; issue #18): the log-normal α prior's value and
gradient, the tie pairs, and the bundle LP honouring them."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT
from scenegraph.nio.bundle import model_step
from scenegraph.nio.prior import log_alpha_prior, n_free, tie_average, tie_pairs
from scenegraph.model.style import N_THETA_FULL, THETA_LAYOUT, default_style

A = THETA_LAYOUT["alpha"]


def test_prior_is_zero_at_the_reference_and_its_gradient_matches_differences():
    th = default_style().vector().copy()
    P0, g0 = log_alpha_prior(th, 1.0, 2.0)
    assert P0 == pytest.approx(0.0) and np.allclose(g0, 0.0)
    rng = np.random.default_rng(3)
    th[A] = rng.uniform(0.2, 3.0, N_JOINT) / N_JOINT
    P, g = log_alpha_prior(th, 0.5, 2.0)
    assert P == pytest.approx(0.5 * 2.0 * np.mean(np.log(th[A] * N_JOINT) ** 2))
    for j in (A.start, A.start + 7, A.stop - 1):
        e = np.zeros_like(th)
        e[j] = 1e-7
        fd = (log_alpha_prior(th + e, 0.5, 2.0)[0] - log_alpha_prior(th - e, 0.5, 2.0)[0]) / 2e-7
        assert g[j] == pytest.approx(fd, rel=1e-5)
    assert np.all(g[A.stop:] == 0.0)
    assert log_alpha_prior(th, 0.0, 2.0)[0] == 0.0


def test_tie_pairs_count_the_free_numbers():
    n_lr = sum(1 for d in JOINT_DOF_NAMES if d.endswith("_l"))
    assert len(tie_pairs("lr")) == 4 * n_lr
    assert n_free(tie_pairs("none"), N_THETA_FULL) == N_THETA_FULL
    assert n_free(tie_pairs("lr"), N_THETA_FULL) == N_THETA_FULL - 4 * n_lr
    assert n_free(tie_pairs("groups"), N_THETA_FULL) < n_free(tie_pairs("lr"), N_THETA_FULL)
    with pytest.raises(ValueError, match="unknown tie mode"):
        tie_pairs("mirror")


def test_tie_average_keeps_alpha_sum_and_satisfies_the_ties():
    rng = np.random.default_rng(0)
    th = default_style().vector().copy()
    th[A] = rng.uniform(0.1, 2.0, N_JOINT)
    th[A] /= th[A].sum()
    pairs = tie_pairs("groups")
    t2 = tie_average(th, pairs)
    assert t2[A].sum() == pytest.approx(1.0)
    assert all(t2[i] == pytest.approx(t2[j]) for i, j in pairs)


def test_model_step_holds_ties_and_follows_the_prior_gradient():
    th = default_style().vector().copy()
    scales = np.maximum(np.abs(th), 1e-2)
    g = np.random.default_rng(1).normal(size=len(th))
    cuts = [(1.0, g)]
    pairs = tie_pairs("lr")
    new, model = model_step(th, cuts, 0.1, scales, 0.0, pairs)
    assert all(new[i] - th[i] == pytest.approx(new[j] - th[j], abs=1e-9) for i, j in pairs)
    assert new[A].sum() == pytest.approx(1.0)
    assert model < 1.0
    # with only the prior's linearisation and no cut above 0, the step follows -gP
    gP = np.zeros(len(th))
    gP[A.start] = 1.0
    new2, _ = model_step(th, [(-1.0, np.zeros(len(th)))], 0.1, scales, 0.0, (), (0.0, gP))
    assert new2[A.start] < th[A.start]


def test_learn_header_names_the_prior_tie_and_contact_options():
    from schedules.cli.learn import _option_flags

    assert _option_flags({}) == ""
    flags = _option_flags({"alpha_prior": 1.0, "tie": "lr", "contacts": "onesided"})
    assert flags == " --alpha-prior 1 --tie lr --contacts onesided"


def test_learn_rejects_a_negative_prior_before_reading_the_clip(tmp_path):
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "schedules.cli", "learn", str(tmp_path / "missing.bvh"), "--frames",
                        "0:10", "--alpha-prior", "-1", "-o", str(tmp_path / "s.yaml")],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "--alpha-prior -1" in p.stderr
    assert not (tmp_path / "s.yaml").exists()
