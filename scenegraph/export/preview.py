"""Looking at results: an image strip or movie of the characters, and report plots.

Everything here draws with matplotlib (the optional extra ``plots``) through its object API
(``matplotlib.figure.Figure``; no pyplot, no GUI backend).  Functions take plain data —
numpy arrays, dicts, lists — so the executor can call them without a Scene.

Characters are drawn as their ellipsoids under an orthographic camera: the outline of an
ellipsoid under orthographic projection is an ellipse, computed exactly, and bodies are
painted far to near.  The ground is a grid at z = 0; footprints are discs on it, goals
spheres; a marker is drawn solid while its time interval contains the frame's time and
faint otherwise.

Cameras: ``side`` (from -Y, the default: characters walk left to right along +X),
``front`` (from +X), ``back``, ``three-quarter``, ``top``, or ``AZ,EL`` in degrees (the
camera sits at azimuth AZ from +X toward +Y and elevation EL above the ground).
"""
from __future__ import annotations

import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from scenarios.atomic import atomic_path
from scenarios.errors import ComposeError, InputError

__all__ = [
    "PreviewCharacter", "PreviewMarker", "PreviewScene", "ViewCamera", "parse_camera", "scene_from_stage",
    "open_stage", "stage_time_range", "MAX_STAGE_FRAMES",
    "scene_from_tracks", "render_strip", "render_movie", "render_preview", "have_ffmpeg",
    "plot_energy_per_cycle", "plot_joint_torques", "plot_footprints", "write_report_plots",
]

CAMERAS = {"side": (-90.0, 12.0), "front": (0.0, 12.0), "back": (180.0, 12.0), "three-quarter": (-55.0, 22.0),
           "top": (-90.0, 90.0)}


# --- plain data ------------------------------------------------------------------------------

@dataclass
class PreviewCharacter:
    """One character: joint world transforms (T, J, 4, 4) (column-vector, m) on the scene's
    timeline, and its ellipsoids as (joint index, centre (3,), semi-axes (3,)) in joint frames.
    ``joint_names``/``parents``/``local`` (T, J, 4, 4) are filled when read from a stage."""

    name: str
    color: tuple[float, float, float]
    world: np.ndarray
    ellipsoids: list[tuple[int, np.ndarray, np.ndarray]]
    joint_names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    local: np.ndarray | None = None


@dataclass
class PreviewMarker:
    kind: str
    position: np.ndarray  # (3,) m; a footprint's is on the ground
    radius: float
    interval: tuple[float, float] | None = None
    name: str = ""


@dataclass
class PreviewScene:
    fps: float
    times: np.ndarray  # (T,) s
    characters: list[PreviewCharacter]
    markers: list[PreviewMarker] = field(default_factory=list)
    ramps: list[np.ndarray] = field(default_factory=list)  # upward faces (k, 3) of ramp meshes, world m


@dataclass(frozen=True)
class ViewCamera:
    """Orthographic camera at ``azimuth`` / ``elevation`` (degrees) looking at the action."""

    azimuth: float = -90.0
    elevation: float = 12.0

    def basis(self) -> np.ndarray:
        """Rows: screen right, screen up, toward the camera (world axes)."""
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        right = np.array([-math.sin(az), math.cos(az), 0.0])
        up = np.cross(d, right)
        return np.stack([right, up, d])


def parse_camera(spec: str | None) -> ViewCamera:
    """A camera from a preset name or ``"AZ,EL"`` (degrees)."""
    if spec is None or spec == "":
        return ViewCamera(*CAMERAS["side"])
    key = spec.strip().lower()
    if key in CAMERAS:
        return ViewCamera(*CAMERAS[key])
    try:
        az, el = (float(x) for x in key.split(","))
    except ValueError:
        raise InputError(f"unknown camera {spec!r}: use one of {', '.join(CAMERAS)} or 'AZ,EL' in degrees") from None
    if not (-90.0 <= el <= 90.0):
        raise InputError(f"camera elevation {el} is outside -90..90 degrees")
    return ViewCamera(az, el)


