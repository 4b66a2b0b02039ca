"""``compose preview`` and ``compose export-bvh``: look at a stage, or convert it for mocap tools.

Both read the stage back with UsdSkel (joint transforms evaluated by usd-core), so they work
on any stage ``compose run`` wrote, in any of .usda/.usdc/.usdz.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from scenarios.errors import InputError

__all__ = ["register", "find_stage", "output_path"]

STAGE_EXTS = (".usda", ".usdc", ".usdz", ".usd")


def find_stage(arg: str) -> Path:
    """A stage file, or the one stage inside a run directory."""
    p = Path(arg)
    if p.is_dir():
        found = sorted(x for x in p.iterdir() if x.suffix.lower() in STAGE_EXTS and not x.name.startswith("."))
        if not found:
            raise InputError(f"{p} is a directory without a USD stage (.usda/.usdc/.usdz)")
        if len(found) > 1:
            raise InputError(f"{p} holds several stages ({', '.join(x.name for x in found)}): name one")
        return found[0]
    if not p.exists():
        raise InputError(f"no such stage: {p}")
    if p.suffix.lower() not in STAGE_EXTS:
        raise InputError(f"{p} is not a USD stage (.usda/.usdc/.usdz)")
    return p


def output_path(value: str | None, default: Path, flag: str, suffixes: tuple[str, ...]) -> Path:
    """Where a command will write, checked before any work: not a directory, its folder
    exists, a known suffix, and not the input itself."""
    p = Path(value) if value else default
    if p.is_dir():
        raise InputError(f"{flag} {p}: is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{flag} {p}: folder {parent} does not exist")
    if p.suffix.lower() not in suffixes:
        raise InputError(f"{flag} {p}: expected a file ending in {', '.join(suffixes)}")
    return p


def _preview(args) -> int:
    from scenegraph.export import preview
    stage = find_stage(args.stage)
    out = output_path(args.output, stage.with_name(stage.stem + "_preview.png"), "-o/--output",
                      (".png", ".gif", ".mp4", ".mov", ".m4v"))
    if not 1 <= args.frames <= 200:
        raise InputError(f"--frames {args.frames}: must be between 1 and 200")
    cam = preview.parse_camera(args.camera)
    scene = preview.scene_from_stage(stage)
    wanted_movie = out.suffix.lower() in (".mp4", ".mov", ".m4v")
    written = preview.render_preview(scene, out, frames=args.frames, camera=cam)
    if wanted_movie and written.suffix.lower() == ".png":
        print("ffmpeg not found: wrote an image strip instead of a movie")
    print(f"wrote {written}")
    return 0


def _export_bvh(args) -> int:
    from scenegraph.export import preview
    from scenegraph.export.bvh import bvh_from_joint_transforms, end_site_of
    stage_path = find_stage(args.stage)
    out = output_path(args.output, stage_path.with_suffix(".bvh"), "-o/--output", (".bvh",))
    if args.fps is not None and not (np.isfinite(args.fps) and 0 < args.fps <= 1000):
        raise InputError(f"--fps {args.fps:g}: must be in (0, 1000]")
    stage = preview.open_stage(stage_path)
    t0, t1 = preview.stage_time_range(stage, stage_path)  # checks timeCodesPerSecond too
    tcps = stage.GetTimeCodesPerSecond()
    fps = float(args.fps) if args.fps else tcps
    n = int(np.floor((t1 - t0) / tcps * fps + 1e-9)) + 1
    if n > preview.MAX_STAGE_FRAMES:
        raise InputError(f"{stage_path}: {n} frames at {fps:g} fps, above the limit of {preview.MAX_STAGE_FRAMES}")
    codes = t0 + np.arange(n) * (tcps / fps)  # UsdSkel interpolates between samples
    scene = preview.scene_from_stage(stage_path, codes, with_local=True)
    chars = scene.characters
    if args.character:
        chars = [c for c in chars if c.name == args.character]
        if not chars:
            raise InputError(f"no character {args.character!r} in {stage_path} "
                             f"(has: {', '.join(c.name for c in scene.characters)})")
    for c in chars:
        path = out if len(chars) == 1 else out.with_name(f"{out.stem}_{c.name.replace(' ', '_')}{out.suffix}")
        ends = {}
        has_child = set(c.parents)
        for j, centre, semi in c.ellipsoids:  # End Site: far tip of a leaf body's ellipsoid
            if j not in has_child:
                ends[j] = end_site_of(centre, semi)
        bvh_from_joint_transforms(path, c.joint_names, c.parents, c.local, fps, units=args.units, end_sites=ends)
        print(f"wrote {path} ({c.name}, {len(codes)} frames at {fps:g} fps)")
    return 0


def register(sub) -> None:
    p = sub.add_parser("preview", help="render an image strip or movie of a stage (or of the stage in a run directory)",
                       description="Render the characters (ellipsoids), footprints, goals and ground of a USD stage. "
                                   "A .mp4 output needs ffmpeg (otherwise a PNG strip is written); .gif always works.")
    p.add_argument("stage", metavar="STAGE", help="a .usda/.usdc/.usdz stage, or a run directory holding one")
    p.add_argument("-o", "--output", help="output .png (strip), .gif or .mp4 (default: STAGE_preview.png)")
    p.add_argument("--frames", type=int, default=6, help="frames in the strip (default 6)")
    p.add_argument("--camera", default="side",
                   help="side, front, back, three-quarter, top, or AZ,EL in degrees, e.g. --camera=-55,20 "
                        "(default side)")
    p.set_defaults(func=_preview)

    b = sub.add_parser("export-bvh", help="write the characters of a stage as BVH files",
                       description="BVH: Y up, facing +Z, ZYX channels; one file per character "
                                   "(OUT_<name>.bvh when the stage has several).")
    b.add_argument("stage", metavar="STAGE", help="a .usda/.usdc/.usdz stage, or a run directory holding one")
    b.add_argument("-o", "--output", help="output .bvh (default: STAGE.bvh)")
    b.add_argument("--fps", type=float, help="frame rate of the BVH (default: the stage's)")
    b.add_argument("--character", help="only this character")
    b.add_argument("--units", choices=("cm", "m", "mm"), default="cm", help="length unit (default cm)")
    b.set_defaults(func=_export_bvh)
