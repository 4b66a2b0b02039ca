"""The compose character as an independent Pinocchio model (test-only reference).

One Pinocchio joint per compose DOF (``JointModelRevoluteUnaligned`` or
``JointModelPrismaticUnaligned`` about the DOF's axis, placed at the DOF's offset in its
parent frame), each body's ellipsoid inertia appended to the joint of the frame that
carries it, and one operational frame per handle.  Built only from the public data of
:class:`scenegraph.body.Character`, never from compose's dynamics code.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from scenegraph.body import Character


def build_pinocchio(ch: Character) -> tuple[pin.Model, dict[str, int]]:
    """(model, handle name -> Pinocchio frame id)."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array([0.0, 0.0, -9.81, 0.0, 0.0, 0.0]))
    jid: list[int] = []
    for d in ch.dofs:
        parent = 0 if d.parent < 0 else jid[d.parent]
        axis = np.array(d.axis, dtype=float)
        jm = pin.JointModelPrismaticUnaligned(axis) if d.kind == "prismatic" else pin.JointModelRevoluteUnaligned(axis)
        jid.append(model.addJoint(parent, jm, pin.SE3(np.eye(3), np.array(d.offset, dtype=float)), d.name))
    for b in ch.bodies:
        model.appendBodyToJoint(jid[b.frame], pin.Inertia(b.mass, np.array(b.center), b.inertia), pin.SE3.Identity())
    frames = {}
    for h in ch.handles:
        j = jid[ch.body(h.body).frame]
        frames[h.name] = model.addFrame(
            pin.Frame(h.name, j, pin.SE3(np.eye(3), np.array(h.point, dtype=float)), pin.FrameType.OP_FRAME))
    return model, frames


def random_states(ch: Character, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random (q, qd, qdd) rows within the joint limits, random root position and yaw."""
    rng = np.random.default_rng(seed)
    lo, hi = ch.lower.copy(), ch.upper.copy()
    lo[:3], hi[:3] = (-2.0, -2.0, 0.3), (2.0, 2.0, 1.5)
    lo[3], hi[3] = -np.pi, np.pi
    q = rng.uniform(lo, hi, size=(n, len(lo)))
    qd = rng.normal(scale=2.0, size=q.shape)
    qdd = rng.normal(scale=5.0, size=q.shape)
    return q, qd, qdd
