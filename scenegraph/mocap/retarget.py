"""Fit our character's q to clip joint positions: all frames in one CasADi/IPOPT problem.

    min_Q  Σ_t Σ_k w_k ‖x_k(q_t) − p_kt‖²  +  λ Σ_t ‖q_{t+1} − 2 q_t + q_{t−1}‖²_S  +  ε Σ_t ‖q_t^joint‖²
    s.t.   joint limits

x_k are our points (handles or ``origin:BODY`` joint centres), p_kt the clip points the rig
maps to them.  The second-difference term (λ, scaled per DOF so metres and radians weigh
alike) suppresses frame-to-frame jitter without smoothing the gait; ε keeps DOFs the points
do not determine (toes, wrists) near zero.  The start is an analytic guess: root position
and heading from the hips, everything else standing with slightly bent knees, which puts
IPOPT in the right basin (knees bend forward, no twisted-hip solutions).
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from scenarios.errors import ComposeError

from scenegraph.model.body import Character, N_DOF, N_ROOT, default_character, standing_pose
from scenegraph.model.kinematics import frame_transforms

__all__ = ["PointSpec", "point_name", "resolve_point", "point_expr", "points_fn", "point_positions", "retarget",
           "initial_guess", "RetargetError", "Reconstruction", "reconstruct", "reconstruct_clip"]


class RetargetError(ComposeError):
    """The fit did not converge."""


class PointSpec(BaseModel):
    """A point of our character: ``at`` (fractions of stature) in the frame of ``body``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    name: str = Field(min_length=1)
    body: str
    at: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @field_validator("body")
    @classmethod
    def _body_known(cls, v):
        known = [b.name for b in default_character().bodies]
        if v not in known:
            raise ValueError(f"unknown body {v!r} (known: {', '.join(known)})")
        return v

    @field_validator("at")
    @classmethod
    def _small(cls, v):
        if any(abs(x) > 1.0 for x in v):
            raise ValueError("offsets are fractions of stature and must lie within ±1")
        return v


def point_name(p: "str | PointSpec") -> str:
    return p if isinstance(p, str) else p.name


def resolve_point(ch: Character, p: "str | PointSpec") -> tuple[int, tuple[float, float, float]]:
    """(DOF frame index, offset in that frame in m) of a point of ours on character ``ch``."""
    if isinstance(p, PointSpec):
        return ch.body(p.body).frame, tuple(float(a) * ch.height for a in p.at)
    if p.startswith("origin:"):
        return ch.body(p[len("origin:"):]).frame, (0.0, 0.0, 0.0)
    h = ch.handle(p)
    return ch.body(h.body).frame, tuple(float(a) for a in h.point)


def point_expr(ch: Character, q, point: "str | PointSpec", transforms):
    """Symbolic world position of a point of ours: a handle name, ``origin:BODY`` or a PointSpec."""
    R, p = transforms
    f, off = resolve_point(ch, point)
    if not any(off):
        return p[f]
    return p[f] + ca.mtimes(R[f], ca.DM(off))


@functools.lru_cache(maxsize=64)
def points_fn(ch: Character, points: tuple[str, ...]) -> ca.Function:
    """casadi.Function q (35) → (3, K) positions of our points."""
    q = ca.SX.sym("q", N_DOF)
    tr = frame_transforms(ch, q)
    return ca.Function("points", [q], [ca.horzcat(*[point_expr(ch, q, n, tr) for n in points])])


def point_positions(ch: Character, points, q: np.ndarray) -> np.ndarray:
    """(T, K, 3) numeric positions of our points for q (T, 35) (or (K, 3) for one q)."""
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    Q = q.reshape(-1, N_DOF)
    f = points_fn(ch, tuple(points))
    out = np.asarray(f.map(Q.shape[0])(Q.T))  # (3, K*T), column blocks per frame
    K = len(points)
    out = out.reshape(3, Q.shape[0], K).transpose(1, 2, 0)
    return out[0] if single else out


def _yaw_from_hips(hip_l: np.ndarray, hip_r: np.ndarray) -> np.ndarray:
    """Heading (rad about +Z) whose left axis is along hip_r → hip_l, unwrapped over time."""
    d = hip_l - hip_r
    yaw = np.arctan2(-d[:, 0], d[:, 1])  # left = (−sin ψ, cos ψ)
    return np.unwrap(yaw)


