"""The scenario ``edit:`` block: edit a captured jump keeping its momentum pattern (issue 20
item 3, thesis ch. 4) — the scenario form of ``compose edit CLIP.bvh``.

A scenario with an ``edit:`` block edits a clip instead of synthesising characters, so it
has no ``characters``, ``goals``, ``couplings``, ``schedule``, ``duration``, ``timing``,
``duration_bounds`` or ``environment`` (each is rejected, located, when given: it would have
no effect — the performer's body, the time span and the floor all come from the clip)::

    name: edit_broad_jump
    edit:
      clip: clips/jump_broad_cmu_16_05.bvh   # BVH, relative to the scenario's folder
      frames: [60, 250]                      # source frames [A, B) at the clip's own rate
      further_m: 0.3                         # land this much further (m)
      higher_m: 0.0                          # raise the apex this much (m)
      turn_deg: 0.0                          # turn this much more in the air (deg, CCW seen from above)
      character: jumper                      # the edited character's name in the stage

``compose run`` executes it with :mod:`schedules.execution.edit_run`.  This module is the
language layer: it checks what can be checked from the file alone (the clip exists, is a
BVH inside the allowed folders, has the frames asked for — read from its header) and
imports nothing from ``scenegraph``.

Units: m, deg; frames are the clip file's frame indices (frame 0 included).
"""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, Strict

from scenarios.bundled import BUNDLED_DIR

__all__ = ["EditBlock", "EDIT_LIMITS", "CLIPS_DIR", "EDIT_EXCLUDES", "edit_problems", "clip_path", "bvh_frame_count"]

CLIPS_DIR = BUNDLED_DIR / "clips"
# What a momentum-preserving jump edit can keep physical (scenegraph.export.clip_edit checks the same):
# further_m |·| ≤ 2 m, higher_m in [−0.3, 1] m, turn_deg |·| ≤ 360°.
EDIT_LIMITS = {"further_m": (-2.0, 2.0), "higher_m": (-0.3, 1.0), "turn_deg": (-360.0, 360.0)}
# top-level scenario fields that mean nothing to an edit (the clip gives the body, the time and the floor)
EDIT_EXCLUDES = ("characters", "goals", "couplings", "schedule", "duration", "timing", "duration_bounds",
                 "environment")
MAX_HEADER_BYTES = 1_000_000  # a BVH hierarchy is a few kB; the header is read up to "Frame Time"

Num = Annotated[float, Strict()]
Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")]


class EditBlock(BaseModel):
    """Edit a captured jump: land further, rise higher, turn more in the air, keeping the clip's
    momentum pattern (thesis ch. 4; docs/dynamic-motion.md)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)  # as the schema's models

    clip: str = Field(min_length=1, max_length=1000,
                      description="BVH clip of a jump, relative to the scenario's folder (or a bundled clip "
                                  "under scenarios/clips)")
    frames: tuple[Annotated[int, Strict(), Field(ge=0)], Annotated[int, Strict(), Field(ge=1)]] | None = Field(
        None, description="source frames [A, B) of the jump in the clip file (default: all)")
    further_m: Num = Field(0.0, ge=EDIT_LIMITS["further_m"][0], le=EDIT_LIMITS["further_m"][1],
                           description="land this much further along the jump (m)")
    higher_m: Num = Field(0.0, ge=EDIT_LIMITS["higher_m"][0], le=EDIT_LIMITS["higher_m"][1],
                          description="raise the centre of mass's apex this much (m)")
    turn_deg: Num = Field(0.0, ge=EDIT_LIMITS["turn_deg"][0], le=EDIT_LIMITS["turn_deg"][1],
                          description="turn this much more in the air (deg, counter-clockwise from above)")
    character: Name = Field("jumper", description="the edited character's name in the stage")


def clip_path(block: EditBlock, base_dir: Path | None) -> Path:
    """The clip file of ``block`` (relative paths resolve against the scenario's folder)."""
    p = Path(block.clip).expanduser()
    if not p.is_absolute():
        p = (base_dir or Path.cwd()) / p
    return p.resolve()


def bvh_frame_count(path: Path) -> int | None:
    """The ``Frames:`` count of a BVH file's header, or None when it has none."""
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER_BYTES).decode("utf-8", "replace")
    for line in head.splitlines():
        s = line.strip()
        if s.lower().startswith("frames:"):
            try:
                return int(s.split(":", 1)[1])
            except ValueError:
                return None
    return None


def edit_problems(block: EditBlock, given: set[str], context: dict | None) -> list[tuple[tuple, str]]:
    """(field path, message) of everything wrong with an edit scenario: synthesis fields given
    (``given``: the scenario's top-level fields set in the file) and a clip that is missing,
    not a BVH, outside the allowed folders, or shorter than ``frames``."""
    out: list[tuple[tuple, str]] = []
    for f in EDIT_EXCLUDES:
        if f in given:
            out.append(((f,), f"an edit scenario edits its clip: '{f}' has no effect here (the body, the time "
                              "span and the floor come from the clip); remove it"))
    ctx = context or {}
    base = ctx.get("base_dir")
    base = Path(base) if base is not None else None
    p = clip_path(block, base)
    where = ("edit", "clip")
    if p.suffix.lower() != ".bvh":
        return out + [(where, f"clip {block.clip!r} must be a .bvh file")]
    roots = list(dict.fromkeys([(base or Path.cwd()).resolve(), CLIPS_DIR.resolve()]))
    if not any(p.is_relative_to(r) for r in roots):
        return out + [(where, f"clip path {block.clip!r} leaves the allowed folders (the scenario's folder "
                              f"{roots[0]} and the bundled clips {CLIPS_DIR})")]
    if not p.is_file():
        return out + [(where, f"clip {block.clip!r} not found (looked at {p})")]
    n = bvh_frame_count(p)
    if n is None:
        return out + [(where, f"clip {block.clip!r} has no 'Frames:' line: not a BVH motion")]
    if block.frames is not None:
        a, b = block.frames
        if b <= a + 1:
            out.append((("edit", "frames"), f"frames [{a}, {b}): need at least 2 frames (B > A + 1)"))
        elif b > n:
            out.append((("edit", "frames"), f"frames [{a}, {b}) run past the clip's {n} frames"))
    return out
