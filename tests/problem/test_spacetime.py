"""Spacetime synthesis from footprints, checked by the independent physics audit."""
from dataclasses import replace

import numpy as np
import pytest

from scenegraph.model.body import make_character
from scenegraph.model.footsteps import footsteps_for_walk
from scenegraph.model.gait import initial_motion
from scenegraph.problem import Subproblem, solve
from scenegraph.model.style import default_style
from scenegraph.problem.synthesis import presolve_kinematics, synthesize

CH = make_character()
STYLE = default_style(CH.total_mass)


@pytest.fixture(scope="module")
def walk():
    steps = footsteps_for_walk()  # four footprints, 0.7 m steps at 1.85 steps/s ≈ 1.3 m/s
    # soft footprint springs and a one-sided soft ground at 120 Hz keep planted feet still and
    # swinging toes above the ground between the collocation points
    return steps, synthesize(CH, STYLE, steps, steps[1].t0, steps[-1].t0, soft_pin_hz=120.0,
                             soft_ground_hz=120.0, soft_ground_weight=1e4)


def test_walk_cycle_converges_and_passes_the_audit(walk):
    steps, syn = walk
    res, aud = syn.result, syn.audit
    assert res.success, res.summary()
    # constraints hold at the collocation points (solver's own check) ...
    assert res.violations["footstep"] <= 1e-6
    assert res.violations["penetration"] <= 1e-6
    # ... and the independent audit re-evaluates between them at 120 Hz
    assert aud.footstep_error_max <= 1e-3, aud
    assert aud.penetration_max <= 1e-3, aud
    assert aud.planted_speed_max <= 0.05, aud
    assert aud.friction_violation_max <= 1e-6
    # root residual vs body weight at the solver's force times (nodes and midpoints): with forces
    # that may jump between points it was ≤ 1e-3 at the points and 2.7 bw between them; the
    # dense transcription spreads it over nodes and midpoints (measured 1.9e-4–2.9e-3 RMS while it was
    # built) and holds it at every 120 Hz frame (measured 0.018 bw)
    assert aud.root_residual_rel <= 5e-3, aud
    assert aud.dense_residual_max <= 0.05, aud
    assert aud.joint_limit_violation_max <= 1e-6
    speed = (res.motion.canonical([1.0])[0, 0] - res.motion.canonical([0.0])[0, 0]) / res.motion.duration
    assert 1.1 < speed < 1.5


def test_walk_energy_is_far_below_the_initial_guess(walk):
    steps, syn = walk
    assert syn.result.energy < 0.05 * syn.presolve.energy


@pytest.mark.slow
def test_free_footprint_moves_to_a_lower_energy_spot():
    """A footprint placed 15 cm too wide, then freed: warm-started at the fixed optimum (motion
    and contact forces), the solver moves it and lowers the energy while every constraint
    holds.  It does not converge within 300 iterations (it keeps drifting, see README), so
    only feasibility and the energy decrease are asserted."""
    steps = list(footsteps_for_walk())
    wide = replace(steps[2], position=(steps[2].position[0], steps[2].position[1] - 0.15))
    steps[2] = wide
    fixed = synthesize(CH, STYLE, tuple(steps), steps[1].t0, steps[-1].t0)
    assert fixed.result.success, fixed.result.summary()
    steps[2] = replace(wide, free=True)
    free = solve(Subproblem(CH, STYLE, fixed.result.motion, tuple(steps), free=frozenset({"q", "footprints"}),
                            contact_guess=fixed.result.contact_forces))
    moved = np.subtract(free.footsteps[2].position, wide.position)
    assert np.linalg.norm(moved) > 0.02
    assert free.energy < fixed.result.energy
    assert free.violations["footstep"] <= 1e-5 and free.violations["penetration"] <= 1e-5


