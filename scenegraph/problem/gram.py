"""The Gauss–Newton term of the dynamics residuals, assembled point by point.

The dynamics residuals of the transcription are ``rho = vec(D ⊙ Q(Z))``: the compiled per-point
kernel Q (35 residuals, N·m and N, :func:`~scenegraph.model.residual.compiled_kernel`) at each
evaluation point k of z_k = (q, q̇, q̈, forces) (129 values: rad or m, per world second, per
world second², N), weighted by D (35 × N_e; quadrature weights, √α, √w_root and the body-weight
scale — constants and parameters, never decision variables when the timewarp is held).  By the
chain rule its Jacobian is ``J = diag(vec D) blockdiag(G_k) J_z`` with G_k = ∂Q/∂z at point k (the
compiled kernel Jacobian) and J_z = ∂vec(Z)/∂x (B-spline bases, the friction pyramids, the
shoe and spring forces), so

    Jᵀ J = J_zᵀ blockdiag(G_kᵀ diag(D_k²) G_k) J_z.

This is the same matrix the transcription formed as ``mtimes(J.T, J)`` of CasADi's MX Jacobian
of rho (checked to round-off by tests/problem/test_gram.py), computed without that Jacobian: on
``broad_jump`` (2953 variables, 201 evaluation points) CasADi's AD Jacobian of rho alone took
0.74 s per evaluation and its JᵀJ 1.08 s, 69 % of the solve's CPU (docs/results.md, round 12).
With a free timewarp D depends on x (the warp's slope); the transcription then keeps its AD path.
"""
from __future__ import annotations

import functools

import casadi as ca

from scenegraph.model.body import N_DOF, Character
from scenegraph.model.residual import FORCE_HANDLES, N_THETA, compiled_kernel

__all__ = ["NZ", "gram_fn", "dynamics_gauss_newton"]

NZ = 3 * N_DOF + 3 * len(FORCE_HANDLES)  # z = (q, q̇, q̈, forces): 129


@functools.lru_cache(maxsize=8)
def gram_fn(ch: Character) -> ca.Function:
    """(z (129), θ (N_THETA), d (35)) → G ᵀ diag(d²) G (129 × 129), G = ∂Q/∂z of the compiled kernel."""
    kern = compiled_kernel(ch)
    z, th, d = ca.MX.sym("z", NZ), ca.MX.sym("theta", N_THETA), ca.MX.sym("d", N_DOF)
    q, qd, qdd, f = z[:N_DOF], z[N_DOF:2 * N_DOF], z[2 * N_DOF:3 * N_DOF], z[3 * N_DOF:]
    G = ca.jacobian(kern(q, qd, qdd, f, th), z)
    dG = ca.mtimes(ca.diag(d), G)
    return ca.Function("gram", [z, th, d], [ca.mtimes(dG.T, dG)], ["z", "theta", "d"], ["gram"])


def dynamics_gauss_newton(ch: Character, Z: ca.MX, TH: ca.MX, D: ca.MX, x: ca.MX) -> ca.MX:
    """Jᵀ J (nx × nx) of ``rho = vec(D ⊙ Q(Z, TH))`` with respect to ``x``: ``Z`` (129, N_e) the
    kernel's inputs per evaluation point (MX of x and parameters), ``TH`` (N_THETA, N_e) its θ,
    ``D`` (35, N_e) the weights (must not depend on ``x``: the module docstring)."""
    ne = Z.shape[1]
    Hk = gram_fn(ch).map(ne)(Z, TH, D)  # (129, 129 N_e)
    Hzz = ca.diagcat(*ca.horzsplit(Hk, NZ)) if ne > 1 else Hk
    Jz = ca.jacobian(ca.vec(Z), x)
    return ca.mtimes(Jz.T, ca.mtimes(Hzz, Jz))
