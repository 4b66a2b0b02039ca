"""Mass, centre of mass, momenta and the external wrench a body of meshes needs, from its
vertex trajectories alone.

Each closed mesh is cut into tetrahedra (one per triangle, apex at the mesh's vertex mean)
and its density is uniform.  Inside a tetrahedron positions, velocities and accelerations
are the linear interpolation of its four corners (the apex moves as the mean of the mesh's
vertices), which is exact for any rigid motion.  With the tetrahedron's mass m and corner
values p_i, a_i (i = 0..3)::

    ∫ρ a dV      = m/4  Σ a_i
    ∫ρ r × a dV  = m/20 (Σ p_i × a_i + (Σ p_i) × (Σ a_i))      (linear-element mass matrix)

Velocities and accelerations are central finite differences of the vertex positions at
the audit rate (dt = 1/fps): a_k = (p_{k+1} − 2 p_k + p_{k−1}) / dt², exact for constant
acceleration.  The first and last frames have no acceleration (NaN).

The **external wrench** a body needs besides gravity (g = 9.81 m/s² along −z), world frame:
    F   = ∫ρ a dV − M g                        (N)
    τ_O = ∫ρ r × a dV − c × (M g)              (N·m about the world origin; d/dt H_O = τ)
    τ_c = τ_O − c × F                          (about the centre of mass c)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["G", "Momenta", "momenta"]

G = 9.81  # m/s^2
_GVEC = np.array([0.0, 0.0, -G])


@dataclass(frozen=True, eq=False)
class Momenta:
    """Per frame (T,): ``mass`` kg, ``com`` (T,3) m, ``momentum`` (T,3) kg·m/s,
    ``ang_momentum_com`` (T,3) kg·m²/s about the centre of mass, ``force`` (T,3) N and
    ``torque_origin`` / ``torque_com`` (T,3) N·m: the external wrench needed besides gravity;
    ``second_moment`` (T,) kg·m² for :attr:`gyration_radius`."""

    mass: np.ndarray
    com: np.ndarray
    momentum: np.ndarray
    ang_momentum_com: np.ndarray
    force: np.ndarray
    torque_origin: np.ndarray
    torque_com: np.ndarray
    second_moment: np.ndarray = None  # (T,) ∫ρ |r|² dV about the world origin, kg·m²

    @property
    def gyration_radius(self) -> np.ndarray:
        """(T,) m: sqrt(∫ρ |r − c|² dV / M), the body's size for torques."""
        s = self.second_moment - self.mass * np.einsum("ti,ti->t", self.com, self.com)
        return np.sqrt(np.maximum(s, 0.0) / self.mass)

    def __add__(self, other: "Momenta") -> "Momenta":
        """The momenta of two bodies taken as one system."""
        m = self.mass + other.mass
        com = (self.com * self.mass[:, None] + other.com * other.mass[:, None]) / m[:, None]
        F = self.force + other.force
        tO = self.torque_origin + other.torque_origin
        P = self.momentum + other.momentum
        # H about the new centre: H_c = Σ (H_ci + (c_i − c) × P_i)
        H = (self.ang_momentum_com + np.cross(self.com - com, self.momentum)
             + other.ang_momentum_com + np.cross(other.com - com, other.momentum))
        return Momenta(m, com, P, H, F, tO, tO - np.cross(com, F), self.second_moment + other.second_moment)


def _diffs(P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    V = np.full_like(P, np.nan)
    A = np.full_like(P, np.nan)
    V[1:-1] = (P[2:] - P[:-2]) / (2 * dt)
    A[1:-1] = (P[2:] - 2 * P[1:-1] + P[:-2]) / (dt * dt)
    return V, A


def momenta(points: np.ndarray, tris: np.ndarray, tri_mesh: np.ndarray, vert_mesh: np.ndarray,
            density: np.ndarray, dt: float, chunk: int = 64) -> Momenta:
    """Momenta and needed wrench of meshes with vertex positions ``points`` (T, N, 3) m."""
    T = points.shape[0]
    nm = int(density.shape[0])
    V, A = _diffs(points, dt)
    cnt = np.bincount(vert_mesh, minlength=nm).astype(float)
    out = {k: np.zeros((T, 3)) for k in ("com", "P", "H", "Fa", "rxa")}
    r2 = np.zeros(T)
    mass = np.zeros(T)
    rho = density[tri_mesh]
    i0, i1, i2 = tris[:, 0], tris[:, 1], tris[:, 2]

    W = np.zeros((points.shape[1], nm))
    W[np.arange(points.shape[1]), vert_mesh] = 1.0
    W /= np.maximum(cnt, 1.0)[None, :]

    def apex(X):  # (t, N, 3) -> (t, M, 3): the mean vertex of each mesh
        return np.einsum("tnd,nm->tmd", X, W)

    for a in range(0, T, chunk):
        b = min(T, a + chunk)
        Pk, Vk, Ak = points[a:b], V[a:b], A[a:b]
        Po, Vo, Ao = (apex(X)[:, tri_mesh] for X in (Pk, Vk, Ak))
        p = (Po, Pk[:, i0], Pk[:, i1], Pk[:, i2])
        v = (Vo, Vk[:, i0], Vk[:, i1], Vk[:, i2])
        acc = (Ao, Ak[:, i0], Ak[:, i1], Ak[:, i2])
        vol = np.einsum("tfi,tfi->tf", p[1] - p[0], np.cross(p[2] - p[0], p[3] - p[0])) / 6.0
        m = rho[None, :] * vol  # (t, F)
        Sp, Sv, Sa = sum(p), sum(v), sum(acc)
        mass[a:b] = m.sum(1)
        out["com"][a:b] = np.einsum("tf,tfi->ti", m, Sp) / 4.0
        out["P"][a:b] = np.einsum("tf,tfi->ti", m, Sv) / 4.0
        out["Fa"][a:b] = np.einsum("tf,tfi->ti", m, Sa) / 4.0
        rv = sum(np.cross(pi, vi) for pi, vi in zip(p, v)) + np.cross(Sp, Sv)
        ra = sum(np.cross(pi, ai) for pi, ai in zip(p, acc)) + np.cross(Sp, Sa)
        out["H"][a:b] = np.einsum("tf,tfi->ti", m, rv) / 20.0
        rr = sum(np.einsum("tfi,tfi->tf", pi, pi) for pi in p) + np.einsum("tfi,tfi->tf", Sp, Sp)
        r2[a:b] = np.einsum("tf,tf->t", m, rr) / 20.0
        out["rxa"][a:b] = np.einsum("tf,tfi->ti", m, ra) / 20.0
    safe = np.where(mass > 0, mass, 1.0)
    com = out["com"] / safe[:, None]
    F = out["Fa"] - mass[:, None] * _GVEC
    tO = out["rxa"] - np.cross(com, mass[:, None] * _GVEC)
    Hc = out["H"] - np.cross(com, out["P"])
    return Momenta(mass, com, out["P"], Hc, F, tO, tO - np.cross(com, F), r2)