def _mpl():
    try:
        import matplotlib
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover - exercised only without the extra
        raise ComposeError("previews and plots need matplotlib: pip install 'compose-motion[plots]'") from None
    return matplotlib, Figure


def have_ffmpeg() -> bool:
    return shutil.which("ffmpeg") is not None


# --- building scenes ----------------------------------------------------------------------------

def _drawn_ellipsoids(ch, pos: dict) -> list:
    """(joint, centre, semi-axes) of the box around each solid the stage draws (body frame, m):
    what :func:`scene_from_stage` reads back from the meshes (keel solids for feet and toes,
    carried loads as boxes on their handles)."""
    from scenegraph.model.body import drawn_shapes
    from scenegraph.model.body import carried_half_extents
    out = []
    for bi, d in enumerate(drawn_shapes(ch)):
        out.append((pos[bi], *d.bounds()))
    index = {b.name: i for i, b in enumerate(ch.bodies)}
    for handle, extra in ch.loads:
        h = ch.handle(handle)
        out.append((pos[index[h.body]], np.array(h.point, float), carried_half_extents(extra)))
    return out


def scene_from_tracks(tracks, fps: float, markers=()) -> PreviewScene:
    """A preview scene from :class:`~scenegraph.export.usd.CharacterTrack` s (uses our FK)."""
    from scenegraph.model.kinematics import numeric_fk
    from scenegraph.export.usd import _CHARACTER_COLORS, _start_code, joint_paths
    starts = [_start_code(t.start_time, fps, t.name) for t in tracks]
    c0 = min(starts)
    c1 = max(s + np.asarray(t.q).shape[0] - 1 for s, t in zip(starts, tracks))
    codes = np.arange(c0, c1 + 1)
    chars = []
    for n, (s, tr) in enumerate(zip(starts, tracks)):
        q = np.asarray(tr.q, dtype=float)
        idx = np.clip(codes - s, 0, q.shape[0] - 1)  # hold the first/last pose outside the track
        R, p = numeric_fk(tr.character, q[idx])
        order, paths = joint_paths(tr.character)
        W = np.zeros(R.shape[:2] + (4, 4))
        W[..., :3, :3], W[..., :3, 3], W[..., 3, 3] = R, p, 1.0
        W = W[:, order]
        pos = {bi: j for j, bi in enumerate(order)}
        ells = _drawn_ellipsoids(tr.character, pos)
        color = tuple(tr.color) if tr.color is not None else _CHARACTER_COLORS[n % len(_CHARACTER_COLORS)]
        chars.append(PreviewCharacter(tr.name, color, W, ells, [p.rsplit("/", 1)[-1] for p in paths]))
    mk = [PreviewMarker(m.kind, np.asarray(m.position, float), float(m.radius),
                        tuple(m.interval) if m.interval is not None else None, m.name) for m in markers]
    return PreviewScene(float(fps), codes / float(fps), chars, mk)


def _np_matrices(arr) -> np.ndarray:
    """Vt.Matrix4dArray (row-vector) → numpy (N, 4, 4) column-vector."""
    return np.array(arr, dtype=float).reshape(-1, 4, 4).transpose(0, 2, 1)


