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

    plain = " --alpha-prior 0 --spring-prior 0 --tie none --contacts central"
    assert _option_flags({}) == plain  # a style learned before round 14: no prior, central contacts
    flags = _option_flags({"alpha_prior": 1.0, "tie": "lr", "contacts": "onesided"})
    assert flags == " --alpha-prior 1 --alpha-ref uniform --spring-prior 0 --tie lr --contacts onesided"
    import argparse

    from schedules.cli.learn import DEFAULTS, register
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    a = ap.parse_args(["learn", "c.bvh", "--frames", "1:9", "-o", "s.yaml"])
    assert (a.alpha_prior, a.spring_prior, a.tie, a.contacts) == (0.1, 0.1, "coarse", "onesided") == \
        tuple(DEFAULTS[k] for k in ("alpha_prior", "spring_prior", "tie", "contacts"))
    a = ap.parse_args(["learn", "c.bvh", "--frames", "1:9", "-o", "s.yaml", *plain.split()])
    assert (a.alpha_prior, a.spring_prior, a.tie, a.contacts, a.alpha_ref) == (0.0, 0.0, "none", "central", None)


def test_learn_rejects_a_negative_prior_before_reading_the_clip(tmp_path):
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "schedules.cli", "learn", str(tmp_path / "missing.bvh"), "--frames",
                        "0:10", "--alpha-prior", "-1", "-o", str(tmp_path / "s.yaml")],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "--alpha-prior -1" in p.stderr
    assert not (tmp_path / "s.yaml").exists()


# --- round 13: strength reference, spring prior, coarse ties, ratio ties --------------------------

def test_strength_reference_is_symmetric_normalised_and_makes_weak_joints_dear():
    from scenegraph.nio.prior import alpha_reference

    u = alpha_reference("uniform")
    assert np.allclose(u, 1.0 / N_JOINT)
    s = alpha_reference("strength")
    assert s.sum() == pytest.approx(1.0) and np.all(s > 0)
    i = JOINT_DOF_NAMES.index
    for d in JOINT_DOF_NAMES:
        if d.endswith("_l"):
            assert s[i(d)] == s[i(d[:-2] + "_r")]
    # a newton-metre at the wrist costs more than one at the hip, at the elbow more than at the knee
    assert s[i("wrist_flex_l")] > s[i("shoulder_flex_l")] > s[i("hip_flex_l")]
    assert s[i("elbow_flex_r")] > s[i("knee_flex_r")]
    with pytest.raises(ValueError, match="unknown alpha reference"):
        alpha_reference("mass")


def test_log_prior_around_a_reference_is_zero_there_with_exact_gradient():
    from scenegraph.nio.prior import alpha_reference

    ref = alpha_reference("strength")
    th = default_style().vector().copy()
    th[A] = ref
    P0, g0 = log_alpha_prior(th, 1.0, 3.0, ref)
    assert P0 == pytest.approx(0.0, abs=1e-15) and np.allclose(g0, 0.0)
    th[A] = ref * np.random.default_rng(5).uniform(0.3, 3.0, N_JOINT)
    P, g = log_alpha_prior(th, 0.7, 3.0, ref)
    assert P == pytest.approx(0.7 * 3.0 * np.mean(np.log(th[A] / ref) ** 2))
    j = A.start + 9
    e = np.zeros_like(th)
    e[j] = 1e-9
    fd = (log_alpha_prior(th + e, 0.7, 3.0, ref)[0] - log_alpha_prior(th - e, 0.7, 3.0, ref)[0]) / 2e-9
    assert g[j] == pytest.approx(fd, rel=1e-5)


