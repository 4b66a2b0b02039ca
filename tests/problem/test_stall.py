"""The IPOPT iteration callback that stops stalled solves and remembers the best feasible iterate
(STALL_RATE = 0.1 % mean relative gain per iterate over the patience window)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from scenegraph.problem import StallMonitor


def _arg(x, f, g):
    names = ca.nlpsol_out()
    out = [ca.DM()] * len(names)  # IPOPT hands the callback DMs
    out[names.index("x")] = ca.DM(x)
    out[names.index("f")] = ca.DM(f)
    out[names.index("g")] = ca.DM(g)
    return out


def test_best_feasible_iterate_is_kept_and_infeasible_ones_ignored():
    m = StallMonitor(2, 1, np.array([0.0]), np.array([0.0]), patience=3)
    m.eval(_arg([5.0, 5.0], 1.0, [0.5]))       # infeasible: not a candidate however low f is
    assert m.best_x is None
    m.eval(_arg([1.0, 2.0], 10.0, [0.0]))      # feasible
    m.eval(_arg([3.0, 4.0], 12.0, [0.0]))      # feasible but worse
    assert m.best == 10.0 and m.best_x.tolist() == [1.0, 2.0]
    stops = [m.eval(_arg([3.0, 4.0], 12.0, [0.0]))[0] for _ in range(2)]
    assert stops == [0, 1] and m.stalled      # three feasible iterates without improvement
    # steady progress (1 % per iterate) does not stall; a 0.01 % creep does
    # infeasible iterates in between neither count nor restart the count
    m.reset()
    out = []
    for k in range(8):
        out.append(m.eval(_arg([0.0, 0.0], 5.0, [0.0] if k % 2 == 0 else [1.0]))[0])
    assert out.index(1) == 6, out  # the 4th feasible iterate: 3 without gain after the first
    for f0, per, stalls in ((100.0, 0.99, False), (100.0, 0.9999, True)):
        m.reset()
        out = [m.eval(_arg([0.0, 0.0], f0 * per ** k, [0.0]))[0] for k in range(5)]
        assert (1 in out) == stalls, (per, out)
    m.reset()
    assert m.best == np.inf and m.best_x is None and not m.stalled and m.trace == []
