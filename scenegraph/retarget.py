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

import casadi as ca
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from scenarios.errors import ComposeError

from .body import Character, N_DOF, N_ROOT, standing_pose
from .kinematics import frame_transforms

__all__ = ["PointSpec", "point_name", "resolve_point", "point_expr", "points_fn", "point_positions", "retarget",
           "initial_guess", "RetargetError"]


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
        from .body import _default

        if v not in {b.name for b in _default.bodies}:
            raise ValueError(f"unknown body {v!r} (known: {', '.join(b.name for b in _default.bodies)})")
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
    """Fit ``ch`` to a :class:`~scenegraph.mocap.ClipData`; returns a MocapClip."""
    from .mocap import MocapClip

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
    return MocapClip(data, ch, q, err, info)
