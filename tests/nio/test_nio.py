"""Nonlinear Inverse Optimization: energy and gradient, D(θ), CLI errors, synthetic recovery."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import N_JOINT, make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.nio import NIO, d_penalty, joint_rms_deg, style_from_theta
from scenegraph.model.style import default_style


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
    _, lam = nio.forces(m, th)
    E, g = nio.energy(th, m, lam)
    assert E > 0 and np.all(np.isfinite(g))
    rng = np.random.default_rng(1)
    for i in rng.choice(len(th), 8, replace=False):
        h = 1e-6 * max(1.0, abs(th[i]))
        tp, tm = th.copy(), th.copy()
        tp[i] += h
        tm[i] -= h
        fd = (nio.energy(tp, m, lam)[0] - nio.energy(tm, m, lam)[0]) / (2 * h)
        assert fd == pytest.approx(g[i], rel=1e-4, abs=1e-9 * max(1.0, abs(E)))


def test_contact_forces_minimise_energy(small):
    """The profiled contact coefficients beat zero forces, scaled copies of themselves and
    random feasible perturbations; the solver's λ = 0 at touch-down / lift-off is kept."""
    ch, fs, m, nio = small
    th = default_style().vector()
    F, lam = nio.forces(m, th)
    E = nio.energy(th, m, lam)[0]
    assert E < nio.energy(th, m, 0 * lam)[0]
    for c in (0.95, 1.05):
        assert E <= nio.energy(th, m, c * lam)[0] + 1e-9 * E
    rng = np.random.default_rng(3)
    held = nio.nlp.ubx[nio.nlp.x_layout["lambda"]] == 0
    assert held.any() and np.all(lam[held] == 0)
    for _ in range(3):
        d = np.where(held, 0.0, rng.normal(scale=1e-3, size=lam.size))
        assert E <= nio.energy(th, m, np.maximum(lam + d, 0.0))[0] + 1e-9 * E
    assert F[2::3].min() >= -1e-9  # normal components push


def test_initial_theta_paper(small):
    ch, fs, m, nio = small
    th = nio.initial_theta()
    st = style_from_theta(th)
    assert np.allclose(st.alpha, 1 / N_JOINT)
    assert np.all(st.ks1 >= 0) and np.all(st.kd >= 0)
    q = m.canonical(np.linspace(0, 1, 50))[:, 6:]
    assert np.abs(st.q_rest - q.mean(axis=0)).max() < 0.05  # q̄ ≈ mean pose


def test_alpha_floor_bounds_the_model_step(small):
    """``alpha_floor`` (NIO.alpha_floor, which run_bundle passes on) is a lower bound of every
    α_j in the bundle's LP step (Σα = 1 kept); without it the same cut drives α_0 to 0."""
    from scenegraph.nio.bundle import model_step
    from scenegraph.nio.theta import theta_scales
    *_, nio = small
    th = default_style(nio.ch.total_mass).vector()
    g = np.zeros_like(th)
    g[0] = 10.0  # the model falls as α_0 falls
    scales = theta_scales(style_from_theta(th))
    floor = 0.5 / N_JOINT
    for f, expect_below in ((0.0, True), (floor, False)):
        new, _ = model_step(th, [(1.0, g)], 4.0, scales, alpha_floor=f)
        assert abs(new[:N_JOINT].sum() - 1.0) < 1e-9
        assert new[:N_JOINT].min() >= f - 1e-12
        assert (new[0] < floor - 1e-6) == expect_below


def test_joint_rms_zero_for_same_motion(small):
    _, _, m, _ = small
    assert joint_rms_deg(m, m) == 0.0


def test_cli_learn_bad_input(tmp_path, capsys):
    from schedules.cli.main import main
    out = tmp_path / "s.yaml"
    assert main(["learn", "nope.bvh", "--frames", "1:60", "-o", str(out)]) == 2
    assert main(["learn", "nope.bvh", "--frames", "60", "-o", str(out)]) == 2
    capsys.readouterr()
    assert main(["learn", "nope.bvh", "--frames", "1:60", "--alpha-floor", "2", "-o", str(out)]) == 2
    assert "--alpha-floor 2.0: must lie in [0, 1]" in capsys.readouterr().err
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    assert main(["learn", str(bad), "--frames", "1:60", "-o", str(out)]) == 2
    assert not out.exists()


