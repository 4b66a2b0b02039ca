"""Momentum-preserving edits of a captured jump (thesis ch. 4): longer, higher, turned.

The clip's motion q(t) (35 DOFs at ``fps``, our character) is cut into three stages by its
feet: ground (take-off), flight (no foot handle within FLIGHT_CLEARANCE of its standing
height), ground (landing).  Its momentum curves are pre-fitted: the centre of mass c(t), the
linear momentum P = m ċ and the angular momentum H about c (:func:`body_momenta`); in flight
c is fitted with a ballistic parabola (g = 9.81 fixed).

The edit keeps the *shape* of those curves and changes their values where the new
constraints need it:

* flight: a new apex rise h' = h + ``higher`` gives the take-off vertical speed √(2 g h') and
  a new flight time (the same landing height); the flight's frames are re-timed to it; the
  horizontal take-off velocity covers the clip's flight distance + ``longer`` in that time.
  c'(t) is the exact parabola from the take-off point with that velocity;
* ground stages: each momentum component is scaled, P'_k(t) = s_k P_k(t) with s_k the ratio
  of the new to the clip's momentum at take-off (landing), so the push-off and the landing
  absorption keep their curves (components whose take-off momentum is below 0.2 m/s × m
  get an additive ramp instead); c' integrates P'/m;
* turn: an extra rotation ψ(t) about the vertical through c' with ψ̇ = K / I_zz(t) (I_zz the
  pose's inertia about that axis), i.e. a constant extra angular momentum K in flight, ramped
  in on the push-off (following the vertical momentum's rise) and out on the landing; K makes
  the total ψ equal ``turn``;
* the pose: joint angles are the clip's (re-timed in flight); the root is moved so that the
  model's centre of mass is c'(t) and turned by ψ(t); on the ground a Gauss–Newton leg fit
  keeps every planted foot handle where it was planted (take-off feet where the clip had them,
  landing feet where they touch down), then the root is re-centred on c' (IK_ROUNDS times).

:func:`naive_edit` is the displacement-map edit it is compared with: the same clip with the
root shifted by ``longer`` (a smoothstep over the flight) and raised by ``higher``·sin(πτ/T)
in flight, times unchanged.

Units: m, s, rad, kg; world frame z up (the clip as :func:`scenegraph.mocap.clip.load_clip` gives it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenegraph.model.body import N_DOF, Character
from scenegraph.model.kinematics import handle_positions_fn, numeric_fk
from scenegraph.model.legfit import fit_legs as _fit_legs
from scenegraph.model.residual import CONTACT_HANDLES

__all__ = ["JumpStages", "EditResult", "body_momenta", "jump_stages", "momentum_edit", "naive_edit",
           "momentum_correlation", "G", "FLIGHT_CLEARANCE", "IK_ROUNDS"]

G = 9.81
FLIGHT_CLEARANCE = 0.02  # m above its standing height: a foot handle is off the ground (README_jump: 2 cm)
IK_ROUNDS = 3
SMOOTH = 0.025  # s: σ of the Gaussian that smooths the leg corrections in time
BLEND = 0.12  # s: leg corrections fade out after take-off and in before touch-down
SCALE_MIN_SPEED = 0.2  # m/s: a take-off velocity component below this is edited additively, not scaled


@dataclass(frozen=True)
class JumpStages:
    """Frames of a clip: ground [0, a), flight [a, b), ground [b, T); ``planted`` (T, 6) bool
    per CONTACT_HANDLES handle; ``stand`` (6,) m standing height of each handle."""

    a: int
    b: int
    planted: np.ndarray
    stand: np.ndarray


@dataclass(frozen=True)
class EditResult:
    """The edited motion ``q`` (T', 35) at ``fps``, its stages, and what was asked and met."""

    q: np.ndarray
    fps: float
    stages: JumpStages
    clip_stages: JumpStages
    asked: dict
    measured: dict


def body_momenta(ch: Character, q: np.ndarray, fps: float):
    """(com (T,3) m, P (T,3) kg·m/s, H (T,3) kg·m²/s about the com, Izz (T,) kg·m² about the
    vertical through the com) of poses ``q`` (T, 35) sampled at ``fps`` (central differences)."""
    R, p = numeric_fk(ch, q)  # (T, nb, 3, 3), (T, nb, 3)
    m = np.array([b.mass for b in ch.bodies])
    ctr = np.array([b.center for b in ch.bodies])
    Ib = np.array([b.inertia for b in ch.bodies])
    x = p + np.einsum("tbij,bj->tbi", R, ctr)  # body centres of mass
    M = m.sum()
    com = np.einsum("b,tbi->ti", m, x) / M
    dt = 1.0 / fps
    v = np.gradient(x, dt, axis=0)
    vc = np.gradient(com, dt, axis=0)
    Rd = np.gradient(R, dt, axis=0)
    W = np.einsum("tbij,tbkj->tbik", Rd, R)  # ω^ = Ṙ Rᵀ
    w = np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)
    Iw = np.einsum("tbij,bjk,tblk->tbil", R, Ib, R)  # world inertia per body
    r = x - com[:, None]
    H = np.einsum("b,tbi->ti", m, np.cross(r, v - vc[:, None])) + np.einsum("tbij,tbj->ti", Iw, w)
    Izz = np.einsum("b,tb->t", m, r[..., 0] ** 2 + r[..., 1] ** 2) + Iw[..., 2, 2].sum(axis=1)
    return com, M * vc, H, Izz


