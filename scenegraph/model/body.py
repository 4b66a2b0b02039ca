"""The character: 18 ellipsoid bodies, 35 DOFs, handles and joint limits.

Frames and conventions
----------------------
World: right-handed, Z up, ground z = 0, SI units.  At q = 0 the character stands upright
at the origin facing +X with its left side toward +Y, arms hanging down; every joint frame
is then parallel to the world frame, so offsets and ellipsoid axes are given in world axes.

Generalized coordinates (``q``, 35 numbers)
  * 0–2   root translation of the pelvis frame origin (m, world X, Y, Z);
  * 3–5   root orientation as intrinsic Z-Y-X Euler angles (yaw, pitch, roll; rad).
          Gimbal lock sits at pitch = ±90°, i.e. lying down, outside what we synthesise.
  * 6–34  29 joint DOFs (rad).  Every joint DOF is one rotation about a fixed axis of its
          frame, so a ball joint is a chain of three single-axis rotations (an Euler chain)
          and a saddle a chain of two.  The chain orders put the rotation whose range stays
          well inside ±90° in the middle (hips/waist: flex, abduct, twist; shoulders: flex,
          twist (±75°), abduct) so gimbal lock stays outside the range of motion.

Joint DOFs (29): waist ball 3, chest hinge 1, neck hinge 1, shoulders ball 3+3,
elbows hinge 1+1, wrists hinge 1+1, hips ball 3+3, knees hinge 1+1, ankles saddle 2+2,
toes hinge 1+1.  18 articulated bodies need 17 joints; with three ball pairs (+10) and
saddle ankles (+2) that is exactly 29, so neck and wrists are hinges (the issue's list of
joint types adds up to 30 on its own; see README).

Anthropometry: segment lengths as fractions of stature (Winter 2009), segment masses as
fractions of total mass (de Leva 1996, with the foot split 80/20 into foot and toes).
Ellipsoid semi-axes: half the segment length along the segment; the cross-section from
the segment's mass at a density of 1000 kg/m³.  Inertia is that of a uniform ellipsoid.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import dataclass, field, replace

import numpy as np

from scenarios.errors import InputError

__all__ = [
    "Dof", "Body", "Handle", "Character", "PRESETS", "make_character", "N_DOF", "N_ROOT", "N_JOINT",
    "DOF_NAMES", "JOINT_DOF_NAMES",
]

N_ROOT = 6
N_JOINT = 29
N_DOF = N_ROOT + N_JOINT
DENSITY = 1000.0  # kg/m^3
G = 9.81  # m/s^2


@dataclass(frozen=True)
class Dof:
    """One generalized coordinate: a translation or rotation along/about ``axis``.

    ``axis`` is a unit vector in the frame of the DOF's parent; ``offset`` (m) is the
    position of this DOF's frame origin in its parent frame (zero inside a joint chain).
    ``body`` names the body carried by this frame if the frame ends a joint, else None.
    """

    name: str
    kind: str  # "prismatic" | "revolute"
    axis: tuple[float, float, float]
    parent: int  # index of parent DOF frame, -1 = world
    offset: tuple[float, float, float]
    lower: float
    upper: float
    body: str | None = None


@dataclass(frozen=True)
class Body:
    """A rigid ellipsoid.  ``center`` (m) and ``semi_axes`` (m) in the body's frame."""

    name: str
    frame: int  # index of the DOF frame that carries the body
    parent: str | None
    mass: float  # kg
    center: tuple[float, float, float]
    semi_axes: tuple[float, float, float]
    # kg·m², body axes: what carried loads add to the uniform ellipsoid of ``mass`` (set by
    # Character.with_extra_mass; not in the repr, so unloaded models keep their fingerprints)
    inertia_extra: tuple | None = field(default=None, repr=False)

    @property
    def inertia(self) -> np.ndarray:
        """3×3 inertia about the centre of mass, body axes (kg·m²): a uniform ellipsoid of
        ``mass`` plus ``inertia_extra`` (the carried loads' share, see with_extra_mass)."""
        I = ellipsoid_inertia(self.mass, self.semi_axes)
        return I if self.inertia_extra is None else I + np.asarray(self.inertia_extra, float)


