"""The synthesis-free diagnostic of issue #18 item 2 (scenegraph.nio.ranking): the energy split
adds up, the log ratio has the sign the ranking needs, and, on a real transcription, the split
is the energy's own (E linear in α)."""
from __future__ import annotations

import numpy as np
import pytest

from scenegraph.model.body import JOINT_DOF_NAMES, N_JOINT
from scenegraph.model.style import default_style
from scenegraph.nio.ranking import ENERGY_GROUPS, energy_split, rank_report
from scenegraph.nio.theta import ALPHA


def test_groups_cover_every_joint_once():
    owners = [[g for g, pre in ENERGY_GROUPS.items() if d.startswith(pre)] for d in JOINT_DOF_NAMES]
    assert all(len(o) == 1 for o in owners)


def test_split_adds_up_to_the_energy():
    rng = np.random.default_rng(0)
    A = rng.uniform(0, 3, N_JOINT)
    alpha = rng.uniform(0, 1, N_JOINT) / N_JOINT
    E = float(alpha @ A) + 0.25
    s = energy_split(E, A, alpha)
    assert sum(s.values()) == pytest.approx(E)
    assert s["rest"] == pytest.approx(0.25)
    arms = [j for j, d in enumerate(JOINT_DOF_NAMES) if d.startswith(("shoulder_", "elbow_", "wrist_"))]
    assert s["arms"] == pytest.approx(float(alpha[arms] @ A[arms]))


class _FakeNIO:
    """measure(θ, m) -> (E, ∂E/∂θ, F, λ) with E = Σ α_j A_j(m) + r(m)."""

    def __init__(self, table):
        self.table = table

    def measure(self, theta, m):
        A, r = self.table[m]
        g = np.zeros(len(theta))
        g[ALPHA] = A
        return float(theta[ALPHA] @ A + r), g, None, None


def test_rank_report_sign_and_where_a_rival_is_cheaper():
    th = default_style().vector().copy()
    arms = np.array([d.startswith(("shoulder_", "elbow_", "wrist_")) for d in JOINT_DOF_NAMES])
    A_real = np.where(arms, 1.0, 2.0)
    A_flail = np.where(arms, 3.0, 0.1)  # cheap legs and trunk, dear arms
    nio = _FakeNIO({"real": (A_real, 0.1), "flail": (A_flail, 0.1)})
    rep = rank_report(nio, th, "real", {"flail": "flail"}, local_g=False)
    E_real = float(th[ALPHA] @ A_real) + 0.1
    E_fl = float(th[ALPHA] @ A_flail) + 0.1
    assert rep["E_real"] == pytest.approx(E_real) and rep["E_rival"]["flail"] == pytest.approx(E_fl)
    assert rep["log_ratio"]["flail"] == pytest.approx(np.log(E_real / E_fl))
    assert rep["log_ratio"]["flail"] > 0  # uniform α: the flailing motion is cheaper
    assert rep["split"]["flail"]["arms"] > rep["split"]["real"]["arms"]
    assert rep["log_ratio_muscle"]["flail"] == pytest.approx(np.log((E_real - 0.1) / (E_fl - 0.1)))
    # weighting the arms up makes the real motion the cheaper one
    th2 = th.copy()
    th2[ALPHA] = np.where(arms, 10.0, 0.1)
    th2[ALPHA] /= th2[ALPHA].sum()
    assert rank_report(nio, th2, "real", {"flail": "flail"}, local_g=False)["max_log_ratio"] < 0


@pytest.mark.slow
def test_split_on_a_real_transcription_is_linear_in_alpha():
    """E(X; θ) of a real NIO problem: Σ α_j ∂E/∂α_j + rest, and the rest does not change with α."""
    from scenegraph.model.body import make_character
    from scenegraph.model.footsteps import footsteps_for_walk
    from scenegraph.model.gait import initial_motion
    from scenegraph.nio.problem import NIO

    ch = make_character("adult_male")
    steps = footsteps_for_walk(3)
    t1 = max(s.t1 for s in steps)
    m = initial_motion(ch, steps, 0.0, t1)
    nio = NIO(ch, m, steps, local=True)
    th = default_style(ch.total_mass).vector()
    E, g, _, lam = nio.measure(th, m)
    s = energy_split(E, g[ALPHA], th[ALPHA])
    th2 = th.copy()
    th2[ALPHA] = np.random.default_rng(1).uniform(0.5, 2, N_JOINT) / N_JOINT
    E2, g2 = nio.energy(th2, m, lam)  # same contact forces: only α changed
    s2 = energy_split(E2, g2[ALPHA], th2[ALPHA])
    assert s2["rest"] == pytest.approx(s["rest"], rel=1e-8)
    assert sum(s2.values()) == pytest.approx(E2, rel=1e-10)
    # the muscle rows are Σ α_j A_j, and root + other is the rest
    p = nio.model.parts(th2, m, lam)
    assert p["muscle"] == pytest.approx(E2 - s2["rest"], rel=1e-8)
    assert p["root"] + p["other"] == pytest.approx(s2["rest"], rel=1e-8)
    assert p["root"] > 0 and p["other"] >= -1e-12
