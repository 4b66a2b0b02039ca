"""The outcome of a solve: :class:`Result`, its :class:`SolveTiming`, and readers of a solution vector.

:func:`read_solution` turns a solution x of an :class:`~.transcription.NLP` into a motion,
footsteps, the energy (paper Eq. 13: Σ w T' α Q_m², in N² m² s) and the external
forces (world frame, N, at world times s); :func:`violations` gives the worst violation of each
constraint group (m for positions, the constraint's own unit otherwise).  Times in
:class:`SolveTiming` are wall-clock seconds.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from scenegraph.model.body import G
from scenegraph.model.dynamics import friction_basis
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.problem.transcription import NLP

__all__ = ["Result", "SolveTiming", "read_solution", "violations", "violation_scale"]


@dataclass(frozen=True)
class SolveTiming:
    """Where the wall time of one solve went (s).

    ``build``: transcription and nlpsol creation (0 when a built problem was passed in).
    ``f``, ``grad_f``, ``g``, ``jac_g``, ``hess``: evaluation of the objective, its gradient,
    the constraints, their Jacobian and the Lagrangian Hessian, as CasADi records them in
    ``solver.stats()`` (``t_wall_nlp_*``; ``grad_f`` includes ``t_wall_nlp_grad``, the one
    Lagrangian gradient CasADi evaluates after IPOPT for the multipliers).  ``callbacks``: time
    inside our Python iteration callbacks (``IterationCallback``).  ``linear_solver_and_ipopt``:
    IPOPT's own work, dominated by the MUMPS factorisations: the solver's total wall time
    (``t_wall_total`` when CasADi records it, else the wall time of the solver call) minus all
    evaluations and callbacks, clipped at 0.  ``total``: the whole solve, build included.
    """

    build: float = 0.0
    f: float = 0.0
    grad_f: float = 0.0
    g: float = 0.0
    jac_g: float = 0.0
    hess: float = 0.0
    callbacks: float = 0.0
    linear_solver_and_ipopt: float = 0.0
    total: float = 0.0

    @classmethod
    def from_stats(cls, stats: dict, *, build: float, callbacks: float, solver_wall: float,
                   total: float) -> SolveTiming:
        """The timing of a solve from CasADi's ``solver.stats()``; ``solver_wall`` is the measured
        wall time of the solver call (used when the stats carry no ``t_wall_total``)."""
        def t(key: str) -> float:
            return float(stats.get(f"t_wall_{key}", 0.0) or 0.0)

        ev = dict(f=t("nlp_f"), grad_f=t("nlp_grad_f") + t("nlp_grad"), g=t("nlp_g"), jac_g=t("nlp_jac_g"),
                  hess=t("nlp_hess_l"))
        wall = float(stats["t_wall_total"]) if "t_wall_total" in stats else solver_wall
        own = max(0.0, wall - sum(ev.values()) - callbacks)
        return cls(build=build, callbacks=callbacks, linear_solver_and_ipopt=own, total=total, **ev)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass
class Result:
    """Outcome of one solve."""

    motion: Motion
    footsteps: tuple[Footstep, ...]
    status: str
    success: bool
    iterations: int
    seconds: float
    energy: float
    objective: float
    violations: dict[str, float]
    contact_forces: dict = field(default_factory=dict)  # handle -> (times, forces (n,3))
    label: str = "step"
    timing: SolveTiming | None = None

    def summary(self) -> str:
        worst = max(self.violations.items(), key=lambda kv: kv[1], default=("none", 0.0))
        return (f"{self.label}: {self.status} in {self.iterations} it, {self.seconds:.2f} s, "
                f"E={self.energy:.4g}, worst violation {worst[0]}={worst[1]:.2e}")


def violation_scale(nlp: NLP, name: str) -> float:
    """Factor from a constraint group's rows to the unit its violation is reported in: 1 for
    positions (m) and most groups; 1/M for ``flight_momentum``, whose rows are momenta (kg·m/s,
    kg·m²/s) — reported per kilogram of body (m/s of the centre of mass, m²/s), so one tolerance
    means the same for a child and an adult (a 1e-3 kg·m/s row is 1.4e-5 m/s for 73 kg)."""
    return 1.0 / nlp.sp.character.total_mass if name == "flight_momentum" else 1.0


def violations(nlp: NLP, x: np.ndarray, p: np.ndarray | None = None) -> dict[str, float]:
    """Worst violation per constraint group of ``x`` with parameters ``p`` (default: the NLP's own
    ``p0``); 0 when satisfied.  Units: m for positions, per kilogram of body for the flight
    momenta (:func:`violation_scale`)."""
    gv = np.asarray(nlp.g_fn(x, nlp.p0 if p is None else p)).ravel()
    out = {}
    for name, sl, _ in nlp.groups:
        lo, hi, v = nlp.lbg[sl], nlp.ubg[sl], gv[sl]
        viol = np.maximum(np.maximum(lo - v, v - hi), 0.0) * violation_scale(nlp, name)
        key = name.split(":")[0] if name.startswith("target") else name
        out[key] = max(out.get(key, 0.0), float(viol.max()) if viol.size else 0.0)
    return out


def read_solution(nlp: NLP, x: np.ndarray, p: np.ndarray) -> tuple[Motion, tuple, float, dict]:
    """(motion, footsteps, energy, forces) of a solution vector ``x`` of ``nlp`` with parameters
    ``p``; forces: handle → (world times s, forces N (n, 3)), contact forces from λ plus each
    spring's force over its interval (external forces at their handle, for the audit)."""
    sp = nlp.sp
    P, W, F, E, _, FS = (np.asarray(v) for v in nlp.unpack(x, p))
    F = F.ravel()
    motion = Motion(np.asarray(P, float), np.asarray(W, float).ravel())
    steps = list(sp.footsteps)
    for j, si in enumerate(nlp.free_steps):
        steps[si] = replace(steps[si], position=(float(F[2 * j]), float(F[2 * j + 1])))
    mg = sp.character.total_mass * G
    forces: dict = {}
    at_node: dict = {}
    s_pts = nlp.s_points
    for c, (h, k, sl) in enumerate(nlp.contact_index):
        V = nlp.contact_basis[c] if nlp.contact_basis else friction_basis()
        f = mg * V @ x[sl]
        forces.setdefault(h, []).append((float(motion.time([s_pts[k]])[0]), f))
        at_node[h, k] = f
    if len(nlp.s_eval) > len(s_pts):  # transcribed densely (evaluation points between the nodes)
        # the transcription's force is piecewise linear in s between nodes: report it at the
        # midpoints too (where the dense residual was evaluated), so readers that interpolate
        # linearly in world time between samples see the force the solver balanced
        for (h, k), f in list(at_node.items()):
            if (h, k + 1) in at_node:
                t_mid = float(motion.time([0.5 * (s_pts[k] + s_pts[k + 1])])[0])
                forces[h].append((t_mid, 0.5 * (f + at_node[h, k + 1])))
    contact = {}
    for h, v in forces.items():
        v = sorted(v, key=lambda tf: tf[0])
        contact[h] = (np.array([tt for tt, _ in v]), np.array([ff for _, ff in v]))
    t_pts = motion.time(nlp.s_eval)  # spring forces: at every evaluation point
    for j, h in enumerate(nlp.spring_handles):
        fj = FS[3 * j:3 * j + 3, :].T
        on = (t_pts >= sp.springs[j].times[0] - 1e-9) & (t_pts <= sp.springs[j].times[-1] + 1e-9)
        if h in contact:
            t_old, f_old = contact[h]
            t_all = np.unique(np.r_[t_old, t_pts[on]])
            f_all = np.zeros((len(t_all), 3))
            for tt, ff in zip(t_old, f_old):
                f_all[np.argmin(np.abs(t_all - tt))] += ff
            for tt, ff in zip(t_pts[on], fj[on]):
                f_all[np.argmin(np.abs(t_all - tt))] += ff
            contact[h] = (t_all, f_all)
        elif on.any():
            o = np.argsort(t_pts[on], kind="stable")
            contact[h] = (t_pts[on][o], fj[on][o])
    return motion, tuple(steps), float(np.ravel(E)[0]), contact
