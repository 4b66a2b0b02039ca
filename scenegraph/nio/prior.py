"""Priors and tying for NIO (issue #18): a log-normal prior on α instead of the α floor, and
left/right symmetry or one α per joint group as equalities on θ.

Why: learned from one stride, NIO drives the α of the joints that move most (hip and knee
flexion, waist, shoulder flexion) to 0 — "that joint costs nothing" makes X_T optimal for
one motion and predicts nothing about another (both `walk` from 07_01 and the style learned
from 16_18's straight part have α = 0 at hip_flex and waist_flex).

- :func:`log_alpha_prior`: P(θ) = w · scale · mean_j ln(α_j / α_ref)²  with α_ref = 1/M (the
  paper's initial α; the default style's), ``scale`` the NIO objective at θ0 so that w is
  unitless (w = 1: every α an e-fold off costs as much as the initial G).  Its gradient is
  exact; the bundle method adds its linearisation to the LP and accepts a step on the true
  G + D + P.
- :func:`tie_pairs`: index pairs (i, j) of θ held equal (the LP adds δ_i = δ_j, and
  :func:`tie_average` makes θ0 satisfy them): "lr" ties α, ks1, ks2 and kd of each left/right
  DOF pair (q_rest stays per side: the sign conventions of the lateral DOFs differ between
  sides); "groups" also ties α within each joint group of :data:`ALPHA_GROUPS`.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT
from scenegraph.model.style import THETA_LAYOUT

__all__ = ["log_alpha_prior", "tie_pairs", "tie_average", "ALPHA_GROUPS", "TIE_MODES", "ALPHA_MIN"]

TIE_MODES = ("none", "lr", "groups")
ALPHA_MIN = 1e-4 / N_JOINT  # the log's domain: α below this is clipped (a guard, not a floor that binds)
ALPHA_GROUPS = (  # one α per group with tie mode "groups" (name prefixes of JOINT_DOF_NAMES)
    ("waist_", "chest_"), ("neck_",), ("shoulder_",), ("elbow_", "wrist_"), ("hip_",), ("knee_",),
    ("ankle_", "toe_"),
)


def log_alpha_prior(theta: np.ndarray, weight: float, scale: float) -> tuple[float, np.ndarray]:
    """P(θ) and ∇P (see the module docstring); zero for weight 0."""
    g = np.zeros(len(theta))
    if weight <= 0:
        return 0.0, g
    sl = THETA_LAYOUT["alpha"]
    a = np.maximum(np.asarray(theta, float)[sl], ALPHA_MIN)
    la = np.log(a * N_JOINT)
    c = weight * scale / N_JOINT
    g[sl] = c * 2.0 * la / a
    return float(c * np.sum(la ** 2)), g


def _dof(name: str) -> int:
    return JOINT_DOF_NAMES.index(name)


def tie_pairs(mode: str) -> list[tuple[int, int]]:
    """θ index pairs held equal under ``mode`` (one of :data:`TIE_MODES`)."""
    if mode not in TIE_MODES:
        raise ValueError(f"unknown tie mode {mode!r} (one of {', '.join(TIE_MODES)})")
    if mode == "none":
        return []
    pairs = []
    fields = ("alpha", "ks1", "ks2", "kd")
    for j, d in enumerate(JOINT_DOF_NAMES):
        if d.endswith("_l") and d[:-2] + "_r" in JOINT_DOF_NAMES:
            r = _dof(d[:-2] + "_r")
            for f in fields:
                s = THETA_LAYOUT[f].start
                pairs.append((s + j, s + r))
    if mode == "groups":
        s = THETA_LAYOUT["alpha"].start
        for pre in ALPHA_GROUPS:
            idx = [j for j, d in enumerate(JOINT_DOF_NAMES) if d.startswith(pre)]
            pairs += [(s + idx[0], s + k) for k in idx[1:]]
    return pairs


def tie_average(theta: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    """θ with every connected set of tied components replaced by its mean (so θ satisfies
    the ties and keeps each set's total)."""
    th = np.asarray(theta, float).copy()
    parent = list(range(len(th)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in pairs:
        parent[root(i)] = root(j)
    sets: dict[int, list[int]] = {}
    for i in {k for p in pairs for k in p}:
        sets.setdefault(root(i), []).append(i)
    for idx in sets.values():
        th[idx] = th[idx].mean()
    return th


def n_free(pairs: list[tuple[int, int]], n: int) -> int:
    """The number of free θ components left by the ties (connected sets count once)."""
    probe = tie_average(np.arange(n, dtype=float), pairs)
    return len(np.unique(probe))