def jump_stages(ch: Character, q: np.ndarray, stand_frames: int = 20) -> JumpStages:
    """The stages of a jump clip (the longest run of frames with every foot handle more than
    FLIGHT_CLEARANCE above its standing height, the median of the first ``stand_frames``)."""
    hp = np.asarray(handle_positions_fn(ch, tuple(CONTACT_HANDLES)).map(len(q))(q.T)).reshape(
        3, len(CONTACT_HANDLES), len(q), order="F")
    z = hp[2].T  # (T, 6)
    stand = np.median(z[:stand_frames], axis=0)
    up = z > stand + FLIGHT_CLEARANCE
    air = up.all(axis=1)
    best, k = (0, 0), 0
    while k < len(air):
        if air[k]:
            j = k
            while j < len(air) and air[j]:
                j += 1
            if j - k > best[1] - best[0]:
                best = (k, j)
            k = j
        else:
            k += 1
    if best[1] - best[0] < 5:
        raise ValueError("no flight found in the clip (both feet off the ground for at least 5 frames)")
    return JumpStages(best[0], best[1], ~up, stand)


def _ballistic_fit(t: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c0, v0) of c(τ) = c0 + v0 τ − (0, 0, g/2) τ² fitted to c (n, 3) at τ = t − t[0]."""
    tau = t - t[0]
    A = np.stack([np.ones_like(tau), tau], axis=1)
    c0, v0 = np.zeros(3), np.zeros(3)
    for k in range(3):
        y = c[:, k] + (G * tau ** 2 / 2 if k == 2 else 0.0)
        (c0[k], v0[k]), *_ = np.linalg.lstsq(A, y, rcond=None)
    return c0, v0


def _retime(q: np.ndarray, a: int, b: int, n_new: int) -> np.ndarray:
    """q with its frames [a, b) replaced by n_new frames over the same span (linear, per DOF;
    the yaw unwrapped)."""
    u_old = np.linspace(0.0, 1.0, b - a + 1)  # frames a..b (b: the first landing frame)
    u_new = np.linspace(0.0, 1.0, n_new + 1)
    mid = np.stack([np.interp(u_new, u_old, q[a:b + 1, k]) for k in range(N_DOF)], axis=1)
    return np.concatenate([q[:a], mid[:-1], q[b:]], axis=0)


def _scaled(P: np.ndarray, at: np.ndarray, new: np.ndarray, ramp: np.ndarray, m: float) -> np.ndarray:
    """P (n, 3) with each component scaled so that its value at ``at`` (3,) becomes ``new``
    (3,); components below SCALE_MIN_SPEED × m get ``(new − at) · ramp`` added instead."""
    out = P.copy()
    for k in range(3):
        if abs(at[k]) > SCALE_MIN_SPEED * m:
            out[:, k] = P[:, k] * new[k] / at[k]
        else:
            out[:, k] = P[:, k] + (new[k] - at[k]) * ramp
    return out


def _blend_into_flight(d: np.ndarray, a: int, b: int, n: int) -> np.ndarray:
    """Corrections ``d`` (T, 35) of the ground frames carried into the flight [a, b): the
    take-off's fading out and the landing's fading in over ``n`` frames (smoothstep), so the
    legs do not jump at take-off or touch-down."""
    out = d.copy()
    k = np.arange(a, b)
    u0 = np.clip((k - a + 1) / max(n, 1), 0.0, 1.0)
    u1 = np.clip((b - k) / max(n, 1), 0.0, 1.0)
    w0 = 1 - u0 * u0 * (3 - 2 * u0)
    w1 = 1 - u1 * u1 * (3 - 2 * u1)
    out[a:b] = np.outer(w0, d[a - 1]) + np.outer(w1, d[b] if b < len(d) else 0.0)
    return out


def _smooth(d: np.ndarray, sigma: float) -> np.ndarray:
    """Each column of d (T, n) convolved with a Gaussian of ``sigma`` frames (ends padded by
    their values)."""
    r = int(math.ceil(3 * sigma))
    if r < 1:
        return d
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    pad = np.concatenate([np.repeat(d[:1], r, 0), d, np.repeat(d[-1:], r, 0)])
    return np.stack([np.convolve(pad[:, j], k, mode="valid") for j in range(d.shape[1])], axis=1)


def _inertia_com(ch: Character, q: np.ndarray) -> np.ndarray:
    """(T, 3, 3) inertia tensors (kg·m²) of poses q about their centres of mass, world axes."""
    R, p = numeric_fk(ch, q)
    m = np.array([b.mass for b in ch.bodies])
    x = p + np.einsum("tbij,bj->tbi", R, np.array([b.center for b in ch.bodies]))
    r = x - (np.einsum("b,tbi->ti", m, x) / m.sum())[:, None]
    Iw = np.einsum("tbij,bjk,tblk->til", R, np.array([b.inertia for b in ch.bodies]), R)
    rr = np.einsum("tbi,tbi->tb", r, r)
    return Iw + np.einsum("b,tb->t", m, rr)[:, None, None] * np.eye(3) - np.einsum("b,tbi,tbj->tij", m, r, r)


def _rotate_about_com(q: np.ndarray, c: np.ndarray, Rc: np.ndarray) -> np.ndarray:
    """Poses q (T, 35) rotated by Rc (T, 3, 3) about their centres of mass c (T, 3): the root
    (Rz(yaw) Ry(pitch) Rx(roll)) and its position; yaw kept continuous with q's."""
    out = q.copy()
    cy, sy, cp, sp, cr, sr = (f(q[:, k]) for k in (3, 4, 5) for f in (np.cos, np.sin))
    Rr = np.empty((len(q), 3, 3))
    Rr[:, 0] = np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], 1)
    Rr[:, 1] = np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], 1)
    Rr[:, 2] = np.stack([-sp, cp * sr, cp * cr], 1)
    Rn = np.einsum("tij,tjk->tik", Rc, Rr)
    yaw = np.arctan2(Rn[:, 1, 0], Rn[:, 0, 0])
    out[:, 3] = yaw + 2 * np.pi * np.round((q[:, 3] - yaw) / (2 * np.pi))
    out[:, 4] = np.arcsin(np.clip(-Rn[:, 2, 0], -1.0, 1.0))
    out[:, 5] = np.arctan2(Rn[:, 2, 1], Rn[:, 2, 2])
    out[:, :3] = c + np.einsum("tij,tj->ti", Rc, q[:, :3] - c)
    return out


