"""The energy NIO compares motions by: E(X; θ) of the spacetime solver with λ profiled out.

    E(X; θ) = (OBJ_SCALE / m g)² Σ_k w_k T'_k [ Σ_j α_j Q_mj(s_k)² + w_r Σ_i Q_0i(s_k)² ]
              + (OBJ_SCALE · LAM_REG)² |λ|²

on the collocation grid of the NIO problem's NLP (s_k: canonical time, w_k: trapezoid
weights, T'_k: the target's timewarp slope, which is fixed because NIO frees q only).  For a
fixed q the contact coefficients λ ≥ 0 minimising it are found point by point by
non-negative least squares (the residuals are affine in the contact forces), so E is exactly
the objective the spacetime solver minimises, with λ profiled out.  Forces F are (24, N):
3 world-frame components (N) per force handle and collocation point.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np
from scipy.optimize import nnls

from scenegraph.model.body import G, N_DOF, N_JOINT, N_ROOT, Character
from scenegraph.model.dynamics import friction_basis
from scenegraph.model.motion import Motion
from scenegraph.problem import NLP, OBJ_SCALE
from scenegraph.model.residual import FORCE_HANDLES, W_ROOT, residual_kernel
from scenegraph.nio.theta import ALPHA, KERNEL, N_THETA_FULL

__all__ = ["EnergyModel", "LAM_REG", "force_jacobian"]

LAM_REG = 1e-3  # the solver's λ regularisation (kept for a well-posed contact split)


@functools.lru_cache(maxsize=4)
def force_jacobian(ch: Character) -> ca.Function:
    """(q, qd, qdd, f, θ_kernel) -> (Q, ∂Q/∂f): the residual kernel and its force Jacobian."""
    k = residual_kernel(ch)
    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    f = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("th", k.size1_in(4))
    Q = k(q, qd, qdd, f, th)
    return ca.Function("dQdf", [q, qd, qdd, f, th], [Q, ca.jacobian(Q, f)])


class EnergyModel:
    """E(X; θ), its θ-gradient and the energy-optimal contact forces of a motion, on the
    collocation grid of ``nlp`` (a transcription of a q-only subproblem of ``target``).

    Attributes: ``N`` collocation points, ``mg`` body weight (N), ``wT`` = w_k T'_k (s),
    ``c`` the per-point energy weights, ``planted[k]``: (force handle index, λ slice into x)
    of the planted contacts at point k, ``V`` the friction pyramid (3×4)."""

    def __init__(self, ch: Character, nlp: NLP, target: Motion):
        self.ch, self.nlp = ch, nlp
        s = nlp.s_points
        self.N = N = len(s)
        wq = np.zeros(N)
        wq[1:] += np.diff(s) / 2
        wq[:-1] += np.diff(s) / 2
        self.mg = ch.total_mass * G
        T1 = target.time(s, 1)  # warp is fixed (free = q): the same for every counterexample
        self.wT = wq * T1
        self.c = self.wT * (OBJ_SCALE / self.mg) ** 2
        self.planted: list[list[tuple[int, slice]]] = [[] for _ in range(N)]
        for h, k, sl in nlp.contact_index:
            self.planted[k].append((FORCE_HANDLES.index(h), sl))
        self.V = friction_basis()
        self._energy_fn = self._make_energy_fn()

    def _make_energy_fn(self) -> ca.Function:
        N = self.N
        th = ca.MX.sym("theta", N_THETA_FULL)
        q, qd, qdd = (ca.MX.sym(n, N_DOF, N) for n in ("q", "qd", "qdd"))
        F = ca.MX.sym("F", 3 * len(FORCE_HANDLES), N)
        alpha = th[ALPHA.start:ALPHA.stop]
        thk = th[KERNEL.start:KERNEL.stop]
        QQ = residual_kernel(self.ch).map(N)(q, qd, qdd, F, ca.repmat(thk, 1, N))
        per = ca.mtimes(alpha.T, QQ[:N_JOINT, :] ** 2) + W_ROOT * ca.sum1(QQ[N_JOINT:, :] ** 2)
        E = ca.mtimes(per, ca.DM(self.c))
        return ca.Function("nio_E", [th, q, qd, qdd, F], [E, ca.gradient(E, th)])

    def states(self, motion: Motion):
        """(q, q̇, q̈), each (35, N), of ``motion`` at the collocation points."""
        q, qd, qdd = motion.state_at_s(self.nlp.s_points)
        return q.T, qd.T, qdd.T

    def forces(self, motion: Motion, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact forces (24, N) minimising E for the fixed q of ``motion`` (NNLS per point),
        and λ in the solver's layout (the NLP's ``x_layout["lambda"]`` block)."""
        q, qd, qdd = self.states(motion)
        fn = force_jacobian(self.ch).map(self.N)
        nf = 3 * len(FORCE_HANDLES)
        thk = np.tile(theta[KERNEL, None], (1, self.N))
        Q0, J = fn(q, qd, qdd, np.zeros((nf, self.N)), thk)
        Q0, J = np.asarray(Q0), np.asarray(J)  # J: (35, 24 N)
        wsq = np.sqrt(np.r_[np.maximum(theta[ALPHA], 0.0), np.full(N_ROOT, W_ROOT)])
        F = np.zeros((nf, self.N))
        lam_slice = self.nlp.x_layout["lambda"]
        lam = np.zeros(lam_slice.stop - lam_slice.start)
        off = lam_slice.start
        for k, pl in enumerate(self.planted):
            if not pl:
                continue
            Jk = J[:, k * nf:(k + 1) * nf]
            A = np.hstack([Jk[:, 3 * i:3 * i + 3] @ (self.mg * self.V) for i, _ in pl])
            reg = LAM_REG * self.mg / np.sqrt(max(self.wT[k], 1e-12))
            AA = np.vstack([wsq[:, None] * A, reg * np.eye(A.shape[1])])
            bb = np.r_[-wsq * Q0[:, k], np.zeros(A.shape[1])]
            x, _ = nnls(AA, bb, maxiter=50 * A.shape[1])
            for c, (i, sl) in enumerate(pl):
                lk = x[4 * c:4 * c + 4]
                F[3 * i:3 * i + 3, k] += self.mg * self.V @ lk
                lam[sl.start - off:sl.stop - off] = lk
        return F, lam

    def energy(self, theta: np.ndarray, motion: Motion, F: np.ndarray,
               lam: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """E(X; θ) for motion q and forces F, and ∂E/∂θ.  With ``lam`` (the contact
        coefficients of F) the solver's λ regularisation (OBJ_SCALE·LAM_REG)² |λ|² is added:
        that is the objective the spacetime solver minimises, so X_T is a minimum of this
        measure under θ* (without it, E(X_T; θ*) is not minimal and G(θ*) > 0)."""
        E, g = self._energy_fn(theta, *self.states(motion), F)
        E = float(E)
        if lam is not None:
            E += float((OBJ_SCALE * LAM_REG) ** 2 * np.sum(np.asarray(lam) ** 2))
        return E, np.asarray(g).ravel()

    def measure(self, theta: np.ndarray, motion: Motion):
        """(E, ∂E/∂θ, F, λ) of ``motion`` under θ with its energy-optimal contact forces."""
        F, lam = self.forces(motion, theta)
        E, g = self.energy(theta, motion, F, lam)
        return E, g, F, lam