def initial_guess(ch: Character, targets: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(T, 35): root at the clip's hip centre and heading, standing pose, knees bent 10°."""
    T = targets.shape[0]
    q = np.tile(standing_pose(ch), (T, 1))
    if "hip_l" in names and "hip_r" in names:
        hl, hr = targets[:, names.index("hip_l")], targets[:, names.index("hip_r")]
        q[:, 3] = _yaw_from_hips(hl, hr)
        q[:, 0:3] = 0.5 * (hl + hr)
    for side in ("l", "r"):
        q[:, ch.dof_index(f"knee_flex_{side}")] = math.radians(10)
        q[:, ch.dof_index(f"hip_flex_{side}")] = math.radians(5)
        q[:, ch.dof_index(f"ankle_flex_{side}")] = math.radians(5)
        q[:, ch.dof_index(f"elbow_flex_{side}")] = math.radians(10)
    return q


@functools.lru_cache(maxsize=16)
def _frame_cost(ch: Character, points: tuple[str, ...]) -> ca.Function:
    q = ca.SX.sym("q", N_DOF)
    P = ca.SX.sym("p", 3, len(points))
    w = ca.SX.sym("w", len(points))
    tr = frame_transforms(ch, q)
    c = 0
    for k, n in enumerate(points):
        e = point_expr(ch, q, n, tr) - P[:, k]
        c += w[k] * ca.sumsqr(e)
    return ca.Function("frame_cost", [q, P, w], [c])


# Extra pull toward zero for DOFs that the points determine poorly or that the fit would
# otherwise misuse: rolling the foot (ankle inversion) buys a few mm of sideways toe
# displacement that our 2-DOF ankle cannot produce by yaw (no tibial torsion in the model);
# without this term the fit rolls the feet by ±25–35° to gain 1–3 mm.  Wrists have no
# target (the CMU hand points do not fit our forearm length).
DEFAULT_REST = {"ankle_inv": 3e-4, "wrist_flex": 1e-4}


def _quadratic_terms(T: int, smoothness: float, rw: np.ndarray) -> ca.DM:
    """Constant Hessian S (sparse, N·T square) of the smoothness and rest terms, x = vec(Q)."""
    # per-DOF scale for the smoothness term: root translations in m, rotations in rad,
    # with a rough lever arm of 0.5 m so that 1 rad ~ 0.5 m of handle motion.
    scale = np.full(N_DOF, 0.5 ** 2)
    scale[0:3] = 1.0
    rows, cols, vals = [], [], []
    if T >= 3 and smoothness > 0:
        # D2ᵀD2 for second differences along time (pentadiagonal), times diag(scale)
        A = np.zeros((T, T))
        for t in range(T - 2):
            v = np.zeros(T)
            v[t:t + 3] = (1.0, -2.0, 1.0)
            A += np.outer(v, v)
        ti, tj = np.nonzero(A)
        for i in range(N_DOF):
            rows.append(ti * N_DOF + i)
            cols.append(tj * N_DOF + i)
            vals.append(2.0 * smoothness * scale[i] * A[ti, tj])
    idx = np.arange(T * N_DOF)
    rows.append(idx)
    cols.append(idx)
    vals.append(2.0 * np.tile(rw, T))
    rows, cols, vals = (np.concatenate(a) for a in (rows, cols, vals))
    n = T * N_DOF
    # sum duplicates (the diagonal appears in both parts)
    key = rows * n + cols
    uk, inv = np.unique(key, return_inverse=True)
    v = np.zeros(len(uk))
    np.add.at(v, inv, vals)
    sp = ca.Sparsity.triplet(n, n, (uk // n).astype(int).tolist(), (uk % n).astype(int).tolist())
    return ca.DM(sp, v)


@functools.lru_cache(maxsize=16)
def _frame_kernels(ch: Character, points: tuple) -> tuple[ca.Function, ca.Function]:
    """Per-frame (cost, gradient) and Hessian w.r.t. q, as SX functions (cheap to map)."""
    q = ca.SX.sym("q", N_DOF)
    P = ca.SX.sym("p", 3, len(points))
    w = ca.SX.sym("w", len(points))
    c = _frame_cost(ch, points)(q, P, w)
    H, g = ca.hessian(c, q)
    return (ca.Function("frame_grad", [q, P, w], [c, g]), ca.Function("frame_hess", [q, P, w], [H]))


@functools.lru_cache(maxsize=8)
def _build_solver(ch: Character, specs: tuple, T: int, smoothness: float, rw: tuple, max_iter: int,
                  verbose: bool):
    """IPOPT over x = vec(Q), parameters p = [vec(P); w].  Gradient and Hessian are assembled
    from per-frame SX kernels (the Hessian is block diagonal plus the constant quadratic
    terms S), which is several times faster than AD through the mapped cost."""
    K = len(specs)
    x = ca.MX.sym("x", N_DOF * T)
    p = ca.MX.sym("p", 3 * K * T + K)
    X = ca.reshape(x, N_DOF, T)
    Pp = ca.reshape(p[:3 * K * T], 3, K * T)
    W = ca.repmat(p[3 * K * T:], 1, T)
    fgrad, fhess = _frame_kernels(ch, specs)
    c, g = fgrad.map(T, "serial")(X, Pp, W)
    Hs = fhess.map(T, "serial")(X, Pp, W)
    S = _quadratic_terms(T, smoothness, np.asarray(rw))
    Sx = ca.mtimes(S, x)
    f = (ca.sum2(c) + 0.5 * ca.dot(x, Sx)) / T  # per-frame average
    grad = (ca.vec(g) + Sx) / T
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", 0, 1)
    Hblk = ca.diagcat(*ca.horzsplit(Hs, N_DOF))
    hess = ca.Function("hess_lag", [x, p, lam_f, lam_g], [ca.triu(lam_f / T * (Hblk + S))],
                       ["x", "p", "lam_f", "lam_g"], ["hess"])
    grad_f = ca.Function("grad_f", [x, p], [f, grad], ["x", "p"], ["f", "grad"])
    opts = {"ipopt.print_level": 5 if verbose else 0, "print_time": False, "ipopt.max_iter": max_iter,
            "ipopt.tol": 1e-10, "ipopt.acceptable_tol": 1e-8, "ipopt.sb": "yes",
            "ipopt.linear_solver": "mumps", "hess_lag": hess, "grad_f": grad_f}
    return ca.nlpsol("retarget", "ipopt", {"x": x, "f": f, "p": p}, opts)


def retarget(data, ch: Character, smoothness: float = 1e-3, rest_weight: float = 1e-5,
             rest_weights: dict[str, float] | None = None,
             max_iter: int = 500, q0: np.ndarray | None = None, verbose: bool = False):
    """Fit ``ch`` to a :class:`~scenegraph.mocap.clip.ClipData`; returns the fit ``(q, fit_error, info)``.

    ``q`` (T, 35) is read-only, ``fit_error`` (T, K) the distance (m) of each fitted point to
    its clip point, ``info`` the solver's status, iterations, seconds and objective.
    :func:`scenegraph.mocap.clip.load_clip` wraps them into a ``MocapClip``.
    """
    t0 = time.perf_counter()
    names = tuple(data.target_names)
    specs = tuple(data.target_specs)
    targets = np.asarray(data.targets)
    T, K = targets.shape[:2]
    w = np.asarray(data.target_weights, dtype=float)
    w = w / w.sum()
    if q0 is None:
        q0 = initial_guess(ch, targets, names)

    rw = np.zeros(N_DOF)
    rw[N_ROOT:] = rest_weight
    extra = DEFAULT_REST if rest_weights is None else rest_weights
    for i, d in enumerate(ch.dofs):
        base = d.name[:-2] if d.name.endswith(("_l", "_r")) else d.name
        if i >= N_ROOT and (base in extra or d.name in extra):
            rw[i] = extra.get(d.name, extra.get(base))
    solver = _build_solver(ch, specs, T, smoothness, tuple(rw), max_iter, verbose)
    q0 = np.array(q0, dtype=float).reshape(T, N_DOF)
    lo = np.tile(ch.lower, (T, 1))
    hi = np.tile(ch.upper, (T, 1))
    # Yaw is periodic: keep each frame within ±90° of the guess's unwrapped heading, so
    # the fit cannot jump by a full turn between frames.
    lo[:, 3] = np.maximum(lo[:, 3], q0[:, 3] - math.pi / 2)
    hi[:, 3] = np.minimum(hi[:, 3], q0[:, 3] + math.pi / 2)
    x0 = np.clip(q0, lo + 1e-9, hi - 1e-9).ravel()
    lo, hi = lo.ravel(), hi.ravel()
    P = targets.reshape(T * K, 3).T  # (3, T*K): frame t's points in columns t*K … t*K+K−1
    sol = solver(x0=x0, lbx=lo, ubx=hi, p=np.concatenate([P.ravel(order="F"), w]))
    stats = solver.stats()
    q = np.asarray(sol["x"]).reshape(T, N_DOF)
    if not stats["success"] and stats["return_status"] not in ("Solved_To_Acceptable_Level",
                                                                 "Search_Direction_Becomes_Too_Small"):
        raise RetargetError(f"retarget fit of {data.file} did not converge: {stats['return_status']}")
    pts = point_positions(ch, specs, q)
    err = np.linalg.norm(pts - targets, axis=-1)
    q.setflags(write=False)
    err.setflags(write=False)
    info = {"status": stats["return_status"], "iterations": int(stats["iter_count"]),
            "seconds": time.perf_counter() - t0, "objective": float(sol["f"])}
    return q, err, info


# --- smooth reconstruction (NIO paper, Appendix A) --------------------------------------------

CONTACT_HANDLES = ("heel_l", "ball_l", "toe_l", "heel_r", "ball_r", "toe_r")
W_ROOT = 100.0


@dataclass(frozen=True)
class Reconstruction:
    """Outcome of :func:`reconstruct_clip`: the motion plus what the fit says about it.

    ``contact_forces`` maps a contact handle to (times (n,), world forces (n, 3) N);
    ``footprints`` lists (handle, start s, end s, (x, y)) of the planted contacts;
    ``fit_error`` (T, K) the distance (m) of each fitted point to its clip point;
    ``root_residual`` (N, 6) the residual root force Q_0 at the collocation times, in units
    of body weight (N/(m g) for translations, N·m/(m g) = m for rotations).
    """

    motion: "object"  # scenegraph.model.motion.Motion
    times: np.ndarray
    q: np.ndarray
    fit_error: np.ndarray
    root_residual: np.ndarray
    contact_forces: dict
    footprints: tuple
    solver: dict


@functools.lru_cache(maxsize=8)
def _root_kernel(ch: Character) -> ca.Function:
    """(q, q̇, q̈, forces at CONTACT_HANDLES (18, world N)) → Q_0 (6): the root residual."""
    from scenegraph.model.dynamics import rnea

    q, qd, qdd = (ca.SX.sym(n, N_DOF) for n in ("q", "qd", "qdd"))
    fc = ca.SX.sym("f", 3 * len(CONTACT_HANDLES))
    ext = []
    for i, name in enumerate(CONTACT_HANDLES):
        h = ch.handle(name)
        ext.append((ch.body(h.body).frame, h.point, fc[3 * i:3 * i + 3]))
    tau = rnea(ch, q, qd, qdd, ext)
    return ca.Function("root_residual", [q, qd, qdd, fc], [tau[:N_ROOT]])


@functools.lru_cache(maxsize=8)
def _recon_kernels(ch: Character, specs: tuple) -> tuple[ca.Function, ca.Function]:
    """Per-frame kernels with their Jacobians (SX, mapped over frames by the caller):

    kin(q)              → points (3, K), d points/dq (3K, 35), contact handles (3, 6), d/dq (18, 35)
    root(q, q̇, q̈, f)   → Q_0 (6), dQ_0/d(q, q̇, q̈, f) (6, 123)
    """
    q = ca.SX.sym("q", N_DOF)
    tr = frame_transforms(ch, q)
    X = ca.horzcat(*[point_expr(ch, q, n, tr) for n in specs])
    Hc = ca.horzcat(*[point_expr(ch, q, n, tr) for n in CONTACT_HANDLES])
    kin = ca.Function("recon_kin", [q], [X, ca.jacobian(ca.vec(X), q), Hc, ca.jacobian(ca.vec(Hc), q)])
    qd, qdd = ca.SX.sym("qd", N_DOF), ca.SX.sym("qdd", N_DOF)
    fc = ca.SX.sym("f", 3 * len(CONTACT_HANDLES))
    q0 = _root_kernel(ch)(q, qd, qdd, fc)
    root = ca.Function("recon_root", [q, qd, qdd, fc], [q0, ca.jacobian(q0, ca.vertcat(q, qd, qdd, fc))])
    return kin, root


class _LeastSquares:
    """r(x), sparse J(x) of the reconstruction, assembled from per-frame kernels in numpy."""

    def __init__(self, ch, specs, targets, w, times, K, contacts, pairs, w_root, w_contact, planted, w_acc=0.0):
        from scenegraph.model.body import G
        from scenegraph.model.dynamics import friction_basis
        from scenegraph.model.motion import basis

        self.T, self.Kp = targets.shape[:2]
        T = self.T
        self.K = K
        self.dur = float(times[-1] - times[0])
        s = (times - times[0]) / self.dur
        self.B = [basis(K, s, d) for d in (0, 1, 2)]
        self.mg = ch.total_mass * G
        self.kin, self.root = (f.map(T, "serial") for f in _recon_kernels(ch, specs))
        self.targets = targets
        self.sw = np.sqrt(w / T)  # (Kp,)
        wq = np.full(T, 1.0 / (T - 1))
        wq[[0, -1]] *= 0.5
        self.cr = np.sqrt(w_root * wq * self.dur) / self.mg  # (T,)
        self.pairs = pairs
        self.planted = planted
        self.cc = math.sqrt(w_contact / T)
        self.nc = len(contacts)
        self.n_ctrl = K * N_DOF
        self.n_lam = 4 * len(pairs)
        self.n = self.n_ctrl + self.n_lam + (2 * self.nc if planted else 0)
        self.V = friction_basis()
        # the spline support of each frame: up to 4 control points
        self.span = [np.flatnonzero(np.abs(self.B[0][f]) + np.abs(self.B[1][f]) + np.abs(self.B[2][f]) > 0)
                     for f in range(T)]
        self.h_index = [CONTACT_HANDLES.index(h) for _, h, _ in pairs]
        self.by_frame = [[] for _ in range(T)]
        for j, (_, _, k) in enumerate(pairs):
            self.by_frame[k].append(j)
        self.ca = np.sqrt(w_acc * wq * self.dur)  # (T,) acceleration regulariser weights
        self.m = 3 * self.Kp * T + 6 * T + (3 * len(pairs) if planted else 0) + self.n_lam + N_DOF * T

    def unpack(self, x):
        ctrl = x[:self.n_ctrl].reshape(self.K, N_DOF)
        lam = x[self.n_ctrl:self.n_ctrl + self.n_lam]
        F = x[self.n_ctrl + self.n_lam:].reshape(-1, 2)
        return ctrl, lam, F

    def forces(self, lam):
        """(T, 18) world contact forces at CONTACT_HANDLES."""
        f = np.zeros((self.T, 3 * len(CONTACT_HANDLES)))
        for j, (_, h, k) in enumerate(self.pairs):
            hi = self.h_index[j]
            f[k, 3 * hi:3 * hi + 3] += self.mg * self.V @ lam[4 * j:4 * j + 4]
        return f

    def evaluate(self, x, jac: bool = True):
        import scipy.sparse as sps

        T, Kp = self.T, self.Kp
        ctrl, lam, F = self.unpack(x)
        Q = self.B[0] @ ctrl
        Qd = self.B[1] @ ctrl / self.dur
        Qdd = self.B[2] @ ctrl / self.dur ** 2
        fc = self.forces(lam)
        X, JX, Hc, JH = (np.asarray(a) for a in self.kin(Q.T))
        Q0, JR = (np.asarray(a) for a in self.root(Q.T, Qd.T, Qdd.T, fc.T))
        X = X.reshape(3, T, Kp).transpose(1, 2, 0)  # (T, Kp, 3)
        Hc = Hc.reshape(3, T, 6).transpose(1, 2, 0)  # (T, 6, 3)
        r_fit = ((X - self.targets) * self.sw[None, :, None]).ravel()
        r_root = (Q0.T * self.cr[:, None]).ravel()  # (T*6,)
        parts = [r_fit, r_root]
        if self.planted and self.pairs:
            r_c = np.array([Hc[k, self.h_index[j]] - np.array([F[ci, 0], F[ci, 1], 0.0])
                            for j, (ci, _, k) in enumerate(self.pairs)]) * self.cc
            parts.append(r_c.ravel())
        parts.append(1e-3 * lam)
        parts.append((Qdd * self.ca[:, None]).ravel())
        r = np.concatenate(parts)
        self.Q0 = Q0.T
        if not jac:
            return r, None
        rows, cols, vals = [], [], []
        JX = JX.reshape(3 * Kp, T, N_DOF)  # rows: vec(X) of one frame = point-major (x,y,z per point)
        JH = JH.reshape(18, T, N_DOF)
        JR = JR.reshape(6, T, 3 * N_DOF + 18)
        base_root = 3 * Kp * T
        cidx = np.arange(N_DOF)
        for f in range(T):
            ks = self.span[f]
            # fit rows of frame f: row (f*Kp + kp)*3 + a  ↔  vec index kp*3 + a
            blk = JX[:, f, :] * np.repeat(self.sw, 3)[:, None]  # (3Kp, 35)
            b0 = self.B[0][f, ks]
            rr = f * 3 * Kp + np.arange(3 * Kp)
            for kk, bk in zip(ks, b0):
                if bk != 0.0:
                    rows.append(np.repeat(rr, N_DOF))
                    cols.append(np.tile(kk * N_DOF + cidx, 3 * Kp))
                    vals.append((blk * bk).ravel())
            # root rows of frame f
            Jq, Jqd, Jqdd, Jf = (JR[:, f, :N_DOF], JR[:, f, N_DOF:2 * N_DOF], JR[:, f, 2 * N_DOF:3 * N_DOF],
                                 JR[:, f, 3 * N_DOF:])
            rr = base_root + 6 * f + np.arange(6)
            for kk in ks:
                blk = (Jq * self.B[0][f, kk] + Jqd * self.B[1][f, kk] / self.dur
                       + Jqdd * self.B[2][f, kk] / self.dur ** 2) * self.cr[f]
                rows.append(np.repeat(rr, N_DOF))
                cols.append(np.tile(kk * N_DOF + cidx, 6))
                vals.append(blk.ravel())
            for j in self.by_frame[f]:
                hi = self.h_index[j]
                blk = Jf[:, 3 * hi:3 * hi + 3] @ (self.mg * self.V) * self.cr[f]  # (6, 4)
                rows.append(np.repeat(rr, 4))
                cols.append(np.tile(self.n_ctrl + 4 * j + np.arange(4), 6))
                vals.append(blk.ravel())
        row0 = base_root + 6 * T
        if self.planted and self.pairs:
            for j, (ci, _, k) in enumerate(self.pairs):
                hi = self.h_index[j]
                rr = row0 + 3 * j + np.arange(3)
                blk = JH[3 * hi:3 * hi + 3, k, :] * self.cc
                for kk, bk in zip(self.span[k], self.B[0][k, self.span[k]]):
                    if bk != 0.0:
                        rows.append(np.repeat(rr, N_DOF))
                        cols.append(np.tile(kk * N_DOF + cidx, 3))
                        vals.append((blk * bk).ravel())
                rows.append(rr[:2])
                cols.append(self.n_ctrl + self.n_lam + 2 * ci + np.arange(2))
                vals.append(np.full(2, -self.cc))
            row0 += 3 * len(self.pairs)
        rows.append(row0 + np.arange(self.n_lam))
        cols.append(self.n_ctrl + np.arange(self.n_lam))
        vals.append(np.full(self.n_lam, 1e-3))
        row0 += self.n_lam
        for f in range(T):  # acceleration rows: q̈_f = B2[f] ctrl / dur²
            rr = row0 + N_DOF * f + cidx
            for kk in self.span[f]:
                rows.append(rr)
                cols.append(kk * N_DOF + cidx)
                vals.append(np.full(N_DOF, self.B[2][f, kk] / self.dur ** 2 * self.ca[f]))
        J = sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(len(r), self.n))
        return r, J


class _Cache:
    def __init__(self, ls):
        self.ls, self.x, self.r, self.J = ls, None, None, None

    def get(self, x, jac=True):
        x = np.asarray(x, dtype=float).ravel()
        if self.x is None or not np.array_equal(x, self.x) or (jac and self.J is None):
            self.r, self.J = self.ls.evaluate(x, jac)
            self.x = x.copy()
        return self.r, self.J


class _LsqCallback(ca.Callback):
    """A CasADi callback over the cached residual r(x) and Jacobian J of a least-squares
    problem; the subclass declares its inputs and outputs as (name, sparsity) pairs (name
    None: CasADi's default ``i<k>``/``o<k>``) and computes them in ``eval``."""

    def __init__(self, name: str, cache, n: int, ins, outs, opts: dict | None = None):
        ca.Callback.__init__(self)
        self.cache, self.n = cache, n
        self._ins, self._outs = ins, outs
        self.construct(name, opts or {})

    def get_n_in(self):
        return len(self._ins)

    def get_n_out(self):
        return len(self._outs)

    def get_name_in(self, i):
        return self._ins[i][0] or f"i{i}"

    def get_name_out(self, i):
        return self._outs[i][0] or f"o{i}"

    def get_sparsity_in(self, i):
        return self._ins[i][1]

    def get_sparsity_out(self, i):
        return self._outs[i][1]


def _dense(rows: int, cols: int = 1) -> ca.Sparsity:
    return ca.Sparsity.dense(rows, cols)


class _FCallback(_LsqCallback):
    """f(x) = |r|²."""

    def __init__(self, cache, n):
        super().__init__("recon_f", cache, n, [(None, _dense(n))], [(None, _dense(1))], {"enable_fd": False})

    def eval(self, arg):
        r, _ = self.cache.get(arg[0], jac=False)
        return [float(r @ r)]

    # CasADi's NLP factory differentiates f once (for the gradient); hand it ours.
    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        self._jac = _JacCallback(name, self.cache, self.n, opts)
        return self._jac


class _JacCallback(_LsqCallback):
    """∂f/∂x = 2 rᵀJ (inputs: x and the nominal output f)."""

    def __init__(self, name, cache, n, opts):
        super().__init__(name, cache, n, [(None, _dense(n)), (None, _dense(1))], [(None, _dense(1, n))], opts)

    def eval(self, arg):
        r, J = self.cache.get(arg[0])
        return [ca.DM(2.0 * (J.T @ r)).T]


class _GradCallback(_LsqCallback):
    """(f, ∇f) = (|r|², 2 Jᵀr)."""

    def __init__(self, cache, n):
        super().__init__("recon_grad_f", cache, n, [("x", _dense(n)), ("p", _dense(0))],
                         [("f", _dense(1)), ("grad", _dense(n))])

    def eval(self, arg):
        r, J = self.cache.get(arg[0])
        return [float(r @ r), ca.DM(2.0 * (J.T @ r))]


class _HessCallback(_LsqCallback):
    """Gauss–Newton Hessian 2 λ_f JᵀJ (upper triangle) on a fixed sparsity pattern."""

    def __init__(self, cache, n, pattern):
        coo = pattern.tocoo()
        keep = coo.row <= coo.col
        r, c = coo.row[keep], coo.col[keep]
        order = np.lexsort((r, c))  # column-major, rows ascending: CasADi's CCS order
        r, c = r[order], c[order]
        sp = ca.Sparsity.triplet(n, n, r.tolist(), c.tolist())
        super().__init__("recon_hess", cache, n,
                         [("x", _dense(n)), ("p", _dense(0)), ("lam_f", _dense(1)), ("lam_g", _dense(0))],
                         [("hess_gamma_x_x", sp)])
        self.r, self.c, self.sp = r, c, sp

    def eval(self, arg):
        _, J = self.cache.get(arg[0])
        H = (J.T @ J).tocsr()
        lam_f = float(arg[2])
        vals = np.asarray(H[self.r, self.c]).ravel() * 2.0 * lam_f
        return [ca.DM(self.sp, vals)]


def reconstruct_clip(clip, ctrl_hz: float = 10.0, w_root: float = W_ROOT, planted: bool = True,
                     w_contact: float = 10.0, contacts=None, max_iter: int = 100, tol: float = 1e-8,
                     w_acc: float = 1e-7, obj_scale: float = 100.0, verbose: bool = False) -> Reconstruction:
    """Appendix A: fit a B-spline motion to the clip's points with the root residual softly zero.

        min  Σ_f Σ_k w_k ‖x_k(q(t_f)) − p_kf‖² / T  +  w_r Σ_n h ‖Q_0(t_n) / (m g)‖²
           +  w_c Σ_contacts Σ_f ‖h(q(t_f)) − (x_c, y_c, 0)‖² / T        (with ``planted``)
           +  10⁻⁶ ‖λ‖²  +  w_a Σ_n h ‖q̈(t_n)‖²
        over spline control points (within joint limits), contact coefficients λ ≥ 0 (force
        m g V λ at each contact handle while it is in contact) and the contact positions
        (x_c, y_c): a contact handle is pulled to one point on the floor over its interval.

    Collocation points are the clip's frames (h their quadrature weights × duration).
    ``contacts`` defaults to :func:`~scenegraph.mocap.contacts.detect_contacts` of the retargeted
    clip.  Everything is a sum of squares, so IPOPT gets a Gauss–Newton Hessian, assembled
    with the gradient from per-frame kernels (callbacks); only bounds constrain it.  (Hard
    contact constraints with CasADi's automatic derivatives made IPOPT wander for hundreds of
    iterations at seconds each.)
    """
    import scipy.sparse as sps

    from scenegraph.mocap.contacts import detect_contacts
    from scenegraph.model.dynamics import friction_basis
    from scenegraph.model.motion import Motion

    t_start = time.perf_counter()
    ch = clip.character
    data = clip.data
    specs = tuple(data.target_specs)
    times = np.asarray(clip.times, dtype=float)
    T = len(times)
    if T < 4:
        raise ComposeError("a reconstruction needs at least 4 frames")
    duration = float(times[-1] - times[0])
    K = max(4, int(round(duration * ctrl_hz)) + 3)
    if contacts is None:
        contacts = detect_contacts(clip)
    pairs = [(ci, f"{c.handle}_{c.side}", k) for ci, c in enumerate(contacts)
             for k in range(c.first_frame, c.last_frame + 1)]
    w = np.asarray(data.target_weights, dtype=float)
    ls = _LeastSquares(ch, specs, np.asarray(data.targets), w / w.sum(), times, K, contacts, pairs,
                       w_root, w_contact, planted, w_acc)
    cache = _Cache(ls)

    # start: least-squares spline through the retargeted frames; contact forces carrying
    # the body weight, shared among the handles in contact
    m0 = Motion.from_samples(times, np.asarray(clip.q), K)
    ctrl0 = np.clip(m0.ctrl, ch.lower + 1e-9, ch.upper - 1e-9)
    V = friction_basis()
    n_in = np.zeros(T)
    for _, _, k in pairs:
        n_in[k] += 1
    lam0 = np.array([1.0 / (4 * V[2, 0] * n_in[k]) for _, _, k in pairs for _ in range(4)])
    F0 = np.array([c.position[:2] for c in contacts]).ravel() if planted else np.zeros(0)
    x0 = np.concatenate([ctrl0.ravel(), lam0, F0])
    # λ for that motion: a bounded linear least-squares problem (Q_0 is linear in λ)
    r0, J0 = ls.evaluate(x0)
    if ls.n_lam:
        from scipy.optimize import lsq_linear

        lam_cols = slice(ls.n_ctrl, ls.n_ctrl + ls.n_lam)
        A = J0[:, lam_cols]
        b = r0 - A @ x0[lam_cols]
        x0[lam_cols] = np.maximum(lsq_linear(A, -b, bounds=(0.0, np.inf), lsmr_tol="auto").x, 1e-6)
        _, J0 = ls.evaluate(x0)
    pattern = (abs(J0).T @ abs(J0) + sps.identity(ls.n)).tocsc()  # structural, with the diagonal

    x = ca.MX.sym("x", ls.n)
    fcb, gcb, hcb = _FCallback(cache, ls.n), _GradCallback(cache, ls.n), _HessCallback(cache, ls.n, pattern)
    opts = {"grad_f": gcb, "hess_lag": hcb, "print_time": False,
            # The start is close (retargeted motion, λ from a bounded linear solve): a small
            # fixed barrier and tight bound push keep the many λ ≈ 0 where they are.  With
            # λ at its bounds the Gauss–Newton steps creep near the end, so we also accept
            # when the objective has stopped changing (relative 1e-5 over 5 iterations).
            "ipopt": {"print_level": 5 if verbose else 0, "max_iter": max_iter, "tol": tol,
                      "acceptable_tol": 1e3, "acceptable_obj_change_tol": 1e-5, "acceptable_iter": 5,
                      "linear_solver": "mumps", "sb": "yes",
                      "mu_strategy": "monotone", "mu_init": 1e-4, "bound_push": 1e-8, "bound_frac": 1e-8,
                      "obj_scaling_factor": obj_scale}}
    solver = ca.nlpsol("reconstruct", "ipopt", {"x": x, "f": fcb(x)}, opts)
    lbx = np.concatenate([np.tile(ch.lower, K), np.zeros(ls.n_lam), np.full(len(F0), -np.inf)])
    ubx = np.concatenate([np.tile(ch.upper, K), np.full(ls.n_lam, np.inf), np.full(len(F0), np.inf)])
    sol = solver(x0=x0, lbx=lbx, ubx=ubx)
    st = solver.stats()
    xs = np.asarray(sol["x"]).ravel()
    status = st.get("return_status", "unknown")
    if not (st.get("success") or status == "Solved_To_Acceptable_Level"):
        raise RetargetError(f"reconstruction of {data.file} did not converge: {status}")

    ctrl, lam, F = ls.unpack(xs)
    ls.evaluate(xs, jac=False)
    motion = Motion(ctrl.copy(), Motion.uniform_warp(times[0], times[-1]))
    q = ls.B[0] @ ctrl
    err = np.linalg.norm(point_positions(ch, specs, q) - np.asarray(data.targets), axis=-1)
    fc = ls.forces(lam)
    forces: dict = {}
    for j, (_, hname, k) in enumerate(pairs):
        hi = CONTACT_HANDLES.index(hname)
        forces.setdefault(hname, []).append((times[k], fc[k, 3 * hi:3 * hi + 3]))
    forces = {h: (np.array([t for t, _ in v]), np.array([fv for _, fv in v])) for h, v in forces.items()}
    prints = tuple((f"{c.handle}_{c.side}", float(times[c.first_frame]), float(times[c.last_frame]),
                    (float(F[i, 0]), float(F[i, 1])) if planted else tuple(c.position[:2]))
                   for i, c in enumerate(contacts))
    info = {"status": status, "iterations": int(st.get("iter_count", -1)),
            "seconds": time.perf_counter() - t_start, "objective": float(sol["f"]),
            "n_ctrl": K, "n_contact_pairs": len(pairs)}
    return Reconstruction(motion, times, q, err, ls.Q0 / ls.mg, forces, prints, info)


def reconstruct(clip, **kw):
    """The smooth reconstruction (Appendix A) of a fitted clip as a :class:`~scenegraph.model.motion.Motion`."""
    return reconstruct_clip(clip, **kw).motion
