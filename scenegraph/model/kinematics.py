"""Forward kinematics of a :class:`~scenegraph.model.body.Character`, symbolic (CasADi) or numeric.

Every DOF frame i has a rotation ``R[i]`` (frame → world) and an origin ``p[i]`` (world, m).
The functions here accept CasADi SX/MX or numpy inputs; numeric helpers wrap them in cached
``casadi.Function`` objects.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import Character, N_DOF

__all__ = ["axis_rotation", "frame_transforms", "handle_position", "body_transforms", "numeric_fk",
           "handle_positions_fn"]


def axis_rotation(axis, angle):
    """Rotation matrix about a fixed unit ``axis`` (one of ±X, ±Y, ±Z) by ``angle`` (rad)."""
    c, s = ca.cos(angle), ca.sin(angle)
    ax = [float(a) for a in axis]
    k = int(np.argmax(np.abs(ax)))
    sign = ax[k]
    s = s * sign
    if k == 0:
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if k == 1:
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


def local_transform(dof, qi):
    """(E, r): rotation frame→parent and origin in parent (m) of one DOF frame."""
    off = ca.DM(dof.offset)
    if dof.kind == "prismatic":
        return ca.DM.eye(3), off + ca.DM(dof.axis) * qi
    return axis_rotation(dof.axis, qi), off


def frame_transforms(ch: Character, q):
    """World rotations and origins of all DOF frames: lists R[i] (3×3), p[i] (3×1)."""
    R, p = [], []
    for i, dof in enumerate(ch.dofs):
        E, r = local_transform(dof, q[i])
        if dof.parent < 0:
            R.append(E)
            p.append(r)
        else:
            Rp, pp = R[dof.parent], p[dof.parent]
            R.append(ca.mtimes(Rp, E))
            p.append(pp + ca.mtimes(Rp, r))
    return R, p


def handle_position(ch: Character, q, name: str, transforms=None):
    """World position (m) of a named handle."""
    R, p = transforms if transforms is not None else frame_transforms(ch, q)
    h = ch.handle(name)
    f = ch.body(h.body).frame
    return p[f] + ca.mtimes(R[f], ca.DM(h.point))


def body_transforms(ch: Character, q):
    """[(R, p)] per body in ``ch.bodies`` order: the body frame's world rotation and origin."""
    R, p = frame_transforms(ch, q)
    return [(R[b.frame], p[b.frame]) for b in ch.bodies]


@functools.lru_cache(maxsize=16)
def _fk_function(ch: Character) -> ca.Function:
    q = ca.SX.sym("q", N_DOF)
    outs = []
    for R, p in body_transforms(ch, q):
        outs += [ca.reshape(R, 9, 1), p]
    return ca.Function("fk", [q], [ca.vertcat(*outs)])


def numeric_fk(ch: Character, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body rotations (n_bodies, 3, 3) and origins (n_bodies, 3) for one pose ``q``; or for a
    batch ``q`` of shape (T, 35) returns arrays (T, n_bodies, 3, 3) and (T, n_bodies, 3)."""
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    Q = q.reshape(-1, N_DOF)
    f = _fk_function(ch)
    out = np.asarray(f.map(Q.shape[0])(Q.T)).T  # (T, 12*nb)
    nb = len(ch.bodies)
    out = out.reshape(Q.shape[0], nb, 12)
    R = out[:, :, :9].reshape(Q.shape[0], nb, 3, 3).transpose(0, 1, 3, 2)  # casadi reshape is column-major
    p = out[:, :, 9:]
    return (R[0], p[0]) if single else (R, p)


@functools.lru_cache(maxsize=64)
def handle_positions_fn(ch: Character, names: tuple[str, ...]) -> ca.Function:
    """casadi.Function q (35) → (3, len(names)) world positions of the named handles."""
    q = ca.SX.sym("q", N_DOF)
    tr = frame_transforms(ch, q)
    return ca.Function("handles", [q], [ca.horzcat(*[handle_position(ch, q, n, tr) for n in names])])
