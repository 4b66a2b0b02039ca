"""The compose character as an independent Pinocchio model (test-only reference).

One Pinocchio joint per compose DOF, placed at the DOF's offset in its parent frame, each
body's ellipsoid inertia appended to the joint of the frame that carries it, and one
operational frame per handle.  Joints are either Pinocchio's specialised axis-aligned
types (``aligned=True``, the fast ones: RX/RY/RZ, PX/PY/PZ; a DOF about a negative axis
gets a joint frame turned by 180° so that its axis is positive) or the generic
``JointModelRevoluteUnaligned`` / ``JointModelPrismaticUnaligned`` about the DOF's axis.  Built only from the public data of
:class:`scenegraph.model.body.Character`, never from compose's dynamics code.

Pinocchio's CRBA assumes the joints are numbered depth-first (each subtree a contiguous
block of velocity indices); compose numbers its DOFs parent-before-child but not
depth-first (left arm, left leg, right arm, ...).  So the joints are added in depth-first
order and :class:`PinModel` permutes vectors between the two numberings.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from scenegraph.model.body import Character


def depth_first_order(ch: Character) -> list[int]:
    """compose DOF indices in depth-first order of the DOF tree (children by index)."""
    children: dict[int, list[int]] = {}
    for i, d in enumerate(ch.dofs):
        children.setdefault(d.parent, []).append(i)
    order: list[int] = []
    stack = list(reversed(children.get(-1, [])))
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children.get(i, [])))
    assert sorted(order) == list(range(len(ch.dofs)))
    return order


@dataclass
class PinModel:
    model: pin.Model
    data: pin.Data
    frames: dict[str, int]  # handle name -> Pinocchio frame id
    order: np.ndarray  # order[k] = compose DOF of Pinocchio's q/v index k

    def to_pin(self, x: np.ndarray) -> np.ndarray:
        """compose numbering -> Pinocchio numbering (last axis)."""
        return np.ascontiguousarray(np.asarray(x)[..., self.order])

    def from_pin(self, y: np.ndarray) -> np.ndarray:
        """Pinocchio numbering -> compose numbering (last axis)."""
        y = np.asarray(y)
        out = np.empty_like(y)
        out[..., self.order] = y
        return out

    def rnea(self, q, qd, qdd, fext=None) -> np.ndarray:
        args = [self.model, self.data, self.to_pin(q), self.to_pin(qd), self.to_pin(qdd)]
        return self.from_pin(pin.rnea(*args, fext) if fext is not None else pin.rnea(*args))

    def gravity(self, q) -> np.ndarray:
        return self.from_pin(pin.computeGeneralizedGravity(self.model, self.data, self.to_pin(q)))

    def mass_matrix(self, q) -> np.ndarray:
        """M(q) in compose numbering; CRBA fills the upper triangle, which is symmetrised."""
        U = np.triu(pin.crba(self.model, self.data, self.to_pin(q)))
        M = U + np.triu(U, 1).T
        return self.from_pin(self.from_pin(M).T).T  # permute rows and columns

    def handle_jacobian(self, q, name: str) -> np.ndarray:
        """3×35 Jacobian of a handle's world position (compose numbering)."""
        qp = self.to_pin(q)
        pin.computeJointJacobians(self.model, self.data, qp)
        pin.updateFramePlacements(self.model, self.data)
        J = pin.getFrameJacobian(self.model, self.data, self.frames[name], pin.LOCAL_WORLD_ALIGNED)[:3]
        return self.from_pin(J)

    def joint_of(self, name: str) -> tuple[int, np.ndarray, np.ndarray]:
        """(joint id, handle point in the joint frame, joint-frame rotation to world) for a handle."""
        fr = self.model.frames[self.frames[name]]
        return fr.parentJoint, fr.placement.translation.copy(), self.data.oMi[fr.parentJoint].rotation.copy()


_FLIP = {0: np.diag([-1.0, 1.0, -1.0]), 1: np.diag([-1.0, -1.0, 1.0]), 2: np.diag([1.0, -1.0, -1.0])}


def _joint(kind: str, axis: np.ndarray, aligned: bool):
    """(Pinocchio joint model, F): F rotates the joint frame into the compose DOF frame's axes
    (R_compose = R_joint F^T); identity unless an aligned joint needs its axis flipped."""
    if not aligned:
        jm = pin.JointModelPrismaticUnaligned(axis) if kind == "prismatic" else pin.JointModelRevoluteUnaligned(axis)
        return jm, np.eye(3)
    k = int(np.argmax(np.abs(axis)))
    assert np.isclose(abs(axis[k]), 1.0), "aligned joints need a coordinate axis"
    jm = getattr(pin, f"JointModel{'P' if kind == 'prismatic' else 'R'}{'XYZ'[k]}")()
    return jm, (np.eye(3) if axis[k] > 0 else _FLIP[k])  # a half turn about another axis maps e_k to -e_k


def build_pinocchio(ch: Character, aligned: bool = True) -> PinModel:
    model = pin.Model()
    model.gravity = pin.Motion(np.array([0.0, 0.0, -9.81, 0.0, 0.0, 0.0]))
    order = depth_first_order(ch)
    jid: dict[int, int] = {}
    flip: dict[int, np.ndarray] = {-1: np.eye(3)}
    for i in order:
        d = ch.dofs[i]
        parent = 0 if d.parent < 0 else jid[d.parent]
        jm, flip[i] = _joint(d.kind, np.array(d.axis, dtype=float), aligned)
        Fp = flip[d.parent]
        placement = pin.SE3(Fp.T @ flip[i], Fp.T @ np.array(d.offset, dtype=float))
        jid[i] = model.addJoint(parent, jm, placement, d.name)
    for b in ch.bodies:
        F = flip[b.frame]
        model.appendBodyToJoint(jid[b.frame], pin.Inertia(b.mass, np.array(b.center), b.inertia), pin.SE3(F, np.zeros(3)))
    frames = {}
    for h in ch.handles:
        f = ch.body(h.body).frame
        placement = pin.SE3(flip[f], flip[f] @ np.array(h.point, dtype=float))
        frames[h.name] = model.addFrame(pin.Frame(h.name, jid[f], placement, pin.FrameType.OP_FRAME))
    assert [model.joints[jid[i]].idx_v for i in order] == list(range(len(order)))
    return PinModel(model, model.createData(), frames, np.array(order))


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
