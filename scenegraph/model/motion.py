"""Motion as functions of time: cubic B-splines in canonical time plus a monotone timewarp.

Every DOF is a clamped cubic B-spline q(s) over canonical time s ∈ [0, 1].  World time is
t = T(s), itself a clamped cubic B-spline whose control points increase strictly, which
makes T monotone (a B-spline lies in the convex hull of its control points, and its
derivative is a B-spline whose control points are the scaled differences).  Constraint
times and collocation points are fixed in s, so they travel with the motion when the
timing changes.  World-time rates follow by the chain rule:

    q̇ = q'/T',   q̈ = q''/T'² − q' T''/T'³      (' = d/ds)

A motion becomes a list of frames only at export (:meth:`Motion.sample`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

__all__ = ["clamped_knots", "basis", "Motion", "fit_spline"]

DEGREE = 3


@lru_cache(maxsize=64)
def clamped_knots(n_ctrl: int, degree: int = DEGREE) -> tuple[float, ...]:
    """Uniform clamped knot vector on [0, 1] for ``n_ctrl`` control points."""
    if n_ctrl < degree + 1:
        raise ValueError(f"need at least {degree + 1} control points, got {n_ctrl}")
    inner = np.linspace(0.0, 1.0, n_ctrl - degree + 1)
    return tuple(np.concatenate([[0.0] * degree, inner, [1.0] * degree]))


def _basis0(knots: np.ndarray, degree: int, s: np.ndarray) -> np.ndarray:
    """Cox–de Boor: values of all basis functions at s, shape (len(s), n_ctrl)."""
    n = len(knots) - degree - 1
    s = np.clip(np.asarray(s, dtype=float), knots[0], knots[-1])
    # degree-0 basis; the last non-empty span is closed on the right so s = 1 is covered
    last = np.max(np.nonzero(knots[1:] > knots[:-1])[0])
    N = np.zeros((len(s), len(knots) - 1))
    for i in range(len(knots) - 1):
        if knots[i + 1] > knots[i]:
            right = s <= knots[i + 1] if i == last else s < knots[i + 1]
            N[:, i] = (s >= knots[i]) & right
    for d in range(1, degree + 1):
        M = np.zeros((len(s), len(knots) - 1 - d))
        for i in range(len(knots) - 1 - d):
            a = knots[i + d] - knots[i]
            b = knots[i + d + 1] - knots[i + 1]
            if a > 0:
                M[:, i] += (s - knots[i]) / a * N[:, i]
            if b > 0:
                M[:, i] += (knots[i + d + 1] - s) / b * N[:, i + 1]
        N = M
    return N[:, :n]


def basis(n_ctrl: int, s, deriv: int = 0, degree: int = DEGREE) -> np.ndarray:
    """Matrix B (len(s), n_ctrl) with q^(deriv)(s) = B @ ctrl for a clamped uniform spline."""
    knots = np.array(clamped_knots(n_ctrl, degree))
    s = np.atleast_1d(np.asarray(s, dtype=float))
    if deriv == 0:
        return _basis0(knots, degree, s)
    # derivative of a B-spline: degree-1 spline on the inner knots with difference coefficients
    k = degree
    D = np.zeros((n_ctrl - 1, n_ctrl))
    for i in range(n_ctrl - 1):
        w = k / (knots[i + k + 1] - knots[i + 1])
        D[i, i], D[i, i + 1] = -w, w
    inner_knots = knots[1:-1]
    if deriv == 1:
        return _basis0(inner_knots, k - 1, s) @ D
    return _basis_deriv_from(inner_knots, k - 1, s, deriv - 1) @ D


def _basis_deriv_from(knots: np.ndarray, degree: int, s: np.ndarray, deriv: int) -> np.ndarray:
    n = len(knots) - degree - 1
    if deriv == 0:
        return _basis0(knots, degree, s)
    D = np.zeros((n - 1, n))
    for i in range(n - 1):
        w = degree / (knots[i + degree + 1] - knots[i + 1])
        D[i, i], D[i, i + 1] = -w, w
    return _basis_deriv_from(knots[1:-1], degree - 1, s, deriv - 1) @ D


def fit_spline(s: np.ndarray, values: np.ndarray, n_ctrl: int, smooth: float = 1e-6) -> np.ndarray:
    """Least-squares control points (n_ctrl, dims) of a spline through samples at s."""
    B = basis(n_ctrl, s)
    D2 = basis(n_ctrl, np.linspace(0, 1, 4 * n_ctrl), 2)
    A = B.T @ B + smooth * D2.T @ D2
    return np.linalg.solve(A, B.T @ np.asarray(values, dtype=float).reshape(len(s), -1))


@dataclass(frozen=True)
class Motion:
    """One character's motion.

    ``ctrl`` (n_ctrl, n_dof): control points of the DOF splines (m, rad).
    ``warp`` (n_warp,): strictly increasing control points of T(s) (s).
    """

    ctrl: np.ndarray
    warp: np.ndarray

    @property
    def n_ctrl(self) -> int:
        return self.ctrl.shape[0]

    @property
    def start(self) -> float:
        return float(self.warp[0])

    @property
    def end(self) -> float:
        return float(self.warp[-1])

    @property
    def duration(self) -> float:
        return self.end - self.start

    @staticmethod
    def uniform_warp(t0: float, t1: float, n_warp: int = 6) -> np.ndarray:
        """Control points of the identity-like warp T(s) = t0 + s (t1 − t0)."""
        # Greville abscissae make a clamped spline reproduce linear functions exactly.
        knots = np.array(clamped_knots(n_warp))
        greville = np.array([knots[i + 1:i + 1 + DEGREE].mean() for i in range(n_warp)])
        return t0 + greville * (t1 - t0)

    def canonical(self, s, deriv: int = 0) -> np.ndarray:
        """q^(deriv)(s) in canonical time: (len(s), n_dof)."""
        return basis(self.n_ctrl, s, deriv) @ self.ctrl

    def time(self, s, deriv: int = 0) -> np.ndarray:
        """T^(deriv)(s)."""
        return basis(len(self.warp), s, deriv) @ self.warp

    def to_canonical(self, t) -> np.ndarray:
        """Invert the warp: s with T(s) = t (bisection; T is strictly increasing)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), self.start, self.end)
        lo, hi = np.zeros_like(t), np.ones_like(t)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = self.time(mid) < t
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    def state_at_s(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈) in world time at canonical times s (chain rule through the warp)."""
        q, q1, q2 = (self.canonical(s, d) for d in (0, 1, 2))
        T1, T2 = (self.time(s, d)[:, None] for d in (1, 2))
        return q, q1 / T1, q2 / T1**2 - q1 * T2 / T1**3

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, q̈) at world times t."""
        return self.state_at_s(self.to_canonical(t))

    def sample(self, fps: float) -> tuple[np.ndarray, np.ndarray]:
        """(times, q) at uniform world-time frames from start to end inclusive."""
        n = int(np.floor(self.duration * fps + 1e-9)) + 1
        times = self.start + np.arange(n) / fps
        return times, self.canonical(self.to_canonical(times))

    def with_(self, **changes) -> "Motion":
        return replace(self, **changes)

    @classmethod
    def from_samples(cls, times: np.ndarray, q: np.ndarray, n_ctrl: int, n_warp: int = 6) -> "Motion":
        """Fit a motion to frames (times (T,), q (T, n_dof)) with a uniform warp."""
        times = np.asarray(times, dtype=float)
        s = (times - times[0]) / (times[-1] - times[0])
        return cls(fit_spline(s, q, n_ctrl), cls.uniform_warp(times[0], times[-1], n_warp))
