"""Physics of free flight measured from a stage alone (issue 20): the centre of mass on a
parabola with g = 9.81 m/s² and a constant angular momentum about it.

For each maximal run of frames in which no vertex of the character is within ``contact_tol``
of the ground (``pad`` frames trimmed at each end: the finite differences there straddle
the contact), with the centre of mass c(t) and the angular momentum H_c(t) of
:func:`.momenta.momenta`:

* ``parabola_rms_mm``: RMS residual of the least-squares fit c_z(t) + g t²/2 = a + b t and
  c_x, c_y = a + b t (g fixed at 9.81, not fitted), all three axes together (mm);
* ``fitted_g``: −2 × the t² coefficient of a free quadratic fit of c_z (m/s²), for reference;
* ``ang_mom_drift``: max_t |H_c(t) − mean H_c| / |mean H_c| (dimensionless), and
  ``ang_mom_drift_abs`` the numerator (kg·m²/s), for flights whose angular momentum is near zero.

Frames: world, z up, m, s (the reader converts the stage).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenegraph.stage_audit.checks import heights_above_ground
from scenegraph.stage_audit.momenta import G, momenta
from scenegraph.stage_audit.reader import StageSamples

__all__ = ["FlightPhysics", "flight_physics"]


@dataclass(frozen=True)
class FlightPhysics:
    """One flight: frames [start, stop) of the samples, and its measures (module docstring)."""

    start: int
    stop: int
    duration: float
    parabola_rms_mm: float
    fitted_g: float
    ang_mom_mean: tuple[float, float, float]
    ang_mom_drift: float
    ang_mom_drift_abs: float


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    out, k = [], 0
    while k < len(mask):
        if mask[k]:
            j = k
            while j < len(mask) and mask[j]:
                j += 1
            out.append((k, j))
            k = j
        else:
            k += 1
    return out


def flight_physics(samples: StageSamples, character: str, contact_tol: float = 0.005, pad: int = 2,
                   min_frames: int = 8) -> list[FlightPhysics]:
    """The flights of ``character`` in ``samples`` (a :class:`.reader.StageSamples`)."""
    ch = next(c for c in samples.characters if c.name == character)
    ms = ch.meshes
    h = heights_above_ground(ms.points, samples.ground)
    airborne = h.min(axis=1) > contact_tol
    dt = 1.0 / samples.fps
    M = momenta(ms.points, ms.tris, ms.tri_mesh, ms.vert_mesh, ms.density, dt)
    out = []
    for a, b in _runs(airborne):
        a, b = a + pad, b - pad
        if b - a < min_frames:
            continue
        t = samples.times[a:b] - samples.times[a]
        c = M.com[a:b]
        A = np.stack([np.ones_like(t), t], axis=1)
        res = []
        for axis in range(3):
            y = c[:, axis] + (G * t ** 2 / 2 if axis == 2 else 0.0)
            coef, *_ = np.linalg.lstsq(A, y, rcond=None)
            res.append(y - A @ coef)
        rms = float(np.sqrt(np.mean(np.concatenate(res) ** 2))) * 1000.0
        fitted_g = float(-2 * np.polyfit(t, c[:, 2], 2)[0])
        H = M.ang_momentum_com[a:b]
        H = H[np.all(np.isfinite(H), axis=1)]
        Hm = H.mean(axis=0)
        dev = float(np.linalg.norm(H - Hm, axis=1).max())
        out.append(FlightPhysics(a, b, float(t[-1]), rms, fitted_g, tuple(float(x) for x in Hm),
                                 dev / max(float(np.linalg.norm(Hm)), 1e-12), dev))
    return out
