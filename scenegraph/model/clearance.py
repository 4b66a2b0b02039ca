"""Bodies apart: a conservative sphere set per body and the body-to-body clearance constraints
between two characters where their current motions come close (issue #15, item 5; which
characters and times a scene constrains: :mod:`scenegraph.world.clearance`).

Spheres.  Each body's drawn solid (``body.drawn_shapes``: the dynamics' ellipsoid, keels for
the feet and toes) is sampled densely in the body's frame and cut into slabs along the axis
of its largest extent; each slab gets one sphere centred on that axis whose radius reaches
the slab's farthest sample (plus ``SPHERE_PAD``).  The union of a body's spheres therefore
holds every sample of its solid (to within the sampling, ≤ 1 mm at 24 × 16 samples per
ellipsoid): two characters whose spheres do not overlap have solids that do not overlap.

Constraints.  For the character being solved (a) against another character (b) held at its
current motion, at the given world times, every pair (sphere i of a, sphere j of b) whose
gap ‖c_i − c_j‖ − R_i − R_j is below ``margin`` in the current motions becomes

    ‖c_i(q_a(t)) − c_j(t)‖² ≥ (R_i + R_j)²                       (m²)

with c_j(t) fixed (world m).  Pairs between bodies whose contact a goal asks for (held hands)
are left out.  Pairs farther apart than ``margin`` in the current motions are not
constrained: a step moves a body by less than that near another (the stage audit checks
the result).  Frames: body frames as in ``body.py``; world Z up; m, s.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from scenegraph.model.body import N_DOF, Character, drawn_shapes, keel_points
from scenegraph.model.kinematics import frame_transforms, numeric_fk

__all__ = ["Sphere", "BodyClearance", "body_spheres", "sphere_centers", "clearance_pairs", "sphere_centers_fn",
           "SPHERE_PAD", "CLEARANCE_MARGIN", "CLEARANCE_WEIGHT", "CLEARANCE_HZ"]

SPHERE_PAD = 0.001  # m added to each sphere's radius (sampling)
CLEARANCE_MARGIN = 0.10  # m: pairs closer than this in the current motions are constrained
CLEARANCE_WEIGHT = 1e6  # total least-squares weight of the rows (Subproblem.clearance_weight): as hard
# rows (5144 of them in handhold's adult/c1 full step, starting up to 12 cm inside) IPOPT ended that
# step at its 100-iteration cap at E 40 497; as this one-sided term it converged (95 iterations,
# E 443 against 408 without clearance) with every row met at its time; weight 1e4 left 4.4 mm
CLEARANCE_HZ = 30.0  # clearance constraint times per second (the constraint grid's rate)
SLAB = 0.6  # slab length / cross-section radius: each sphere is at most ~4 % wider than its slab's section


@dataclass(frozen=True)
class Sphere:
    """A sphere fixed to a body: ``point`` (m) in the frame ``frame``, radius ``radius`` (m)."""

    body: str
    frame: int
    point: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class BodyClearance:
    """Keep sphere ``sphere`` (an index into ``body_spheres(ch)``) of the solved character at
    least ``radius`` (m) from the world point ``center`` (m) at world time ``t`` (s)."""

    sphere: int
    t: float
    center: tuple[float, float, float]
    radius: float
    other: str = ""  # the other character's name and body ("name/body")
    other_sphere: int = -1  # index of the other's sphere in body_spheres(its character) (joint problems)


def _samples(shape) -> np.ndarray:
    """Dense points on the surface of a drawn solid, in its body's frame (m)."""
    if shape.kind == "keel":
        return keel_points(shape.center, shape.semi_axes, shape.pitch, 32, 20)
    a, b, c = shape.semi_axes
    u, v = np.meshgrid(np.linspace(0, math.pi, 17), np.linspace(0, 2 * math.pi, 25), indexing="ij")
    P = np.stack([a * np.cos(u), b * np.sin(u) * np.cos(v), c * np.sin(u) * np.sin(v)], -1).reshape(-1, 3)
    return P + np.asarray(shape.center, float)


@functools.lru_cache(maxsize=16)
def body_spheres(ch: Character) -> tuple[Sphere, ...]:
    """The covering spheres of every body (see the module docstring), in ``ch.bodies`` order."""
    out = []
    for b, shape in zip(ch.bodies, drawn_shapes(ch)):
        P = _samples(shape)
        lo, hi = P.min(0), P.max(0)
        ext = hi - lo
        ax = int(np.argmax(ext))
        others = [i for i in range(3) if i != ax]
        mid = (lo + hi) / 2
        cross = float(max(ext[others])) / 2
        n = max(1, int(math.ceil(ext[ax] / max(SLAB * cross, 1e-6))))
        edges = np.linspace(lo[ax], hi[ax], n + 1)
        for k in range(n):
            c = mid.copy()
            c[ax] = (edges[k] + edges[k + 1]) / 2
            inside = (P[:, ax] >= edges[k] - 1e-12) & (P[:, ax] <= edges[k + 1] + 1e-12)
            r = float(np.linalg.norm(P[inside] - c, axis=1).max()) + SPHERE_PAD
            out.append(Sphere(b.name, b.frame, tuple(float(x) for x in c), r))
    return tuple(out)


def sphere_centers(ch: Character, q: np.ndarray) -> np.ndarray:
    """(T, n_spheres, 3) world sphere centres for poses q (T, 35)."""
    R, p = numeric_fk(ch, np.atleast_2d(q))
    idx = {b.name: i for i, b in enumerate(ch.bodies)}
    sp = body_spheres(ch)
    bi = np.array([idx[s.body] for s in sp])
    pts = np.array([s.point for s in sp])
    return np.einsum("tsij,sj->tsi", R[:, bi], pts) + p[:, bi]


@functools.lru_cache(maxsize=16)
def sphere_centers_fn(ch: Character) -> ca.Function:
    """q (35) → (3·n_spheres) world sphere centres (m), stacked."""
    q = ca.SX.sym("q", N_DOF)
    R, p = frame_transforms(ch, q)
    return ca.Function("sphere_centers", [q], [ca.vertcat(*[p[s.frame] + ca.mtimes(R[s.frame], ca.DM(s.point))
                                                            for s in body_spheres(ch)])])


def clearance_pairs(ch_a: Character, q_a: np.ndarray, ch_b: Character, q_b: np.ndarray, times,
                    skip: frozenset = frozenset(), other: str = "",
                    margin: float = CLEARANCE_MARGIN) -> tuple[BodyClearance, ...]:
    """Clearance constraints of character a against b (held) at world ``times`` (s), from their
    current poses there (q_a, q_b: (T, 35)).  ``skip``: (body of a, body of b) pairs whose
    contact is asked for."""
    sa, sb = body_spheres(ch_a), body_spheres(ch_b)
    ca_, cb_ = sphere_centers(ch_a, q_a), sphere_centers(ch_b, q_b)
    ra = np.array([s.radius for s in sa])
    rb = np.array([s.radius for s in sb])
    allowed = np.array([[(x.body, y.body) not in skip for y in sb] for x in sa])
    out = []
    for k, t in enumerate(np.atleast_1d(np.asarray(times, float))):
        d = np.linalg.norm(ca_[k][:, None, :] - cb_[k][None, :, :], axis=-1)
        gap = d - ra[:, None] - rb[None, :]
        for i, j in zip(*np.nonzero((gap < margin) & allowed)):
            out.append(BodyClearance(int(i), float(t), tuple(float(x) for x in cb_[k][j]), float(ra[i] + rb[j]),
                                     f"{other}/{sb[j].body}", int(j)))
    return tuple(out)