@pytest.mark.slow
def test_compose_learn_end_to_end(tmp_path):
    """`compose learn` on one gait cycle of the shipped 07_01 clip (3 NIO iterations): writes a
    style that loads, with its provenance, the "learned by" line naming the non-default
    option, and the example poses of X_T."""
    from pathlib import Path

    from schedules.cli.main import main
    from scenegraph.model.style import load_style
    clip = Path(__file__).resolve().parents[2] / "scenarios" / "clips" / "walk_neutral_cmu_07_01.bvh"
    out = tmp_path / "w.yaml"
    assert main(["learn", str(clip), "--frames", "64:201", "--max-iter", "3", "--alpha-floor", "0.2",
                 "--alpha-prior", "0", "--spring-prior", "0", "--tie", "none", "-o", str(out)]) == 0
    st = load_style(out)
    assert st.provenance.clip == clip.name and st.provenance.frames == "64:201"
    assert st.alpha.min() >= 0.2 / N_JOINT - 1e-9
    first = out.read_text().splitlines()[0]
    assert first.startswith("# learned by: compose learn walk_neutral_cmu_07_01.bvh --frames 64:201")
    assert "--alpha-floor 0.2" in first
    assert st.example is not None and len(st.example.phase_l) == 69  # 1.13 s at 60 fps


def test_learned_header_repeats_non_default_options():
    """A style file's "learned by" line must re-learn it: non-default NIO options become flags
    that `compose learn` accepts."""
    import argparse

    from schedules.cli.learn import _option_flags, register
    prov = {"counterexamples": "spacetime solves of 150 IPOPT iterations", "hessian": "exact",
            "alpha_floor": 0.6 / N_JOINT}
    flags = _option_flags(prov)
    plain = " --alpha-prior 0 --spring-prior 0 --tie none --contacts central"
    assert flags == " --counterexamples ipopt --hessian exact --alpha-floor 0.6" + plain
    assert _option_flags({"counterexamples": "local (one Gauss-Newton step from X_T)"}) == plain
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    a = ap.parse_args(["learn", "c.bvh", "--frames", "1:9", "-o", "s.yaml", *flags.split()])
    assert (a.counterexamples, a.hessian, a.alpha_floor) == ("ipopt", "exact", 0.6)


def test_example_of_covers_the_gait_cycle(small):
    """The example poses a learned style carries: X_T sampled at 60 fps, every sample keyed by
    both legs' phase codes, stance and swing of each leg represented, joints copied exactly."""
    from scenegraph.model.body import N_ROOT
    from scenegraph.nio import example_of
    ch, fs, m, _ = small
    codes, joints = example_of(m, fs).arrays()
    t, q = m.sample(60.0)
    assert codes.shape == (len(t), 2) and np.allclose(joints, q[:, N_ROOT:], atol=1e-5)
    assert np.all((codes >= 0) & (codes <= 2))
    for leg in (0, 1):
        assert (codes[:, leg] < 1).any() and (codes[:, leg] > 1).any()


def test_resample_keeps_the_motion(small):
    from scenegraph.nio import resample
    _, _, m, _ = small
    coarse = resample(m, ctrl_per_second=10.0)  # like a reconstruction
    r = resample(coarse, ctrl_per_second=24.0)
    assert r.n_ctrl > coarse.n_ctrl and r.start == pytest.approx(m.start) and r.end == pytest.approx(m.end)
    assert joint_rms_deg(r, coarse) < 0.5  # measured 0.29° (the knots are not nested; the fit is smoothed)


