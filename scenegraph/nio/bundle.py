"""The default NIO optimiser: a trust-region cutting-plane (bundle) method on Σ_c G_c + D
(one clip or several of one person, :mod:`.multi`).

Every counterexample X_i ever found is a motion satisfying C, so for every θ
G(θ) ≥ E(X_T; θ) − E(X_i; θ) =: L_i(θ) (and ≥ 0).  At the current θ_c each L_i is
linearised with its Eq. 21 gradient (AD, forces re-fitted by NNLS under θ_c); the step
minimises the model Σ_c max(0, max_{i ∈ c} L_i + g_i·δ) (c: the clip a counterexample
belongs to) in the box |δ_j| ≤ r s_j (s: the typical
magnitudes of :func:`.theta.theta_scales`), with Σα = 1 held exactly (so D = 0) — an LP.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from scenegraph.model.motion import Motion
from scenegraph.nio.multi import MultiNIO
from scenegraph.nio.prior import ALPHA_MIN, Prior, tie_average
from scenegraph.nio.records import History, IterationRecord, NIOResult, Problem
from scenegraph.nio.theta import ALPHA, project, style_from_theta, theta_bounds, theta_scales

__all__ = ["run_bundle", "model_step", "cut", "trust_scales", "ALPHA_TRUST"]


def cut(nio: Problem, theta: np.ndarray, motion: Motion, ET: float, gT: np.ndarray):
    """(L_i(θ), ∇L_i): the lower bound of G from counterexample ``motion`` and its gradient,
    given E(X_T; θ) = ``ET`` with gradient ``gT``."""
    E, g, _, _ = nio.measure(theta, motion)
    return ET - E, gT - g


def model_step(theta: np.ndarray, cuts: list, radius: float, scales: np.ndarray, alpha_floor: float = 0.0,
               ties=(), lin: tuple[float, np.ndarray] | None = None, groups=None, tie_w: np.ndarray | None = None):
    """argmin over δ of Σ_c max(0, max_{i ∈ c} L_i + g_i·δ) [+ P0 + gP·δ] + μ Σ|δ/s| subject to
    Σα = 1, the Style bounds (α ≥ ``alpha_floor``), δ_i / w_i = δ_j / w_j for every pair of ``ties``
    (``tie_w``: the tie scales w, default 1, :func:`.prior.tie_scales`) and the
    trust box |δ_j| ≤ radius·s_j (an LP with one epigraph variable per group).  ``groups``: the
    clip index c of every cut (default: one clip, :mod:`.multi`); ``lin`` (P0, gP): a prior's
    value and gradient at θ (:mod:`.prior`), added linearised.  Returns (θ + δ, model value)."""
    from scipy.optimize import linprog

    groups = [0] * len(cuts) if groups is None else [int(c) for c in groups]
    ng = max(groups) + 1 if groups else 1
    n = len(theta)
    M = ALPHA.stop - ALPHA.start
    lo, hi = theta_bounds(alpha_floor)
    dlo = np.maximum(lo - theta, -radius * scales)
    dhi = np.minimum(hi - theta, radius * scales)
    dlo = np.minimum(dlo, 0.0)
    dhi = np.maximum(dhi, 0.0)
    Lmax = max(c[0] for c in cuts)
    model0 = sum(max([0.0] + [c[0] for c, gi in zip(cuts, groups) if gi == k]) for k in range(ng))
    mu = 1e-3 * max(Lmax, 1e-12) / max(radius, 1e-12) / n
    # variables: δ (n), u (n) ≥ |δ/s|, t (one per group) ≥ 0
    gP = np.zeros(n) if lin is None else np.asarray(lin[1], float)
    cvec = np.r_[gP, np.full(n, mu), np.ones(ng)]
    rows, rhs = [], []
    for (L, g), k in zip(cuts, groups):
        rows.append(np.r_[g, np.zeros(n), -np.eye(ng)[k]])
        rhs.append(-L)
    A1 = np.hstack([np.diag(1 / scales), -np.eye(n), np.zeros((n, ng))])
    A2 = np.hstack([-np.diag(1 / scales), -np.eye(n), np.zeros((n, ng))])
    A_ub = np.vstack([np.array(rows), A1, A2])
    b_ub = np.r_[rhs, np.zeros(2 * n)]
    A_eq = [np.r_[np.ones(M), np.zeros(2 * n - M), np.zeros(ng)]]
    b_eq = [1.0 - theta[ALPHA].sum()]
    for i, j in ties:
        row = np.zeros(2 * n + ng)
        row[i], row[j] = (1.0, -1.0) if tie_w is None else (1.0 / tie_w[i], -1.0 / tie_w[j])
        A_eq.append(row)
        b_eq.append(0.0)
    A_eq = np.array(A_eq)
    bounds = list(zip(dlo, dhi)) + [(0, None)] * n + [(0, None)] * ng
    r = linprog(cvec, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if r.status != 0:
        return theta.copy(), model0
    d = r.x[:n]
    return theta + d, float(r.x[2 * n:].sum()) + (0.0 if lin is None else float(lin[0] + gP @ d))


ALPHA_TRUST = ("absolute", "reference")


def trust_scales(scales: np.ndarray, alpha_trust: str = "absolute", alpha_ref: np.ndarray | None = None) -> np.ndarray:
    """The trust box's per-component sizes (θ's units; the box is radius × these): ``scales``
    (:func:`.theta.theta_scales`, α by 1/M) for "absolute"; for "reference" α_j by α_ref,j
    (default 1/M), so a step of radius r changes every α by at most the fraction r of its
    reference — at most ln(1 ± r) in the log-normal prior's units, whatever the joint."""
    if alpha_trust not in ALPHA_TRUST:
        raise ValueError(f"alpha_trust {alpha_trust!r}: one of {', '.join(ALPHA_TRUST)}")
    box = np.asarray(scales, float).copy()
    if alpha_trust == "reference":
        m = ALPHA.stop - ALPHA.start
        box[ALPHA] = np.full(m, 1.0 / m) if alpha_ref is None else np.asarray(alpha_ref, float)
    return box


