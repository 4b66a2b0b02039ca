"""Nonlinear Inverse Optimization: energy and gradient, D(θ), CLI errors, synthetic recovery."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.body import N_JOINT, make_character
from scenegraph.footsteps import footsteps_for_walk
from scenegraph.gait import initial_motion
from scenegraph.nio import NIO, d_penalty, joint_rms_deg, style_from_theta
from scenegraph.style import default_style


@pytest.fixture(scope="module")
def small():
    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3)
    m = initial_motion(ch, fs, 0.0, 1.3)
    return ch, fs, m, NIO(ch, m, fs, solve_iter=5)


def test_d_penalty_and_gradient():
    th = default_style().vector()
    D, g = d_penalty(th)
    assert D == pytest.approx(0.0, abs=1e-20) and np.allclose(g, 0)
    th2 = th.copy()
    th2[0] = -0.01
    D2, g2 = d_penalty(th2)
    s = th2[:N_JOINT].sum() - 1
    assert D2 == pytest.approx(1e4 * (s ** 2 + 0.01 ** 2))
    assert g2[0] == pytest.approx(1e4 * (2 * s - 0.02))


def test_style_from_theta_normalises_and_projects():
    th = default_style().vector()
    th[:N_JOINT] *= 3.0
    th[N_JOINT] = -5.0  # a negative stiffness is projected to 0
    st = style_from_theta(th)
    assert abs(st.alpha.sum() - 1) < 1e-12 and st.ks1[0] == 0.0


def test_energy_gradient_matches_finite_differences(small):
    ch, fs, m, nio = small
    th = nio.initial_theta()
    F, _ = nio.forces(m, th)
    E, g = nio.energy(th, m, F)
    assert E > 0 and np.all(np.isfinite(g))
    rng = np.random.default_rng(1)
    for i in rng.choice(len(th), 8, replace=False):
        h = 1e-6 * max(1.0, abs(th[i]))
        tp, tm = th.copy(), th.copy()
        tp[i] += h
        tm[i] -= h
        fd = (nio.energy(tp, m, F)[0] - nio.energy(tm, m, F)[0]) / (2 * h)
        assert fd == pytest.approx(g[i], rel=1e-4, abs=1e-9 * max(1.0, abs(E)))


def test_contact_forces_minimise_energy(small):
    """NNLS forces beat zero forces and a scaled copy of themselves."""
    ch, fs, m, nio = small
    th = default_style().vector()
    F, _ = nio.forces(m, th)
    E = nio.energy(th, m, F)[0]
    assert E < nio.energy(th, m, 0 * F)[0]
    assert E <= nio.energy(th, m, 1.05 * F)[0] + 1e-9
    assert F[2::3].min() >= -1e-9  # normal components push


def test_initial_theta_paper(small):
    ch, fs, m, nio = small
    th = nio.initial_theta()
    st = style_from_theta(th)
    assert np.allclose(st.alpha, 1 / N_JOINT)
    assert np.all(st.ks1 >= 0) and np.all(st.kd >= 0)
    q = m.canonical(np.linspace(0, 1, 50))[:, 6:]
    assert np.abs(st.q_rest - q.mean(axis=0)).max() < 0.05  # q̄ ≈ mean pose


def test_joint_rms_zero_for_same_motion(small):
    _, _, m, _ = small
    assert joint_rms_deg(m, m) == 0.0


def test_cli_learn_bad_input(tmp_path):
    from schedules.cli import main
    out = tmp_path / "s.yaml"
    assert main(["learn", "nope.bvh", "--frames", "1:60", "-o", str(out)]) == 2
    assert main(["learn", "nope.bvh", "--frames", "60", "-o", str(out)]) == 2
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    assert main(["learn", str(bad), "--frames", "1:60", "-o", str(out)]) == 2
    assert not out.exists()


def test_resample_keeps_the_motion(small):
    from scenegraph.nio import resample
    _, _, m, _ = small
    coarse = resample(m, ctrl_per_second=10.0)  # like a reconstruction
    r = resample(coarse, ctrl_per_second=24.0)
    assert r.n_ctrl > coarse.n_ctrl and r.start == pytest.approx(m.start) and r.end == pytest.approx(m.end)
    assert joint_rms_deg(r, coarse) < 0.5  # measured 0.29° (the knots are not nested; the fit is smoothed)


def test_shipped_styles_have_provenance():
    """Every style in scenarios/styles/ was learned: provenance names a shipped clip (never an
    _iclone one), frames, body, versions, final G and the measured re-synthesis."""
    from pathlib import Path

    from scenegraph.style import load_style
    root = Path(__file__).resolve().parents[1] / "scenarios"
    files = sorted((root / "styles").glob("*.yaml"))
    if not files:
        pytest.skip("no learned style shipped yet")
    for f in files:
        st = load_style(f)
        pv = st.provenance
        assert pv is not None and pv.clip and pv.frames and pv.body, f
        assert "iclone" not in pv.clip and (root / "clips" / pv.clip).is_file(), f
        assert pv.g_final is not None and pv.g_final >= 0 and pv.versions, f
        assert abs(st.alpha.sum() - 1) < 1e-6
        extra = pv.model_extra or {}
        assert set(extra["resynth_rms_deg"]) >= {"learned", "default", "springs_off"}, f
        assert "compose learn" in f.read_text().splitlines()[0], f


def _theta_star(d):
    rng = np.random.default_rng(0)
    a = d.alpha * np.exp(rng.normal(0, 0.5, N_JOINT))
    return d.with_(alpha=a / a.sum(), ks1=d.ks1 * 1.5, ks2=d.ks2 * 0.7, name="star")


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="theta* is not recovered: the spacetime solver does not converge "
                                        "tightly enough for G to be measured (see the docstring)")
def test_synthetic_recovery():
    """One cyclic walk cycle X_T synthesised with a known θ* (α perturbed, springs ×1.5 / ×0.7):
    the synthesis, then a 1500-iteration refinement without IPOPT's "acceptable" exit (the
    pipeline).  NIO (bundle method, 150-iteration counterexamples warm-started at X_T) from the
    default style; re-synthesis by the same pipeline from the same initial motion.

    Goals: G falls ≥ 100× and the re-synthesis with the learned style is ≤ 2° RMS from X_T.
    Measured (2026-11-22, cyclic window): the pipeline itself is the obstacle.  A synthesis
    that IPOPT reports as converged (tol 1e-4, 53 iterations, E 146) keeps falling when
    continued (E 35 after another 485 iterations, the motion 12.4° RMS away; Gauss–Newton steps
    creep along a flat valley at ~0.1 % per iteration), so X_T is not the optimum under θ*:
    G(θ*) = 0.0075 is 21 % of G(default) = 0.0366 and NIO cannot drive G toward 0.  NIO took G
    0.0366 → 0.0298 in 10 iterations (415 s) (see the printed numbers for the re-synthesis).
    What would fix it: a counterexample/synthesis solver that converges (an exact or
    structured-secant Hessian for the dynamics residuals, see README).
    """
    from scenegraph.footsteps import footsteps_for_walk
    from scenegraph.nio import WARM_START
    from scenegraph.spacetime import Subproblem, solve
    from scenegraph.synthesis import synthesize

    ch = make_character("adult_male")
    d = default_style(ch.total_mass)
    star = _theta_star(d)
    fs = footsteps_for_walk(n_steps=4)
    t0, t1 = fs[1].t0, fs[-1].t0  # one cycle: two steps, cyclic

    def pipeline(style):
        m = synthesize(ch, style, fs, t0, t1, cyclic=True, max_iter=1000).result.motion
        return solve(Subproblem(ch, style, m, fs, free=frozenset({"q"}), cyclic=True, max_iter=1500, tol=1e-6,
                                ipopt_options=(("acceptable_iter", 0),))).motion

    XT = pipeline(star)
    nio = NIO(ch, XT, fs, solve_iter=150, cyclic=True, ipopt_options=WARM_START)
    g_star = nio.evaluate(star.vector()).G  # how well the solver still beats X_T at θ* (0 if X_T optimal)
    th0 = d.vector()
    hist = []
    out = nio.run(th0, max_iter=12, callback=hist.append)
    rms = {name: joint_rms_deg(pipeline(st), XT) for name, st in (("learned", out.style), ("default", d))}
    print("G per iteration:", [f"{h.G:.4g}" for h in hist], f"G(theta*) = {g_star:.3g}")
    print(f"G {out.g_initial:.4g} -> {out.g_final:.4g} ({out.stop_reason}, {out.iterations} iterations, "
          f"{out.seconds:.0f} s); resynth rms deg: " + ", ".join(f"{k} {v:.2f}" for k, v in rms.items()))
    assert out.g_initial > 0 and abs(out.style.alpha.sum() - 1) < 1e-9
    assert out.g_final <= 0.01 * out.g_initial  # the two orders of magnitude
    assert rms["learned"] <= 2.0 < rms["default"]
