"""Physical style θ (NIO paper §5): muscle preferences, passive springs, rest pose, shoes.

A style has 29·5 + 2 = 147 numbers:

* ``alpha``  per joint DOF, ≥ 0, Σ = 1: relative cost of muscle effort at that DOF;
* ``ks1``    stretching spring stiffness per joint DOF (N·m/rad), used where q > q̄;
* ``ks2``    contracting spring stiffness per joint DOF (N·m/rad), used where q < q̄;
* ``kd``     damping per joint DOF (N·m·s/rad);
* ``q_rest`` rest pose q̄ per joint DOF (rad);
* ``k_shoe`` shoe spring stiffness (N/m) and ``h_rest`` its rest length h̄ (m).

Per-DOF fields are written in files as a mapping from joint DOF name to value (readable,
order-free), and held in memory as numpy arrays in ``JOINT_DOF_NAMES`` order.

A learned style may also carry ``example``: the poses of the motion it was learned from (X_T),
indexed by the gait phase of each leg, from which a synthesis can take its initial motion as
the paper does (§7; ``gait.initial_motion(example=…)``).  It is not part of θ.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from scenarios.yamlio import dump_yaml_atomic, load_model

from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT

__all__ = ["Style", "ExamplePoses", "default_style", "load_style", "save_style", "PER_DOF_FIELDS",
           "THETA_LAYOUT", "N_THETA_FULL"]

PER_DOF_FIELDS = ("alpha", "ks1", "ks2", "kd", "q_rest")
N_THETA_FULL = len(PER_DOF_FIELDS) * N_JOINT + 2  # 147: the length of Style.vector()
# θ = Style.vector() by name: each field's slice (k_shoe, h_rest: one number each); "springs"
# is ks1, ks2, kd together and "kernel" everything after α (the residual kernel's θ, N_THETA).
THETA_LAYOUT: dict[str, slice] = {
    **{f: slice(i * N_JOINT, (i + 1) * N_JOINT) for i, f in enumerate(PER_DOF_FIELDS)},
    "k_shoe": slice(N_THETA_FULL - 2, N_THETA_FULL - 1), "h_rest": slice(N_THETA_FULL - 1, N_THETA_FULL),
    "springs": slice(N_JOINT, 4 * N_JOINT), "kernel": slice(N_JOINT, N_THETA_FULL),
}
ALPHA_SUM_TOL = 1e-3  # hand-written files round; files written by save_style sum to 1 within 1e-7


class Provenance(BaseModel):
    """Where a learned style came from."""

    model_config = ConfigDict(extra="allow")
    clip: str | None = None
    frames: str | None = None
    body: str | None = None
    versions: dict[str, str] = Field(default_factory=dict)
    g_final: float | None = None


def _check_dof_names(v: dict) -> None:
    """A per-DOF mapping must name every joint DOF once and nothing else."""
    unknown = sorted(set(v) - set(JOINT_DOF_NAMES))
    if unknown:
        raise ValueError(f"unknown joint DOF {unknown[0]!r}")
    missing = [d for d in JOINT_DOF_NAMES if d not in v]
    if missing:
        raise ValueError(f"missing {len(missing)} joint DOF(s), e.g. {missing[0]!r}")


class ExamplePoses(BaseModel):
    """Poses of a style's example motion by leg phase.  Sample i has the phase codes
    ``phase_l[i]``, ``phase_r[i]`` (stance [0, 1), swing [1, 2): ``gait.phase_code``) and the
    joint angles ``joints[dof][i]`` (rad)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    phase_l: list[float] = Field(min_length=2, max_length=10000)
    phase_r: list[float] = Field(min_length=2, max_length=10000)
    joints: dict[str, list[float]]

    @field_validator("phase_l", "phase_r")
    @classmethod
    def _codes(cls, v):
        if not all(np.isfinite(x) and 0.0 <= x <= 2.0 for x in v):
            raise ValueError("phase codes must lie in [0, 2]")
        return v

    @field_validator("joints")
    @classmethod
    def _dofs(cls, v):
        _check_dof_names(v)
        if not all(np.all(np.isfinite(x)) for x in v.values()):
            raise ValueError("joint angles must be finite")
        return v

    @model_validator(mode="after")
    def _same_length(self):
        n = {len(self.phase_l), len(self.phase_r), *(len(x) for x in self.joints.values())}
        if len(n) != 1:
            raise ValueError("phase_l, phase_r and every joint list must have the same length")
        return self

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(codes (T, 2) [left, right], joint angles (T, N_JOINT) in JOINT_DOF_NAMES order)."""
        return (np.column_stack([self.phase_l, self.phase_r]),
                np.column_stack([self.joints[d] for d in JOINT_DOF_NAMES]))

    @classmethod
    def from_arrays(cls, codes: np.ndarray, joints: np.ndarray) -> "ExamplePoses":
        return cls(phase_l=[round(float(x), 4) for x in codes[:, 0]], phase_r=[round(float(x), 4) for x in codes[:, 1]],
                   joints={d: [round(float(x), 5) for x in joints[:, j]] for j, d in enumerate(JOINT_DOF_NAMES)})


class Style(BaseModel):
    """The 147 style parameters θ; see the module docstring for units."""

    model_config = ConfigDict(extra="forbid", arbitrary_types_allowed=True, frozen=True)

    name: str = "default"
    alpha: Any
    ks1: Any
    ks2: Any
    kd: Any
    q_rest: Any
    k_shoe: float = Field(ge=0.0, le=1e7)
    h_rest: float = Field(ge=0.0, le=0.1)
    provenance: Provenance | None = None
    example: ExamplePoses | None = None

    @field_validator(*PER_DOF_FIELDS, mode="before")
    @classmethod
    def _per_dof(cls, v, info):
        name = info.field_name
        if isinstance(v, dict):
            _check_dof_names(v)
            v = [v[d] for d in JOINT_DOF_NAMES]
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"expected {N_JOINT} numbers or a mapping joint DOF -> number") from None
        if arr.shape != (N_JOINT,):
            raise ValueError(f"expected {N_JOINT} values (one per joint DOF), got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("values must be finite")
        if name in ("alpha", "ks1", "ks2", "kd") and np.any(arr < 0):
            j = int(np.argmin(arr))
            raise ValueError(f"must be >= 0, but {JOINT_DOF_NAMES[j]} is {arr[j]}")
        if name == "q_rest" and np.any(np.abs(arr) > np.pi):
            raise ValueError("rest angles must lie in [-pi, pi] rad")
        if name == "alpha" and abs(float(np.sum(arr)) - 1.0) > ALPHA_SUM_TOL:
            raise ValueError(f"must sum to 1 (sums to {float(np.sum(arr)):.6g})")
        arr.setflags(write=False)
        return arr

    def vector(self) -> np.ndarray:
        """θ as one flat array (147,) in the order alpha, ks1, ks2, kd, q_rest, k_shoe, h_rest."""
        return np.concatenate([getattr(self, f) for f in PER_DOF_FIELDS] + [[self.k_shoe, self.h_rest]])

    @classmethod
    def from_vector(cls, theta: np.ndarray, name: str = "learned", provenance: Provenance | None = None) -> "Style":
        t = np.asarray(theta, dtype=float)
        parts = {f: t[THETA_LAYOUT[f]] for f in PER_DOF_FIELDS}
        return cls(name=name, **parts, k_shoe=float(t[-2]), h_rest=float(t[-1]), provenance=provenance)

    def with_(self, **changes) -> "Style":
        data = {f: getattr(self, f) for f in type(self).model_fields}
        data.update(changes)
        return Style(**data)

    def to_data(self) -> dict:
        out: dict[str, Any] = {"name": self.name}
        for f in PER_DOF_FIELDS:
            out[f] = {d: round(float(x), 8) for d, x in zip(JOINT_DOF_NAMES, getattr(self, f))}
        out["k_shoe"] = float(self.k_shoe)
        out["h_rest"] = float(self.h_rest)
        if self.provenance is not None:
            out["provenance"] = self.provenance.model_dump(exclude_none=True)
        if self.example is not None:
            out["example"] = self.example.model_dump()
        return out


def _joint_group(name: str) -> str:
    return name.rsplit("_", 1)[0] if name.endswith(("_l", "_r")) else name


# Stiffness scale (N·m/rad) per joint group for a 73 kg adult: larger joints, stiffer tissue.
_DEFAULT_KS = {
    "waist": 60.0, "chest": 60.0, "neck": 10.0, "shoulder": 8.0, "elbow": 3.0, "wrist": 1.0,
    "hip": 40.0, "knee": 25.0, "ankle": 30.0, "toe": 5.0,
}


def default_style(mass: float = 73.0) -> Style:
    """A neutral style: uniform α, moderate springs about a relaxed standing pose, soft shoes."""
    ks = np.array([_DEFAULT_KS[_joint_group(d).split("_")[0]] for d in JOINT_DOF_NAMES]) * mass / 73.0
    return Style(
        name="default",
        alpha=np.full(N_JOINT, 1.0 / N_JOINT),
        ks1=ks, ks2=ks, kd=0.05 * ks,
        q_rest=np.zeros(N_JOINT),
        k_shoe=2.0e4 * mass / 73.0, h_rest=0.005,
    )


def load_style(path: str | os.PathLike) -> Style:
    """Load and validate a style YAML file; errors name the file, line and field."""
    return load_model(Style, path)


def save_style(style: Style, path: str | os.PathLike, header: str = "") -> None:
    """Write a style atomically as YAML."""
    dump_yaml_atomic(style.to_data(), path, header)
