"""The style vector θ as NIO sees it: bounds, projection, the penalty D (Eq. 18), scales.

θ is :meth:`Style.vector` (147 numbers); its parts are read by name through
:data:`scenegraph.model.style.THETA_LAYOUT` (α, the springs ks1/ks2/kd, q_rest, k_shoe, h_rest).
Units are those of :class:`Style`: α dimensionless, stiffnesses N·m/rad, damping N·m·s/rad,
rest angles rad, shoe stiffness N/m, shoe rest length m.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import N_JOINT
from scenegraph.model.style import N_THETA_FULL, THETA_LAYOUT, Provenance, Style, default_style

__all__ = ["D_WEIGHT", "N_THETA_FULL", "theta_bounds", "project", "style_from_theta", "d_penalty", "theta_scales"]

D_WEIGHT = 1.0e4  # paper: w in Eq. 18
ALPHA = THETA_LAYOUT["alpha"]
SPRINGS = THETA_LAYOUT["springs"]  # ks1, ks2, kd
Q_REST = THETA_LAYOUT["q_rest"]
K_SHOE = THETA_LAYOUT["k_shoe"]
H_REST = THETA_LAYOUT["h_rest"]
KERNEL = THETA_LAYOUT["kernel"]  # everything after α: the residual kernel's θ
# bounds of a Style (its validators), α excluded: it is held by the soft penalty D instead
SPRING_MAX, K_SHOE_MAX, H_REST_MAX = 1e5, 1e7, 0.1


def theta_bounds(alpha_floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) bounds of every θ component; α ≥ ``alpha_floor`` with no upper bound."""
    lo = np.full(N_THETA_FULL, -np.inf)
    hi = np.full(N_THETA_FULL, np.inf)
    lo[ALPHA] = alpha_floor
    lo[SPRINGS], hi[SPRINGS] = 0.0, SPRING_MAX
    lo[Q_REST], hi[Q_REST] = -np.pi, np.pi
    lo[K_SHOE], hi[K_SHOE] = 0.0, K_SHOE_MAX
    lo[H_REST], hi[H_REST] = 0.0, H_REST_MAX
    return lo, hi


def project(th: np.ndarray) -> np.ndarray:
    """θ clipped to the bounds of a Style except α (α is held by the soft constraints D)."""
    th = th.copy()
    th[SPRINGS] = np.clip(th[SPRINGS], 0.0, SPRING_MAX)
    th[Q_REST] = np.clip(th[Q_REST], -np.pi, np.pi)
    th[K_SHOE] = np.clip(th[K_SHOE], 0.0, K_SHOE_MAX)
    th[H_REST] = np.clip(th[H_REST], 0.0, H_REST_MAX)
    return th


def style_from_theta(th: np.ndarray, name: str = "learned", provenance: Provenance | None = None) -> Style:
    """A valid Style from θ: α clipped at 0 and normalised, everything else projected."""
    th = project(np.asarray(th, float))
    a = np.maximum(th[ALPHA], 0.0)
    a = a / a.sum() if a.sum() > 0 else np.full(N_JOINT, 1.0 / N_JOINT)
    th[ALPHA] = a
    return Style.from_vector(th, name=name, provenance=provenance)


def d_penalty(th: np.ndarray) -> tuple[float, np.ndarray]:
    """D(θ) (Eq. 18) and its gradient: D_WEIGHT (Σα − 1)² + D_WEIGHT Σ min(α, 0)²."""
    a = th[ALPHA]
    s = a.sum() - 1.0
    neg = np.minimum(a, 0.0)
    g = np.zeros_like(th)
    g[ALPHA] = D_WEIGHT * (2 * s + 2 * neg)
    return float(D_WEIGHT * (s ** 2 + np.sum(neg ** 2))), g


def theta_scales(style: Style) -> np.ndarray:
    """Typical magnitude of every θ component (the optimisers' diagonal preconditioner and
    trust-box shape), in θ's units."""
    ref = default_style()
    ks = np.maximum(np.maximum(ref.ks1, np.asarray(style.ks1)), 1.0)
    return np.concatenate([np.full(N_JOINT, 1.0 / N_JOINT), ks, ks, 0.1 * ks, np.full(N_JOINT, 0.1),
                           [max(ref.k_shoe, style.k_shoe)], [0.005]])
