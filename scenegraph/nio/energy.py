"""The energy NIO compares motions by: the spacetime solver's objective, with λ profiled out.

E(X; θ) is the objective ``NLP.f`` of the NIO problem's own transcription (a q-only
subproblem of the target, :mod:`scenegraph.problem.transcription`) evaluated at x = (control
points of X, contact coefficients λ) and p = (θ at every point, the fixed data): not a
re-implementation of it, so the energy NIO learns with and the one the synthesis minimises
cannot drift apart.  With the dense dynamics that is

    E = |ρ_dyn|² + |ρ_extra|²,   ρ_dyn = (OBJ_SCALE / m g) √(w_e T'_e) [√α_j Q_mj(s_e); √w_r Q_0i(s_e)]

over the evaluation points s_e (nodes and interval midpoints, Simpson weights w_e; forces
piecewise linear between nodes, the shoe gated), ρ_extra = OBJ_SCALE · 10⁻³ λ (the solver's
λ regularisation) and any other least-squares term of the subproblem.  (The round-10 energy
re-implemented the trapezoid sum at the nodes with the ungated shoe: it overstated E(X_T) by
21.5 % and G by 19 % on 07_01, measured.)

For a fixed q the residuals are affine in λ, so the λ ≥ 0 minimising E (with the solver's
λ = 0 at touch-downs and lift-offs) solve one bound-constrained linear least-squares problem
(:func:`nonneg_lsq`).  Because the per-point style is constant, E is linear in α:
E = Σ_j α_j A_j + R with A_j the squared joint-j residuals at √α = 1, which gives ∂E/∂α
exactly, also at α_j = 0; ∂E/∂θ of the other parts is CasADi's gradient of ``NLP.f``
with respect to p, summed over the points.  Energies are dimensionless (body-weight units
squared times s); forces F are (24, N): 3 world-frame components (N) per force handle at
each node.
"""
from __future__ import annotations

from collections import OrderedDict

import casadi as ca
import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla
from scipy.optimize import nnls

from scenegraph.model.body import G, N_DOF, N_JOINT, Character
from scenegraph.model.motion import Motion
from scenegraph.model.residual import FORCE_HANDLES
from scenegraph.problem import NLP
from scenegraph.nio.theta import ALPHA, KERNEL

__all__ = ["EnergyModel", "nlp_params", "nonneg_lsq"]


def nlp_params(nlp: NLP, theta: np.ndarray, motion: Motion | None = None, unit_alpha: bool = False) -> np.ndarray:
    """The NLP's parameters with style θ (147) at every point (``unit_alpha``: √α = 1
    instead) and, given ``motion``, its timewarp as the fixed warp."""
    N = len(nlp.s_points)
    p = nlp.p0.copy()
    p[nlp.p_layout["theta"]] = np.tile(theta[KERNEL, None], (1, N)).ravel(order="F")
    sa = np.ones(N_JOINT) if unit_alpha else np.sqrt(np.maximum(theta[ALPHA], 0.0))
    p[nlp.p_layout["sqrt_alpha"]] = np.tile(sa[:, None], (1, N)).ravel(order="F")
    if motion is not None:
        w = np.asarray(motion.warp, float)
        sl = nlp.p_layout["warp_fixed"]
        if w.size != sl.stop - sl.start:
            raise ValueError(f"motion has {w.size} timewarp points, the NIO problem {sl.stop - sl.start}")
        p[sl] = w
    return p


def nonneg_lsq(A: sps.spmatrix, b: np.ndarray, x0: np.ndarray | None = None, max_iter: int = 40,
               tol: float = 1e-12) -> tuple[np.ndarray, int]:
    """x ≥ 0 minimising |A x + b|² (A sparse with full column rank), and the iterations used.

    Primal–dual active set (Hintermüller, Ito & Kunisch 2002) on the normal equations, started
    from the active set of ``x0`` (zeros of a previous solution) or from the unconstrained
    solution; it stops when the set repeats, which is the KKT point.  If it cycles or runs
    out of iterations, the exact Lawson–Hanson NNLS on the Cholesky factor is used (returned
    iterations −1)."""
    H = (A.T @ A).tocsc()
    g = np.asarray(A.T @ b).ravel()
    n = g.size
    if n == 0:
        return np.zeros(0), 0
    sc = tol * max(1.0, float(np.abs(g).max()))
    active = np.zeros(n, bool) if x0 is None else np.asarray(x0) <= 0.0
    seen = set()
    for it in range(1, max_iter + 1):
        free = np.flatnonzero(~active)
        x = np.zeros(n)
        if free.size:
            x[free] = spla.spsolve(H[free][:, free], -g[free])
        mu = H @ x + g
        new = np.where(active, mu > sc, x < -sc)
        if np.array_equal(new, active):
            return np.maximum(x, 0.0), it
        key = new.tobytes()
        if key in seen:
            break
        seen.add(key)
        active = new
    Hd = H.toarray()
    R = np.linalg.cholesky(Hd).T  # H = Rᵀ R: |A x + b|² = |R x + R⁻ᵀ g|² + const
    x, _ = nnls(R, -np.linalg.solve(R.T, g), maxiter=50 * n)
    return x, -1


