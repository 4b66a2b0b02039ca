"""The physical checks on sampled meshes: contact, centre of pressure, friction, flight,
floor penetration, stance sliding and overlap between characters.

Units: m, N, s; forces are also given in body weights (bw = M g of the system checked).
A vertex is **in contact** when it is less than ``contact_tol`` above the ground (or below
it).  A frame of a system is **in contact** when any of its vertices is; it is **free
flight** when none is, in it or the frames either side (the finite differences span
them), and no mesh of the system comes within ``contact_tol`` of another character's
(a partner's hand can push); it is **coupled** when it touches another character.
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass

import numpy as np

__all__ = ["heights_above_ground", "contact_support", "hull2d", "outside_distance", "stance_runs",
           "cone_distance", "overlaps", "CharacterPair"]


def heights_above_ground(points: np.ndarray, ground) -> np.ndarray:
    """(T, N) height (m) of each vertex above the ground under it (negative: below)."""
    if ground.flat:
        return points[..., 2].copy()
    return points[..., 2] - ground.height(points[..., 0], points[..., 1])


def hull2d(P: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise, no repeated end) of 2-D points (n, 2): may be 1 or 2
    points when they are degenerate."""
    P = np.unique(np.round(np.asarray(P, float), 9), axis=0)
    if len(P) <= 2:
        return P
    P = P[np.lexsort((P[:, 1], P[:, 0]))]

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in P:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 1e-15:
            lower.pop()
        lower.append(p)
    for p in P[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 1e-15:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _seg_dist(p, a, b) -> float:
    ab = b - a
    L = float(ab @ ab)
    s = 0.0 if L == 0 else float(np.clip((p - a) @ ab / L, 0.0, 1.0))
    return float(np.linalg.norm(p - (a + s * ab)))


def outside_distance(p: np.ndarray, hull: np.ndarray) -> float:
    """Distance (m) of the 2-D point ``p`` outside the convex polygon ``hull`` (0 inside)."""
    if len(hull) == 0:
        return float("inf")
    if len(hull) == 1:
        return float(np.linalg.norm(p - hull[0]))
    if len(hull) == 2:
        return _seg_dist(p, hull[0], hull[1])
    inside = True
    for i in range(len(hull)):
        a, b = hull[i], hull[(i + 1) % len(hull)]
        if (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) < -1e-12:
            inside = False
            break
    if inside:
        return 0.0
    return min(_seg_dist(p, hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull)))


def cone_distance(f_t: float, f_n: float, mu: float) -> float:
    """Distance (N) of a force with tangential size ``f_t`` ≥ 0 and normal part ``f_n`` from
    the friction cone {f_n ≥ 0, f_t ≤ μ f_n} (0 inside)."""
    if f_t <= mu * f_n:
        return 0.0
    if mu * f_t <= -f_n:  # in the polar cone: the nearest admissible force is zero
        return float(np.hypot(f_t, f_n))
    return float((f_t - mu * f_n) / np.sqrt(1.0 + mu * mu))


