"""The root of an initial motion placed where its poses put the feet on the footprints.

``gait.initial_motion`` runs the root through the midpoints of consecutive footprints and takes
the joint angles from an example motion matched by leg phase.  When the example was performed
at another speed or stride (a style learned at 1.36 m/s asked for 1.9 m/s), its planted feet
then sit centimetres to decimetres off their footprints — 8–15 cm ahead on CMU 07_12 with the
07_01 poses — and the kinematic pre-solve has to drag the root back, which it does with large
accelerations.  :func:`fit_root_to_footprints` moves the root instead, by a smooth offset:

1. for every footstep, the mean world offset (x, y, z; m) of its planted handles (heel, ball)
   from their targets (footprint position, ground height) over the frames they are planted;
2. a cubic spline through those per-footstep offsets at the middle of each footstep
   (natural ends, held constant before the first and after the last);
3. the root position minus that spline at every frame.

Heading and joint angles are left as they are, so the poses still come from the example.  A
footstep's offset is a mean over its whole stance, so the root moves by at most the stride
mismatch spread over a step (a few m/s² of root acceleration), not by a frame-by-frame fit.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from scenegraph.model.body import Character
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.ground import FLAT, Ground
from scenegraph.model.kinematics import handle_positions_fn

__all__ = ["footprint_offsets", "fit_root_to_footprints"]


def footprint_offsets(ch: Character, footsteps: tuple[Footstep, ...], times: np.ndarray, q: np.ndarray,
                      ground: Ground = FLAT) -> tuple[np.ndarray, np.ndarray]:
    """(knot times (K,) s, offsets (K, 3) m): per footstep with planted frames, the mean of
    (handle position − its target) over the frames [ta, tb] each of its handles is planted,
    at the middle of those frames.  ``q`` (T, 35) poses at world ``times`` (T,)."""
    times, q = np.asarray(times, float), np.asarray(q, float)
    pts = [(st, cp) for st in footsteps for cp in contact_points(ch, st, None, ground)]
    names = tuple(sorted({cp[0] for _, cp in pts}))
    if not names:
        return np.zeros(0), np.zeros((0, 3))
    hp = np.asarray(handle_positions_fn(ch, names).map(len(times))(q.T)).reshape(3, len(names), len(times), order="F")
    knots, offs = [], []
    for st in footsteps:
        errs, when = [], []
        for handle, (ta, tb), xy in contact_points(ch, st, None, ground):
            inside = (times >= ta - 1e-9) & (times <= tb + 1e-9)
            if not inside.any():
                continue
            target = np.array([xy[0], xy[1], ground.height(xy[0], xy[1])])
            errs.append(hp[:, names.index(handle), inside].T - target)
            when.append(times[inside])
        if errs:
            knots.append(float(np.mean(np.concatenate(when))))
            offs.append(np.concatenate(errs).mean(axis=0))
    if not knots:
        return np.zeros(0), np.zeros((0, 3))
    k, o = np.array(knots), np.array(offs)
    order = np.argsort(k, kind="stable")
    k, o = k[order], o[order]
    # footsteps whose middles coincide (both feet planted over the same frames) share one knot
    ku, inv = np.unique(np.round(k, 9), return_inverse=True)
    return ku, np.stack([o[inv == i].mean(axis=0) for i in range(len(ku))])


def fit_root_to_footprints(ch: Character, footsteps: tuple[Footstep, ...], times: np.ndarray, q: np.ndarray,
                           ground: Ground = FLAT, vertical: bool = True) -> np.ndarray:
    """``q`` (T, 35) with the root position moved by the smooth footprint offset of the module
    docstring (``vertical``: the height too; else x, y only).  Returns a new array."""
    times, q = np.asarray(times, float), np.array(q, float)
    k, o = footprint_offsets(ch, footsteps, times, q, ground)
    if len(k) == 0:
        return q
    dims = 3 if vertical else 2
    if len(k) == 1:
        shift = np.repeat(o[:1, :dims], len(times), axis=0)
    else:
        spl = CubicSpline(k, o[:, :dims], bc_type="natural")
        shift = spl(np.clip(times, k[0], k[-1]))
    q[:, :dims] -= shift
    return q
