"""A foot handle near the floor does not move horizontally (issue #15 item 3): no skid at
touch-down or lift-off, no glide of a planted handle between its pinned collocation points,
no scuff of a swing toe through the floor.

The footstep pins hold a planted handle at the collocation points only; between them (and
just before touch-down, just after lift-off, and for a swing toe skimming the floor) nothing
holds its horizontal velocity.  The term weighs every foot handle's (heel, ball, toe of both
feet) horizontal velocity v_xy (world, m/s) by how close it is to the ground:

    φ(h) = max(1 − h / H_NO_SLIP, 0)²       (h: height above the ground under the handle, m)

so a handle on the floor (h ≤ 0) counts fully, one 10 mm up not at all, and integrates over
the motion on a dense grid (``hz``, 120 Hz by default):

    E_slip = w_slip ∫ φ(h(t)) |v_xy(t)|² dt               (w_slip in s/m², E_slip dimensionless)

entered as least-squares residuals sqrt(w_slip Δt_i) max(1 − h/H, 0) v_xy(t_i), which the
transcription scales by OBJ_SCALE like its other terms (objective += OBJ_SCALE² E_slip, next
to the energy (OBJ_SCALE / m g)² ∫ Σ α Q_m² dt; both integrals over time, so their ratio does
not change with the scene's length, the sampling rate or the body's mass).  Why
:data:`NO_SLIP_WEIGHT`: see its comment.
"""
from __future__ import annotations

import functools

import casadi as ca
import numpy as np

from scenegraph.model.body import N_DOF, Character
from scenegraph.model.kinematics import frame_transforms, handle_position
from scenegraph.model.motion import basis
from scenegraph.model.residual import CONTACT_HANDLES

__all__ = ["NO_SLIP_WEIGHT", "H_NO_SLIP", "phi", "handle_state_fn", "no_slip_residuals", "handle_slip"]

H_NO_SLIP = 0.010  # m: a handle higher than this above the ground may move freely
# w_slip, s/m².  A handle on the floor moving at v for τ seconds costs OBJ_SCALE² w v² τ: the
# 0.1 m/s of a 1 mm glide between two 30 Hz collocation points held through a 0.6 s stance costs
# 900 · 10 · 0.01 · 0.6 = 54; a touch-down skid of 0.7 m/s over its last 5 mm (≈ 10 ms, φ ≈ 0.5)
# ≈ 22; a swing toe crossing the 10 mm band at 6 m/s for 3 ms (φ ≈ 0.3) ≈ 290 — against a
# walking gait cycle's objective of ≈ 440 and a running one's of ≈ 23.  Chosen with
# STANCE_FRAME_WEIGHT (see there: ten times more swamped the run's energy); the same number for
# every gait, body and scene length (module docstring).
NO_SLIP_WEIGHT = 10.0


def phi(h, h0: float = H_NO_SLIP):
    """φ(h) = max(1 − h/h0, 0)² (numpy or CasADi): 1 on the floor, 0 at h0 and above; h < 0 (below
    the floor) grows past 1."""
    if isinstance(h, (ca.SX, ca.MX, ca.DM)):
        return ca.fmax(1.0 - h / h0, 0.0) ** 2
    return np.maximum(1.0 - np.asarray(h, float) / h0, 0.0) ** 2


@functools.lru_cache(maxsize=16)
def handle_state_fn(ch: Character, names: tuple[str, ...] = CONTACT_HANDLES) -> ca.Function:
    """casadi.Function (q, q̇) (35 each; q̇ in world s) → (positions (3, n), velocities (3, n)) of
    the named handles (world, m and m/s): v = J(q) q̇."""
    q, qd = ca.SX.sym("q", N_DOF), ca.SX.sym("qd", N_DOF)
    tr = frame_transforms(ch, q)
    pos = ca.horzcat(*[handle_position(ch, q, n, tr) for n in names])
    vel = ca.reshape(ca.jtimes(ca.vec(pos), q, qd), 3, len(names))
    return ca.Function("handle_state", [q, qd], [pos, vel])


def no_slip_residuals(ch: Character, ground, s: np.ndarray, dt: float, P, warp, n_ctrl: int, n_warp: int,
                      weight: float, h0: float = H_NO_SLIP):
    """Least-squares residuals sqrt(weight · dt) max(1 − h/h0, 0) v_xy (2 per handle and sample) at
    the canonical samples ``s``; ``P`` (n_ctrl × 35) and ``warp`` (n_warp) CasADi control points
    (world velocity q̇ = (dq/ds) / T'(s)).  None without samples."""
    s = np.asarray(s, float)
    if not len(s):
        return None
    B0, B1 = (ca.sparsify(ca.DM(basis(n_ctrl, s, d))) for d in (0, 1))
    T1 = ca.mtimes(ca.sparsify(ca.DM(basis(n_warp, s, 1))), warp).T  # (1, n)
    Q = ca.mtimes(B0, P).T
    Qd = ca.mtimes(B1, P).T / ca.repmat(T1, N_DOF, 1)
    pos, vel = handle_state_fn(ch).map(len(s))(Q, Qd)  # (3, n_h · n) each, handle-major per sample
    h = pos[2, :]
    if ground is not None and not ground.flat:
        h = h - ground.z(pos[0, :], pos[1, :])
    gate = ca.fmax(1.0 - h / h0, 0.0)  # sqrt φ
    return np.sqrt(weight * dt) * ca.vec(vel[:2, :] * ca.repmat(gate, 2, 1))


def handle_slip(ch: Character, ground, q: np.ndarray, qd: np.ndarray, h0: float = H_NO_SLIP):
    """Numeric: (heights (T, n_h) m, horizontal speeds (T, n_h) m/s, φ (T, n_h)) of CONTACT_HANDLES
    for poses ``q`` and world velocities ``qd`` (T, 35)."""
    q, qd = np.atleast_2d(q), np.atleast_2d(qd)
    T = q.shape[0]
    pos, vel = (np.asarray(a).reshape(3, T, -1) for a in handle_state_fn(ch).map(T)(q.T, qd.T))
    h = pos[2] - (0.0 if ground is None or ground.flat else ground.height(pos[0], pos[1]))
    return h, np.linalg.norm(vel[:2], axis=0), phi(h, h0)
