"""The heel's shoe spring (paper Eq. 9) as the compliance of a planned heel contact.

The paper's shoe spring pushes a heel up with g(h̄ − h) k_shoe (h̄ − h) (N, vertical; h the
heel handle's height above the ground, h̄ = ``h_rest``, g the smooth step
``dynamics.sigmoid``).  Applied at every instant, as the residual kernel does, it is a
frictionless force field that holds up any heel within ~5 mm of the floor: a runner's heel
hovering 1–2 mm up carried 0.35–0.57 body weight through its "flights", and a trailing heel
rising through the rest height between two evaluation points left 0.06–0.12 body weight of
the equations of motion unbalanced (measured, issue #15).

Gated (the transcription's and the audits' default), the spring acts only while a footstep
plants that heel (``footsteps.contact_points``), scaled by :func:`shoe_gate`: 1 inside the
heel's planned interval, ramping linearly from 0 over SHOE_RAMP seconds after a touch-down
and before a lift-off that lie inside the motion — a heel on the floor compresses its shoe
by h̄, so an ungated switch would be a force step of k_shoe h̄ that a motion with continuous
acceleration cannot balance on both sides (the same reason the contact forces start and end
at zero).  The ramp ends are nodes of the dense transcription (``_node_grid``), so the gate
is piecewise linear between nodes as the contact forces are.  Times: world s; forces: N.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.footsteps import Footstep, contact_points

__all__ = ["SHOE_RAMP", "SIDES", "heel_intervals", "shoe_gate", "gate_breaks", "shoe_force_numeric"]

SHOE_RAMP = 0.03  # s: the gate's rise after a planned heel touch-down and fall before its lift-off
SIDES = ("l", "r")


def heel_intervals(ch, footsteps, ground=None) -> dict[str, list[tuple[float, float]]]:
    """Side ('l', 'r') → the planned heel contact intervals (world s) of ``footsteps``."""
    out: dict[str, list] = {s: [] for s in SIDES}
    for step in footsteps:
        for handle, (ta, tb), _ in contact_points(ch, step, None, ground):
            if handle.startswith("heel_"):
                out[handle.rsplit("_", 1)[1]].append((float(ta), float(tb)))
    return out


def _ramps(ta: float, tb: float, start: float, end: float) -> tuple[float, float]:
    """Ramp lengths (s) at the two ends of a heel interval: none at an end outside the motion."""
    half = 0.5 * (tb - ta)
    ra = min(SHOE_RAMP, half) if ta > start + 1e-9 else 0.0
    rb = min(SHOE_RAMP, half) if tb < end - 1e-9 else 0.0
    return ra, rb


def shoe_gate(ch, footsteps: tuple[Footstep, ...] | list, times, start: float, end: float,
              ground=None) -> np.ndarray:
    """(2, n) gate in [0, 1] of the left and right shoe spring at world ``times`` (s) of a motion
    over [start, end]: see the module docstring."""
    t = np.atleast_1d(np.asarray(times, float))
    gate = np.zeros((len(SIDES), len(t)))
    for i, side in enumerate(SIDES):
        for ta, tb in heel_intervals(ch, footsteps, ground)[side]:
            ra, rb = _ramps(ta, tb, start, end)
            g = ((t >= ta - 1e-9) & (t <= tb + 1e-9)).astype(float)
            if ra > 0:
                g = np.minimum(g, np.clip((t - ta) / ra, 0.0, 1.0))
            if rb > 0:
                g = np.minimum(g, np.clip((tb - t) / rb, 0.0, 1.0))
            gate[i] = np.maximum(gate[i], g)
    return gate


def gate_breaks(ch, footsteps, start: float, end: float, ground=None) -> list[float]:
    """World times (s) where a gate kinks inside (start, end): interval ends and ramp ends."""
    out = []
    for side in SIDES:
        for ta, tb in heel_intervals(ch, footsteps, ground)[side]:
            ra, rb = _ramps(ta, tb, start, end)
            out += [ta, tb, ta + ra, tb - rb]
    return sorted({t for t in out if start < t < end})


def shoe_force_numeric(height_above_ground, k_shoe: float, h_rest: float) -> np.ndarray:
    """Vertical shoe force (N) of ``dynamics.shoe_force`` at heel heights above the ground (m)."""
    d = h_rest - np.asarray(height_above_ground, float)
    return (np.tanh(500.0 * d) + 1.0) / 2.0 * k_shoe * d