@pytest.mark.slow
def test_timewarp_moves_a_hurried_footstep_later():
    steps = list(footsteps_for_walk())
    steps[2] = replace(steps[2], t0=steps[2].t0 - 0.12, t1=steps[2].t1 - 0.12)  # lands 0.12 s early
    steps = tuple(steps)
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    pre = presolve_kinematics(CH, STYLE, m0, steps)
    res = solve(Subproblem(CH, STYLE, pre.motion, steps, free=frozenset({"q", "warp"})))
    assert res.success, res.summary()
    s_land = pre.motion.to_canonical([steps[2].t0])[0]
    landed = res.motion.time([s_land])[0]
    assert landed > steps[2].t0 + 0.03  # later in world time: only the warp can do that
    assert res.motion.start == pytest.approx(pre.motion.start) and res.motion.end == pytest.approx(pre.motion.end)
    assert np.all(np.diff(res.motion.warp) > 0)
    assert res.violations["footstep"] <= 1e-6


@pytest.mark.slow
def test_run_with_flight_phases():
    """A cyclic run cycle (1 m steps at 2.8 steps/s ≈ 2.8 m/s, stance 38 % of a stride, so
    both feet are off the ground between stances) converges from the initialisation."""
    steps = footsteps_for_walk(step_length=1.0, cadence=2.8, stance_fraction=0.38, gait="run")
    flights = [(a.t1, b.t0) for a, b in zip(steps, steps[1:])]
    assert all(b - a > 0.05 for a, b in flights)
    syn = synthesize(CH, STYLE, steps, steps[1].t0, steps[-1].t0, run=True, max_iter=600, cyclic=True,
                     soft_pin_hz=120.0, soft_ground_hz=120.0, soft_ground_weight=1e4)
    res, aud = syn.result, syn.audit
    assert res.success, res.summary()
    # see test_walk_cycle_converges_and_passes_the_audit; measured 0.0047 (the dense transcription
    # spreads the soft root residual over nodes and midpoints) and 0.030 bw at 120 Hz, in flight
    assert aud.root_residual_rel <= 1e-2, aud
    assert aud.dense_residual_max <= 0.05, aud  # every 120 Hz frame, the flights included
    assert aud.footstep_error_max <= 1e-3, aud
    assert aud.penetration_max <= 1e-3, aud
    assert aud.friction_violation_max <= 1e-6, aud
    assert aud.joint_limit_violation_max <= 1e-6, aud
    # no contact force in flight: the forces exist only inside stances
    for times, _ in res.contact_forces.values():
        for a, b in flights:
            assert not np.any((times > a + 1e-6) & (times < b - 1e-6))
    # the cycle ends where it began, one stride further
    q0, q1 = res.motion.canonical([0.0, 1.0])
    assert q1[0] - q0[0] == pytest.approx(2.0, abs=1e-3)
    np.testing.assert_allclose(q1[2:], q0[2:], atol=1e-6)


def test_spring_force_enters_the_dynamics():
    """A physical spring (rubber-band coupling) pulls the right palm toward a moving anchor:
    the solver's force is k (anchor − palm) at every collocation point, and the independent
    audit balances the equations of motion only when that force is counted."""
    from scenegraph.model.audit import audit_motion
    from scenegraph.model.kinematics import handle_positions_fn
    from scenegraph.problem import Spring

    steps = footsteps_for_walk()
    t0, t1 = steps[1].t0, steps[-1].t0
    m0 = initial_motion(CH, steps, t0, t1)
    times = np.linspace(t0, t1, 40)
    q, _, _ = m0.state_at_s(m0.to_canonical(times))
    palm = np.asarray(handle_positions_fn(CH, ("palm_r",)).map(len(times))(q.T)).T
    anchor = palm + np.array([0.0, -0.08, 0.0])  # 8 cm to the right of the initial palm path
    k = 400.0
    spring = Spring("palm_r", tuple(times), tuple(map(tuple, anchor)), k)
    syn = synthesize(CH, STYLE, steps, t0, t1, springs=(spring,))
    res = syn.result
    assert res.success, res.summary()
    ft, ff = res.contact_forces["palm_r"]
    qs, _, _ = res.motion.state_at_s(res.motion.to_canonical(ft))
    pos = np.asarray(handle_positions_fn(CH, ("palm_r",)).map(len(ft))(qs.T)).T
    expect = k * (np.stack([np.interp(ft, times, anchor[:, c]) for c in range(3)], axis=1) - pos)
    np.testing.assert_allclose(ff, expect, atol=1e-6)
    assert np.abs(ff).max() > 5.0  # a real pull, not a vanishing one
    with_force = syn.audit
    without = audit_motion(CH, STYLE, res.motion, res.footsteps,
                           {h: v for h, v in res.contact_forces.items() if h != "palm_r"})
    assert with_force.root_residual_rel <= 5e-3, with_force  # see test_walk_cycle_converges_and_passes_the_audit
    assert without.root_residual_max > 3 * with_force.root_residual_max + 1.0


