"""Editing a captured jump end to end (``compose edit``): load the clip, edit it keeping its
momentum pattern (:mod:`.momentum_edit`), write a USD stage and a BVH, and measure the edited
flight from the written stage alone (:mod:`.stage_audit.flight`), beside the same
measure of a naive displacement-map edit of the clip.

Units: m, s, deg at this interface (``turn_deg``); the clip is fitted at its own 120 fps.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from scenarios.edit_block import EDIT_LIMITS
from scenarios.errors import InputError

from scenegraph.export.bvh import export_bvh
from scenegraph.mocap.clip import load_clip
from scenegraph.mocap.momentum_edit import momentum_edit, naive_edit
from scenegraph.stage_audit import read_stage
from scenegraph.stage_audit.flight import flight_physics
from scenegraph.export.usd import CharacterTrack, export_usd

__all__ = ["edit_clip", "stage_flight", "EDIT_FPS"]

EDIT_FPS = 120.0  # the clip is fitted and edited at the capture rate: flight physics needs it


def stage_flight(path, name: str = "jumper") -> dict:
    """The longest flight of ``name`` measured from the stage at ``path`` (see
    :func:`scenegraph.stage_audit.flight.flight_physics`), as a dict; {} without a flight."""
    fl = flight_physics(read_stage(path), name)
    if not fl:
        return {}
    f = max(fl, key=lambda f: f.stop - f.start)
    return {"frames": [f.start, f.stop], "duration_s": f.duration, "parabola_rms_mm": f.parabola_rms_mm,
            "fitted_g": f.fitted_g, "ang_mom_drift": f.ang_mom_drift, "ang_mom_drift_abs": f.ang_mom_drift_abs}


def edit_clip(clip, out_usd, out_bvh=None, frames: tuple[int, int] | None = None, longer: float = 0.0,
              higher: float = 0.0, turn_deg: float = 0.0, naive_usd=None, name: str = "jumper") -> dict:
    """Edit the jump in ``clip`` (BVH path; source ``frames`` [A, B)), write the stage
    ``out_usd`` and the BVH ``out_bvh`` (default: next to the stage), and return a report:
    what was asked, what the edit measures (:func:`momentum_edit`), the flight measured from
    the stage, the naive edit's flight (written to ``naive_usd`` or a sibling file) and the
    seconds spent editing (clip fitting excluded).  ``name``: the character's name in the stage."""
    lim = EDIT_LIMITS  # the scenario language's bounds (scenarios/edit_block.py)
    if not (lim["further_m"][0] <= longer <= lim["further_m"][1] and lim["higher_m"][0] <= higher <= lim["higher_m"][1]
            and lim["turn_deg"][0] <= turn_deg <= lim["turn_deg"][1]):
        raise InputError(f"edit: --longer {longer} m (|·| ≤ 2), --higher {higher} m (−0.3…1) and --turn {turn_deg} "
                         "deg (|·| ≤ 360) are beyond what a jump edit can keep physical")
    c = load_clip(clip, fps=EDIT_FPS, frames=frames)
    t0 = time.perf_counter()
    try:
        r = momentum_edit(c.character, c.q, EDIT_FPS, longer, higher, math.radians(turn_deg))
    except ValueError as e:
        raise InputError(f"{clip}: {e}") from None
    seconds = time.perf_counter() - t0
    out_usd = Path(out_usd)
    out_bvh = Path(out_bvh) if out_bvh is not None else out_usd.with_suffix(".bvh")
    export_usd(out_usd, [CharacterTrack(name, c.character, r.q)], EDIT_FPS)
    export_bvh(out_bvh, CharacterTrack(name, c.character, r.q), EDIT_FPS)
    a, b = r.clip_stages.a, r.clip_stages.b
    d = np.asarray(c.q[b, :2] - c.q[a, :2], float)
    qn = naive_edit(c.q, r.clip_stages, EDIT_FPS, longer, higher, direction=d)
    naive_usd = Path(naive_usd) if naive_usd is not None else out_usd.with_name(out_usd.stem + "_naive.usdc")
    export_usd(naive_usd, [CharacterTrack(name, c.character, qn)], EDIT_FPS)
    measured = {k: v for k, v in r.measured.items() if k != "planted_foot_error_frames"}
    return {"clip": str(clip), "frames": list(c.data.frame_range), "asked": r.asked, "measured": measured,
            "stage": str(out_usd), "bvh": str(out_bvh), "flight": stage_flight(out_usd, name),
            "naive": {"stage": str(naive_usd), "flight": stage_flight(naive_usd, name)}, "edit_seconds": seconds}
