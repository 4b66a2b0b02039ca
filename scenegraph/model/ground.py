"""The ground: flat z = 0, with inclined planes (slopes, ramps) over rectangular regions.

Frames and units: world frame, Z up, SI units (m); angles in radians.  A point on the
ground is given by its horizontal position (x, y); the ground height there is h(x, y).

Each :class:`Plane` covers an axis-aligned region [xmin, xmax] × [ymin, ymax] and has the
height

    h(x, y) = tan(angle) · ((x, y) − origin) · (cos heading, sin heading)

(``heading`` is the direction of steepest ascent, ``origin`` a point where h = 0).  The first
plane whose region contains (x, y) gives the height; outside every region the ground is
flat, h = 0.  Region edges are steps wherever the plane is not at height 0 there (a ramp
whose origin lies on one edge meets the flat ground along that edge only); a motion is
expected to stay on one plane while a foot is on it: the CasADi height is piecewise (an
``if_else`` per plane) and its derivative jumps at region edges.

The outward unit normal is n = (−∂h/∂x, −∂h/∂y, 1) / ‖·‖.  Contact forces use the friction
pyramid of :func:`scenegraph.model.dynamics.friction_basis` rotated into the local frame
(t₁, t₂, n): t₁ is world +X projected onto the plane, t₂ = n × t₁.  On flat ground that
frame is the identity and every quantity here equals the flat-ground one exactly, so
``FLAT`` changes nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from scenegraph.model.dynamics import MU, friction_basis

__all__ = ["Plane", "Ground", "FLAT", "ground_from_environment"]


@dataclass(frozen=True)
class Plane:
    """One inclined plane over a region (see the module docstring).

    angle: inclination (rad, |angle| < π/2; positive rises along ``heading``);
    heading: direction of steepest ascent (rad, from +X);
    region: (xmin, ymin, xmax, ymax) (m); origin: (x, y) (m) where the plane has height 0;
    friction: Coulomb μ on this plane (None: the ground's).
    """

    angle: float
    heading: float
    region: tuple[float, float, float, float]
    origin: tuple[float, float]
    friction: float | None = None
    name: str | None = None

    def __post_init__(self):
        if not abs(self.angle) < math.pi / 2:
            raise ValueError(f"plane angle must lie in (-90°, 90°), got {math.degrees(self.angle)}°")
        x0, y0, x1, y1 = self.region
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"plane region must have max > min, got {self.region}")

    @property
    def gradient(self) -> tuple[float, float]:
        """(∂h/∂x, ∂h/∂y) (dimensionless)."""
        t = math.tan(self.angle)
        return t * math.cos(self.heading), t * math.sin(self.heading)

    def contains(self, x, y):
        """Whether (x, y) (m; numbers or arrays) lies in the region (edges included)."""
        x0, y0, x1, y1 = self.region
        return (np.asarray(x) >= x0) & (np.asarray(x) <= x1) & (np.asarray(y) >= y0) & (np.asarray(y) <= y1)

    def plane_height(self, x, y):
        """Height (m) of the infinite plane at (x, y): numbers, arrays or CasADi expressions."""
        gx, gy = self.gradient
        return gx * (x - self.origin[0]) + gy * (y - self.origin[1])

    def edge_heights(self) -> tuple[float, float]:
        """(lowest, highest) plane height (m) over the region's corners."""
        x0, y0, x1, y1 = self.region
        z = [self.plane_height(a, b) for a in (x0, x1) for b in (y0, y1)]
        return min(z), max(z)


@dataclass(frozen=True)
class Ground:
    """Flat ground z = 0 plus ``planes`` (first match wins); ``friction`` is μ off the planes."""

    friction: float = MU
    planes: tuple[Plane, ...] = ()

    @property
    def flat(self) -> bool:
        return not self.planes

    # --- numpy ----------------------------------------------------------------------------
    def _which(self, x, y) -> np.ndarray:
        """Index of the plane under each point (−1: flat ground); shape of broadcast(x, y)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        idx = np.full(x.shape, -1, int)
        for i, pl in reversed(list(enumerate(self.planes))):  # first match wins: assign it last
            idx = np.where(pl.contains(x, y), i, idx)
        return idx

    def height(self, x, y):
        """Ground height h (m) at (x, y) (m): a float for scalars, else an array."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        h = np.zeros(x.shape)
        idx = self._which(x, y)
        for i, pl in enumerate(self.planes):
            h = np.where(idx == i, pl.plane_height(x, y), h)
        return float(h) if h.ndim == 0 else h

    def gradient(self, x, y) -> np.ndarray:
        """(∂h/∂x, ∂h/∂y) at (x, y): shape (..., 2)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        g = np.zeros(x.shape + (2,))
        idx = self._which(x, y)
        for i, pl in enumerate(self.planes):
            g[idx == i] = pl.gradient
        return g

    def normal(self, x, y) -> np.ndarray:
        """Outward unit normal at (x, y): shape (..., 3) (Z up on flat ground)."""
        g = self.gradient(x, y)
        n = np.concatenate([-g, np.ones(g.shape[:-1] + (1,))], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def friction_at(self, x, y) -> float:
        """Coulomb μ at one point (x, y) (m)."""
        i = int(self._which(x, y))
        if i < 0 or self.planes[i].friction is None:
            return float(self.friction)
        return float(self.planes[i].friction)

    def frame(self, x, y) -> np.ndarray:
        """Local contact frame at one point: 3×3 rotation with columns (t₁, t₂, n) (world)."""
        n = self.normal(x, y).reshape(3)
        if n[2] >= 1.0 - 1e-15:
            return np.eye(3)
        t1 = np.array([1.0, 0.0, 0.0]) - n[0] * n
        if np.linalg.norm(t1) < 1e-9:  # cannot happen for |angle| < 90°, kept for safety
            t1 = np.array([0.0, 1.0, 0.0]) - n[1] * n
        t1 /= np.linalg.norm(t1)
        return np.column_stack([t1, np.cross(n, t1), n])

    def friction_basis(self, x, y) -> np.ndarray:
        """V (3×4, world): the friction pyramid at (x, y); a contact force is f = V λ, λ ≥ 0.

        Equals :func:`scenegraph.model.dynamics.friction_basis` (μ of the ground) on flat ground.
        """
        V = friction_basis(self.friction_at(x, y))
        return V if self.flat else self.frame(x, y) @ V

    def cone_violation(self, x, y, f) -> float:
        """How far a world force f (N) at (x, y) leaves the Coulomb cone (N; 0 inside):
        max(‖f_t‖ − μ f_n, −f_n) with f_n = f · n."""
        f = np.asarray(f, float)
        n = self.normal(x, y).reshape(3)
        fn = float(f @ n)
        ft = float(np.linalg.norm(f - fn * n))
        return max(0.0, ft - self.friction_at(x, y) * fn, -fn)

    # --- CasADi ---------------------------------------------------------------------------
    def z(self, x, y):
        """Ground height at (x, y) for the solver: exactly ``0.0`` on flat ground, a float for
        numeric (x, y), else a CasADi expression (``if_else`` over the planes' regions)."""
        if self.flat:
            return 0.0
        if not any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in (x, y)):
            return self.height(float(x), float(y))
        h = 0.0
        for pl in reversed(self.planes):  # first match wins: outermost if_else
            x0, y0, x1, y1 = pl.region
            inside = ca.logic_and(ca.logic_and(x >= x0, x <= x1), ca.logic_and(y >= y0, y <= y1))
            h = ca.if_else(inside, pl.plane_height(x, y), h)
        return h


FLAT = Ground()


def ground_from_environment(env, friction: float | None = None) -> Ground:
    """The Ground of a scenario's ``environment`` (schema degrees → radians).

    ``friction`` is μ off the slopes (default: :data:`scenegraph.model.dynamics.MU`, which is what
    the solver has always used on flat ground); a slope's own ``friction`` overrides it.
    """
    planes = []
    for s in env.slopes:
        reg = (float(s.region.min[0]), float(s.region.min[1]), float(s.region.max[0]), float(s.region.max[1]))
        origin = tuple(float(v) for v in s.origin) if s.origin is not None else \
            ((reg[0] + reg[2]) / 2, (reg[1] + reg[3]) / 2)
        planes.append(Plane(math.radians(s.angle), math.radians(s.heading), reg, origin,
                            None if s.friction is None else float(s.friction), s.name))
    return Ground(float(MU if friction is None else friction), tuple(planes))