# --- Hessian modes ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_window():
    """The walk's initial motion with only the control points of a 0.35 s window free, soft
    footprint springs on (nonlinear least squares beyond the dynamics)."""
    steps = footsteps_for_walk()
    m0 = initial_motion(CH, steps, steps[1].t0, steps[-1].t0)
    w0 = steps[1].t0 + 0.3
    return steps, m0, (w0, w0 + 0.35)


def _hessian_check(b, x, n_dirs=3, h=1e-5):
    """Relative error of the Hessian given to IPOPT (λ_f = 1, λ_g = 0: the objective's) times
    random directions against central differences of the objective's AD gradient."""
    import casadi as ca

    Hu = np.asarray(ca.DM(b.hess_lag(x, b.p0, 1.0, np.zeros(b.lbg.size))).full())
    H = Hu + np.triu(Hu, 1).T
    xs = ca.MX.sym("x", x.size)
    grad = ca.Function("grad_f", [xs], [ca.gradient(b.f_fn(xs, b.p0), xs)])
    rng = np.random.default_rng(3)
    errs = []
    for _ in range(n_dirs):
        v = rng.normal(size=x.size)
        v /= np.linalg.norm(v)
        fd = (np.asarray(grad(x + h * v)).ravel() - np.asarray(grad(x - h * v)).ravel()) / (2 * h)
        errs.append(np.linalg.norm(H @ v - fd) / np.linalg.norm(fd))
    return max(errs)


def test_exact_hessian_matches_finite_differences(small_window):
    """hessian="exact" hands IPOPT the true Hessian of the objective (residual curvature of the
    dynamics kernel and of the soft springs included); the Gauss–Newton one measurably is not.
    The style has no smooth-step kinks (ks2 = ks1, no shoe spring), whose curvature the exact
    mode holds out on purpose (kernel_hessian)."""
    from scenegraph.problem import transcribe

    steps, m0, window = small_window
    smooth = STYLE.with_(ks2=STYLE.ks1, k_shoe=0.0)
    errs = {}
    for mode in ("exact", "gauss_newton"):
        b = transcribe(Subproblem(CH, smooth, m0, steps, window=window, free=frozenset({"q"}), soft_pin_hz=120.0,
                             hessian=mode))
        x = b.x0 + 1e-3 * np.random.default_rng(0).normal(size=b.x0.size)  # off the initial guess
        x[b.x_layout["lambda"]] = np.abs(x[b.x_layout["lambda"]])
        errs[mode] = _hessian_check(b, x)
    assert errs["exact"] < 1e-6, errs
    assert errs["gauss_newton"] > 1e-5, errs  # the check can tell the two apart


@pytest.mark.xfail(strict=False, reason=(
    "known defect (round 7): the exact-Hessian window solve is fragile. Single-threaded MUMPS, "
    "footsteps 0.18 m apart (the one footstep generator): Error_In_Step_Computation after 9 "
    "iterations; 0.17 m with 2-thread MUMPS: the 100-iteration cap. Production steps use the "
    "Gauss-Newton Hessian; exact is an option of compose learn."))
def test_exact_hessian_solves_a_window():
    """A 0.35 s window of a solved walk (the bench_walk configuration) re-solved with the exact
    Hessian, warm-started as the executor warm-starts (contact forces as λ, a monotone barrier
    from μ = 1e-4), ends successfully within its 100-iteration cap with its constraints held
    (measured: 7 iterations with multithreaded MUMPS, 11 single-threaded — machine-dependent,
    so not asserted; with IPOPT's default barrier the
    same solve left the start at 20–50× its objective, or ended "Error in step computation")."""
    steps = footsteps_for_walk()
    r = synthesize(CH, STYLE, steps, steps[1].t0, steps[-1].t0, soft_pin_hz=120.0).result
    assert r.success, r.summary()
    window = (steps[1].t0 + 0.3, steps[1].t0 + 0.65)
    res = solve(Subproblem(CH, STYLE, r.motion, steps, window=window, free=frozenset({"q"}), hessian="exact",
                           contact_guess=r.contact_forces, max_iter=100, window_only=True,
                           ipopt_options=(("mu_strategy", "monotone"), ("mu_init", 1e-4))))
    assert res.success, res.summary()  # within max_iter=100; the count itself depends on the machine's MUMPS/BLAS
    assert res.violations["footstep"] <= 1e-4 and res.violations["penetration"] <= 1e-4, res.summary()


