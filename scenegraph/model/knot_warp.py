"""A timewarp that puts a knot of the motion's B-splines on given instants (a plan's flight ends).

Why.  Between two knots a motion's q̈ is linear in canonical time, so it can kink only at a
knot.  A flight holds the momentum ballistic at its nodes, its take-off and touch-down
included (:mod:`scenegraph.problem.flight`), so a knot interval that holds a flight's end and
the first milliseconds of the stance after it is ballistic throughout: the landing force
cannot start before the next knot, and the solver pays root residual for the force it needs
there (tackle_dodge's tackler: 0.066 body weight 6 ms after a touch-down that lay 5 ms past a
knot, docs/results.md round 15).  With a knot on every flight end, q̈ kinks where the force
starts or stops, as the true motion's does.

How.  The motion keeps its control-point count and its uniform knots in canonical time s; the
warp T(s) gets the motion's own knot vector (``n_ctrl`` control points) and is the smoothest
one (least Σ (Δ² w)² of its control points) with T(0) and T(1) unchanged and T(u_k) = e for
the knot u_k nearest (in world time) to each event e.  An event whose nearest knot is an end
or already taken keeps no knot.  The control points are refitted so that q(t) is the same
motion in world time to the fit's precision (:func:`align_knots` reports it).
Units: world times in s.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.motion import Motion, basis, clamped_knots, fit_spline

__all__ = ["align_knots", "knot_times"]


def knot_times(motion: Motion) -> np.ndarray:
    """World times (s) of the motion's distinct knots, ends included."""
    return motion.time(np.unique(clamped_knots(motion.n_ctrl)))


def _evenest_warp(w0: np.ndarray, s_fix: np.ndarray, t_fix: np.ndarray) -> np.ndarray:
    """Control points w of the warp on the clamped uniform knots of len(w0) control points with
    T(s_fix) = t_fix whose differences stay closest to those of ``w0`` (least Σ (Δw − Δw0)²:
    knot spacing as even as the events allow; an equality-constrained least squares solved
    through its KKT system)."""
    n = len(w0)
    D = np.diff(np.eye(n), 1, axis=0)
    B = basis(n, s_fix)
    m = len(s_fix)
    K = np.block([[2.0 * D.T @ D, B.T], [B, np.zeros((m, m))]])
    rhs = np.r_[2.0 * D.T @ (D @ w0), t_fix]
    return np.linalg.solve(K, rhs)[:n]


def align_knots(motion: Motion, events) -> Motion:
    """``motion`` re-parametrised so that a knot lies on each of ``events`` (world s) where a
    distinct inner knot is nearest to it; the same motion in world time, refitted.  Returns
    ``motion`` itself when no event lies inside it, or when the smoothest warp through the
    events would not be strictly increasing (events closer than the knot spacing allows)."""
    ev = sorted(float(e) for e in events if motion.start + 1e-9 < float(e) < motion.end - 1e-9)
    if not ev:
        return motion
    n = motion.n_ctrl
    u = np.unique(clamped_knots(n))
    tk = motion.time(u)
    pairs: dict[int, float] = {}
    for e in ev:
        k = int(np.argmin(np.abs(tk - e)))
        if 0 < k < len(u) - 1 and k not in pairs:
            pairs[k] = e
    if not pairs:
        return motion
    ks = sorted(pairs)
    s_fix = np.r_[0.0, u[ks], 1.0]
    t_fix = np.r_[motion.start, [pairs[k] for k in ks], motion.end]
    if np.any(np.diff(t_fix) <= 0):
        return motion
    w = _evenest_warp(Motion.uniform_warp(motion.start, motion.end, n), s_fix, t_fix)
    s_d = np.linspace(0.0, 1.0, 16 * n)
    if np.any(np.diff(w) <= 0) or np.any(basis(n, s_d, 1) @ w <= 0):
        return motion
    t_d = basis(n, s_d) @ w
    q_d = motion.canonical(motion.to_canonical(t_d))
    return Motion(fit_spline(s_d, q_d, n, smooth=1e-9), w)