def test_flight_phase_detection():
    """Runs (flight phases) get ball-only footsteps in `compose learn`; walks keep heel and ball."""
    from schedules.cli.learn import _has_flight
    walk = footsteps_for_walk(n_steps=4)
    run = footsteps_for_walk(n_steps=4, step_length=1.0, cadence=2.8, stance_fraction=0.38, gait="run")
    assert not _has_flight(walk, walk[0].t0, walk[-1].t1)
    assert _has_flight(run, run[0].t0, run[-1].t1)


@pytest.fixture(scope="module")
def local_nio():
    """(X_T: a kinematically pre-solved walk that satisfies C, local NIO on it, θ: the default style)."""
    from scenegraph.problem.synthesis import presolve_kinematics
    ch = make_character("adult_male")
    fs = footsteps_for_walk(n_steps=3)
    d = default_style(ch.total_mass)
    m = presolve_kinematics(ch, d, initial_motion(ch, fs, 0.0, 1.3), fs).motion
    return m, NIO(ch, m, fs, local=True), d.vector()


def test_local_counterexample_lowers_energy_within_C(local_nio):
    """The Gauss–Newton counterexample (local NIO) of a motion that satisfies C: lower energy,
    C kept to feas_tol, and G(θ) = E(X_T) − E(X_S) ≥ 0 with a finite Eq. 21 gradient."""
    m, nio, th = local_nio
    E, _, _, lam = nio.measure(th, m)
    XS, viol = nio.local_counterexample(th, m, lam)
    assert viol <= nio.feas_tol
    assert nio.measure(th, XS)[0] < 0.99 * E
    ev = nio.evaluate(th)
    assert ev.G > 0 and np.all(np.isfinite(ev.grad))


def test_seeded_counterexamples_enter_g(local_nio):
    """``run_bundle(seeds=…)``: a known motion within C below E(X_T) (here two Gauss–Newton steps
    from X_T) is a counterexample from the start: the reported G(θ0) is at least
    E(X_T) − E(seed), and at least G(θ0) without the seed.

    What the mathematics guarantees: G(θ0) = E(X_T) − min E over the candidates (X_T, the
    seeds, the local counterexample), and the seeded run's candidates are a superset of the
    plain run's, so seeded ≥ plain.  Not that it is strictly larger: the second Gauss–Newton
    step need not lower E below the first (on one machine both gave 539181.419653153), and
    the two runs reach the same numbers by different code paths, so the comparisons allow
    a rounding tolerance relative to E(X_T)."""
    m, nio, th = local_nio
    ET, _, _, lam = nio.measure(th, m)
    X1, _ = nio.local_counterexample(th, m, lam)
    X2, viol = nio.local_counterexample(th, X1, nio.measure(th, X1)[3])
    assert viol <= nio.feas_tol
    E2 = nio.measure(th, X2)[0]
    plain = nio.run_bundle(th, max_iter=0)
    seeded = nio.run_bundle(th, max_iter=0, seeds=(X2,))
    tol = 1e-9 * abs(ET)
    assert seeded.g_initial >= ET - E2 - tol
    assert seeded.g_initial >= plain.g_initial - tol
    assert plain.g_initial >= -tol  # X_T itself is a candidate: G(θ0) ≥ 0


def test_shipped_styles_have_provenance():
    """Every style in scenarios/styles/ was learned: provenance names a shipped clip (never an
    _iclone one), frames, body, versions, final G, and the re-synthesis where it was measured (the
    styles re-learned in round 14 with the prior carry none: issue #18 made the held-out test the
    measure, docs/learning.md)."""
    from pathlib import Path

    from scenegraph.model.style import load_style
    root = Path(__file__).resolve().parents[2] / "scenarios"
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
        if "resynth_rms_deg" in extra:  # measured by bench_nio.py --out (a smoke test since issue #18)
            assert set(extra["resynth_rms_deg"]) >= {"learned", "default", "springs_off"}, f
        assert "compose learn" in f.read_text().splitlines()[0], f
        assert st.example is not None and len(st.example.phase_l) >= 20, f  # X_T's poses by leg phase


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="learned / default / springs off 4.41 / 4.32 / 4.39 deg on 07_01 "
                                        "(2026-12-01): <= 5 deg, but not below the ablations (README, "
                                        "Learning a style)")