def test_spring_prior_value_gradient_and_only_springs():
    from scenegraph.nio.prior import Prior, spring_prior

    ref = default_style().vector().copy()
    typ = np.maximum(np.abs(ref), 1.0)
    P0, g0 = spring_prior(ref, 2.0, 5.0, ref, typ)
    assert P0 == 0.0 and np.all(g0 == 0.0)
    th = ref.copy()
    rng = np.random.default_rng(2)
    th += rng.normal(size=len(th)) * typ
    P, g = spring_prior(th, 2.0, 5.0, ref, typ)
    springs = np.r_[tuple(np.arange(THETA_LAYOUT[f].start, THETA_LAYOUT[f].stop) for f in ("ks1", "ks2", "kd"))]
    z = (th[springs] - ref[springs]) / typ[springs]
    assert P == pytest.approx(2.0 * 5.0 * np.mean(z ** 2))
    other = np.setdiff1d(np.arange(len(th)), springs)
    assert np.all(g[other] == 0.0)
    for j in springs[[0, 40, -1]]:
        e = np.zeros_like(th)
        e[j] = 1e-4 * typ[j]
        fd = (spring_prior(th + e, 2.0, 5.0, ref, typ)[0] - spring_prior(th - e, 2.0, 5.0, ref, typ)[0]) / (2 * e[j])
        assert g[j] == pytest.approx(fd, rel=1e-6)
    both = Prior(5.0, 1.0, None, 2.0, ref, typ)
    Pa, _ = log_alpha_prior(th, 1.0, 5.0)
    assert both(th)[0] == pytest.approx(Pa + P)
    assert not Prior(5.0).active
    with pytest.raises(ValueError, match="reference"):
        Prior(5.0, spring_weight=1.0)


def test_coarse_ties_leave_59_free_numbers():
    assert n_free(tie_pairs("groups"), N_THETA_FULL) == 89
    assert n_free(tie_pairs("coarse"), N_THETA_FULL) == 59


def test_ratio_ties_keep_the_reference_ratios_in_tie_average_and_the_lp():
    from scenegraph.nio.prior import alpha_reference, tie_scales
    from scenegraph.nio.theta import theta_scales
    from scenegraph.nio.theta import style_from_theta

    ref = alpha_reference("strength")
    th = default_style().vector().copy()
    rng = np.random.default_rng(7)
    th[A] = rng.uniform(0.1, 2.0, N_JOINT)
    th[A] /= th[A].sum()
    for f in ("ks1", "ks2", "kd"):
        th[THETA_LAYOUT[f]] = rng.uniform(0.0, 50.0, N_JOINT)
    typ = theta_scales(style_from_theta(th))
    w = tie_scales(th, ref, typ)
    pairs = tie_pairs("coarse")
    t2 = tie_average(th, pairs, w)
    for i, j in pairs:
        assert t2[i] / w[i] == pytest.approx(t2[j] / w[j])
    # left/right pairs have equal scales: their ties stay plain equalities
    for i, j in tie_pairs("lr"):
        assert w[i] == pytest.approx(w[j])
        assert t2[i] == pytest.approx(t2[j])
    # elbow and wrist share one α factor on the strength reference: their ratio is the reference's
    i = JOINT_DOF_NAMES.index
    assert t2[A.start + i("wrist_flex_l")] / t2[A.start + i("elbow_flex_l")] == pytest.approx(
        ref[i("wrist_flex_l")] / ref[i("elbow_flex_l")])
    t2[A] /= t2[A].sum()
    g = rng.normal(size=len(th))
    new, _ = model_step(t2, [(1.0, g)], 0.2, np.maximum(np.abs(t2), 1e-2), 0.0, pairs, None, None, w)
    for i, j in pairs:
        assert (new[i] - t2[i]) / w[i] == pytest.approx((new[j] - t2[j]) / w[j], abs=1e-9)


def test_learn_header_names_the_reference_and_spring_prior():
    from schedules.cli.learn import _option_flags

    flags = _option_flags({"alpha_prior": 0.3, "alpha_ref": "strength", "spring_prior": 1.0, "tie": "coarse"})
    assert flags == " --alpha-prior 0.3 --alpha-ref strength --spring-prior 1 --tie coarse --contacts central"


@pytest.mark.parametrize("extra, message", [(["--spring-prior", "-1"], "--spring-prior -1"),
                                            (["--alpha-ref", "strength", "--alpha-prior", "0", "--tie", "none"],
                                             "--alpha-ref strength")])
