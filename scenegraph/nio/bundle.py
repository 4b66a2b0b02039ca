"""The default NIO optimiser: a trust-region cutting-plane (bundle) method on G + D.

Every counterexample X_i ever found is a motion satisfying C, so for every θ
G(θ) ≥ E(X_T; θ) − E(X_i; θ) =: L_i(θ) (and ≥ 0).  At the current θ_c each L_i is
linearised with its Eq. 21 gradient (AD, forces re-fitted by NNLS under θ_c); the step
minimises the model max(0, max_i L_i + g_i·δ) in the box |δ_j| ≤ r s_j (s: the typical
magnitudes of :func:`.theta.theta_scales`), with Σα = 1 held exactly (so D = 0) — an LP.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from scenegraph.model.motion import Motion
from scenegraph.nio.records import History, IterationRecord, NIOResult, Problem
from scenegraph.nio.theta import ALPHA, project, style_from_theta, theta_bounds, theta_scales

__all__ = ["run_bundle", "model_step", "cut"]


def cut(nio: Problem, theta: np.ndarray, motion: Motion, ET: float, gT: np.ndarray):
    """(L_i(θ), ∇L_i): the lower bound of G from counterexample ``motion`` and its gradient,
    given E(X_T; θ) = ``ET`` with gradient ``gT``."""
    E, g, _, _ = nio.measure(theta, motion)
    return ET - E, gT - g


def model_step(theta: np.ndarray, cuts: list, radius: float, scales: np.ndarray, alpha_floor: float = 0.0):
    """argmin over δ of max(0, max_i L_i + g_i·δ) + μ Σ|δ/s| subject to Σα = 1, the Style
    bounds (α ≥ ``alpha_floor``) and the trust box |δ_j| ≤ radius·s_j (an LP).  Returns
    (θ + δ, model value)."""
    from scipy.optimize import linprog

    n = len(theta)
    M = ALPHA.stop - ALPHA.start
    lo, hi = theta_bounds(alpha_floor)
    dlo = np.maximum(lo - theta, -radius * scales)
    dhi = np.minimum(hi - theta, radius * scales)
    dlo = np.minimum(dlo, 0.0)
    dhi = np.maximum(dhi, 0.0)
    Lmax = max(c[0] for c in cuts)
    mu = 1e-3 * max(Lmax, 1e-12) / max(radius, 1e-12) / n
    # variables: δ (n), u (n) ≥ |δ/s|, t ≥ 0
    cvec = np.r_[np.zeros(n), np.full(n, mu), 1.0]
    rows, rhs = [], []
    for L, g in cuts:
        rows.append(np.r_[g, np.zeros(n), -1.0])
        rhs.append(-L)
    A1 = np.hstack([np.diag(1 / scales), -np.eye(n), np.zeros((n, 1))])
    A2 = np.hstack([-np.diag(1 / scales), -np.eye(n), np.zeros((n, 1))])
    A_ub = np.vstack([np.array(rows), A1, A2])
    b_ub = np.r_[rhs, np.zeros(2 * n)]
    A_eq = np.r_[np.ones(M), np.zeros(2 * n - M), 0.0][None, :]
    b_eq = [1.0 - theta[ALPHA].sum()]
    bounds = list(zip(dlo, dhi)) + [(0, None)] * n + [(0, None)]
    r = linprog(cvec, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if r.status != 0:
        return theta.copy(), Lmax
    d = r.x[:n]
    return theta + d, float(r.x[-1])


def run_bundle(nio: Problem, theta0: np.ndarray, *, max_iter: int = 30, rtol: float = 0.02, patience: int = 3,
               g_abs: float = 1e-3, trust: float = 0.03, min_trust: float = 1e-3, max_trust: float = 4.0,
               max_cuts: int = 40, max_tries: int = 4, callback: Callable[[IterationRecord], None] | None = None,
               seeds: tuple[Motion, ...] = ()) -> NIOResult:
    """Minimise G + D from θ0 by the bundle method.

    The trial θ gets its own counterexample (``nio.evaluate``: a spacetime solve
    warm-started from the best known motion, or the local step), which is added to the
    bundle.  G(θ_c) itself is re-read with every new counterexample (a later solve can show
    that the current G was underestimated), and the trial is accepted when G + D is below
    that; r doubles when the decrease was ≥ half the model's prediction, else r halves (the
    halving of footnote 3) and the enriched model is re-solved (at most ``max_tries`` trials
    per iteration).  The returned g_initial and g_final are G at θ0 and at the result re-read
    with all counterexamples found.  ``seeds``: motions known to satisfy C (e.g. syntheses
    from a neutral initial motion under θ0) that start the bundle as counterexamples.

    Stop: G + D below ``g_abs`` × its initial value; a relative decrease below ``rtol`` or
    no accepted step in ``patience`` iterations; or ``max_iter`` iterations (a safety net,
    reported as such).
    """
    log = History(callback)
    th = project(np.asarray(theta0, float))
    a = np.maximum(th[ALPHA], 0)
    th[ALPHA] = a / a.sum()
    scales = theta_scales(style_from_theta(th))
    cur = nio.evaluate(th, tuple(seeds))
    bundle: list[Motion] = list(seeds) + ([cur.motion_S] if cur.G > 0 else [])
    n_eval = 1
    log.add(0, cur.G, cur, 0.0, 1)
    g0 = cur.G + cur.D
    slow, fails, reason, r = 0, 0, "max_iter", trust
    it = 0
    for it in range(1, max_iter + 1):
        if cur.G + cur.D <= g_abs * max(g0, 1e-300):
            reason = f"G below {g_abs:g} x G_initial"
            it -= 1
            break
        if not bundle:
            reason = "no counterexample: the solver found no motion below E(X_T)"
            it -= 1
            break
        ET, gT, _, _ = nio.measure(cur.theta, nio.target)
        cuts = [cut(nio, cur.theta, m, ET, gT) for m in bundle]
        # G(θ_c) with everything known now (later counterexamples can reveal a larger G)
        prev = max(0.0, max(c[0] for c in cuts)) + cur.D
        tries = 0
        accepted = False
        while r >= min_trust and tries < max_tries:
            th_new, model = model_step(cur.theta, cuts, r, scales, nio.alpha_floor)
            pred = prev - model
            if pred <= 1e-12 * max(prev, 1e-300):
                r *= 0.5
                continue
            new = nio.evaluate(th_new, tuple(bundle))
            tries += 1
            n_eval += 1
            if new.G > 0:
                bundle.append(new.motion_S)
                bundle = bundle[-max_cuts:]
            c_new = cut(nio, cur.theta, new.motion_S, ET, gT)
            prev = max(prev, c_new[0] + cur.D)
            actual = prev - (new.G + new.D)
            if nio.verbose:
                print(f"    trial r={r:.3g}: G(θ_c)={prev:.5g} model={model:.5g} G(trial)={new.G + new.D:.5g}",
                      flush=True)
            if actual > 0:
                cur = new
                accepted = True
                r_used = r
                if actual >= 0.5 * pred:
                    r = min(max_trust, 2 * r)
                break
            r *= 0.5
            cuts.append(c_new)
        if not accepted:
            log.add(it, prev - cur.D, cur, 0.0, tries)
            fails += 1
            r = max(r, 4 * min_trust)
            if fails >= patience:
                reason = f"no decrease of G + D found in {patience} iterations"
                break
            continue
        fails = 0
        log.add(it, cur.G, cur, r_used, tries)
        rel = (prev - (cur.G + cur.D)) / max(prev, 1e-300)
        slow = slow + 1 if rel < rtol else 0
        if slow >= patience:
            reason = f"relative decrease < {rtol} for {patience} iterations"
            break
    # G(θ0) re-read with every counterexample found: the first solve alone can underestimate it
    ET0, gT0, _, _ = nio.measure(th, nio.target)
    g_init = max([log.records[0].G] + [cut(nio, th, m, ET0, gT0)[0] for m in bundle])
    ET1, gT1, _, _ = nio.measure(cur.theta, nio.target)
    g_fin = max([0.0] + [cut(nio, cur.theta, m, ET1, gT1)[0] for m in bundle])
    return log.result(style_from_theta(cur.theta), cur, g_init, g_fin, n_eval, reason)
