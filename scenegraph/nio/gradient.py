"""The paper's NIO optimiser (``method="gradient"``): a preconditioned gradient step on
G + D with the halving line search of footnote 3.

Kept for comparison: with the noisy counterexamples of a 60-iteration solve it stalled
(G 0.0022 → 0.0016, then no decrease); the bundle method (:mod:`.bundle`) is the default.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from scenegraph.nio.records import Evaluation, History, IterationRecord, NIOResult, Problem
from scenegraph.nio.theta import project, style_from_theta, theta_scales

__all__ = ["run_gradient"]


def run_gradient(nio: Problem, theta0: np.ndarray, *, max_iter: int = 30, rtol: float = 0.02, patience: int = 2,
                 g_abs: float = 1e-4, trust: float = 0.1, min_beta: float = 1e-6,
                 callback: Callable[[IterationRecord], None] | None = None) -> NIOResult:
    """Minimise G + D from θ0: step −β·trust·s²∇/max|s∇| (s: :func:`.theta.theta_scales`),
    β halved from 1 while the half step is better; the trust length adapts to the accepted β.

    Stop: G + D below ``g_abs`` × its initial value, a zero gradient, no decrease along the
    line (after shortening), a relative decrease below ``rtol`` for ``patience`` iterations,
    or ``max_iter`` iterations."""
    log = History(callback)
    scales = theta_scales(style_from_theta(theta0))
    cur = nio.evaluate(project(np.asarray(theta0, float)))
    n_eval = 1
    log.add(0, cur.G, cur, 0.0, 1)
    g0 = cur.G + cur.D
    slow, reason, it = 0, "max_iter", 0
    cache: dict[float, Evaluation] = {}
    if cur.G <= 0.0:
        reason = "no counterexample: the solver found no motion below E(X_T) (raise solve_iter)"
        max_iter = 0
    for it in range(1, max_iter + 1):
        if cur.G + cur.D <= g_abs * max(g0, 1e-300):
            reason = "G below tolerance"
            it -= 1
            break
        d = scales ** 2 * cur.grad  # preconditioned gradient
        nrm = np.max(np.abs(d / scales))
        if not np.isfinite(nrm) or nrm == 0:
            reason = "zero gradient"
            it -= 1
            break
        delta = d * (trust / nrm)
        cache = {}

        def at(beta):
            if beta not in cache:
                cache[beta] = nio.evaluate(project(cur.theta - beta * delta), (cur.motion_S,))
            return cache[beta]

        beta = 1.0  # footnote 3
        while beta > min_beta and at(beta).G + at(beta).D > at(beta / 2).G + at(beta / 2).D:
            beta /= 2
        new = at(beta)
        n_eval += len(cache)
        prev = cur.G + cur.D
        if new.G + new.D >= prev:
            # no decrease along this direction: try shorter steps once, then stop
            trust *= 0.25
            log.add(it, cur.G, cur, 0.0, len(cache))
            if trust < 1e-3:
                reason = "line search found no decrease"
                break
            slow += 1
            if slow >= patience + 1:
                reason = "line search found no decrease"
                break
            continue
        cur = new
        trust = min(4.0, trust * (2.0 if beta == 1.0 else max(beta, 1e-3) * 2))
        log.add(it, cur.G, cur, beta, len(cache))
        rel = (prev - (cur.G + cur.D)) / max(prev, 1e-300)
        slow = slow + 1 if rel < rtol else 0
        if slow >= patience:
            reason = f"relative decrease < {rtol} for {patience} iterations"
            break
    return log.result(style_from_theta(cur.theta), cur, log.records[0].G, cur.G, n_eval, reason)
