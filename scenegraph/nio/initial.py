"""The paper's initial θ (§6.1): α = 1/M, q̄ = the mean pose of X_T, springs by Eq. 22."""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from scenegraph.model.body import N_JOINT, N_ROOT
from scenegraph.model.motion import Motion
from scenegraph.model.residual import residual_kernel
from scenegraph.model.style import THETA_LAYOUT, Style, default_style
from scenegraph.nio.energy import EnergyModel
from scenegraph.nio.theta import ALPHA, KERNEL, Q_REST, SPRINGS, project

__all__ = ["initial_theta", "fit_springs"]

SPRING_PARTS = ("ks1", "ks2", "kd")  # the passive generalized force is linear in each


def initial_theta(model: EnergyModel, target: Motion, base: Style | None = None, rest_from_target: bool = True,
                  springs_from_target: bool = True) -> np.ndarray:
    """α = 1/M, q̄ = the time-weighted mean pose of ``target`` (rad), springs by Eq. 22
    (least squares of the inferred muscle forces, stiffnesses ≥ 0); shoe from ``base``
    (default: the default style of the character's mass)."""
    base = base or default_style(model.ch.total_mass)
    th = base.vector().copy()
    th[ALPHA] = 1.0 / N_JOINT
    q, qd, _ = model.states(target)
    if rest_from_target:
        th[Q_REST] = np.clip(q[N_ROOT:, :] @ (model.wT / model.wT.sum()), -np.pi, np.pi)
    if springs_from_target:
        th = fit_springs(model, target, th)
    return project(th)


def fit_springs(model: EnergyModel, target: Motion, th: np.ndarray) -> np.ndarray:
    """Eq. 22: per joint DOF, min Σ_t Q_mj² over (ks1, ks2, kd) ≥ 0.  Q_mj is affine in its
    own DOF's spring and damper (generalized passive forces act on their DOF only), so
    each DOF is a 3-unknown NNLS; contact forces are re-inferred once with the springs."""
    M = N_JOINT
    N = model.N
    kernel = residual_kernel(model.ch).map(N)
    q, qd, qdd = model.states(target)
    for _ in range(2):
        F, _ = model.forces(target, th)
        th0 = th.copy()
        th0[SPRINGS] = 0.0
        Q0 = np.asarray(kernel(q, qd, qdd, F, np.tile(th0[KERNEL, None], (1, N))))
        # passive generalized force is linear in (ks1, ks2, kd): get its columns by probing
        cols = []
        for part in SPRING_PARTS:
            thp = th0.copy()
            thp[THETA_LAYOUT[part]] = 1.0
            Qp = np.asarray(kernel(q, qd, qdd, F, np.tile(thp[KERNEL, None], (1, N))))
            cols.append(Qp[:M] - Q0[:M])
        w = np.sqrt(model.wT)
        for j in range(M):
            A = np.stack([c[j] * w for c in cols], axis=1)
            b = -Q0[j] * w
            # a small ridge keeps unobservable springs near zero
            ridge = 1e-3 * np.linalg.norm(A) + 1e-9
            x, _ = nnls(np.vstack([A, ridge * np.eye(3)]), np.r_[b, np.zeros(3)])
            for part, xk in zip(SPRING_PARTS, x):
                th[THETA_LAYOUT[part].start + j] = xk
    return th