def scene_from_stage(path, codes: Sequence[float] | None = None, *, with_local: bool = False) -> PreviewScene:
    """Read any UsdSkel stage back: joint world transforms at ``codes`` (default: every
    integer time code from start to end), ellipsoids fitted to the rigidly skinned meshes,
    and compose markers.  Works on every stage :func:`~scenegraph.export.usd.export_usd`
    writes (and on other UsdSkel stages, approximating each mesh by its bounding ellipsoid)."""
    from pxr import Tf
    path = Path(path)
    stage = open_stage(path)
    if codes is None:
        t0, t1 = stage_time_range(stage, path)
        codes = np.arange(math.floor(t0), math.floor(t1) + 1, dtype=float)
    else:
        stage_time_range(stage, path)  # the frame rate is checked all the same
    codes = np.asarray(codes, dtype=float)
    try:
        return _scene_from_stage(stage, path, codes, with_local)
    except ComposeError:
        raise
    except (Tf.ErrorException, ValueError, IndexError, TypeError, ZeroDivisionError, np.linalg.LinAlgError) as exc:
        # a stage compose did not write, with skeletons or meshes it cannot make sense of
        reason = " ".join(str(exc).split())[:200]
        raise InputError(f"{path}: not a stage compose can read ({type(exc).__name__}: {reason})") from None


MAX_STAGE_FRAMES = 1_000_000  # time codes read from one stage (a compose stage has 30 per second)


def open_stage(path) -> "Usd.Stage":
    """Open a USD stage; a missing, empty, binary or malformed file is an InputError with a
    one-line reason (never a pxr.Tf.ErrorException traceback)."""
    from pxr import Tf, Usd
    path = Path(path)
    if not path.exists():
        raise InputError(f"no such stage: {path}")
    if not path.is_file():
        raise InputError(f"{path} is not a file")
    if path.stat().st_size == 0:
        raise InputError(f"{path} is empty, not a USD stage")
    try:
        stage = Usd.Stage.Open(str(path))
    except Tf.ErrorException as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        reason = next((ln.rsplit(" : ", 1)[-1].strip("'") for ln in lines if "Error in" in ln), "unreadable")
        raise InputError(f"{path} is not a readable USD stage: {reason[:200]}") from None
    if stage is None:
        raise InputError(f"cannot open {path} as a USD stage")
    return stage


def stage_time_range(stage, path) -> tuple[float, float]:
    """(start, end) time codes of a stage, checked: a positive frame rate, finite, ordered, at
    most MAX_STAGE_FRAMES."""
    tcps = stage.GetTimeCodesPerSecond()
    if not (math.isfinite(tcps) and 0 < tcps <= 10_000):
        raise InputError(f"{path}: timeCodesPerSecond {tcps:g} is not a frame rate")
    if not stage.HasAuthoredTimeCodeRange():
        return 0.0, 0.0
    t0, t1 = float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 >= t0):
        raise InputError(f"{path}: time code range [{t0:g}, {t1:g}] is not a valid animation range")
    if t1 - t0 + 1 > MAX_STAGE_FRAMES:
        raise InputError(f"{path}: {t1 - t0 + 1:.0f} time codes, above the limit of {MAX_STAGE_FRAMES}")
    return t0, t1