def _basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def ground_normal(ground, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Mean upward unit normal (3,) of the ground under the points (x, y)."""
    if ground.flat:
        return np.array([0.0, 0.0, 1.0])
    h = 1e-3
    dx = (ground.height(x + h, y) - ground.height(x - h, y)) / (2 * h)
    dy = (ground.height(x, y + h) - ground.height(x, y - h)) / (2 * h)
    n = np.array([-np.mean(dx), -np.mean(dy), 1.0])
    return n / np.linalg.norm(n)


@dataclass(frozen=True)
class SupportFrame:
    """One contact frame: centre of pressure (3,) m (None when the normal force is not
    above the threshold), its distance outside the support polygon (m), friction use
    |f_t| / f_n, the force distance from the friction cone (N) and the normal force (N).

    :attr:`moment_outside` (N m) is the same CoP excess as a moment: the smallest change of
    the needed moment about the support (normal force × distance outside) that would bring
    the centre of pressure onto the polygon.  The distance is that moment divided by the
    normal force, so at small normal forces a small moment reads as a large distance."""

    cop: np.ndarray | None
    outside: float
    friction_use: float
    cone_excess: float
    normal_force: float

    @property
    def moment_outside(self) -> float:
        """Normal force × distance outside (N m); nan where no CoP is computed."""
        return float("nan") if self.cop is None else self.normal_force * self.outside


def contact_support(F: np.ndarray, tau_O: np.ndarray, contact_pts: np.ndarray, ground, mu: float,
                    min_normal: float) -> SupportFrame:
    """Where the needed wrench (F, τ about the origin) would have to act through the contact
    vertices ``contact_pts`` (k, 3): the ground plane through their mean with the ground's
    normal, the centre of pressure on it, and its distance outside their convex hull."""
    p0 = contact_pts.mean(axis=0)
    n = ground_normal(ground, contact_pts[:, 0], contact_pts[:, 1])
    fn = float(F @ n)
    ft = float(np.linalg.norm(F - fn * n))
    excess = cone_distance(ft, fn, mu)
    use = ft / fn if fn > min_normal else float("nan")
    if fn <= min_normal:
        return SupportFrame(None, float("nan"), use, excess, fn)
    tau = tau_O - np.cross(p0, F)
    r = np.cross(n, tau) / fn
    cop = p0 + r
    e1, e2 = _basis(n)
    Q = (contact_pts - p0) @ np.stack([e1, e2], 1)
    c2 = np.array([r @ e1, r @ e2])
    return SupportFrame(cop, outside_distance(c2, hull2d(Q)), use, excess, fn)


def stance_runs(points: np.ndarray, heights: np.ndarray, contact_tol: float, min_frames: int, dt: float,
                planted_speed: float = 0.1):
    """Per vertex, its runs of consecutive contact frames.

    A **stance** is a run of at least ``min_frames`` frames in which the vertex is, at some
    frame, slower than ``planted_speed`` (m/s, horizontal): it was planted (or came to rest).
    Its slide is the largest horizontal distance from where the vertex was at the run's
    first frame, so a touch-down or lift-off skid inside the run counts.  A run never slower
    than ``planted_speed`` is a **scuff**: a swing foot brushing through the contact band,
    a clearance fault, not sliding.  Short slow runs (a brief touch, a run cut by the clip's
    ends) are neither.  Returns (stances, scuffs): stances as (vertex, first, last, slide m),
    scuffs as (vertex, first, last, largest horizontal speed m/s)."""
    inc = heights < contact_tol
    T, N = inc.shape
    stances, scuffs = [], []
    cols = np.nonzero(inc.any(axis=0))[0]
    if len(cols) == 0:
        return stances, scuffs
    vel = np.gradient(points[:, cols, :2], dt, axis=0) if T > 1 else np.zeros((T, len(cols), 2))
    speed = np.linalg.norm(vel, axis=2)
    for c, j in enumerate(cols):
        m = inc[:, j]
        d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
        starts, ends = np.nonzero(d == 1)[0], np.nonzero(d == -1)[0] - 1
        for a, b in zip(starts, ends):
            sp = speed[a:b + 1, c]
            if sp.min() >= planted_speed:
                scuffs.append((int(j), int(a), int(b), float(sp.max())))
            elif b - a + 1 >= min_frames:
                xy = points[a:b + 1, j, :2]
                stances.append((int(j), int(a), int(b), float(np.linalg.norm(xy - xy[0], axis=1).max())))
    return stances, scuffs


@dataclass(frozen=True)
class CharacterPair:
    """Overlap of two characters: ``depth`` (T,) m, the largest penetration depth between a
    mesh of one and a mesh of the other (their convex hulls, :func:`overlap_depth`; 0: apart), ``near`` (T,) bool, any two meshes
    within ``tol`` (bounding boxes), and ``where`` (T,) the deepest mesh pair, 'a/mesh~b/mesh'."""

    a: str
    b: str
    depth: np.ndarray
    near: np.ndarray
    where: tuple
    depth_allowed: np.ndarray = None  # (T,) m, the same over the asked-for contacts only


def _mesh_boxes(points: np.ndarray, vert_mesh: np.ndarray, nm: int) -> np.ndarray:
    """(T, M, 2, 3) axis-aligned bounds of each mesh (vertices are grouped by mesh)."""
    starts = np.r_[0, np.nonzero(np.diff(vert_mesh))[0] + 1]
    lo = np.minimum.reduceat(points, starts, axis=1)
    hi = np.maximum.reduceat(points, starts, axis=1)
    return np.stack([lo, hi], axis=2)


def _hull_normals(pts: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull, QhullError
    try:
        return ConvexHull(pts).equations[:, :3]
    except (QhullError, ValueError):
        return np.zeros((0, 3))


def overlap_depth(pa: np.ndarray, pb: np.ndarray) -> float:
    """Penetration depth (m) of the convex hulls of two point sets by separating axes over
    both hulls' face normals: 0 when some axis separates them, else the smallest overlap of
    their projections.  Exact when the deepest direction is a face normal (boxes face to
    face, finely tessellated ellipsoids); otherwise an upper bound, as is taking a
    non-convex mesh's hull."""
    N = np.concatenate([_hull_normals(pa), _hull_normals(pb)])
    if len(N) == 0:
        return 0.0
    A, B = pa @ N.T, pb @ N.T
    ov = np.minimum(A.max(0) - B.min(0), B.max(0) - A.min(0))
    return float(max(0.0, ov.min()))


def overlaps(chars, tol: float, allowed: tuple[str, ...] = ()) -> list[CharacterPair]:
    """Overlap of every pair of characters (see :class:`CharacterPair`).  Mesh pairs that
    match an ``allowed`` pattern 'charA/meshA~charB/meshB' (fnmatch, either order) are a
    contact that was asked for: they count as ``near`` but not in ``depth``."""
    boxes = []
    for c in chars:
        ms = c.meshes
        order = np.argsort(ms.vert_mesh, kind="stable")
        assert np.all(order == np.arange(len(order))), "vertices must be grouped by mesh"
        boxes.append(_mesh_boxes(ms.points, ms.vert_mesh, len(ms.names)))
    out = []
    for i in range(len(chars)):
        for j in range(i + 1, len(chars)):
            A, B = chars[i], chars[j]
            bA, bB = boxes[i], boxes[j]
            T = bA.shape[0]
            # (T, MA, MB) boxes within tol
            sep = np.maximum(bA[:, :, None, 0, :] - bB[:, None, :, 1, :], bB[:, None, :, 0, :] - bA[:, :, None, 1, :])
            close = np.all(sep < tol, axis=-1)
            depth, depth_ok = np.zeros(T), np.zeros(T)
            near = close.any(axis=(1, 2))
            where = [""] * T
            for t, ma, mb in zip(*np.nonzero(np.all(sep < 0, axis=-1))):
                na, nb = A.meshes.names[ma], B.meshes.names[mb]
                key1, key2 = f"{A.name}/{na}~{B.name}/{nb}", f"{B.name}/{nb}~{A.name}/{na}"
                pa = A.meshes.points[t, A.meshes.vert_mesh == ma]
                pb = B.meshes.points[t, B.meshes.vert_mesh == mb]
                d = overlap_depth(pa, pb)
                if any(fnmatch.fnmatchcase(key1, pat) or fnmatch.fnmatchcase(key2, pat) for pat in allowed):
                    depth_ok[t] = max(depth_ok[t], d)
                elif d > depth[t]:
                    depth[t], where[t] = d, key1
            out.append(CharacterPair(A.name, B.name, depth, near, tuple(where), depth_ok))
    return out
