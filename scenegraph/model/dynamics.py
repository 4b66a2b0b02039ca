"""Generalized forces of the character (NIO paper §4, Eq. 5–11), symbolic in CasADi.

All generalized forces are per DOF: N for the root translations, N·m for rotations (for the
root Euler angles, the generalized force conjugate to that angle).  Forces and points are
world-frame (Z up) unless stated.

The inertial and gravity terms come from one recursive Newton–Euler pass (O(n), body-frame
3-vector algebra, gravity as a base acceleration of +g); external point forces (contact,
shoe springs, a partner's hand, an impact) enter as Jᵀf through the same backward pass.
The paper's split (Eq. 10–11) then reads

    Q_id = M(q) q̈ + C(q, q̇) − Q_g          (what the RNEA returns)
    Q_m  = Q_id − Q_p − Q_c − Q_s − Q_ext   on the 29 joint DOFs (muscle torques)
    Q_0  = Q_id − Q_c − Q_s − Q_ext         on the 6 root DOFs (must vanish)
"""
from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from scenegraph.model.body import G, N_DOF, N_ROOT, Character
from scenegraph.model.kinematics import frame_transforms, handle_position, local_transform

__all__ = ["rnea", "external_generalized_force", "passive_force", "sigmoid", "friction_basis",
           "shoe_force", "muscle_and_residual", "MU", "ExternalForce", "gravity_vector", "mass_matrix"]

MU = 0.8  # friction coefficient of the 4-vector cone basis


def sigmoid(x):
    """The paper's smooth step g(x) = (tanh(500 x) + 1) / 2."""
    return (ca.tanh(500.0 * x) + 1.0) / 2.0


def friction_basis(mu: float = MU) -> np.ndarray:
    """V (3×4): columns span the friction pyramid; a contact force is f = V λ with λ ≥ 0."""
    return np.array([[mu, -mu, 0.0, 0.0], [0.0, 0.0, mu, -mu], [1.0, 1.0, 1.0, 1.0]]) / np.sqrt(1 + mu * mu)


# (body frame index, point in that frame (m), world force (N))
ExternalForce = tuple[int, Sequence[float], object]


def _forward(ch: Character, q, qd, qdd, gravity: bool):
    n = len(ch.dofs)
    E, r, Rw, w, al, a = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    zero = ca.DM.zeros(3, 1)
    for i, dof in enumerate(ch.dofs):
        E[i], r[i] = local_transform(dof, q[i])
        s = ca.DM(dof.axis)
        if dof.parent < 0:
            wp, alp, ap, Rp = zero, zero, ca.DM([0, 0, G if gravity else 0.0]), ca.DM.eye(3)
        else:
            wp, alp, ap, Rp = w[dof.parent], al[dof.parent], a[dof.parent], Rw[dof.parent]
        Et = E[i].T
        a_origin = ap + ca.cross(alp, r[i]) + ca.cross(wp, ca.cross(wp, r[i]))
        w_in, al_in, a_in = ca.mtimes(Et, wp), ca.mtimes(Et, alp), ca.mtimes(Et, a_origin)
        if dof.kind == "revolute":
            w[i] = w_in + s * qd[i]
            al[i] = al_in + s * qdd[i] + ca.cross(w_in, s * qd[i])
            a[i] = a_in
        else:
            w[i], al[i] = w_in, al_in
            a[i] = a_in + s * qdd[i] + 2 * ca.cross(w_in, s * qd[i])
        Rw[i] = ca.mtimes(Rp, E[i])
    return E, r, Rw, w, al, a


def _backward(ch: Character, E, r, f, n_):
    tau = [None] * len(ch.dofs)
    for i in reversed(range(len(ch.dofs))):
        dof = ch.dofs[i]
        s = ca.DM(dof.axis)
        tau[i] = ca.dot(s, n_[i]) if dof.kind == "revolute" else ca.dot(s, f[i])
        if dof.parent >= 0:
            fp = ca.mtimes(E[i], f[i])
            f[dof.parent] = f[dof.parent] + fp
            n_[dof.parent] = n_[dof.parent] + ca.mtimes(E[i], n_[i]) + ca.cross(r[i], fp)
    return ca.vertcat(*tau)


def _apply_external(f, n_, Rw, ext: Sequence[ExternalForce], sign: float):
    for frame, point, force in ext:
        fl = ca.mtimes(Rw[frame].T, force)
        f[frame] = f[frame] + sign * fl
        n_[frame] = n_[frame] + sign * ca.cross(ca.DM(list(point)) if not isinstance(point, (ca.SX, ca.MX)) else point, fl)