def test_real_resynthesis_of_shipped_walk():
    """The issue's real re-synthesis check on the shipped `walk` style (learned from one gait
    cycle of 07_01): synthesise with the clip's own footprints from the paper's initial motion
    (poses of X_T by leg phase, ``resynthesize_from_example``); joint RMS against X_T ≤ 5° and
    clearly (≥ 30 %) below the default style and the learned style with springs off."""
    from pathlib import Path

    from schedules.cli.learn import clip_target
    from scenegraph.nio import resynthesize_from_example
    from scenegraph.model.style import load_style

    root = Path(__file__).resolve().parents[2] / "scenarios"
    walk = load_style(root / "styles" / "walk.yaml")
    ch, XT, steps, _ = clip_target(root / "clips" / walk.provenance.clip,
                                   tuple(map(int, walk.provenance.frames.split(":"))), walk.provenance.body)
    zero = np.zeros(N_JOINT)
    rms = {name: joint_rms_deg(resynthesize_from_example(ch, XT, steps, st).motion, XT)
           for name, st in (("learned", walk), ("default", default_style(ch.total_mass)),
                            ("springs_off", walk.with_(ks1=zero, ks2=zero, kd=zero, name="springs_off")))}
    print("re-synthesis rms deg:", rms)
    assert rms["learned"] <= 5.0
    assert rms["learned"] <= 0.7 * min(rms["default"], rms["springs_off"])


MAX_NIO_ITER = 200
HESSIAN = "gauss_newton"  # Subproblem.hessian of the synthetic recovery (see its docstring)


def _theta_star(d):
    rng = np.random.default_rng(0)
    a = d.alpha * np.exp(rng.normal(0, 0.5, N_JOINT))
    return d.with_(alpha=a / a.sum(), ks1=d.ks1 * 1.5, ks2=d.ks2 * 0.7, name="star")


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="G falls 25x, not 100x, and theta* is not recovered: "
                                        "re-synthesis 9.25 deg from X_T (default 14.29); with the exact "
                                        "Hessian 65x, 10.68 deg (default 2.90); exact IPOPT counterexamples "
                                        "11x, 2.50 deg (default 2.90) (docstring)")
def test_synthetic_recovery():
    """One cyclic walk cycle X_T synthesised with a known θ* (α perturbed, springs ×1.5 / ×0.7)
    by the pipeline: synthesis, then a refinement of up to 1500 iterations without IPOPT's
    "acceptable" exit (a synthesis IPOPT calls converged at tol 1e-4 keeps falling, E 146 → 35,
    and moves 12° when continued: on this flat energy a loosely converged X_T is not the
    optimum under θ*).  NIO from the default style with *local* counterexamples (one
    Gauss–Newton step from X_T within C, ``NIO(local=True)``); re-synthesis by the same pipeline
    from the same initial motion (not from X_T).  Numbers are printed (see README Status).

    Measured back to back (2026-11-22 07:00–07:40 UTC, commit 07fa17b, machine heavily loaded;
    `python -c "from test_nio import synthetic_recovery; synthetic_recovery(MODE)"` from
    tests/):
    - ``hessian="gauss_newton"`` (the default, this test): G 1.04e-3 → 4.10e-5 (25×; G(θ*) =
      2.1e-4) in 78 iterations; α moves away from α* (mean |log α/α*| 0.71 vs 0.33 at the
      default); re-synthesis 9.25° RMS from X_T (default 14.29°).
    - ``hessian="exact"`` in every IPOPT solve (X_T's pipeline and the re-syntheses; the local
      counterexample stays a Gauss–Newton step): G 8.68e-4 → 1.34e-5 (65×; G(θ*) 2.1e-4) in 100
      iterations; some α driven to 0; re-synthesis 10.68° (default 2.90°: the exact solves stop
      at the stationary point next to their start, so the default style lands closer).
    - ``hessian="exact"`` with IPOPT counterexamples (``synthetic_recovery("exact", local=False,
      max_iter=40)``, 36 iterations, 2170 s loaded): G 4.76e-2 → 4.16e-3 (11×; G(θ*) 1.33e-2);
      re-synthesis 2.50° (default 2.90°); α not recovered (0.81).
    - 2026-12-01, X_T refined with the exact Hessian (3000 iterations, tol 1e-9, still not
      converged), local counterexamples: G 8.2e-4 → 2.0e-5 (41×; G(θ*) 6.8e-5); exact
      re-synthesis from X_T, warm-started: learned 1.75°, θ* itself 1.43°, default 0.26°
      (README, "Synthetic check of the measure itself"): the test's second half fails for θ*.
    An earlier solver version gave 54× and 22.5° (default 8.6°).  Why: the energy is
    multi-modal and flat (IPOPT's inertia correction shrinks the steps along the flat
    directions in both Hessian modes, README "Exact Hessian"), so which minimum the pipeline
    reaches depends on θ and the solver in ways G does not see; G is local.
    """
    r = synthetic_recovery(HESSIAN)
    assert r["g_initial"] > 0 and abs(r["alpha_sum"] - 1) < 1e-9
    assert r["g_final"] <= 0.01 * r["g_initial"]  # the two orders of magnitude
    assert r["rms_learned"] <= 2.0 < r["rms_default"]