@dataclass(frozen=True)
class Handle:
    """A named point fixed on a body, in that body's frame (m)."""

    name: str
    body: str
    point: tuple[float, float, float]


CARRIED_DENSITY = 300.0  # kg/m^3: the drawn size of a carried load (a packed suitcase)
CARRIED_SHAPE = (1.33, 0.4, 1.0)  # a suitcase's proportions: long along x (forward), thin sideways


def carried_half_extents(mass: float) -> np.ndarray:
    """Half extents (m, body axes) of the box a carried load of ``mass`` kg is (drawn and in
    the dynamics: :meth:`Character.with_extra_mass`)."""
    shape = np.array(CARRIED_SHAPE)
    return 0.5 * shape * (max(mass, 1e-6) / CARRIED_DENSITY / shape.prod()) ** (1.0 / 3.0)


def ellipsoid_inertia(mass: float, semi_axes) -> np.ndarray:
    """3×3 inertia (kg·m²) of a uniform solid ellipsoid about its centre, its own axes."""
    a, b, c = (float(x) for x in semi_axes)
    return mass / 5.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def box_inertia(mass: float, half_extents) -> np.ndarray:
    """3×3 inertia (kg·m²) of a uniform box about its centre, its own axes."""
    a, b, c = (float(x) for x in half_extents)
    return mass / 3.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def _parallel_axis(mass: float, d) -> np.ndarray:
    """What a mass at offset ``d`` (m) from a centre adds to the inertia about it (kg·m²)."""
    d = np.asarray(d, float)
    return mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