def _hold_angular_momentum(ch: Character, q: np.ndarray, a: int, b: int, fps: float, rounds: int = 2) -> np.ndarray:
    """q with the flight frames [a, b) turned about their centre of mass so that the angular
    momentum about it is constant: a whole-body angular velocity ω_c = I⁻¹(H̄ − H) is added,
    with H̄ the I⁻¹-weighted mean of H so that ∫ω_c dt = 0 and the pose at touch-down is
    (to first order) unchanged; ``rounds`` passes."""
    out = q.copy()
    dt = 1.0 / fps
    for _ in range(rounds):
        c, _, H, _ = body_momenta(ch, out, fps)
        Iinv = np.linalg.inv(_inertia_com(ch, out[a:b]))
        Hf = H[a:b]
        Hbar = np.linalg.solve(Iinv.sum(axis=0), np.einsum("tij,tj->i", Iinv, Hf))
        w = np.einsum("tij,tj->ti", Iinv, Hbar - Hf)
        Rc = np.empty((b - a, 3, 3))
        R = np.eye(3)
        for k in range(b - a):  # exp(ω dt) by Rodrigues, integrated from the take-off
            th = float(np.linalg.norm(w[k])) * dt
            if th > 1e-12:
                u = w[k] / np.linalg.norm(w[k])
                K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
                R = (np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K) @ R
            Rc[k] = R
        out[a:b] = _rotate_about_com(out[a:b], c[a:b], Rc)
    return out