def _scene_from_stage(stage, path: Path, codes: np.ndarray, with_local: bool) -> PreviewScene:
    from pxr import Usd, UsdGeom, UsdSkel
    tcps = stage.GetTimeCodesPerSecond() or 24.0
    cache = UsdSkel.Cache()
    chars: list[PreviewCharacter] = []
    xf = UsdGeom.XformCache()
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            skel = binding.GetSkeleton()
            sq = cache.GetSkelQuery(skel)
            joints = [str(j) for j in sq.GetJointOrder()]
            topo = sq.GetTopology()
            parents = [int(topo.GetParent(i)) for i in range(len(joints))]
            W = np.zeros((len(codes), len(joints), 4, 4))
            L = np.zeros_like(W) if with_local else None
            for k, c in enumerate(codes):
                xf.SetTime(Usd.TimeCode(float(c)))
                W[k] = _np_matrices(sq.ComputeJointWorldTransforms(xf))
                if with_local:
                    L[k] = _np_matrices(sq.ComputeJointLocalTransforms(Usd.TimeCode(float(c))))
            bind = _np_matrices(sq.GetJointWorldBindTransforms())
            ells: list[tuple[int, np.ndarray, np.ndarray]] = []
            color = None
            for skq in binding.GetSkinningTargets():
                mesh = UsdGeom.Mesh(skq.GetPrim())
                if not mesh:
                    continue
                pts = np.asarray(mesh.GetPointsAttr().Get(), dtype=float)
                if pts.size == 0:
                    continue
                idx, wts = skq.ComputeJointInfluences()
                idx = np.asarray(idx)
                if idx.size == 0:
                    continue
                j = int(np.bincount(idx).argmax())
                mapper = skq.GetJointMapper()
                if mapper is not None and not mapper.IsIdentity():
                    order = [str(x) for x in (skq.GetJointOrder() or [])]
                    if order:
                        j = joints.index(order[j])
                G = _np_matrices([skq.GetGeomBindTransform()])[0]
                ph = np.c_[pts, np.ones(len(pts))] @ G.T
                loc = ph @ np.linalg.inv(bind[j]).T
                lo, hi = loc[:, :3].min(0), loc[:, :3].max(0)
                ells.append((j, (lo + hi) / 2, np.maximum((hi - lo) / 2, 1e-4)))
                if color is None:
                    dc = mesh.GetDisplayColorPrimvar()
                    if dc and dc.Get() is not None and len(dc.Get()):
                        color = tuple(float(x) for x in dc.Get()[0])
            name = skel.GetPrim().GetAttribute("compose:character").Get() if skel.GetPrim().HasAttribute(
                "compose:character") else prim.GetName()
            chars.append(PreviewCharacter(str(name), color or (0.6, 0.6, 0.6), W, ells,
                                          [j.rsplit("/", 1)[-1] for j in joints], parents, L))
    if not chars:
        raise InputError(f"{path} has no UsdSkel character (no SkelRoot with a bound Skeleton)")
    markers, ramps = [], []
    for prim in stage.Traverse():
        if not prim.HasAttribute("compose:kind") or not prim.IsA(UsdGeom.Gprim) or prim.IsA(UsdGeom.BasisCurves):
            continue
        kind = str(prim.GetAttribute("compose:kind").Get())
        if kind in ("slope", "ground") and prim.IsA(UsdGeom.Mesh):  # a ramp: draw its top at its height
            ramps += _upward_faces(prim)
            continue
        M = _np_matrices([UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())])[0]
        pos = M[:3, 3].copy()
        radius = float(prim.GetAttribute("radius").Get() or 0.05)
        if prim.IsA(UsdGeom.Cylinder):
            pos[2] -= float(prim.GetAttribute("height").Get() or 0.0) / 2
        a, b = prim.GetAttribute("compose:startTime"), prim.GetAttribute("compose:endTime")
        interval = (float(a.Get()), float(b.Get())) if a and b and a.HasValue() and b.HasValue() else None
        markers.append(PreviewMarker(kind, pos, radius, interval, prim.GetName()))
    return PreviewScene(float(tcps), codes / float(tcps), chars, markers, ramps)


def _upward_faces(prim) -> list[np.ndarray]:
    """The faces of a mesh prim whose normal points up (world, m): a ramp's walking surface."""
    from pxr import Usd, UsdGeom
    mesh = UsdGeom.Mesh(prim)
    M = _np_matrices([UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())])[0]
    P = np.asarray(mesh.GetPointsAttr().Get(), float)
    P = P @ M[:3, :3].T + M[:3, 3]
    out, o = [], 0
    idx = list(mesh.GetFaceVertexIndicesAttr().Get())
    for n in mesh.GetFaceVertexCountsAttr().Get():
        f = P[idx[o:o + n]]
        o += n
        nrm = np.cross(f[1] - f[0], f[2] - f[0])
        if np.linalg.norm(nrm) > 0 and nrm[2] / np.linalg.norm(nrm) > 0.3:
            out.append(f)
    return out


# --- drawing -------------------------------------------------------------------------------------