def _per_clip(seeds, n: int) -> list[list[Motion]]:
    """Seed motions per clip: one clip's seeds may be given as a plain tuple of motions."""
    seeds = list(seeds)
    if seeds and isinstance(seeds[0], Motion):
        seeds = [seeds]
    if len(seeds) > n:
        raise ValueError(f"seeds for {len(seeds)} clips, the problem has {n}")
    return [list(s) for s in seeds] + [[] for _ in range(n - len(seeds))]


def run_bundle(nio: Problem, theta0: np.ndarray, *, max_iter: int = 30, rtol: float = 0.02, patience: int = 3,
               g_abs: float = 1e-3, trust: float = 0.03, min_trust: float = 1e-3, max_trust: float = 4.0,
               max_cuts: int = 40, max_tries: int = 4, callback: Callable[[IterationRecord], None] | None = None,
               seeds=(), prior_weight: float = 0.0, ties=(), alpha_ref: np.ndarray | None = None,
               spring_weight: float = 0.0, spring_ref: np.ndarray | None = None,
               tie_w: np.ndarray | None = None, alpha_trust: str = "absolute") -> NIOResult:
    """Minimise Σ_c G_c + D (+ P) from θ0 by the bundle method.

    ``nio``: a :class:`.multi.MultiNIO` (several clips) or one NIO problem (run as the
    one-clip MultiNIO).  Every clip keeps its own counterexamples (at most ``max_cuts``
    each) and its cuts bound its own G_c (:func:`model_step`'s groups).

    ``prior_weight`` w > 0 adds the log-normal prior on α of :func:`.prior.log_alpha_prior`
    (scaled by G + D at θ0, linearised in each LP, the true value in every comparison; α ≥
    :data:`.prior.ALPHA_MIN` keeps its log finite); ``ties`` (θ index pairs, :func:`.prior.tie_pairs`)
    are held equal (θ0 averaged over each tied set first; with ``tie_w`` the ratios θ_i / w_i).
    ``alpha_ref``: the α prior's centre (default 1/M, :func:`.prior.alpha_reference`);
    ``spring_weight`` > 0 adds the quadratic prior on the springs around those of ``spring_ref``
    (default θ0; :func:`.prior.spring_prior`), in the same units as the α prior.

    The trial θ gets its own counterexample per clip (``NIO.evaluate``: a spacetime solve
    warm-started from the best known motion, or the local step), which is added to that
    clip's bundle.  G(θ_c) itself is re-read with every new counterexample (a later solve can
    show that the current G was underestimated), and the trial is accepted when G + D is
    below that; r doubles when the decrease was ≥ half the model's prediction, else r halves
    (the halving of footnote 3) and the enriched model is re-solved (at most ``max_tries``
    trials per iteration).  The returned g_initial and g_final are G at θ0 and at the result
    re-read with all counterexamples found.  ``seeds``: motions known to satisfy C (e.g.
    syntheses from a neutral initial motion under θ0) that start the bundle as
    counterexamples — a tuple of motions (one clip) or one tuple per clip.

    ``alpha_trust``: the trust box of α — "absolute" (every α_j by r/M, the paper's scale) or
    "reference" (α_j by r·α_ref,j: the same *relative* change for every joint, the geometry of
    the log-normal prior).  With a strength reference (α_ref 26× below 1/M at hip, knee, ankle
    and trunk) an absolute box lets a first step change those α by up to 78 % of α_ref at
    r = 0.03, and the LP sees the prior only by its tangent, which is zero at the prior's
    centre θ0: at W = 1 every trial's true prior cost exceeded its decrease of G and no step was
    accepted (round 13; docs/learning.md).  With a uniform reference both are the same box.

    Stop: G + D below ``g_abs`` × its initial value; a relative decrease below ``rtol`` or
    no accepted step in ``patience`` iterations; or ``max_iter`` iterations (a safety net,
    reported as such).
    """
    prob = nio if hasattr(nio, "clips") else MultiNIO((nio,))
    clips = prob.clips
    nc = len(clips)
    log = History(callback)
    th = project(np.asarray(theta0, float))
    a = np.maximum(th[ALPHA], 0)
    th[ALPHA] = a / a.sum()
    ties = list(ties)
    if ties:
        th = tie_average(th, ties, tie_w)
    floor = max(prob.alpha_floor, ALPHA_MIN) if prior_weight > 0 else prob.alpha_floor
    if prior_weight > 0:
        th[ALPHA] = np.maximum(th[ALPHA], floor)
        th[ALPHA] /= th[ALPHA].sum()
    scales = theta_scales(style_from_theta(th))
    box = trust_scales(scales, alpha_trust, alpha_ref)  # the LP's box; the spring prior keeps `scales`
    k_ref = th.copy() if spring_ref is None else np.asarray(spring_ref, float)
    bundle = _per_clip(seeds, nc)
    cur = first = prob.evaluate(th, bundle)
    p_scale = max(cur.G + cur.D, 1e-12)

    P = Prior(p_scale, prior_weight, alpha_ref, spring_weight, k_ref, scales)

    def extra(e):  # D + P of an evaluation
        return e.D + P(e.theta)[0]

    def add(ev):  # each clip's new counterexample joins its own bundle
        for c, part in enumerate(ev.parts):
            if part.G > 0:
                bundle[c] = (bundle[c] + [part.motion_S])[-max_cuts:]

    def bound(theta, known=None):  # Σ_c max(known_c, 0, every cut of clip c) at theta
        out = []
        for c, clip in enumerate(clips):
            ET, gT, _, _ = clip.measure(theta, clip.target)
            out.append(max([0.0 if known is None else known[c]] + [cut(clip, theta, m, ET, gT)[0] for m in bundle[c]]))
        return sum(out)
    add(cur)
    n_eval = 1
    log.add(0, cur.G, cur, 0.0, 1)
    g0 = cur.G + extra(cur)
    slow, fails, reason, r = 0, 0, "max_iter", trust
    it = 0
    for it in range(1, max_iter + 1):
        if cur.G + extra(cur) <= g_abs * max(g0, 1e-300):
            reason = f"G below {g_abs:g} x G_initial"
            it -= 1
            break
        if not any(bundle):
            reason = "no counterexample: the solver found no motion below E(X_T)"
            it -= 1
            break
        meas = [clip.measure(cur.theta, clip.target)[:2] for clip in clips]
        cuts, groups = [], []
        for c, clip in enumerate(clips):
            cuts += [cut(clip, cur.theta, m, *meas[c]) for m in bundle[c]]
            groups += [c] * len(bundle[c])
        # G(θ_c) with everything known now (later counterexamples can reveal a larger G)
        Gc = [max([0.0] + [L for (L, _), k in zip(cuts, groups) if k == c]) for c in range(nc)]
        prev = sum(Gc) + extra(cur)
        tries = 0
        accepted = False
        while r >= min_trust and tries < max_tries:
            th_new, model = model_step(cur.theta, cuts, r, box, floor, ties,
                                       P(cur.theta) if P.active else None, groups, tie_w)
            pred = prev - model
            if pred <= 1e-12 * max(prev, 1e-300):
                r *= 0.5
                continue
            new = prob.evaluate(th_new, bundle)
            tries += 1
            n_eval += 1
            add(new)
            c_new = [cut(clip, cur.theta, new.parts[c].motion_S, *meas[c]) for c, clip in enumerate(clips)]
            Gc = [max(Gc[c], c_new[c][0]) for c in range(nc)]
            prev = sum(Gc) + extra(cur)
            actual = prev - (new.G + extra(new))
            if prob.verbose:
                print(f"    trial r={r:.3g}: G(θ_c)={prev:.5g} model={model:.5g} G(trial)={new.G + extra(new):.5g}",
                      flush=True)
            if actual > 0:
                cur = new
                accepted = True
                r_used = r
                if actual >= 0.5 * pred:
                    r = min(max_trust, 2 * r)
                break
            r *= 0.5
            cuts += c_new
            groups += list(range(nc))
        if not accepted:
            log.add(it, prev - extra(cur), cur, 0.0, tries)
            fails += 1
            r = max(r, 4 * min_trust)
            if fails >= patience:
                reason = f"no decrease of G + D found in {patience} iterations"
                break
            continue
        fails = 0
        log.add(it, cur.G, cur, r_used, tries)
        rel = (prev - (cur.G + extra(cur))) / max(prev, 1e-300)
        slow = slow + 1 if rel < rtol else 0
        if slow >= patience:
            reason = f"relative decrease < {rtol} for {patience} iterations"
            break
    # G(θ0) re-read with every counterexample found: the first solve alone can underestimate it
    g_init = bound(th, [p.G for p in first.parts])
    g_fin = bound(cur.theta)
    return log.result(style_from_theta(cur.theta), cur, g_init, g_fin, n_eval, reason)