def synthetic_recovery(hessian: str = "gauss_newton", local: bool = True, max_iter: int = MAX_NIO_ITER) -> dict:
    """The synthetic recovery experiment with the spacetime Hessian ``hessian`` in every IPOPT
    solve (X_T's pipeline, the re-syntheses; NIO's local counterexample is a Gauss–Newton step
    either way); prints and returns its numbers."""
    from scenegraph.model.footsteps import footsteps_for_walk
    from scenegraph.problem import Subproblem, solve
    from scenegraph.problem.synthesis import synthesize

    ch = make_character("adult_male")
    d = default_style(ch.total_mass)
    star = _theta_star(d)
    fs = footsteps_for_walk(n_steps=4)
    t0, t1 = fs[1].t0, fs[-1].t0  # one cycle: two steps, cyclic

    def pipeline(style):
        m = synthesize(ch, style, fs, t0, t1, cyclic=True, max_iter=1000, hessian=hessian).result.motion
        return solve(Subproblem(ch, style, m, fs, free=frozenset({"q"}), cyclic=True, max_iter=1500, tol=1e-6,
                                ipopt_options=(("acceptable_iter", 0),), hessian=hessian)).motion

    XT = pipeline(star)
    nio = NIO(ch, XT, fs, cyclic=True, local=local, hessian=hessian)
    g_star = nio.evaluate(star.vector()).G  # the floor: X_T is not exactly stationary under θ*
    hist = []
    out = nio.run(d.vector(), max_iter=max_iter, rtol=0.003, patience=6, callback=hist.append)
    rms = {name: joint_rms_deg(pipeline(st), XT) for name, st in (("learned", out.style), ("default", d))}
    lr = np.abs(np.log(out.style.alpha / star.alpha)).mean()
    print(f"[{hessian}, local={local}] G {out.g_initial:.4g} -> {out.g_final:.4g} (ratio {out.g_final / out.g_initial:.3g}; "
          f"G(theta*) {g_star:.3g}; {out.stop_reason}, {out.iterations} iterations, {out.seconds:.0f} s); "
          "resynth rms deg: " + ", ".join(f"{k} {v:.2f}" for k, v in rms.items())
          + f"; alpha mean |log a/a*| learned {lr:.3f} default {np.abs(np.log(d.alpha / star.alpha)).mean():.3f}",
          flush=True)
    return {"g_initial": out.g_initial, "g_final": out.g_final, "g_star": g_star, "iterations": out.iterations,
            "seconds": out.seconds, "rms_learned": rms["learned"], "rms_default": rms["default"],
            "alpha_sum": float(out.style.alpha.sum()), "alpha_log_err": lr}