def _ellipse_2d(P: np.ndarray, A: np.ndarray):
    """Outline of the ellipsoid {c + A u : |u| = 1} under projection rows P (2×3):
    (width, height, angle in degrees) for matplotlib's Ellipse."""
    B = P @ A
    M = B @ B.T
    w, V = np.linalg.eigh(M)
    w = np.maximum(w, 0.0)
    ang = math.degrees(math.atan2(V[1, 1], V[0, 1]))
    return 2 * math.sqrt(w[1]), 2 * math.sqrt(w[0]), ang


def _frame_items(scene: PreviewScene, k: int, cam: ViewCamera):
    """Drawable items (depth, kind, centre2d, w, h, angle, color, alpha) at frame k."""
    basis = cam.basis()
    P, d = basis[:2], basis[2]
    items = []
    t = scene.times[k]
    for m in scene.markers:
        active = m.interval is None or (m.interval[0] - 1e-9 <= t <= m.interval[1] + 1e-9)
        if m.kind == "footprint":
            A = np.diag([m.radius, m.radius, 1e-4])
            color, depth = (0.15, 0.15, 0.15), -1e9  # on the ground: drawn first
        else:
            A = np.eye(3) * m.radius
            color, depth = (0.95, 0.75, 0.1), float(d @ m.position)
        w, h, ang = _ellipse_2d(P, A)
        items.append((depth, "marker", P @ m.position, w, h, ang, color, 0.85 if active else 0.2))
    for ch in scene.characters:
        Wk = ch.world[k]
        for j, c, s in ch.ellipsoids:
            R, p = Wk[j, :3, :3], Wk[j, :3, 3]
            cw = p + R @ c
            w, h, ang = _ellipse_2d(P, R @ np.diag(s))
            items.append((float(d @ cw), "body", P @ cw, w, h, ang, ch.color, 1.0))
    items.sort(key=lambda it: it[0])
    return items


def _scene_bounds(scene: PreviewScene, cam: ViewCamera, ks) -> tuple[np.ndarray, np.ndarray]:
    P = cam.basis()[:2]
    pts = []
    for k in ks:
        for ch in scene.characters:
            Wk = ch.world[k]
            for j, c, s in ch.ellipsoids:
                cw = Wk[j, :3, 3] + Wk[j, :3, :3] @ c
                pts.append(P @ cw + s.max())
                pts.append(P @ cw - s.max())
    for m in scene.markers:
        pts.append(P @ m.position + m.radius)
        pts.append(P @ m.position - m.radius)
    for face in scene.ramps:
        pts.extend(face @ P.T)
    pts = np.array(pts)
    lo, hi = pts.min(0), pts.max(0)
    pad = 0.08 * max(hi - lo) + 0.05
    return lo - pad, hi + pad


def _ground_lines(scene: PreviewScene, cam: ViewCamera, ks):
    """Projected grid lines of the ground (z = 0) under the action, 0.5 m spacing."""
    pts = [ch.world[k][:, :3, 3] for ch in scene.characters for k in ks]
    pts += [m.position[None, :] for m in scene.markers]
    xy = np.concatenate(pts, axis=0)[:, :2]
    lo, hi = np.floor(xy.min(0) / 0.5) * 0.5 - 1.0, np.ceil(xy.max(0) / 0.5) * 0.5 + 1.0
    P = cam.basis()[:2]
    lines = []
    for x in np.arange(lo[0], hi[0] + 1e-9, 0.5):
        lines.append([P @ np.array([x, lo[1], 0.0]), P @ np.array([x, hi[1], 0.0])])
    for y in np.arange(lo[1], hi[1] + 1e-9, 0.5):
        lines.append([P @ np.array([lo[0], y, 0.0]), P @ np.array([hi[0], y, 0.0])])
    corners = [P @ np.array([a, b, 0.0]) for a, b in ((lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1]))]
    return lines, corners


