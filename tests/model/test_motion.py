"""B-spline motion with a timewarp: bases, derivatives, warp inversion, chain rule."""
import numpy as np
import pytest

from scenegraph.model.motion import Motion, basis


def test_basis_partition_of_unity_and_derivatives():
    s = np.linspace(0, 1, 41)
    for n in (4, 7, 15):
        B = basis(n, s)
        assert np.allclose(B.sum(axis=1), 1.0)
        c = np.random.default_rng(n).normal(size=(n, 3))
        h = 1e-6
        inner = s[1:-1]
        for d in (1, 2):
            fd = (basis(n, inner + h, d - 1) - basis(n, inner - h, d - 1)) @ c / (2 * h)
            assert np.allclose(fd, basis(n, inner, d) @ c, atol=1e-5 * (1 + np.abs(fd).max()))


def test_uniform_warp_is_identity_and_inverts():
    m = Motion(np.zeros((8, 2)), Motion.uniform_warp(0.4, 1.6, 6))
    s = np.linspace(0, 1, 11)
    assert np.allclose(m.time(s), 0.4 + 1.2 * s)
    t = np.array([0.4, 0.7, 1.6])
    assert np.allclose(m.time(m.to_canonical(t)), t, atol=1e-12)


def test_chain_rule_through_a_nonuniform_warp():
    rng = np.random.default_rng(1)
    warp = np.cumsum(rng.uniform(0.1, 0.4, 7))
    m = Motion(rng.normal(size=(10, 3)), warp)
    t = np.linspace(m.start + 0.05, m.end - 0.05, 9)
    q, qd, qdd = m.at(t)
    h = 1e-5
    qp, qm = m.at(t + h)[0], m.at(t - h)[0]
    assert np.allclose((qp - qm) / (2 * h), qd, rtol=1e-4, atol=1e-5)
    assert np.allclose((qp - 2 * q + qm) / h**2, qdd, rtol=2e-3, atol=2e-3)


def test_sample_is_uniform_in_world_time():
    m = Motion.from_samples(np.linspace(0, 1, 31), np.sin(np.linspace(0, 3, 31))[:, None], 12)
    times, q = m.sample(30)
    assert times[0] == pytest.approx(0.0) and times[-1] == pytest.approx(1.0)
    assert np.allclose(np.diff(times), 1 / 30)
    assert np.abs(q[:, 0] - np.sin(3 * times)).max() < 5e-3