def test_learn_rejects_bad_prior_options_before_reading_the_clip(tmp_path, extra, message):
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-m", "schedules.cli", "learn", str(tmp_path / "missing.bvh"), "--frames",
                        "0:10", *extra, "-o", str(tmp_path / "s.yaml")], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and message in p.stderr
    assert not (tmp_path / "s.yaml").exists()


@pytest.mark.slow
def test_learn_with_strength_prior_and_coarse_ties_keeps_them():
    """learn_style on a kinematically pre-solved three-step walk with the strength reference,
    both priors and coarse ties: the learned θ holds every tie (α in a group keeps the
    reference's ratios; left/right springs equal) and the provenance names the options; with no
    iteration the style's α is the reference itself."""
    from scenegraph.model.body import make_character
    from scenegraph.model.footsteps import footsteps_for_walk
    from scenegraph.model.gait import initial_motion
    from scenegraph.nio import learn_style
    from scenegraph.nio.prior import alpha_reference
    from scenegraph.problem.synthesis import presolve_kinematics

    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3, step_length=0.7)
    m = presolve_kinematics(ch, default_style(ch.total_mass), initial_motion(ch, fs, 0.0, 1.3), fs).motion
    ref = alpha_reference("strength")
    kw = dict(prior_weight=0.1, alpha_ref="strength", spring_prior=0.1, tie="coarse")
    r0 = learn_style(ch, m, fs, max_iter=0, **kw)
    assert np.allclose(r0.style.alpha, ref, rtol=1e-9)
    res = learn_style(ch, m, fs, max_iter=3, **kw)
    th = res.theta
    a = th[A] / ref
    i = JOINT_DOF_NAMES.index
    for pre in (("elbow_", "wrist_"), ("hip_",), ("ankle_", "toe_")):
        idx = [j for j, d in enumerate(JOINT_DOF_NAMES) if d.startswith(pre)]
        assert np.allclose(a[idx], a[idx[0]], rtol=1e-6)
    for f in ("ks1", "ks2", "kd"):
        s = THETA_LAYOUT[f].start
        assert th[s + i("knee_flex_l")] == pytest.approx(th[s + i("knee_flex_r")], rel=1e-6, abs=1e-9)
    prov = res.style.provenance.model_dump()
    assert prov["alpha_ref"] == "strength" and prov["tie"] == "coarse" and prov["spring_prior"] == 0.1


def test_reference_trust_box_bounds_the_log_change_of_every_alpha():
    """With the strength reference an absolute box (α by r/M) lets a step of r = 0.03 move the
    strong joints' α (reference 26× below 1/M) by ~78 % — a log change of −1.5, which the
    log-normal prior charges ~2.3 per joint; the reference box moves every α by at most 3 %."""
    from scenegraph.nio.bundle import trust_scales
    from scenegraph.nio.prior import alpha_reference
    from scenegraph.nio.theta import theta_scales

    ref = alpha_reference("strength")
    th = default_style().vector().copy()
    th[A] = ref
    scales = theta_scales(default_style())
    g = np.zeros(len(th))
    g[A] = -1.0 / ref  # a cut that pays for lowering every α in proportion to 1/α_ref
    g[A.start + JOINT_DOF_NAMES.index("wrist_flex_l")] = 5.0
    cuts = [(1.0, g)]
    for mode, worst in (("absolute", 0.5), ("reference", None)):
        box = trust_scales(scales, mode, ref)
        new, _ = model_step(th, cuts, 0.03, box, 0.0)
        assert new[A].sum() == pytest.approx(1.0)
        dlog = np.abs(np.log(np.maximum(new[A], 1e-12) / ref))
        if worst is None:
            assert dlog.max() <= np.log(1 / 0.97) + 1e-9
        else:
            assert dlog.max() > worst
    assert np.array_equal(trust_scales(scales, "absolute", ref), scales)
    u = trust_scales(scales, "reference", None)
    assert np.allclose(u[A], 1.0 / N_JOINT) and np.allclose(u, scales)  # uniform: the same box
    with pytest.raises(ValueError, match="alpha_trust"):
        trust_scales(scales, "log")