def _draw_frame(ax, scene: PreviewScene, k: int, cam: ViewCamera, ks, limits, title: bool = True):
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Ellipse, Polygon
    ax.clear()
    lines, corners = _ground_lines(scene, cam, ks)
    if cam.elevation > 0:
        ax.add_patch(Polygon(np.array(corners), closed=True, facecolor=(0.93, 0.93, 0.9), edgecolor="none", zorder=0))
    ax.add_collection(LineCollection(lines, colors=[(0.75, 0.75, 0.72)], linewidths=0.5, zorder=1))
    P = cam.basis()[:2]
    for face in scene.ramps:  # ramps at their height, over the grid and under the bodies
        ax.add_patch(Polygon(face @ P.T, closed=True, facecolor=(0.80, 0.74, 0.62), edgecolor=(0.55, 0.5, 0.42),
                             linewidth=0.6, alpha=0.9, zorder=1.5))
    for z, (depth, kind, c2, w, h, ang, color, alpha) in enumerate(_frame_items(scene, k, cam)):
        edge = tuple(0.55 * x for x in color)
        ax.add_patch(Ellipse(tuple(c2), w, h, angle=ang, facecolor=color, edgecolor=edge, linewidth=0.6,
                             alpha=alpha, zorder=2 + z))
    lo, hi = limits
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)
    if title:
        ax.set_title(f"t = {scene.times[k]:.2f} s", fontsize=9)


def _pick_frames(scene: PreviewScene, n: int) -> list[int]:
    T = len(scene.times)
    n = max(1, min(int(n), T))
    return sorted(set(int(round(x)) for x in np.linspace(0, T - 1, n)))


def _atomic_save(fig, path: Path, **kw) -> Path:
    """Save ``fig`` through the atomic writer (the format follows ``path``'s extension)."""
    with atomic_path(path, suffix=path.suffix) as tmp:
        fig.savefig(tmp, **kw)
    return path


def render_strip(scene: PreviewScene, out, *, frames: int = 6, camera: ViewCamera | str | None = None,
                 panel_inches: float = 2.6, dpi: int = 110) -> Path:
    """A PNG strip of ``frames`` evenly spaced frames (one row, or rows of up to 6)."""
    _, Figure = _mpl()
    cam = camera if isinstance(camera, ViewCamera) else parse_camera(camera)
    ks = _pick_frames(scene, frames)
    limits = _scene_bounds(scene, cam, range(len(scene.times)))
    ncol = min(len(ks), 6)
    nrow = int(math.ceil(len(ks) / ncol))
    aspect = (limits[1][1] - limits[0][1]) / max(limits[1][0] - limits[0][0], 1e-9)
    fig = Figure(figsize=(panel_inches * ncol, max(panel_inches * nrow * min(max(aspect, 0.35), 2.0), 1.2) + 0.4))
    names = ", ".join(ch.name for ch in scene.characters)
    fig.suptitle(f"{names} — camera az {cam.azimuth:.0f}°, el {cam.elevation:.0f}°", fontsize=10)
    for i, k in enumerate(ks):
        ax = fig.add_subplot(nrow, ncol, i + 1)
        _draw_frame(ax, scene, k, cam, range(len(scene.times)), limits)
    fig.tight_layout()
    return _atomic_save(fig, Path(out), dpi=dpi)


def render_movie(scene: PreviewScene, out, *, camera: ViewCamera | str | None = None, fps: float | None = None,
                 inches: float = 6.0, dpi: int = 100) -> Path:
    """An MP4 (needs ffmpeg) or GIF (Pillow) of every frame."""
    _, Figure = _mpl()
    from matplotlib import animation
    out = Path(out)
    cam = camera if isinstance(camera, ViewCamera) else parse_camera(camera)
    fps = float(fps or scene.fps)
    ext = out.suffix.lower()
    if ext == ".gif":
        writer = animation.PillowWriter(fps=fps)
    elif ext in (".mp4", ".mov", ".m4v"):
        if not have_ffmpeg():
            raise ComposeError(f"writing {out.name} needs ffmpeg, which is not installed")
        writer = animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])
    else:
        raise InputError(f"unknown movie format {out.suffix!r} (use .mp4 or .gif)")
    all_k = range(len(scene.times))
    limits = _scene_bounds(scene, cam, all_k)
    aspect = (limits[1][1] - limits[0][1]) / max(limits[1][0] - limits[0][0], 1e-9)
    h = inches * min(max(aspect, 0.3), 1.5)
    fig = Figure(figsize=(inches, round(h * dpi / 2) * 2 / dpi))  # even pixel sizes for yuv420p
    ax = fig.add_axes((0, 0, 1, 0.94))
    with atomic_path(out, suffix=ext) as tmp:
        with writer.saving(fig, tmp, dpi):
            for k in all_k:
                _draw_frame(ax, scene, k, cam, all_k, limits)
                writer.grab_frame()
    return out