class EnergyModel:
    """E(X; θ), its θ-gradient and the energy-optimal contact coefficients of a motion, read
    from ``nlp`` (the transcription of a q-only subproblem of ``target``).

    Attributes: ``N`` nodes, ``mg`` body weight (N), ``wT`` = trapezoid weight × T' at the
    nodes (s; the time weights of :func:`.initial.initial_theta`), ``n_solves`` / ``pdas_fallbacks``
    counts of λ solves and of those that needed the exact NNLS."""

    CACHE = 64  # per-motion λ Jacobians kept (the bundle holds at most 40 motions)

    def __init__(self, ch: Character, nlp: NLP, target: Motion):
        self.ch, self.nlp = ch, nlp
        lay = nlp.x_layout
        if any(lay[k].stop > lay[k].start for k in ("warp", "footprints")) or nlp.rho_dyn_fn is None:
            raise ValueError("NIO's energy needs the NLP of a q-only subproblem (timewarp and footprints held)")
        s = nlp.s_points
        self.N = len(s)
        wq = np.zeros(self.N)
        wq[1:] += np.diff(s) / 2
        wq[:-1] += np.diff(s) / 2
        self.wT = wq * target.time(s, 1)
        self.mg = ch.total_mass * G
        self._lam = lay["lambda"]
        self._open = np.flatnonzero(nlp.ubx[self._lam] > 0)  # the others are held at 0 by the solver
        x, p = nlp.x, nlp.p
        rho = ca.vertcat(nlp.rho_dyn_fn(x, p), nlp.rho_extra_fn(x, p))
        self._rho_fn = ca.Function("nio_rho", [x, p], [rho])
        self._jac_fn = ca.Function("nio_rho_lam", [x, p], [ca.jacobian(rho, x)[:, self._lam]])
        self._f_fn = ca.Function("nio_E", [x, p], [nlp.f, ca.gradient(nlp.f, p)])
        n_dyn = int(nlp.rho_dyn_fn.size1_out(0))
        if n_dyn % N_DOF:
            raise ValueError("NIO's energy needs a dynamic subproblem (rho_dyn of 35 rows per point)")
        rows = np.arange(n_dyn) % N_DOF
        self._joint = np.full(int(rho.shape[0]), -1)  # joint j of each muscle row of ρ, −1 elsewhere
        self._joint[:n_dyn] = np.where(rows < N_JOINT, rows, -1)
        self._cache: OrderedDict = OrderedDict()
        self.n_solves = self.pdas_fallbacks = 0

    def states(self, motion: Motion):
        """(q, q̇, q̈), each (35, N), of ``motion`` at the nodes."""
        q, qd, qdd = motion.state_at_s(self.nlp.s_points)
        return q.T, qd.T, qdd.T

    def x_of(self, motion: Motion, lam: np.ndarray | None = None) -> np.ndarray:
        """The NLP's decision vector of ``motion`` with contact coefficients ``lam`` (default 0)."""
        x = self.nlp.x0.copy()
        ctrl = np.asarray(motion.ctrl, float).ravel()
        sl = self.nlp.x_layout["ctrl"]
        if ctrl.size != sl.stop - sl.start:
            raise ValueError(f"motion has {ctrl.size} control values, the NIO problem {sl.stop - sl.start}")
        x[sl] = ctrl
        x[self._lam] = 0.0 if lam is None else lam
        return x

    def _unit(self, motion: Motion) -> tuple[sps.csc_matrix, np.ndarray]:
        """(∂ρ/∂λ at √α = 1 over the open λ, the previous λ of this motion): the contact forces
        enter the residuals through the contact Jacobian only, so at √α = 1 this depends on q
        alone and is kept per motion."""
        key = (np.asarray(motion.ctrl, float).tobytes(), np.asarray(motion.warp, float).tobytes())
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        p1 = self.nlp.p0.copy()  # θ of the kernel does not enter ∂ρ/∂λ
        p1[self.nlp.p_layout["sqrt_alpha"]] = 1.0
        p1[self.nlp.p_layout["warp_fixed"]] = np.asarray(motion.warp, float)
        J = sps.csc_matrix(self._jac_fn(self.x_of(motion), p1).sparse())[:, self._open]
        self._cache[key] = [J, None]
        while len(self._cache) > self.CACHE:
            self._cache.popitem(last=False)
        return self._cache[key]

    def _row_scale(self, theta: np.ndarray) -> np.ndarray:
        sa = np.sqrt(np.maximum(theta[ALPHA], 0.0))
        return np.where(self._joint >= 0, sa[np.maximum(self._joint, 0)], 1.0)

    def forces(self, motion: Motion, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contact forces (24, N) at the nodes minimising E for the fixed q of ``motion``, and
        λ in the solver's layout (the NLP's ``x_layout["lambda"]`` block)."""
        entry = self._unit(motion)
        J1, prev = entry
        r0 = np.asarray(self._rho_fn(self.x_of(motion), nlp_params(self.nlp, theta, motion))).ravel()
        S = sps.diags(self._row_scale(theta))
        lo, it = nonneg_lsq((S @ J1).tocsc(), r0, prev)
        self.n_solves += 1
        self.pdas_fallbacks += it < 0
        entry[1] = lo
        lam = np.zeros(self._lam.stop - self._lam.start)
        lam[self._open] = lo
        return self.force_matrix(lam), lam

    def force_matrix(self, lam: np.ndarray) -> np.ndarray:
        """(24, N) world forces (N) at the nodes of contact coefficients ``lam`` (m g V λ)."""
        F = np.zeros((3 * len(FORCE_HANDLES), self.N))
        off = self._lam.start
        for (h, k, sl), V in zip(self.nlp.contact_index, self.nlp.contact_basis):
            i = FORCE_HANDLES.index(h)
            F[3 * i:3 * i + 3, k] += self.mg * np.asarray(V) @ lam[sl.start - off:sl.stop - off]
        return F

    def energy(self, theta: np.ndarray, motion: Motion, lam: np.ndarray) -> tuple[float, np.ndarray]:
        """E(X; θ) = NLP.f at (X, λ = ``lam``) under θ, and ∂E/∂θ at fixed λ."""
        theta = np.asarray(theta, float)
        x = self.x_of(motion, lam)
        E, gp = self._f_fn(x, nlp_params(self.nlp, theta, motion))
        gp = np.asarray(gp).ravel()
        g = np.zeros_like(theta)
        th_sl = self.nlp.p_layout["theta"]
        g[KERNEL] = gp[th_sl].reshape(KERNEL.stop - KERNEL.start, self.N, order="F").sum(axis=1)
        r1 = np.asarray(self._rho_fn(x, nlp_params(self.nlp, theta, motion, unit_alpha=True))).ravel()
        m = self._joint >= 0
        g[ALPHA] = np.bincount(self._joint[m], weights=r1[m] ** 2, minlength=N_JOINT)
        return float(E), g

    def parts(self, theta: np.ndarray, motion: Motion, lam: np.ndarray) -> dict[str, float]:
        """E(X; θ) at contact coefficients ``lam`` split into ``muscle`` (Σ α_j Q_mj², the joint
        rows of ρ_dyn), ``root`` (the root-residual rows of ρ_dyn) and ``other`` (the rest of
        the objective: the λ regularisation and any other term)."""
        x = self.x_of(motion, lam)
        E = float(self._f_fn(x, nlp_params(self.nlp, theta, motion))[0])
        r = np.asarray(self._rho_fn(x, nlp_params(self.nlp, theta, motion))).ravel()
        n_dyn = int(self.nlp.rho_dyn_fn.size1_out(0))
        muscle = float(np.sum(r[:n_dyn][self._joint[:n_dyn] >= 0] ** 2))
        root = float(np.sum(r[:n_dyn][self._joint[:n_dyn] < 0] ** 2))
        return {"muscle": muscle, "root": root, "other": E - muscle - root}

    def measure(self, theta: np.ndarray, motion: Motion):
        """(E, ∂E/∂θ, F, λ) of ``motion`` under θ with its energy-optimal contact forces."""
        F, lam = self.forces(motion, theta)
        E, g = self.energy(theta, motion, lam)
        return E, g, F, lam
