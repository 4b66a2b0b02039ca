"""The per-point dynamics residual of one character: the physics model's kernels, no solver.

At one instant, with the generalised coordinates q (35: root x, y, z, yaw, pitch, roll, then
29 joint angles; m and rad), their time derivatives q̇, q̈ (world seconds), the external forces
at FORCE_HANDLES (3 each, N, world frame) and the style numbers θ of the kernel (N_THETA:
passive springs ks1, ks2, damping kd, rest angles q̄ per joint, shoe stiffness and rest
height), the kernel returns

    [Q_m (29 joint torques, N m); Q_0 (6 root residual: N and N m)],

the inverse dynamics plus passive, contact and shoe terms (``dynamics.muscle_and_residual``).
The energy of paper Eq. 13 is a weighted sum of their squares (muscle weights α, root weight
W_ROOT).  The transcription (``scenegraph.problem.transcription``), the independent physics
audit (``scenegraph.model.audit``) and NIO all evaluate this one kernel.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import N_DOF, N_JOINT, Character
from scenegraph.model.dynamics import muscle_and_residual
from scenegraph.model.kinematics import frame_transforms, handle_position
from scenegraph.model.style import Style

__all__ = ["W_ROOT", "CONTACT_HANDLES", "FORCE_HANDLES", "N_THETA", "residual_kernel", "compiled_kernel",
           "kernel_hessian", "handles_kernel", "theta_kernel_vector"]

W_ROOT = 100.0  # paper: weight of the root residual
CONTACT_HANDLES = ("heel_l", "ball_l", "toe_l", "heel_r", "ball_r", "toe_r")
FORCE_HANDLES = CONTACT_HANDLES + ("palm_l", "palm_r")
N_THETA = 4 * N_JOINT + 2  # style numbers the kernel needs: ks1, ks2, kd, q_rest, k_shoe, h_rest


def _kernel_expr(ch: Character, q, qd, qdd, fc, th):
    """[Q_m (29); Q_0 (6)] as SX of the kernel's symbols (see residual_kernel)."""
    class _S:  # the style numbers the dynamics need
        ks1, ks2, kd, q_rest = (th[i * N_JOINT:(i + 1) * N_JOINT] for i in range(4))
        k_shoe, h_rest = th[4 * N_JOINT], th[4 * N_JOINT + 1]

    ext = []
    for i, name in enumerate(FORCE_HANDLES):
        h = ch.handle(name)
        ext.append((ch.body(h.body).frame, h.point, fc[3 * i:3 * i + 3]))
    qm, q0 = muscle_and_residual(ch, q, qd, qdd, _S, ext)
    return ca.vertcat(qm, q0)


@functools.lru_cache(maxsize=8)
def residual_kernel(ch: Character) -> ca.Function:
    """(q, q̇, q̈ (35 each), forces at FORCE_HANDLES (3·8, world N), θ (118)) → [Q_m (29); Q_0 (6)]."""
    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    fc = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("theta", N_THETA)
    return ca.Function("compose_residual", [q, qd, qdd, fc, th], [_kernel_expr(ch, q, qd, qdd, fc, th)],
                       ["q", "qd", "qdd", "f", "theta"], ["Q"])


@functools.lru_cache(maxsize=8)
def compiled_kernel(ch: Character) -> ca.Function:
    """:func:`residual_kernel` compiled to C with its Jacobian (disk cache, ``codegen.compiled``)."""
    from scenegraph.model.codegen import compiled
    return compiled(residual_kernel(ch), with_jacobian=True)


@functools.lru_cache(maxsize=8)
def kernel_hessian(ch: Character, compile: bool = True) -> ca.Function:
    """(q, q̇, q̈, forces, θ, w (35)) → ∇²_z (w · Q(z)) (129×129, z = (q, q̇, q̈, forces)).

    The second-order term of the exact Hessian of a weighted sum of squares Σ w_i Q_i, with
    one exception: the paper's smooth steps g(x) = (tanh(500 x) + 1)/2 that blend the passive
    springs (ks1/ks2) and switch the shoe spring are held at their values when differentiating
    twice (their first derivatives stay in the gradient).  Their own curvature is a spike of
    ~500² at the kink (a heel at its 5 mm rest height, a joint at q̄): with it IPOPT's inertia
    correction reached 1e10–1e17 and stopped with "Error in step computation" (measured).  Away
    from the kinks (|x| ≫ 2 mm) this is the exact Hessian.  The kernel is linear in q̈ and in
    the forces, so only (q, q̇) rows and columns are non-zero (3319 entries; ~140 k SX
    instructions, compiled at -O1 in ~20 s once)."""
    from scenegraph.model import dynamics as dyn

    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    fc = ca.SX.sym("f", 3 * len(FORCE_HANDLES))
    th = ca.SX.sym("theta", N_THETA)
    w = ca.SX.sym("w", N_DOF)
    held, smooth_step = [], dyn.sigmoid

    def held_step(x):  # a symbol in place of g(x): differentiated as a constant
        g = ca.SX.sym(f"g{len(held)}", x.shape)
        held.append((g, smooth_step(x)))
        return g

    dyn.sigmoid = held_step
    try:
        Q = _kernel_expr(ch, q, qd, qdd, fc, th)
    finally:
        dyn.sigmoid = smooth_step
    z = ca.vertcat(q, qd, qdd, fc)
    H, _ = ca.hessian(ca.dot(w, Q), z)
    if held:
        H = ca.substitute(H, ca.vertcat(*[g for g, _ in held]), ca.vertcat(*[v for _, v in held]))
    f = ca.Function("compose_residual_hess", [q, qd, qdd, fc, th, w], [H],
                    ["q", "qd", "qdd", "f", "theta", "w"], ["H"])
    if not compile:
        return f
    from scenegraph.model.codegen import compiled
    return compiled(f)


@functools.lru_cache(maxsize=8)
def handles_kernel(ch: Character, names: tuple[str, ...]) -> ca.Function:
    """q (35) → world positions (m) of the handles ``names``, stacked (3 per handle)."""
    q = ca.SX.sym("q", N_DOF)
    tr = frame_transforms(ch, q)
    return ca.Function("handles", [q], [ca.vertcat(*[handle_position(ch, q, n, tr) for n in names])])


def theta_kernel_vector(style: Style) -> np.ndarray:
    """The kernel's θ (N_THETA) of a style: ks1, ks2, kd, q_rest (29 each), k_shoe, h_rest."""
    return np.concatenate([style.ks1, style.ks2, style.kd, style.q_rest, [style.k_shoe, style.h_rest]])