def render_preview(scene: PreviewScene, out, *, frames: int = 6, camera: ViewCamera | str | None = None) -> Path:
    """Movie when ``out`` asks for one and it can be made (MP4 needs ffmpeg), else a PNG strip
    (an MP4 request without ffmpeg writes ``out`` with the suffix ``.png``)."""
    out = Path(out)
    ext = out.suffix.lower()
    if ext == ".gif" or (ext in (".mp4", ".mov", ".m4v") and have_ffmpeg()):
        return render_movie(scene, out, camera=camera)
    if ext in (".mp4", ".mov", ".m4v"):
        out = out.with_suffix(".png")
    elif ext != ".png":
        raise InputError(f"unknown preview format {out.suffix!r} (use .png, .gif or .mp4)")
    return render_strip(scene, out, frames=frames, camera=camera)


# --- report plots -----------------------------------------------------------------------------

def plot_energy_per_cycle(energies, out, *, title: str = "Energy per schedule cycle") -> Path:
    """``energies``: a sequence of per-cycle energies, or {label: sequence} (e.g. per
    character or per step).  Log scale when positive values span more than 100×."""
    _, Figure = _mpl()
    series = dict(energies) if isinstance(energies, Mapping) else {"energy": energies}
    fig = Figure(figsize=(6.0, 3.6))
    ax = fig.add_subplot(1, 1, 1)
    allv = []
    for label, vals in series.items():
        v = np.asarray(vals, dtype=float).ravel()
        ax.plot(np.arange(1, len(v) + 1), v, marker="o", label=str(label))
        allv.append(v)
    v = np.concatenate(allv) if allv else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size and np.all(v > 0) and v.max() / v.min() > 100:
        ax.set_yscale("log")
    from matplotlib.ticker import MaxNLocator
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("cycle")
    ax.set_ylabel("energy")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if len(series) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _atomic_save(fig, Path(out), dpi=110)


_GROUPS = (("legs", ("hip", "knee", "ankle", "toe")), ("arms", ("shoulder", "elbow", "wrist")),
           ("trunk and neck", ("waist", "chest", "neck", "root")))


def plot_joint_torques(times, torques, names: Sequence[str], out, *, title: str = "Joint torques") -> Path:
    """``torques`` (T, n) N·m at ``times`` (T,) s, columns named by ``names`` (DOF names);
    one panel per body region."""
    _, Figure = _mpl()
    t = np.asarray(times, dtype=float).ravel()
    tau = np.asarray(torques, dtype=float)
    if tau.ndim != 2 or tau.shape[0] != t.size or tau.shape[1] != len(names):
        raise InputError(f"torques must have shape (len(times), len(names)) = ({t.size}, {len(names)}), got {tau.shape}")
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        g = next((label for label, keys in _GROUPS if any(n.startswith(k) for k in keys)), "other")
        groups.setdefault(g, []).append(i)
    fig = Figure(figsize=(7.5, 2.3 * len(groups) + 0.5))
    for r, (label, idx) in enumerate(groups.items()):
        ax = fig.add_subplot(len(groups), 1, r + 1)
        for i in idx:
            ax.plot(t, tau[:, i], linewidth=1.0, label=names[i])
        ax.set_ylabel(f"{label}\nN·m", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, ncol=4, loc="upper right")
        if r == len(groups) - 1:
            ax.set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _atomic_save(fig, Path(out), dpi=110)