def test_window_only_and_open_end_transcription(small_window):
    """A receding window's transcription: ``window_only`` keeps exactly the collocation points
    whose q, q̇ or q̈ a free control point reaches (the dynamics elsewhere are constants);
    ``open_end`` also frees the control points straddling the window's end and keeps no
    point past it."""
    from scenegraph.model.motion import basis
    from scenegraph.problem import transcribe, window_mask

    steps, m0, window = small_window
    sp = Subproblem(CH, STYLE, m0, steps, window=window, free=frozenset({"q"}))
    whole = transcribe(sp).s_points
    local = transcribe(replace(sp, window_only=True)).s_points
    mask = window_mask(sp, m0.n_ctrl)
    reach = np.zeros(len(whole), bool)
    for d in (0, 1, 2):
        reach |= np.any(basis(m0.n_ctrl, whole, d)[:, mask] != 0.0, axis=1)
    assert 0 < len(local) < len(whole)
    np.testing.assert_array_equal(local, whole[reach])
    sp_open = replace(sp, window_only=True, open_end=True)
    open_mask = window_mask(sp_open, m0.n_ctrl)
    assert mask.sum() < open_mask.sum() and np.all(open_mask[mask])  # a superset: the straddling points
    s_end = float(m0.to_canonical([window[1]])[0])
    pts = transcribe(sp_open).s_points
    assert pts.max() <= s_end + 1e-9 and pts.min() < s_end


def test_unknown_hessian_mode_is_rejected(small_window):
    from scenegraph.problem import transcribe

    steps, m0, window = small_window
    with pytest.raises(ValueError, match="hessian"):
        transcribe(Subproblem(CH, STYLE, m0, steps, window=window, hessian="newton"))


def test_named_layout_and_solve_timing(small_window):
    """The NLP names its x/p slices (NIO and the joint problem substitute parameters by name),
    and a solve reports where its wall time went."""
    from scenegraph.problem import make_solver, transcribe
    from scenegraph.model.residual import theta_kernel_vector

    steps, m0, window = small_window
    nlp = transcribe(Subproblem(CH, STYLE, m0, steps, window=window, free=frozenset({"q"}), max_iter=3,
                                stall_iterations=2))
    for layout, n in ((nlp.x_layout, nlp.x0.size), (nlp.p_layout, nlp.p0.size)):
        sl = list(layout.values())
        assert sl[0].start == 0 and sl[-1].stop == n
        assert all(a.stop == b.start for a, b in zip(sl, sl[1:]))
    N = len(nlp.s_points)
    np.testing.assert_array_equal(nlp.p0[nlp.p_layout["ctrl_fixed"]], np.asarray(m0.ctrl, float).ravel())
    np.testing.assert_array_equal(nlp.p0[nlp.p_layout["theta"]].reshape(-1, N, order="F")[:, 0],
                                  theta_kernel_vector(STYLE))
    np.testing.assert_allclose(nlp.p0[nlp.p_layout["sqrt_alpha"]].reshape(-1, N, order="F")[:, -1],
                               np.sqrt(STYLE.alpha))
    assert nlp.x_layout["lambda"].stop - nlp.x_layout["lambda"].start == 4 * len(nlp.contact_index)

    res = solve(nlp.sp, make_solver(nlp))
    t = res.timing
    assert t.build == 0.0 and min(t.as_dict().values()) >= 0.0
    assert t.hess > 0.0 and t.callbacks > 0.0 and t.total == res.seconds
    parts = t.f + t.grad_f + t.g + t.jac_g + t.hess + t.callbacks + t.linear_solver_and_ipopt
    assert parts <= t.total + 1e-6
