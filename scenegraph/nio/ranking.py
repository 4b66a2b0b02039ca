"""Does a style make the real held-out motion cheaper than the flailing ones? (issue #18 item 2)

A diagnostic that needs no synthesis: a style that predicts a real trial must give that trial
(moved onto its own footsteps, so that it satisfies the same constraints C) a lower energy than
the motions the synthesis lands in when it fails.  Round 12 measured the opposite for the
shipped ``walk`` θ on 07_12: E(real) = 9.24, E(flailing synthesis) = 0.40 — the flailing is
that style's optimum, so no start or solver setting can make the prediction look like the
trial.

For one θ, :func:`rank_report` gives (energies of :class:`.energy.EnergyModel`: the synthesis
objective, dimensionless, contact forces profiled out):

- ``E_real`` and ``E_rival[name]`` for every rival motion (same NIO problem: same footsteps,
  same transcription), and ``log_ratio[name]`` = ln(E_real / E_rival) (< 0: the real motion is
  the cheaper; the ranking a predicting style needs), and ``log_ratio_muscle`` the same of the
  muscle terms alone (the real trial keeps the root residual its projection left, which no
  θ but the shoe changes: on 07_12 it is 5.3 of E, the syntheses' 0.05–0.07);
- ``split``: each motion's energy by part — the muscle terms α_j A_j summed over the joint
  groups legs / trunk (waist, chest, neck) / arms, and the rest (root residual, λ
  regularisation), with the root residual's own share as ``root`` when the NIO problem's
  energy model gives it (:meth:`.energy.EnergyModel.parts`) — which says *where* a rival is cheaper;
- ``G_local``: the held-out NIO loss E(X_real) − E(X_S) with X_S the local counterexample
  (one Gauss–Newton step from X_real within C, what ``compose learn`` trains with) — how far
  the real motion is from a local optimum of θ's energy, in the same units.
"""
from __future__ import annotations

import numpy as np

from scenegraph.model.body import JOINT_DOF_NAMES
from scenegraph.model.motion import Motion
from scenegraph.nio.theta import ALPHA

__all__ = ["ENERGY_GROUPS", "energy_split", "rank_report"]

ENERGY_GROUPS = {  # name prefixes of JOINT_DOF_NAMES
    "legs": ("hip_", "knee_", "ankle_", "toe_"),
    "trunk": ("waist_", "chest_", "neck_"),
    "arms": ("shoulder_", "elbow_", "wrist_"),
}


def _group_mask(group: str) -> np.ndarray:
    return np.array([d.startswith(ENERGY_GROUPS[group]) for d in JOINT_DOF_NAMES])


def energy_split(E: float, dE_dalpha: np.ndarray, alpha: np.ndarray) -> dict[str, float]:
    """E split into the muscle terms of each joint group (α_j A_j, A_j = ∂E/∂α_j: E is linear
    in α) and ``rest`` = E − Σ_j α_j A_j (root residual and the λ regularisation)."""
    part = np.asarray(alpha, float) * np.asarray(dE_dalpha, float)
    out = {g: float(part[_group_mask(g)].sum()) for g in ENERGY_GROUPS}
    out["rest"] = float(E - part.sum())
    return out


def rank_report(nio, theta: np.ndarray, real: Motion, rivals: dict[str, Motion], local_g: bool = True) -> dict:
    """The ranking of ``real`` against ``rivals`` under θ (module docstring).  ``nio``: an NIO
    problem whose target is ``real`` (``local=True`` for ``G_local``)."""
    theta = np.asarray(theta, float)
    alpha = theta[ALPHA]
    E_r, g_r, _, lam_r = nio.measure(theta, real)
    split = {"real": energy_split(E_r, g_r[ALPHA], alpha)}
    parts = getattr(getattr(nio, "model", None), "parts", None)
    if parts is not None:
        split["real"]["root"] = parts(theta, real, lam_r)["root"]
    E_riv, ratio = {}, {}
    for name, m in rivals.items():
        E, g, _, lam = nio.measure(theta, m)
        E_riv[name] = float(E)
        ratio[name] = float(np.log(max(E_r, 1e-300) / max(E, 1e-300)))
        split[name] = energy_split(E, g[ALPHA], alpha)
        if parts is not None:
            split[name]["root"] = parts(theta, m, lam)["root"]
    G = float(nio.evaluate(theta).G) if local_g else None
    worst = max(ratio.values()) if ratio else None

    def muscle(sp):
        return sum(sp[g] for g in ENERGY_GROUPS)
    m_ratio = {k: float(np.log(max(muscle(split["real"]), 1e-300) / max(muscle(split[k]), 1e-300))) for k in rivals}
    worst_m = max(m_ratio.values()) if m_ratio else None
    line = (f"E_real={E_r:.3g} " + " ".join(f"E_{k}={v:.3g}" for k, v in E_riv.items())
            + (f" max_log_ratio={worst:+.2f} max_log_ratio_muscle={worst_m:+.2f}" if worst is not None else "")
            + (f" G_local={G:.3g} G_rel={G / max(E_r, 1e-300):.3f}" if G is not None else "")
            + " | " + "; ".join(f"{k}: " + " ".join(f"{g}={v:.3g}" for g, v in s.items()) for k, s in split.items()))
    return {"E_real": float(E_r), "E_rival": E_riv, "log_ratio": ratio, "max_log_ratio": worst,
            "log_ratio_muscle": m_ratio, "max_log_ratio_muscle": worst_m,
            "G_local": G, "split": split, "line": line}