@dataclass(frozen=True)
class Character:
    """An articulated character: DOF frames, bodies, handles.  Immutable."""

    preset: str
    height: float
    mass: float
    dofs: tuple[Dof, ...]
    bodies: tuple[Body, ...]
    handles: tuple[Handle, ...]
    joint_parent: tuple[tuple[str, str | None], ...] = field(default=())
    # Point masses added with with_extra_mass (handle, kg), in order: the stage draws them as
    # carried objects and the bodies as they were before (not part of the fingerprint).
    loads: tuple[tuple[str, float], ...] = field(default=())

    @property
    def dof_names(self) -> list[str]:
        return [d.name for d in self.dofs]

    def body(self, name: str) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise InputError(f"unknown body {name!r} (known: {', '.join(b.name for b in self.bodies)})")

    def handle(self, name: str) -> Handle:
        for h in self.handles:
            if h.name == name:
                return h
        raise InputError(f"unknown handle {name!r} (known: {', '.join(h.name for h in self.handles)})")

    def dof_index(self, name: str) -> int:
        for i, d in enumerate(self.dofs):
            if d.name == name:
                return i
        raise InputError(f"unknown DOF {name!r}")

    @property
    def lower(self) -> np.ndarray:
        return np.array([d.lower for d in self.dofs])

    @property
    def upper(self) -> np.ndarray:
        return np.array([d.upper for d in self.dofs])

    @property
    def total_mass(self) -> float:
        return float(sum(b.mass for b in self.bodies))

    def fingerprint(self) -> str:
        """A stable hash of everything that defines the model (for compiled-code caches)."""
        parts = [self.dofs, self.bodies, self.handles]
        if self.loads:  # a load changes the inertias (Body.inertia_extra), which the repr leaves out
            parts.append(["loads-with-inertia", self.loads])
        blob = json.dumps(parts, default=str, sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def with_extra_mass(self, handle: str, mass: float) -> "Character":
        """Add a mass (kg) rigidly at a handle (e.g. a carried suitcase): the solid box the
        stage draws for it (:func:`carried_half_extents`, centred on the handle, body axes,
        uniform).  The body's mass, centre and inertia become those of the body and the box
        together (parallel-axis terms included: the box's centre is 8.5 cm from the hand's
        joint for the suitcase, and its own inertia is several times the hand's)."""
        h = self.handle(handle)
        bodies = []
        for b in self.bodies:
            if b.name == h.body:
                m = b.mass + mass
                c_old, p = np.array(b.center, float), np.array(h.point, float)
                c_new = (c_old * b.mass + p * mass) / m
                I = (b.inertia + _parallel_axis(b.mass, c_old - c_new)
                     + box_inertia(mass, carried_half_extents(mass)) + _parallel_axis(mass, p - c_new))
                extra = I - ellipsoid_inertia(m, b.semi_axes)
                b = replace(b, mass=m, center=tuple(c_new), inertia_extra=tuple(map(tuple, extra)))
            bodies.append(b)
        return replace(self, bodies=tuple(bodies), loads=self.loads + ((handle, float(mass)),))

    def with_limits(self, name: str, lower: float, upper: float) -> "Character":
        i = self.dof_index(name)
        if lower > upper:
            raise InputError(f"joint limit for {name!r}: lower {lower} > upper {upper}")
        dofs = list(self.dofs)
        dofs[i] = replace(dofs[i], lower=lower, upper=upper)
        return replace(self, dofs=tuple(dofs))


# --- presets -----------------------------------------------------------------------------

@dataclass(frozen=True)
class Preset:
    height: float  # m
    mass: float  # kg
    female: bool
    head_scale: float = 1.0  # children have relatively larger heads


PRESETS: dict[str, Preset] = {
    "adult_male": Preset(1.75, 73.0, False),
    "adult_female": Preset(1.65, 61.0, True),
    "child": Preset(1.20, 23.0, False, head_scale=1.35),
}

# de Leva (1996) mass fractions (% of body mass): male, female.
_MASS = {
    "head": (6.94, 6.68), "thorax": (15.96, 15.45), "abdomen": (16.33, 14.65), "pelvis": (11.17, 12.47),
    "upper_arm": (2.71, 2.55), "forearm": (1.62, 1.38), "hand": (0.61, 0.56),
    "thigh": (14.16, 14.78), "shank": (4.33, 4.81), "foot": (1.37 * 0.8, 1.29 * 0.8),
    "toes": (1.37 * 0.2, 1.29 * 0.2),
}

D = math.radians


def _limits() -> dict[str, tuple[float, float]]:
    return {
        "waist_flex": (D(-30), D(60)), "waist_lat": (D(-30), D(30)), "waist_twist": (D(-40), D(40)),
        "chest_flex": (D(-20), D(30)), "neck_flex": (D(-50), D(60)),
        "hip_flex": (D(-30), D(120)), "hip_abd": (D(-30), D(45)), "hip_rot": (D(-40), D(45)),
        "knee_flex": (D(0), D(150)), "ankle_flex": (D(-50), D(30)), "ankle_inv": (D(-25), D(35)),
        "toe_flex": (D(-40), D(70)),
        "shoulder_flex": (D(-60), D(170)), "shoulder_twist": (D(-75), D(75)), "shoulder_abd": (D(-30), D(170)),
        "elbow_flex": (D(0), D(150)), "wrist_flex": (D(-70), D(80)),
    }


def make_character(preset: str = "adult_male", height: float | None = None, mass: float | None = None) -> Character:
    """Build the 35-DOF character of a preset, scaled to ``height`` (m) and ``mass`` (kg)."""
    if preset not in PRESETS:
        raise InputError(f"unknown body preset {preset!r} (known: {', '.join(PRESETS)})")
    p = PRESETS[preset]
    H = p.height if height is None else float(height)
    M = p.mass if mass is None else float(mass)
    if not (0.5 <= H <= 2.5):
        raise InputError(f"height {H} m is outside 0.5–2.5 m")
    if not (5.0 <= M <= 300.0):
        raise InputError(f"mass {M} kg is outside 5–300 kg")
    sex = 1 if p.female else 0
    raw = {k: v[sex] for k, v in _MASS.items()}
    raw["head"] *= p.head_scale
    total = sum(raw[k] * (2 if k in ("upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toes") else 1)
                for k in raw)
    mfrac = {k: v / total for k, v in raw.items()}

    # Segment geometry as fractions of stature (Winter).
    L = dict(
        hip_z=0.530 * H, hip_half=0.095 * H / 2 * 1.0 + 0.0,
        pelvis=0.060 * H, abdomen=0.100 * H, thorax=0.128 * H, head=0.182 * H * (1 + (p.head_scale - 1) * 0.5),
        shoulder_half=0.129 * H, shoulder_drop=0.030 * H,
        upper_arm=0.186 * H, forearm=0.146 * H, hand=0.108 * H,
        thigh=0.245 * H, shank=0.246 * H, ankle_z=0.039 * H,
        heel_back=0.040 * H, ball_fwd=0.085 * H, toe_len=0.030 * H,
    )
    lim = _limits()
    dofs: list[Dof] = []

    def add(name, kind, axis, parent, offset=(0.0, 0.0, 0.0), body=None, limits=None):
        lo, hi = limits if limits is not None else (-math.inf, math.inf)
        dofs.append(Dof(name, kind, tuple(float(a) for a in axis), parent, tuple(float(o) for o in offset),
                        float(lo), float(hi), body))
        return len(dofs) - 1

    X, Y, Z = (1, 0, 0), (0, 1, 0), (0, 0, 1)
    nY, nX, nZ = (0, -1, 0), (-1, 0, 0), (0, 0, -1)
    add("root_tx", "prismatic", X, -1, limits=(-1e3, 1e3))
    add("root_ty", "prismatic", Y, 0, limits=(-1e3, 1e3))
    add("root_tz", "prismatic", Z, 1, limits=(0.0, 3.0))
    add("root_yaw", "revolute", Z, 2, limits=(-4 * math.pi, 4 * math.pi))
    add("root_pitch", "revolute", Y, 3, limits=(D(-80), D(80)))
    pelvis = add("root_roll", "revolute", X, 4, body="pelvis", limits=(D(-80), D(80)))

    def joint(prefix, parent, offset, axes, body, side=""):
        """A chain of single-axis rotations; only the first carries the offset."""
        idx = parent
        for k, (dname, axis) in enumerate(axes):
            lname = f"{dname}_{side}" if side else dname
            idx = add(lname, "revolute", axis, idx, offset if k == 0 else (0, 0, 0),
                      body=body if k == len(axes) - 1 else None, limits=lim[dname])
        return idx

    abdomen = joint("waist", pelvis, (0, 0, L["pelvis"]),
                    [("waist_flex", Y), ("waist_lat", X), ("waist_twist", Z)], "abdomen")
    thorax = joint("chest", abdomen, (0, 0, L["abdomen"]), [("chest_flex", Y)], "thorax")
    joint("neck", thorax, (0, 0, L["thorax"]), [("neck_flex", Y)], "head")

    for side, s in (("l", 1.0), ("r", -1.0)):
        sX = X if s > 0 else nX
        sZ = Z if s > 0 else nZ
        sh = joint("shoulder", thorax, (0, s * L["shoulder_half"], L["thorax"] - L["shoulder_drop"]),
                   [("shoulder_flex", nY), ("shoulder_twist", sZ), ("shoulder_abd", sX)], f"upper_arm_{side}", side)
        el = joint("elbow", sh, (0, 0, -L["upper_arm"]), [("elbow_flex", nY)], f"forearm_{side}", side)
        joint("wrist", el, (0, 0, -L["forearm"]), [("wrist_flex", nY)], f"hand_{side}", side)
        hip = joint("hip", pelvis, (0, s * L["hip_half"], 0.0),
                    [("hip_flex", nY), ("hip_abd", sX), ("hip_rot", sZ)], f"thigh_{side}", side)
        kn = joint("knee", hip, (0, 0, -L["thigh"]), [("knee_flex", Y)], f"shank_{side}", side)
        an = joint("ankle", kn, (0, 0, -L["shank"]), [("ankle_flex", nY), ("ankle_inv", sX)], f"foot_{side}", side)
        joint("toe", an, (L["ball_fwd"], 0, -L["ankle_z"] * 0.6), [("toe_flex", nY)], f"toes_{side}", side)

    frame_of = {d.body: i for i, d in enumerate(dofs) if d.body}

    def ell(name, parent, mass_key, center, axis_len, along, ratio=(1.0, 1.0)):
        """Ellipsoid with semi-axis axis_len/2 along world axis ``along`` (0,1,2)."""
        m = M * mfrac[mass_key]
        a = axis_len / 2.0
        # cross-section semi-axes from mass at DENSITY: m = rho * 4/3 pi a b c, b = r1 k, c = r2 k
        k = math.sqrt(m / (DENSITY * 4.0 / 3.0 * math.pi * a * ratio[0] * ratio[1]))
        others = [k * ratio[0], k * ratio[1]]
        semi = [0.0, 0.0, 0.0]
        semi[along] = a
        j = 0
        for ax in range(3):
            if ax != along:
                semi[ax] = others[j]
                j += 1
        return Body(name, frame_of[name], parent, m, tuple(float(c) for c in center), tuple(semi))

    bodies = [
        ell("pelvis", None, "pelvis", (0, 0, L["pelvis"] / 2), L["pelvis"], 2, (0.7, 1.4)),
        ell("abdomen", "pelvis", "abdomen", (0, 0, L["abdomen"] / 2), L["abdomen"], 2, (0.75, 1.3)),
        ell("thorax", "abdomen", "thorax", (0, 0, L["thorax"] / 2), L["thorax"], 2, (0.75, 1.4)),
        ell("head", "thorax", "head", (0, 0, L["head"] / 2), L["head"], 2),
    ]
    for side in ("l", "r"):
        bodies += [
            ell(f"upper_arm_{side}", "thorax", "upper_arm", (0, 0, -L["upper_arm"] / 2), L["upper_arm"], 2),
            ell(f"forearm_{side}", f"upper_arm_{side}", "forearm", (0, 0, -L["forearm"] / 2), L["forearm"], 2),
            ell(f"hand_{side}", f"forearm_{side}", "hand", (0, 0, -L["hand"] / 2), L["hand"], 2, (0.5, 1.0)),
            ell(f"thigh_{side}", "pelvis", "thigh", (0, 0, -L["thigh"] / 2), L["thigh"], 2),
            ell(f"shank_{side}", f"thigh_{side}", "shank", (0, 0, -L["shank"] / 2), L["shank"], 2),
            ell(f"foot_{side}", f"shank_{side}", "foot",
                ((L["ball_fwd"] - L["heel_back"]) / 2, 0, -L["ankle_z"] * 0.5), L["ball_fwd"] + L["heel_back"], 0,
                (0.8, 0.6)),
            ell(f"toes_{side}", f"foot_{side}", "toes", (L["toe_len"] / 2, 0, -L["ankle_z"] * 0.15), L["toe_len"], 0,
                (1.6, 0.6)),
        ]
    sole = -L["ankle_z"]
    handles = [
        Handle("pelvis", "pelvis", (0.0, 0.0, 0.0)),
        Handle("chest", "thorax", (0.0, 0.0, L["thorax"] * 0.5)),
        Handle("head", "head", (0.0, 0.0, L["head"] * 0.5)),
        Handle("head_top", "head", (0.0, 0.0, L["head"])),
    ]
    for side in ("l", "r"):
        toe_joint_z = -L["ankle_z"] * 0.6
        handles += [
            Handle(f"heel_{side}", f"foot_{side}", (-L["heel_back"], 0.0, sole)),
            Handle(f"ball_{side}", f"foot_{side}", (L["ball_fwd"], 0.0, sole)),
            Handle(f"toe_{side}", f"toes_{side}", (L["toe_len"], 0.0, sole - toe_joint_z)),
            Handle(f"palm_{side}", f"hand_{side}", (0.0, 0.0, -L["hand"] * 0.45)),
            Handle(f"shoulder_{side}", f"upper_arm_{side}", (0.0, 0.0, 0.0)),
            Handle(f"knee_{side}", f"shank_{side}", (0.0, 0.0, 0.0)),
            Handle(f"ankle_{side}", f"foot_{side}", (0.0, 0.0, 0.0)),
            Handle(f"wrist_{side}", f"hand_{side}", (0.0, 0.0, 0.0)),
            Handle(f"elbow_{side}", f"forearm_{side}", (0.0, 0.0, 0.0)),
            Handle(f"hip_{side}", f"thigh_{side}", (0.0, 0.0, 0.0)),
        ]
    return Character(preset, H, M, tuple(dofs), tuple(bodies), tuple(handles))


# --- what is drawn ------------------------------------------------------------------------

@dataclass(frozen=True)
class DrawnShape:
    """The visible solid of one body, in the body's frame (m).

    ``kind`` "ellipsoid": centre ``center``, semi-axes ``semi_axes``.

    ``kind`` "keel" (feet and toes): a spindle lying on a straight keel.  ``center`` is the
    keel's midpoint, the keel runs along x from −a to +a at that height, and the cross-
    section at x = a·u is an ellipse with semi-axes (b·s, c·s), s = sqrt(1 − u²), whose
    lowest point is on the keel (``semi_axes`` = (a, b, c)).  Its ends (the keel's ends) are
    the contact handles; rolled by ψ about the keel it dips at most b² ψ² / (2c) below it.
    Volume 4/3 π a b c; centre of mass 9π/32 · c above the keel.

    ``mass`` (kg) is the body's own (loads removed) and ``com`` its centre of mass."""

    body: str
    kind: str
    center: tuple[float, float, float]
    semi_axes: tuple[float, float, float]
    mass: float
    com: tuple[float, float, float]
    pitch: float = 0.0  # rad: a keel's local frame is the body's turned by this about y (rear end up)

    @property
    def rotation(self) -> np.ndarray:
        """3×3: the keel's local axes (x along the keel, rear to front; z up from it) in the body frame."""
        ca, sa = math.cos(self.pitch), math.sin(self.pitch)
        return np.array([[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]])

    def bounds(self, segments: tuple[int, int] = (16, 10)) -> tuple[np.ndarray, np.ndarray]:
        """(centre, half extents) of the axis-aligned box of the drawn mesh's vertices in the
        body frame (m), for the mesh the stage writes with ``segments``."""
        c, s = np.array(self.center, float), np.array(self.semi_axes, float)
        if self.kind == "keel":
            P = keel_points(self.center, self.semi_axes, self.pitch, *segments)
            lo, hi = P.min(0), P.max(0)
            return (lo + hi) / 2, (hi - lo) / 2
        return c, s

    @property
    def volume(self) -> float:
        a, b, c = self.semi_axes
        return 4.0 / 3.0 * math.pi * a * b * c

    @property
    def inertia(self) -> np.ndarray:
        """3×3 inertia (kg·m²) of the drawn solid at uniform density about its centre of mass."""
        a, b, c = self.semi_axes
        m = self.mass
        if self.kind == "ellipsoid":
            return ellipsoid_inertia(m, self.semi_axes)
        u, w = np.polynomial.legendre.leggauss(64)  # slices along the keel
        s = np.sqrt(1.0 - u * u)
        dm = w * s * s / np.sum(w * s * s) * m  # slice mass ∝ its area π b c s²
        zc = c * s - 9.0 * math.pi / 32.0 * c  # slice centre above the solid's centre of mass
        x = a * u
        yy, zz = dm * (b * s) ** 2 / 4.0, dm * (c * s) ** 2 / 4.0 + dm * zc * zc
        xx = dm * x * x
        I = np.diag([np.sum(yy + zz), np.sum(xx + zz), np.sum(xx + yy)])
        R = self.rotation
        return R @ I @ R.T


def keel_points(center, semi_axes, pitch: float = 0.0, n_around: int = 16, n_rings: int = 10) -> np.ndarray:
    """Vertices (N, 3) of a keel solid's mesh in the body frame: the rear end, ``n_rings − 1``
    rings of ``n_around`` points (the first of each on the keel), the front end.  The keel's
    local frame is turned by ``pitch`` about y (see :class:`DrawnShape`)."""
    a, b, c = (float(x) for x in semi_axes)
    n_len = max(2, int(n_rings))
    pts = [(-a, 0.0, 0.0)]
    for i in range(1, n_len):
        u = -math.cos(math.pi * i / n_len)
        s = math.sqrt(max(0.0, 1.0 - u * u))
        for k in range(n_around):
            ph = 2 * math.pi * k / n_around - math.pi / 2  # k = 0: the lowest point, on the keel
            pts.append((a * u, b * s * math.cos(ph), c * s * (1.0 + math.sin(ph))))
    pts.append((a, 0.0, 0.0))
    ca, sa = math.cos(pitch), math.sin(pitch)
    R = np.array([[ca, 0.0, sa], [0.0, 1.0, 0.0], [-sa, 0.0, ca]])
    return np.asarray(center, float) + np.array(pts) @ R.T


TOES_KEEL_PITCH = math.radians(15.0)  # the toes' keel rises 15° from the tip toward the toe joint


def _own_mass_and_center(ch: Character, b: Body) -> tuple[float, np.ndarray]:
    """A body's mass and centre before with_extra_mass added its loads."""
    m, mc = b.mass, np.array(b.center, float) * b.mass
    for handle, extra in ch.loads:
        h = ch.handle(handle)
        if h.body == b.name:
            m -= extra
            mc -= np.array(h.point, float) * extra
    return m, mc / m


KEEL_COM = 9.0 * math.pi / 32.0  # a keel solid's centre of mass above its keel, per unit c


def drawn_shapes(ch: Character) -> tuple[DrawnShape, ...]:
    """The solid drawn for each body (in ``ch.bodies`` order): the dynamics' ellipsoid, except
    each foot and each toes segment, drawn as a keel solid (see :class:`DrawnShape`) whose
    keel joins its contact handles — heel to ball on the foot — or ends at one — the toes'
    keel ends at the toe tip and rises 15° toward the toe joint — so the visible feet rest on
    the floor exactly when the handles do.  Each keel keeps the body's centre of mass.  The
    foot keeps its volume at the model's density (1000 kg/m³); the toes are drawn as wide as
    the foot, so their smaller volume holds their mass at a higher density (the stage states
    every mass with UsdPhysics).  Inertias: the drawn
    solids' differ from the ellipsoids' the dynamics use (docs/usd-output.md)."""
    out = []
    foot_half_width: dict[str, float] = {}
    for b in ch.bodies:
        m, c = _own_mass_and_center(ch, b)
        kind, center, semi = "ellipsoid", tuple(float(x) for x in c), b.semi_axes
        side = b.name.rsplit("_", 1)[-1]
        ends = None
        if b.name.startswith("foot_"):
            ends = (ch.handle(f"heel_{side}").point, ch.handle(f"ball_{side}").point)
        elif b.name.startswith("toes_"):
            tip = ch.handle(f"toe_{side}").point
            ends = ((0.0, 0.0, tip[2]), tip)
        pitch = 0.0
        if ends is not None and b.name.startswith("foot_"):
            (x0, _, z0), (x1, _, z1) = ends
            a = (x1 - x0) / 2.0
            hc = (c[2] - z0) / KEEL_COM
            if not (a > 0 and hc > 0 and abs(z1 - z0) < 1e-12 and abs(c[0] - (x0 + x1) / 2.0) < 1e-9
                    and abs(c[1]) < 1e-9):
                raise InputError(f"body {b.name!r}: its centre of mass is not above the middle of its contact handles")
            w = m / (DENSITY * 4.0 / 3.0 * math.pi * a * hc)
            foot_half_width[side] = w
            kind, center, semi = "keel", ((x0 + x1) / 2.0, 0.0, float(z0)), (float(a), float(w), float(hc))
        elif ends is not None:
            # The toes' keel ends at the toe tip and rises 15° toward the joint, so its rear end
            # stays near the joint axis: a keel flat along the sole would start 0.4 ankle
            # heights below the joint and, the foot pitched heel-up with the toes flat, swing
            # below the ball handle (3 mm measured in the walk).  Tip E, angle α, centre of
            # mass C: C − E = −a d + k n with d = (cos α, 0, −sin α), n = (sin α, 0, cos α).
            tip = np.array(ends[1], float)
            al = TOES_KEEL_PITCH
            dx, dz = c[0] - tip[0], c[2] - tip[2]
            a = -dx * math.cos(al) + dz * math.sin(al)
            k = dx * math.sin(al) + dz * math.cos(al)
            if not (a > 0 and k > 0 and abs(c[1]) < 1e-9):
                raise InputError(f"body {b.name!r}: cannot draw a keel from its toe handle through its centre of mass")
            d = np.array([math.cos(al), 0.0, -math.sin(al)])
            mid = tip - a * d
            w = foot_half_width.get(side, b.semi_axes[1])
            kind, center, semi, pitch = "keel", tuple(float(x) for x in mid), (float(a), float(w), float(k / KEEL_COM)), al
        out.append(DrawnShape(b.name, kind, center, tuple(float(x) for x in semi), float(m),
                              tuple(float(x) for x in c), float(pitch)))
    return tuple(out)


def standing_pose(ch: Character) -> np.ndarray:
    """q of the character standing at the origin with soles on the ground (m, rad)."""
    q = np.zeros(N_DOF)
    hip_z = -ch.dofs[ch.dof_index("hip_flex_l")].offset[2]
    leg = sum(-ch.dofs[ch.dof_index(n)].offset[2] for n in ("knee_flex_l", "ankle_flex_l"))
    q[2] = leg + hip_z + (-ch.handle("heel_l").point[2])
    return q


@functools.lru_cache(maxsize=None)
def default_character() -> Character:
    """The ``adult_male`` preset at its own height and mass, built once on first use.

    It knows every DOF, body and handle name (validators check names against it); importing
    this module builds nothing.
    """
    return make_character()


# The DOF order make_character builds (root, trunk, left arm, left leg, right arm, right leg);
# tests/model/test_body.py checks it against default_character().
_SIDE_DOFS = ("shoulder_flex", "shoulder_twist", "shoulder_abd", "elbow_flex", "wrist_flex",
              "hip_flex", "hip_abd", "hip_rot", "knee_flex", "ankle_flex", "ankle_inv", "toe_flex")
DOF_NAMES: tuple[str, ...] = (("root_tx", "root_ty", "root_tz", "root_yaw", "root_pitch", "root_roll",
                               "waist_flex", "waist_lat", "waist_twist", "chest_flex", "neck_flex")
                              + tuple(f"{d}_{side}" for side in ("l", "r") for d in _SIDE_DOFS))
JOINT_DOF_NAMES: tuple[str, ...] = DOF_NAMES[N_ROOT:]
assert len(DOF_NAMES) == N_DOF, len(DOF_NAMES)
__all__ += ["standing_pose", "default_character", "DrawnShape", "drawn_shapes", "keel_points"]