def rnea(ch: Character, q, qd, qdd, ext: Sequence[ExternalForce] = (), gravity: bool = True):
    """Inverse dynamics Q_id = M q̈ + C − Q_g − Σ Jᵀ f_ext  (35-vector)."""
    E, r, Rw, w, al, a = _forward(ch, q, qd, qdd, gravity)
    n = len(ch.dofs)
    f = [ca.DM.zeros(3, 1) for _ in range(n)]
    n_ = [ca.DM.zeros(3, 1) for _ in range(n)]
    for b in ch.bodies:
        i = b.frame
        c = ca.DM(b.center)
        Ic = ca.DM(b.inertia)
        ac = a[i] + ca.cross(al[i], c) + ca.cross(w[i], ca.cross(w[i], c))
        F = b.mass * ac
        f[i] = f[i] + F
        n_[i] = n_[i] + ca.mtimes(Ic, al[i]) + ca.cross(w[i], ca.mtimes(Ic, w[i])) + ca.cross(c, F)
    _apply_external(f, n_, Rw, ext, -1.0)
    return _backward(ch, E, r, f, n_)


def external_generalized_force(ch: Character, q, ext: Sequence[ExternalForce]):
    """Σ Jᵀ f over world point forces (35-vector), via the RNEA backward pass only."""
    n = len(ch.dofs)
    E, r, Rw = [None] * n, [None] * n, [None] * n
    for i, dof in enumerate(ch.dofs):
        E[i], r[i] = local_transform(dof, q[i])
        Rw[i] = E[i] if dof.parent < 0 else ca.mtimes(Rw[dof.parent], E[i])
    f = [ca.DM.zeros(3, 1) for _ in range(n)]
    n_ = [ca.DM.zeros(3, 1) for _ in range(n)]
    _apply_external(f, n_, Rw, ext, 1.0)
    return _backward(ch, E, r, f, n_)


def passive_force(q_joint, qd_joint, ks1, ks2, kd, q_rest):
    """Q_p on the joint DOFs (Eq. 6–7): −k_s(q)(q − q̄) − k_d q̇, k_s blended by g(q − q̄).

    k_s1 acts where q > q̄ (stretching), k_s2 where q < q̄.  Units N·m/rad, N·m·s/rad.
    """
    x = q_joint - q_rest
    gx = sigmoid(x)
    ks = gx * ks1 + (1 - gx) * ks2
    return -ks * x - kd * qd_joint


def shoe_force(heel_height, k_shoe, h_rest):
    """Vertical shoe-spring force (N) at a heel (Eq. 9): g(h̄ − h) k_shoe (h̄ − h)."""
    d = h_rest - heel_height
    return sigmoid(d) * k_shoe * d


def muscle_and_residual(ch: Character, q, qd, qdd, style, ext: Sequence[ExternalForce] = ()):
    """(Q_m (29), Q_0 (6)) for a pose, its rates, external forces (contact, couplings) and a
    style (an object with numpy/casadi attributes alpha, ks1, ks2, kd, q_rest, k_shoe, h_rest).

    The shoe springs act at both heels and are added to ``ext`` here.
    """
    tr = frame_transforms(ch, q)
    shoe = []
    for side in ("l", "r"):
        h = ch.handle(f"heel_{side}")
        z = handle_position(ch, q, h.name, tr)[2]
        fz = shoe_force(z, style.k_shoe, style.h_rest)
        shoe.append((ch.body(h.body).frame, h.point, ca.vertcat(0, 0, fz)))
    tau = rnea(ch, q, qd, qdd, list(ext) + shoe)
    qp = passive_force(q[N_ROOT:], qd[N_ROOT:], style.ks1, style.ks2, style.kd, style.q_rest)
    return tau[N_ROOT:] - qp, tau[:N_ROOT]


def gravity_vector(ch: Character, q):
    """The generalized gravity load −Q_g = RNEA(q, 0, 0) (35-vector)."""
    z = ca.DM.zeros(N_DOF)
    return rnea(ch, q, z, z)


def mass_matrix(ch: Character, q):
    """M(q) (35×35) as the Jacobian of the RNEA with respect to q̈ (symbolic)."""
    qdd = ca.SX.sym("qdd", N_DOF)
    tau = rnea(ch, q, ca.DM.zeros(N_DOF), qdd, gravity=False)
    return ca.jacobian(tau, qdd)
