"""Priors and tying for NIO (issue #18): a log-normal prior on α instead of the α floor, and
left/right symmetry or one α per joint group as equalities on θ.

Why: learned from one stride, NIO drives the α of the joints that move most (hip and knee
flexion, waist, shoulder flexion) to 0 — "that joint costs nothing" makes X_T optimal for
one motion and predicts nothing about another (both `walk` from 07_01 and the style learned
from 16_18's straight part have α = 0 at hip_flex and waist_flex).

- :func:`log_alpha_prior`: P(θ) = w · scale · mean_j ln(α_j / α_ref,j)²  with α_ref of
  :func:`alpha_reference` (default 1/M, the paper's initial α), ``scale`` the NIO objective at θ0 so that w is
  unitless (w = 1: every α an e-fold off costs as much as the initial G).  Its gradient is
  exact; the bundle method adds its linearisation to the LP and accepts a step on the true
  G + D + P.
- :func:`tie_pairs`: index pairs (i, j) of θ held equal (the LP adds δ_i = δ_j, and
  :func:`tie_average` makes θ0 satisfy them): "lr" ties α, ks1, ks2 and kd of each left/right
  DOF pair (q_rest stays per side: the sign conventions of the lateral DOFs differ between
  sides); "groups" also ties α within each joint group of :data:`ALPHA_GROUPS`; "coarse" ties α
  *and* the springs (ks1, ks2, kd) within each group (147 → 59 free numbers: 7 α, 21 springs,
  29 rest angles, the shoe's 2).  Ties within a group hold ratios given by :func:`tie_scales`
  (θ_i / w_i = θ_j / w_j), left/right ties are equalities.
- :func:`alpha_reference`: the prior's centre α_ref — "uniform" (1/M, the paper's initial α) or
  "strength" (α_ref,j ∝ 1/τ_j², τ_j a reference joint strength: Σ_j α_j τ_j² then measures
  effort as Σ (τ_j / τ_ref,j)², the normalised-effort form of the motor-control literature,
  under which a weak joint's torque costs more than the same torque at a strong one).
- :func:`spring_prior`: a quadratic prior on ks1, ks2, kd around their Eq. 22 values (the
  paper's initial fit), each in units of its typical size (:func:`.theta.theta_scales`).
- :class:`Prior`: both together, P(θ) and ∇P, as the bundle method uses them.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT
from scenegraph.model.style import THETA_LAYOUT

__all__ = ["log_alpha_prior", "spring_prior", "alpha_reference", "Prior", "tie_pairs", "tie_average", "n_free",
           "tie_scales",
           "ALPHA_GROUPS", "TIE_MODES", "ALPHA_REFS", "ALPHA_MIN", "STRENGTH_NM"]

TIE_MODES = ("none", "lr", "groups", "coarse")
ALPHA_REFS = ("uniform", "strength")
# Reference joint strengths (N·m) of an adult man, by DOF name prefix: peak isometric joint
# torques rounded to one significant figure, the order of magnitude of the ranges the
# biomechanics literature reports (trunk and hip 100-300, knee and ankle 100-250, shoulder and
# elbow 50-100, neck ~30, wrist ~15, toes ~20 N·m).  Only their ratios matter (Σα = 1): they set
# how much a newton-metre at one joint costs relative to another.  Not fitted to any clip.
STRENGTH_NM = (
    ("waist_flex", 200.0), ("waist_lat", 200.0), ("waist_twist", 100.0), ("chest_flex", 200.0), ("neck_", 30.0),
    ("shoulder_flex", 80.0), ("shoulder_twist", 50.0), ("shoulder_abd", 70.0), ("elbow_", 70.0), ("wrist_", 15.0),
    ("hip_flex", 200.0), ("hip_abd", 150.0), ("hip_rot", 80.0), ("knee_", 200.0), ("ankle_flex", 200.0),
    ("ankle_inv", 40.0), ("toe_", 20.0),
)
ALPHA_MIN = 1e-4 / N_JOINT  # the log's domain: α below this is clipped (a guard, not a floor that binds)
ALPHA_GROUPS = (  # one α per group with tie mode "groups" (name prefixes of JOINT_DOF_NAMES)
    ("waist_", "chest_"), ("neck_",), ("shoulder_",), ("elbow_", "wrist_"), ("hip_",), ("knee_",),
    ("ankle_", "toe_"),
)


def alpha_reference(kind: str = "uniform") -> np.ndarray:
    """The prior's centre α_ref (29, Σ = 1): "uniform" 1/M; "strength" ∝ 1/τ_j² with τ_j of
    :data:`STRENGTH_NM` (module docstring)."""
    if kind == "uniform":
        return np.full(N_JOINT, 1.0 / N_JOINT)
    if kind != "strength":
        raise ValueError(f"unknown alpha reference {kind!r} (one of {', '.join(ALPHA_REFS)})")
    tau = np.array([next(v for pre, v in STRENGTH_NM if d.startswith(pre)) for d in JOINT_DOF_NAMES])
    a = 1.0 / tau ** 2
    return a / a.sum()


def log_alpha_prior(theta: np.ndarray, weight: float, scale: float,
                    ref: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """P(θ) = w · scale · mean_j ln(α_j / α_ref,j)² and ∇P (α_ref default 1/M); zero for weight 0."""
    g = np.zeros(len(theta))
    if weight <= 0:
        return 0.0, g
    sl = THETA_LAYOUT["alpha"]
    a = np.maximum(np.asarray(theta, float)[sl], ALPHA_MIN)
    r = np.full(N_JOINT, 1.0 / N_JOINT) if ref is None else np.asarray(ref, float)
    la = np.log(a / r)
    c = weight * scale / N_JOINT
    g[sl] = c * 2.0 * la / a
    return float(c * np.sum(la ** 2)), g


SPRING_FIELDS = ("ks1", "ks2", "kd")


def spring_prior(theta: np.ndarray, weight: float, scale: float, ref: np.ndarray,
                 typical: np.ndarray) -> tuple[float, np.ndarray]:
    """P(θ) = w · scale · mean over the spring components of ((k − k_ref) / s)² and ∇P; ``ref``
    and ``typical`` are full θ vectors (k_ref: the Eq. 22 springs; s: typical sizes, N·m/rad
    or N·m·s/rad).  Zero for weight 0."""
    g = np.zeros(len(theta))
    if weight <= 0:
        return 0.0, g
    idx = np.r_[tuple(np.arange(THETA_LAYOUT[f].start, THETA_LAYOUT[f].stop) for f in SPRING_FIELDS)]
    th = np.asarray(theta, float)
    s = np.asarray(typical, float)[idx]
    z = (th[idx] - np.asarray(ref, float)[idx]) / s
    c = weight * scale / idx.size
    g[idx] = c * 2.0 * z / s
    return float(c * np.sum(z ** 2)), g


class Prior:
    """P(θ) = log-normal prior on α (weight ``alpha_weight``, centre ``alpha_ref``) + quadratic
    prior on the springs (weight ``spring_weight``, centre the springs of ``spring_ref``, sizes
    ``typical``), both in units of ``scale`` (the NIO objective at θ0), so the weights are
    unitless.  Calling it returns (P, ∇P)."""

    def __init__(self, scale: float, alpha_weight: float = 0.0, alpha_ref: np.ndarray | None = None,
                 spring_weight: float = 0.0, spring_ref: np.ndarray | None = None, typical: np.ndarray | None = None):
        if spring_weight > 0 and (spring_ref is None or typical is None):
            raise ValueError("a spring prior needs its reference θ and typical sizes")
        self.scale, self.alpha_weight, self.alpha_ref = float(scale), float(alpha_weight), alpha_ref
        self.spring_weight, self.spring_ref, self.typical = float(spring_weight), spring_ref, typical

    @property
    def active(self) -> bool:
        return self.alpha_weight > 0 or self.spring_weight > 0

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        P, g = log_alpha_prior(theta, self.alpha_weight, self.scale, self.alpha_ref)
        if self.spring_weight > 0:
            P2, g2 = spring_prior(theta, self.spring_weight, self.scale, self.spring_ref, self.typical)
            P, g = P + P2, g + g2
        return P, g


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
    if mode in ("groups", "coarse"):
        for f in ("alpha",) + (SPRING_FIELDS if mode == "coarse" else ()):
            s = THETA_LAYOUT[f].start
            for pre in ALPHA_GROUPS:
                idx = [j for j, d in enumerate(JOINT_DOF_NAMES) if d.startswith(pre)]
                pairs += [(s + idx[0], s + k) for k in idx[1:]]
    return pairs


def tie_average(theta: np.ndarray, pairs: list[tuple[int, int]], w: np.ndarray | None = None) -> np.ndarray:
    """θ with every connected set of tied components replaced by its mean (so θ satisfies
    the ties and keeps each set's total).  With tie scales ``w`` (:func:`tie_scales`) a tie holds
    θ_i / w_i = θ_j / w_j, and each set gets the mean of θ / w times w."""
    th = np.asarray(theta, float).copy()
    w = np.ones(len(th)) if w is None else np.asarray(w, float)
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
        th[idx] = (th[idx] / w[idx]).mean() * w[idx]
    return th


def tie_scales(theta0: np.ndarray, alpha_ref: np.ndarray | None = None,
               typical: np.ndarray | None = None) -> np.ndarray:
    """Scales w of the ties (θ_i / w_i = θ_j / w_j): α by α_ref (tied α keep the reference's
    ratios: "one α per group" is one factor on the group's strength-based reference), the
    springs by the left/right mean of θ0's springs (the Eq. 22 fit) plus 1 % of their typical
    size (a spring the fit put at 0 can still move); everything else 1.  For left/right ties
    both sides have the same scale, so those ties are plain equalities."""
    th0 = np.asarray(theta0, float)
    w = np.ones(len(th0))
    if alpha_ref is not None:
        w[THETA_LAYOUT["alpha"]] = np.asarray(alpha_ref, float) * N_JOINT
    if typical is not None:
        lr = tie_pairs("lr")
        sym, typ = tie_average(th0, lr), tie_average(np.asarray(typical, float), lr)
        for f in SPRING_FIELDS:
            sl = THETA_LAYOUT[f]
            w[sl] = np.abs(sym[sl]) + 0.01 * typ[sl]
    return w


def n_free(pairs: list[tuple[int, int]], n: int) -> int:
    """The number of free θ components left by the ties (connected sets count once)."""
    probe = tie_average(np.arange(n, dtype=float), pairs)
    return len(np.unique(probe))