def _turn_about(q: np.ndarray, c: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Poses turned by ψ (T,) about the vertical through c (T, 3)."""
    out = q.copy()
    cs, sn = np.cos(psi), np.sin(psi)
    d = q[:, :2] - c[:, :2]
    out[:, 0] = c[:, 0] + cs * d[:, 0] - sn * d[:, 1]
    out[:, 1] = c[:, 1] + sn * d[:, 0] + cs * d[:, 1]
    out[:, 3] = q[:, 3] + psi
    return out


def momentum_edit(ch: Character, q: np.ndarray, fps: float, longer: float = 0.0, higher: float = 0.0,
                  turn: float = 0.0) -> EditResult:
    """The clip ``q`` (T, 35) at ``fps`` edited to land ``longer`` m further along its jump,
    rise ``higher`` m higher and turn ``turn`` rad more about the vertical (module docstring)."""
    q = np.asarray(q, float)
    st = jump_stages(ch, q)
    a, b = st.a, st.b
    t = np.arange(len(q)) / fps
    c, P, H, Izz = body_momenta(ch, q, fps)
    M = ch.total_mass
    c0, v0 = _ballistic_fit(t[a:b], c[a:b])
    Tf = (b - a) / fps  # take-off (frame a) to touch-down (frame b)
    h = v0[2] ** 2 / (2 * G)
    dz = c0[2] + v0[2] * Tf - G * Tf ** 2 / 2 - c0[2]  # landing com height relative to take-off
    vz = math.sqrt(2 * G * max(h + higher, 1e-4))
    Tn = (vz + math.sqrt(max(vz * vz - 2 * G * dz, 0.0))) / G  # vz T − g T²/2 = dz
    vh = v0[:2]
    u = vh / max(np.linalg.norm(vh), 1e-9)
    dist = float(vh @ u) * Tf
    v_par = (dist + longer) / Tn
    v_perp = (vh - u * (vh @ u)) * Tf / Tn
    v_new = np.r_[u * v_par + v_perp, vz]
    n_new = max(2, int(round(Tn * fps)))
    b_new = a + n_new
    qn = _retime(q, a, b, n_new)
    # momentum on the ground stages: the clip's curves, scaled to the new take-off / landing
    tn = np.arange(len(qn)) / fps
    Pn = np.zeros((len(qn), 3))
    ramp_pre = np.clip((t[:a] - t[a] + 0.3) / 0.3, 0.0, 1.0)
    Pn[:a] = _scaled(P[:a], M * v0, M * v_new, ramp_pre, M)
    v_land_clip = v0 - np.r_[0.0, 0.0, G * Tf]
    v_land_new = v_new - np.r_[0.0, 0.0, G * Tn]
    ramp_post = np.clip(1.0 - (t[b:] - t[b]) / 0.3, 0.0, 1.0)
    Pn[b_new:] = _scaled(P[b:], M * v_land_clip, M * v_land_new, ramp_post, M)
    tau = tn[a:b_new] - tn[a]
    # the new com: integrate P'/m on the ground stages, the exact parabola in flight
    cn = np.zeros((len(qn), 3))
    cn[0] = c[0]
    for k in range(1, a):
        cn[k] = cn[k - 1] + (Pn[k - 1] + Pn[k]) / (2 * M) / fps
    ca0 = cn[a - 1] + (Pn[a - 1] / M + v_new) / 2 / fps
    cn[a:b_new] = ca0 + np.outer(tau, v_new) - np.outer(tau ** 2, [0.0, 0.0, G / 2])
    tl = Tn
    cn[b_new] = ca0 + v_new * tl - np.r_[0.0, 0.0, G * tl * tl / 2]
    Pn[a:b_new] = M * (v_new - np.outer(tau, [0.0, 0.0, G]))
    for k in range(b_new + 1, len(qn)):
        cn[k] = cn[k - 1] + (Pn[k - 1] + Pn[k]) / (2 * M) / fps
    # the root carries the com: model com of the re-timed pose → c'
    cm, _, _, Izz_n = body_momenta(ch, qn, fps)
    cm_landing = cm[b_new].copy()  # the re-timed clip's com at touch-down
    out = qn.copy()
    out[:, :3] += cn - cm
    # the turn: ψ̇ = K / Izz, K ramped in with the vertical push-off and out over the landing
    psi = np.zeros(len(qn))
    if abs(turn) > 0:
        w = np.ones(len(qn))
        pz = np.clip(Pn[:a, 2], 0.0, None)
        w[:a] = pz / max(pz[-1], 1e-9) * (tn[:a] > tn[a] - 0.35)
        w[b_new:] = np.clip(1.0 - (tn[b_new:] - tn[b_new]) / 0.2, 0.0, 1.0)
        rate = w / Izz_n
        K = turn / (rate.sum() / fps)
        psi = np.cumsum(K * rate) / fps
    out = _turn_about(out, cn, psi)
    # planted feet stay put: take-off feet where the clip planted them, landing feet where they touch down
    stn = np.concatenate([st.planted[:a], np.zeros((n_new, len(CONTACT_HANDLES)), bool), st.planted[b:]])
    for _ in range(IK_ROUNDS):
        hq = np.asarray(handle_positions_fn(ch, tuple(CONTACT_HANDLES)).map(len(qn))(qn.T)).reshape(
            3, len(CONTACT_HANDLES), len(qn), order="F").transpose(2, 0, 1)
        # before the flight: the clip's own footprints; after it: the clip's foot tracks moved
        # rigidly as the body lands (shifted by the landing displacement, turned by the final ψ)
        targ = hq.copy()
        shift = cn[b_new] - cm_landing
        cs, sn = math.cos(psi[-1]), math.sin(psi[-1])
        rel = hq[b_new:, :2, :] + shift[None, :2, None] - cn[b_new, :2][None, :, None]
        targ[b_new:, 0, :] = cn[b_new, 0] + cs * rel[:, 0] - sn * rel[:, 1]
        targ[b_new:, 1, :] = cn[b_new, 1] + sn * rel[:, 0] + cs * rel[:, 1]
        fit = _fit_legs(ch, out, targ, stn)
        out = out + _smooth(_blend_into_flight(fit - out, a, b_new, int(round(BLEND * fps))), SMOOTH * fps)
        cm, _, _, _ = body_momenta(ch, out, fps)
        out[:, :3] += cn - cm
    out = _hold_angular_momentum(ch, out, a, b_new, fps)
    # measures: how far a planted handle is from its target after the smoothing (m)
    hp = np.asarray(handle_positions_fn(ch, tuple(CONTACT_HANDLES)).map(len(out))(out.T)).reshape(
        3, len(CONTACT_HANDLES), len(out), order="F").transpose(2, 0, 1)
    err = np.where(stn, np.linalg.norm(hp - targ, axis=1), 0.0)
    foot_err = float(err.max())
    c2, P2, H2, _ = body_momenta(ch, out, fps)
    # compared in the turned frame: the edit's momenta rotated back by ψ about the vertical
    cs, sn = np.cos(-psi), np.sin(-psi)
    P2l = np.c_[cs * P2[:, 0] - sn * P2[:, 1], sn * P2[:, 0] + cs * P2[:, 1], P2[:, 2]]
    H2l = np.c_[cs * H2[:, 0] - sn * H2[:, 1], sn * H2[:, 0] + cs * H2[:, 1], H2[:, 2]]
    st2 = JumpStages(a, b_new, stn, st.stand)
    dist_new = float((c2[b_new] - c2[a])[:2] @ u)
    measured = {"flight_s": Tn, "clip_flight_s": Tf, "com_apex_rise": float(c2[a:b_new, 2].max() - c2[a, 2]),
                "clip_com_apex_rise": float(c[a:b, 2].max() - c[a, 2]),
                "com_flight_distance": dist_new, "clip_com_flight_distance": float((c[b] - c[a])[:2] @ u),
                "turn_deg": math.degrees(float(out[-1, 3] - q[-1, 3])), "planted_foot_error_max": foot_err,
                "planted_foot_error_frames": err.max(axis=1),
                "momentum_corr": momentum_correlation(P, H, (a, b), P2l, H2l, (a, b_new))}
    asked = {"longer": longer, "higher": higher, "turn_deg": math.degrees(turn)}
    return EditResult(out, fps, st2, st, asked, measured)


def naive_edit(q: np.ndarray, stages: JumpStages, fps: float, longer: float = 0.0, higher: float = 0.0,
               direction=(1.0, 0.0)) -> np.ndarray:
    """The displacement-map edit: the root shifted ``longer`` m along ``direction`` by a
    smoothstep over the flight and raised ``higher``·sin(π τ / T) in it; times unchanged."""
    out = np.array(q, float)
    a, b = stages.a, stages.b
    k = np.arange(len(q))
    s = np.clip((k - a) / max(b - a, 1), 0.0, 1.0)
    s = s * s * (3 - 2 * s)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    out[:, 0] += longer * s * d[0]
    out[:, 1] += longer * s * d[1]
    inside = (k >= a) & (k < b)
    out[inside, 2] += higher * np.sin(np.pi * (k[inside] - a) / (b - a))
    return out


def _stagewise(x: np.ndarray, cuts: tuple[int, int], n: tuple[int, int, int] = (60, 40, 60)) -> np.ndarray:
    """x (T, …) resampled stage by stage (ground, flight, ground) to n samples each."""
    a, b = cuts
    parts = []
    for (lo, hi), m in zip(((2, a), (a, b), (b, len(x) - 2)), n):  # the ends' differences are one-sided
        u = np.linspace(lo, hi - 1, m)
        parts.append(np.stack([np.interp(u, np.arange(len(x)), x[:, k]) for k in range(x.shape[1])], axis=1))
    return np.concatenate(parts)


def momentum_correlation(P, H, cuts, P2, H2, cuts2) -> dict:
    """Pearson correlations of two jumps' momentum curves on a stage-normalised time axis:
    the larger horizontal (forward) and the vertical linear momentum and the angular momentum about the
    clip's dominant axis; ``min`` is the smallest of the three."""
    A, B = _stagewise(np.c_[P, H], cuts), _stagewise(np.c_[P2, H2], cuts2)
    axis = 3 + int(np.argmax(np.abs(A[:, 3:]).mean(axis=0)))
    out = {}
    fwd = int(np.argmax(np.abs(A[:, :2]).mean(axis=0)))
    for name, k in (("P_forward", fwd), ("P_z", 2), ("H_main", axis)):
        out[name] = float(np.corrcoef(A[:, k], B[:, k])[0, 1])
    out["min"] = min(out.values())
    return out
