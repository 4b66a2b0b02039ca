"""compose's dynamics against Pinocchio (an independent rigid-body library) and hand-computed cases."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from conftest import BODIES, character
from pinocchio_model import build_pinocchio, random_states
from scenegraph.model.body import G, N_DOF, N_JOINT, N_ROOT, standing_pose
from scenegraph.model.dynamics import (MU, external_generalized_force, friction_basis, gravity_vector, mass_matrix,
                                 muscle_and_residual, passive_force, rnea, shoe_force, sigmoid)
from scenegraph.model.kinematics import handle_position
from scenegraph.model.style import default_style

N_STATES = 200
TOL = 1e-8


def rel_err(ours: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-state relative error; states along the first axis."""
    axes = tuple(range(1, ours.ndim))
    return np.sqrt(np.sum((ours - ref) ** 2, axis=axes)) / np.sqrt(np.sum(ref ** 2, axis=axes))


def sym():
    return [ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd")]


@pytest.mark.parametrize("preset,height,mass,aligned", [b + (True,) for b in BODIES] + [BODIES[0] + (False,)])
def test_matches_pinocchio(preset, height, mass, aligned):
    """Inverse dynamics, mass matrix and gravity vector on 200 random states within the joint limits
    (Pinocchio with its axis-aligned joint types, and once with its generic unaligned ones)."""
    ch = character(preset, height, mass)
    pm = build_pinocchio(ch, aligned)
    q, qd, qdd = random_states(ch, N_STATES, seed=len(preset) + int(ch.height * 100))
    assert np.all(q[:, N_ROOT:] >= ch.lower[N_ROOT:]) and np.all(q[:, N_ROOT:] <= ch.upper[N_ROOT:])

    qs, qds, qdds = sym()
    f = ca.Function("f", [qs, qds, qdds], [rnea(ch, qs, qds, qdds), gravity_vector(ch, qs), mass_matrix(ch, qs)])
    tau, grav, M = f.map(N_STATES)(q.T, qd.T, qdd.T)
    tau, grav = np.array(tau).T, np.array(grav).T
    M = np.array(M).reshape(N_DOF, N_STATES, N_DOF).transpose(1, 0, 2)

    tau_p = np.array([pm.rnea(*s) for s in zip(q, qd, qdd)])
    grav_p = np.array([pm.gravity(x) for x in q])
    M_p = np.array([pm.mass_matrix(x) for x in q])

    assert rel_err(tau, tau_p).max() <= TOL
    assert rel_err(grav, grav_p).max() <= TOL
    assert rel_err(M, M_p).max() <= TOL
    assert np.allclose(M, M.transpose(0, 2, 1), atol=1e-12)
    assert np.all(np.linalg.eigvalsh(M)[:, 0] > 0)  # positive definite
    # inverse dynamics really is M qdd + h: the velocity-free part equals M qdd + g
    f0 = ca.Function("f0", [qs, qdds], [rnea(ch, qs, ca.DM.zeros(N_DOF), qdds)])
    tau0 = np.array(f0.map(N_STATES)(q.T, qdd.T)).T
    assert np.allclose(tau0, np.einsum("nij,nj->ni", M, qdd) + grav, rtol=1e-9, atol=1e-9)


def test_root_translation_carries_total_weight(adult):
    """Static: the generalized force on root z is the total weight, on root x/y zero, anywhere."""
    q, *_ = random_states(adult, 5, seed=3)
    for x in q:
        g = np.array(ca.evalf(gravity_vector(adult, ca.DM(x)))).ravel()
        assert g[2] == pytest.approx(adult.total_mass * G, rel=1e-12)
        assert abs(g[0]) < 1e-9 and abs(g[1]) < 1e-9


# --- external point forces: sign and Jᵀf --------------------------------------------------------

def _handle_ext(ch, name, force):
    h = ch.handle(name)
    return (ch.body(h.body).frame, h.point, ca.DM(force))


def test_weight_at_pelvis_cancels_vertical_root_residual(adult):
    """Lifting the standing character by its weight at the pelvis zeroes Q_0's translation part;
    the force passes through the root rotation axes and loads no joint, so nothing else changes."""
    q = ca.DM(standing_pose(adult))
    z = ca.DM.zeros(N_DOF)
    weight = adult.total_mass * G
    free = np.array(ca.evalf(rnea(adult, q, z, z))).ravel()
    lifted = np.array(ca.evalf(rnea(adult, q, z, z, [_handle_ext(adult, "pelvis", [0, 0, weight])]))).ravel()
    assert free[2] == pytest.approx(weight, rel=1e-12)
    assert np.allclose(lifted[:3], 0.0, atol=1e-9)
    assert np.allclose(lifted[3:], free[3:], atol=1e-9)
    # the same force pushing down doubles it (sign check)
    pushed = np.array(ca.evalf(rnea(adult, q, z, z, [_handle_ext(adult, "pelvis", [0, 0, -weight])]))).ravel()
    assert pushed[2] == pytest.approx(2 * weight, rel=1e-12)


@pytest.mark.parametrize("aligned", [True, False])
@pytest.mark.parametrize("handle", ["palm_r", "heel_l", "toe_r", "head", "chest"])
def test_external_force_is_jacobian_transpose(adult, handle, aligned):
    """Σ Jᵀf from the RNEA backward pass equals Jᵀf with J from casadi.jacobian of the handle
    position, and from Pinocchio's frame Jacobian; rnea subtracts it like Pinocchio's fext."""
    pm = build_pinocchio(adult, aligned)
    q, qd, qdd = random_states(adult, 4, seed=7)
    qs = ca.SX.sym("q", N_DOF)
    J = ca.Function("J", [qs], [ca.jacobian(handle_position(adult, qs, handle), qs)])
    rng = np.random.default_rng(11)
    frame, point, _ = _handle_ext(adult, handle, [0, 0, 0])
    for x, v, a in zip(q, qd, qdd):
        force = rng.normal(scale=100.0, size=3)
        ext = [(frame, point, ca.DM(force))]
        Qext = np.array(ca.evalf(external_generalized_force(adult, ca.DM(x), ext))).ravel()
        Jc = np.array(J(x))
        assert np.allclose(Qext, Jc.T @ force, rtol=1e-10, atol=1e-9)

        assert np.allclose(Jc, pm.handle_jacobian(x, handle), atol=1e-10)

        # rnea with the force == Pinocchio's rnea with the same force in the joint frame
        tau = np.array(ca.evalf(rnea(adult, ca.DM(x), ca.DM(v), ca.DM(a), ext))).ravel()
        pin.forwardKinematics(pm.model, pm.data, pm.to_pin(x))
        jid, point_j, R_j = pm.joint_of(handle)
        fl = R_j.T @ force  # Pinocchio takes fext as a spatial force in the joint frame
        fext = pin.StdVec_Force()
        for j in range(pm.model.njoints):
            fext.append(pin.Force(fl, np.cross(point_j, fl)) if j == jid else pin.Force.Zero())
        tau_p = pm.rnea(x, v, a, fext)
        assert rel_err(tau[None], tau_p[None])[0] <= TOL
        tau_free = np.array(ca.evalf(rnea(adult, ca.DM(x), ca.DM(v), ca.DM(a)))).ravel()
        assert np.allclose(tau_free - tau, Qext, rtol=1e-10, atol=1e-8)


def test_friction_cone_basis_and_contact_force(adult):
    """V's columns are unit forces on the friction pyramid's edges; Q_c of f = Vλ is Jᵀ V λ."""
    V = friction_basis()
    assert V.shape == (3, 4)
    assert np.allclose(np.linalg.norm(V, axis=0), 1.0)
    assert np.all(V[2] > 0)
    assert np.allclose(np.abs(V[:2]).max(axis=0) / V[2], MU)  # each edge on the cone |f_t| = μ f_n
    lam = np.array([10.0, 0.0, 25.0, 5.0])
    f = V @ lam
    assert np.hypot(f[0], f[1]) <= MU * f[2]

    q = standing_pose(adult)
    qs = ca.SX.sym("q", N_DOF)
    J = np.array(ca.Function("J", [qs], [ca.jacobian(handle_position(adult, qs, "ball_l"), qs)])(q))
    Q = np.array(ca.evalf(external_generalized_force(adult, ca.DM(q), [_handle_ext(adult, "ball_l", f)]))).ravel()
    assert np.allclose(Q, J.T @ V @ lam, atol=1e-9)
    assert Q[2] == pytest.approx(f[2])  # the root z DOF feels the vertical contact force


# --- passive springs and shoes -----------------------------------------------------------------

def _passive(q, qd, ks1, ks2, kd, q_rest):
    return np.array(ca.evalf(passive_force(ca.DM(q), ca.DM(qd), ca.DM(ks1), ca.DM(ks2), ca.DM(kd),
                                           ca.DM(q_rest)))).ravel()


@pytest.fixture
def springs():
    rng = np.random.default_rng(5)
    ks1 = rng.uniform(10, 50, N_JOINT)
    ks2 = rng.uniform(60, 100, N_JOINT)  # always different from ks1
    kd = rng.uniform(0.5, 2.0, N_JOINT)
    q_rest = rng.uniform(-0.5, 0.5, N_JOINT)
    return ks1, ks2, kd, q_rest


def test_spring_at_rest_gives_zero(springs):
    ks1, ks2, kd, q_rest = springs
    assert np.allclose(_passive(q_rest, np.zeros(N_JOINT), ks1, ks2, kd, q_rest), 0.0, atol=1e-14)


def test_spring_switches_between_stiffnesses(springs):
    """Above rest (stretch) k_s1 acts, below (contract) k_s2, far (0.1 rad) from the switch."""
    ks1, ks2, kd, q_rest = springs
    zero = np.zeros(N_JOINT)
    d = 0.1
    assert np.allclose(_passive(q_rest + d, zero, ks1, ks2, kd, q_rest), -ks1 * d, rtol=1e-12)
    assert np.allclose(_passive(q_rest - d, zero, ks1, ks2, kd, q_rest), ks2 * d, rtol=1e-12)
    # at the switch the blend is g(x) = (tanh(500 x) + 1) / 2
    x = 1e-3
    g = (np.tanh(0.5) + 1) / 2
    assert np.allclose(_passive(q_rest + x, zero, ks1, ks2, kd, q_rest), -(g * ks1 + (1 - g) * ks2) * x, rtol=1e-12)
    assert float(sigmoid(0.0)) == 0.5
    # damping opposes velocity
    qd = np.linspace(-2, 2, N_JOINT)
    assert np.allclose(_passive(q_rest, qd, ks1, ks2, kd, q_rest), -kd * qd, rtol=1e-12)


def test_shoe_spring():
    k, h_rest = 2.0e4, 0.005
    assert abs(float(shoe_force(h_rest + 0.05, k, h_rest))) < 1e-12  # heel above the rest length: no force
    assert float(shoe_force(h_rest + 1e-6, k, h_rest)) <= 0.0 + 1e-3
    h = h_rest - 0.02  # compressed well below the rest length: k (h̄ − h), pushing up
    assert float(shoe_force(h, k, h_rest)) == pytest.approx(k * 0.02, rel=1e-8)
    assert float(shoe_force(h_rest, k, h_rest)) == 0.0


def test_muscle_and_residual_split(adult):
    """Standing still on compressed shoes: Q_0 (root) = weight − both shoe forces on z; Q_m = Q_id − Q_p."""
    style = default_style(adult.total_mass)
    q = standing_pose(adult)
    z = np.zeros(N_DOF)
    Qm, Q0 = (np.array(ca.evalf(x)).ravel() for x in muscle_and_residual(adult, ca.DM(q), ca.DM(z), ca.DM(z), style))
    f_shoe = float(shoe_force(0.0, style.k_shoe, style.h_rest))  # both heels at z = 0 in the standing pose
    assert f_shoe > 0
    assert Q0[2] == pytest.approx(adult.total_mass * G - 2 * f_shoe, rel=1e-10)
    heels = [_handle_ext(adult, f"heel_{s}", [0, 0, f_shoe]) for s in "lr"]
    tau = np.array(ca.evalf(rnea(adult, ca.DM(q), ca.DM(z), ca.DM(z), heels))).ravel()
    qp = _passive(q[N_ROOT:], z[N_ROOT:], style.ks1, style.ks2, style.kd, style.q_rest)
    assert np.allclose(Q0, tau[:N_ROOT], atol=1e-9)
    assert np.allclose(Qm, tau[N_ROOT:] - qp, atol=1e-9)
