"""The equations of motion of a solved motion checked densely: at every frame of a uniform grid
(120 Hz by default), between the solver's collocation points and through every flight.

The solver reports each handle's external force at its own times (``contact_forces``: handle
→ (world times s, forces N (n, 3), world frame)).  What the force is *between* those times is
part of the representation the solver optimised, so it is read the same way here:

* a contact handle (``CONTACT_HANDLES``) pushes only inside the planted intervals its footsteps
  give it (``footsteps.contact_points``); inside one interval its force is the piecewise-linear
  interpolant **in canonical time s** of the samples that lie in that interval (the
  transcription's λ is piecewise linear in s between its nodes), zero outside every interval —
  in flight too;
* any other handle (a coupling's spring at a palm) is interpolated linearly in s within runs
  of samples (a gap of more than 2.5 × the median of the larger half of the spacings ends a run),
  zero outside.

With those forces the residual kernel (``residual.residual_kernel``, the same kernel the
solver and :mod:`.audit` use) gives the root residual Q_0 (6: the
generalised forces of root x, y, z in N and of its yaw, pitch, roll in N m) at every frame.
:func:`dense_residual` returns it; its ``force_max_bw`` (the largest translational root
residual, in body weights) is what issue #15 asks to be ≤ 0.05.  The heel shoe springs act
as the solver's did: only in planned heel contact (``shoe_gate=True``, :mod:`.shoe`; the
kernel's own switched off and the gated force added at the heels) or everywhere (False, the
round-8 semantics).  This module imports no transcription: it is a check of it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenegraph.model.body import G, N_ROOT, Character
from scenegraph.model.footsteps import Footstep, contact_points
from scenegraph.model.ground import FLAT, Ground
from scenegraph.model.motion import Motion
from scenegraph.model.kinematics import handle_positions_fn
from scenegraph.model.residual import CONTACT_HANDLES, FORCE_HANDLES, residual_kernel, theta_kernel_vector
from scenegraph.model.shoe import SIDES, shoe_force_numeric, shoe_gate
from scenegraph.model.style import Style

__all__ = ["DenseResidual", "dense_residual", "force_at", "shoe_forces", "kernel_theta"]


@dataclass(frozen=True)
class DenseResidual:
    """Root residual of a motion on a uniform world-time grid.

    ``times`` (T,) s; ``root`` (6, T): Q_0 (N for x, y, z; N m for yaw, pitch, roll);
    ``force_bw`` (T,): |Q_0[:3]| / (m g); ``moment_bw_m`` (T,): |Q_0[3:]| / (m g) (body
    weight × m); ``airborne`` (T,): no contact handle planted at that frame; ``energy``: the
    paper's muscle energy ∫ Σ α Q_m² dt (N² m² s) by the trapezoid rule over these frames —
    the same quadrature for any transcription, so energies of different grids compare."""

    times: np.ndarray
    root: np.ndarray
    force_bw: np.ndarray
    moment_bw_m: np.ndarray
    airborne: np.ndarray
    energy: float = 0.0

    @property
    def force_max_bw(self) -> float:
        return float(self.force_bw.max()) if self.force_bw.size else 0.0

    @property
    def force_rms_bw(self) -> float:
        return float(np.sqrt(np.mean(self.force_bw ** 2))) if self.force_bw.size else 0.0

    @property
    def moment_max_bw_m(self) -> float:
        return float(self.moment_bw_m.max()) if self.moment_bw_m.size else 0.0

    @property
    def flight_force_max_bw(self) -> float:
        f = self.force_bw[self.airborne]
        return float(f.max()) if f.size else 0.0

    def worst_time(self) -> float:
        return float(self.times[int(np.argmax(self.force_bw))]) if self.force_bw.size else float("nan")


def _lerp_s(s: np.ndarray, s_k: np.ndarray, f_k: np.ndarray) -> np.ndarray:
    """(len(s), 3): linear interpolation in s of samples (s_k, f_k) (s inside their range)."""
    return np.stack([np.interp(s, s_k, f_k[:, d]) for d in range(3)], axis=1)


def force_at(ch: Character, motion: Motion, footsteps: tuple[Footstep, ...], contact_forces: dict,
             times: np.ndarray, ground: Ground = FLAT) -> np.ndarray:
    """External forces (3·len(FORCE_HANDLES), len(times)) at world ``times`` read from the
    solver's samples as described in the module docstring (N, world)."""
    times = np.asarray(times, float)
    s = motion.to_canonical(times)
    F = np.zeros((3 * len(FORCE_HANDLES), len(times)))
    intervals: dict[str, list] = {}
    for step in footsteps:
        for handle, (ta, tb), _ in contact_points(ch, step, None, ground):
            intervals.setdefault(handle, []).append((ta, tb))
    for h, (ht, hf) in (contact_forces or {}).items():
        ht = np.asarray(ht, float)
        hf = np.asarray(hf, float).reshape(-1, 3)
        if not len(ht):
            continue
        o = np.argsort(ht, kind="stable")
        ht, hf = ht[o], hf[o]
        hs = motion.to_canonical(ht)
        i = FORCE_HANDLES.index(h)
        if h in CONTACT_HANDLES and h in intervals:
            runs = [((ht >= ta - 1e-9) & (ht <= tb + 1e-9), (times >= ta - 1e-9) & (times <= tb + 1e-9))
                    for ta, tb in intervals[h]]
        else:
            gaps = np.diff(ht)
            step = float(np.median(np.sort(gaps)[len(gaps) // 2:])) if len(gaps) else 0.0
            cut = np.r_[0, np.nonzero(gaps > 2.5 * step + 1e-9)[0] + 1, len(ht)]
            runs = []
            for a, b in zip(cut[:-1], cut[1:]):
                sel = np.zeros(len(ht), bool)
                sel[a:b] = True
                runs.append((sel, (times >= ht[a] - 1e-9) & (times <= ht[b - 1] + 1e-9)))
        for sel, inside in runs:
            if not sel.any() or not inside.any():
                continue
            F[3 * i:3 * i + 3, inside] = _lerp_s(s[inside], hs[sel], hf[sel]).T
    return F


def kernel_theta(style: Style, gated: bool) -> np.ndarray:
    """The kernel's θ for ``style``: with the kernel's own shoe spring off when ``gated``."""
    th = theta_kernel_vector(style).copy()
    if gated:
        th[-2] = 0.0  # k_shoe (theta_kernel_vector: …, k_shoe, h_rest)
    return th


def shoe_forces(ch: Character, style: Style, motion: Motion, footsteps, q: np.ndarray, times: np.ndarray,
                ground: Ground = FLAT) -> np.ndarray:
    """The gated shoe springs (3·len(FORCE_HANDLES), len(times)) N, world: vertical at each heel,
    g(h̄ − h) k (h̄ − h) × :func:`.shoe.shoe_gate` with h the heel's height above the ground;
    ``q`` (len(times), 35) the poses at ``times``."""
    times = np.atleast_1d(np.asarray(times, float))
    F = np.zeros((3 * len(FORCE_HANDLES), len(times)))
    gate = shoe_gate(ch, footsteps, times, motion.start, motion.end, ground)
    if not gate.any():
        return F
    names = tuple(f"heel_{s}" for s in SIDES)
    hp = np.asarray(handle_positions_fn(ch, names).map(len(times))(np.atleast_2d(q).T)).reshape(
        3, len(names), len(times), order="F")
    for i, name in enumerate(names):
        h = hp[2, i] - (0.0 if ground.flat else ground.height(hp[0, i], hp[1, i]))
        F[3 * FORCE_HANDLES.index(name) + 2] = gate[i] * shoe_force_numeric(h, float(style.k_shoe),
                                                                            float(style.h_rest))
    return F


def dense_residual(ch: Character, style: Style, motion: Motion, footsteps: tuple[Footstep, ...] = (),
                   contact_forces: dict | None = None, rate: float = 120.0, ground: Ground = FLAT,
                   shoe_gate: bool = True) -> DenseResidual:
    """The root residual of ``motion`` at ``rate`` Hz (world time, ends included) with the
    solver's forces read as in the module docstring; see :class:`DenseResidual`."""
    n = max(2, int(round(motion.duration * rate)) + 1)
    t = np.linspace(motion.start, motion.end, n)
    q, qd, qdd = motion.state_at_s(motion.to_canonical(t))
    F = force_at(ch, motion, footsteps, contact_forces or {}, t, ground)
    if shoe_gate:
        F = F + shoe_forces(ch, style, motion, footsteps, q, t, ground)
    th = np.tile(kernel_theta(style, shoe_gate)[:, None], (1, n))
    Q = np.asarray(residual_kernel(ch).map(n)(q.T, qd.T, qdd.T, F, th))
    root = Q[-N_ROOT:, :]
    mg = ch.total_mass * G
    planted = np.zeros(n, bool)
    for step in footsteps:
        for _, (ta, tb), _ in contact_points(ch, step, None, ground):
            planted |= (t >= ta - 1e-9) & (t <= tb + 1e-9)
    per = np.asarray(style.alpha, float) @ Q[:-N_ROOT, :] ** 2
    energy = float(np.sum(0.5 * (per[1:] + per[:-1]) * np.diff(t)))
    return DenseResidual(t, root, np.linalg.norm(root[:3], axis=0) / mg, np.linalg.norm(root[3:], axis=0) / mg,
                         ~planted, energy)
