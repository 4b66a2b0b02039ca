"""Rotation matrix → unit quaternion: the one conversion of compose (USD joint rotations,
BVH and mocap tests).  Quaternions are (w, x, y, z), for column-vector rotation matrices."""
from __future__ import annotations

import numpy as np

__all__ = ["quat_from_matrix"]


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4), w ≥ 0, of rotation matrices (..., 3, 3) (Shepperd's method:
    per matrix the branch of the largest of w², x², y², z², vectorised)."""
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(R.shape[:-2] + (4,))
    # k == 0: w largest
    s = np.sqrt(np.maximum(1.0 + cand[..., 0], 1e-300)) * 2.0
    q0 = np.stack([0.25 * s, (R[..., 2, 1] - R[..., 1, 2]) / s, (R[..., 0, 2] - R[..., 2, 0]) / s,
                   (R[..., 1, 0] - R[..., 0, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    q1 = np.stack([(R[..., 2, 1] - R[..., 1, 2]) / s, 0.25 * s, (R[..., 0, 1] + R[..., 1, 0]) / s,
                   (R[..., 0, 2] + R[..., 2, 0]) / s], -1)
    s = np.sqrt(np.maximum(1.0 - m00 + m11 - m22, 1e-300)) * 2.0
    q2 = np.stack([(R[..., 0, 2] - R[..., 2, 0]) / s, (R[..., 0, 1] + R[..., 1, 0]) / s, 0.25 * s,
                   (R[..., 1, 2] + R[..., 2, 1]) / s], -1)
    s = np.sqrt(np.maximum(1.0 - m00 - m11 + m22, 1e-300)) * 2.0
    q3 = np.stack([(R[..., 1, 0] - R[..., 0, 1]) / s, (R[..., 0, 2] + R[..., 2, 0]) / s,
                   (R[..., 1, 2] + R[..., 2, 1]) / s, 0.25 * s], -1)
    for j, qj in enumerate((q0, q1, q2, q3)):
        q[k == j] = qj[k == j]
    q *= np.where(q[..., :1] < 0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q