def plot_footprints(footprints, out, *, trajectories: Mapping[str, np.ndarray] | None = None,
                    title: str = "Footprints from above") -> Path:
    """Top view.  ``footprints``: dicts with ``position`` (x, y[, z]) and optional
    ``character``, ``radius`` (m), ``interval`` (s) or ``label`` — or
    :class:`~scenegraph.export.usd.Marker` s; ``trajectories``: {name: (T, 2|3) pelvis path}."""
    _, Figure = _mpl()
    from matplotlib.patches import Circle
    fig = Figure(figsize=(7.0, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    colors: dict[str, tuple] = {}
    palette = [(0.80, 0.30, 0.20), (0.20, 0.45, 0.80), (0.25, 0.65, 0.30), (0.75, 0.60, 0.15)]
    pts = []
    for fp in footprints:
        d = fp if isinstance(fp, Mapping) else {"position": fp.position, "character": fp.character,
                                                "radius": fp.radius, "interval": fp.interval, "label": fp.name}
        who = str(d.get("character") or "")
        col = colors.setdefault(who, palette[len(colors) % len(palette)])
        x, y = float(d["position"][0]), float(d["position"][1])
        r = float(d.get("radius") or 0.06)
        ax.add_patch(Circle((x, y), r, facecolor=col, edgecolor="k", linewidth=0.5, alpha=0.7))
        lab = d.get("label")
        if d.get("interval") is not None:
            lab = f"{d['interval'][0]:.2f}s"
        if lab:
            ax.annotate(str(lab), (x, y), xytext=(0, 6), textcoords="offset points", fontsize=6, ha="center")
        pts += [(x - r, y - r), (x + r, y + r)]
    for n, (name, path) in enumerate((trajectories or {}).items()):
        p = np.asarray(path, dtype=float)
        col = colors.setdefault(str(name), palette[len(colors) % len(palette)])
        ax.plot(p[:, 0], p[:, 1], color=col, linewidth=1.2, label=str(name))
        pts += [tuple(x) for x in p[:, :2]]
    for who, col in colors.items():
        if who and who not in (trajectories or {}):
            ax.plot([], [], "o", color=col, label=who)
    if pts:
        P = np.array(pts)
        lo, hi = P.min(0), P.max(0)
        pad = 0.1 * max(hi - lo) + 0.1
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.3)
    if colors and any(colors):
        ax.legend(fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return _atomic_save(fig, Path(out), dpi=110)


def write_report_plots(directory, *, energy=None, torques: Mapping[str, tuple] | None = None, footprints=None,
                       trajectories: Mapping[str, np.ndarray] | None = None, prefix: str = "") -> dict[str, Path]:
    """Write the report's plots into ``directory`` (next to the run report); returns
    {plot name: path}.  ``torques`` = {character: (times, torques (T, n), names)}.
    ``prefix`` (the report file's stem, e.g. ``r`` for ``r.json``) names the files
    ``<prefix>.energy_per_cycle.png`` …, so reports of two runs in one folder keep their own plots."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    pre = f"{prefix}." if prefix else ""
    out: dict[str, Path] = {}
    if energy is not None:
        out["energy"] = plot_energy_per_cycle(energy, d / f"{pre}energy_per_cycle.png")
    for who, (t, tau, names) in (torques or {}).items():
        from scenegraph.export.usd import character_prim_name
        out[f"torques:{who}"] = plot_joint_torques(t, tau, names, d / f"{pre}torques_{character_prim_name(who)}.png",
                                                   title=f"Joint torques — {who}")
    if footprints is not None or trajectories:
        out["footprints"] = plot_footprints(footprints or [], d / f"{pre}footprints.png", trajectories=trajectories)
    return out
