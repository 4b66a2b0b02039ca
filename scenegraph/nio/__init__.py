"""Nonlinear Inverse Optimization (NIO, paper §6): learn a physical style θ from one motion.

Given an observed motion X_T with its footsteps C, NIO looks for the style under which X_T
is the energy-optimal motion (Eq. 16).  It minimises (Eq. 17–19)

    G(θ) + D(θ),   G(θ) = E(X_T; θ) − min_{X ∈ C} E(X; θ),
    D(θ) = w (Σ_j α_j − 1)² + w Σ_j min(α_j, 0)²,   w = 10⁴,

with the energy of the spacetime solver — its NLP objective itself, read from the NIO
problem's transcription (dense dynamics, gated shoe, λ regularisation) — contact forces
profiled out by a bound-constrained least squares, for X_T and every counterexample alike.

The package, in the order of the computation (each module imports only those above it):

- :mod:`.plausibility`, :mod:`.slide`: a motion's best-fit root residual and its stance sliding (mm), model only;
- :mod:`.theta`: θ by name (``style.THETA_LAYOUT``), its bounds and projection, D (Eq. 18);
- :mod:`.prior`: the log-normal prior on α and the left/right / joint-group ties (issue #18);
- :mod:`.energy`: E(X; θ) = the NLP objective, ∂E/∂θ and the energy-optimal contact forces (``EnergyModel``);
- :mod:`.counterexamples`: X_S by a warm-started IPOPT solve or by one Gauss–Newton step
  from X_T within C (the default: IPOPT's capped solves make G mostly solver error); both
  use the transcription's named layout (``NLP.x_layout``, ``NLP.p_layout``);
- :mod:`.records`: evaluations, iteration records, results;
- :mod:`.initial`: the paper's initial θ (§6.1, Eq. 22);
- :mod:`.multi`: several clips of one person in one NIO (Σ_c G_c + D; one clip is the case of one);
- :mod:`.bundle` (default; its cuts grouped by clip) and :mod:`.gradient` (the paper's step): the optimisers;
- :mod:`.problem`: ``NIO``, the problem of one target motion (G(θ) and its Eq. 21 gradient);
- :mod:`.target`: X_T from a reconstructed clip (``feasible_target``), ``joint_rms_deg``;
- :mod:`.resynthesis`: the example poses a style carries and the paper's re-synthesis check;
- :mod:`.learn`: ``learn_style`` / ``learn_multi``, the whole loop with the learned style's provenance.
- :mod:`.heldout`: measures of a prediction against a real trial (issue #18);
- :mod:`.sensitivity`: dX*/dθ at a synthesis by the implicit-function theorem (issue #18);
- :mod:`.ranking`: E(real held-out trial) against E(flailing syntheses) under a θ, split by part (issue #18).

Measured (local counterexamples): synthetic G 9.0e-4 → 1.7e-5 (54×) with the springs
recovered but not α; 07_01 G 1.09 → 0.030 in 121 iterations (~200 s).  What it does not
give: X_T as the optimum of a long re-synthesis (docs/learning.md).
"""
from scenegraph.nio.learn import initial_style, learn_multi, learn_style
from scenegraph.nio.multi import MultiNIO
from scenegraph.nio.problem import NIO
from scenegraph.nio.records import IterationRecord, NIOResult
from scenegraph.nio.resynthesis import example_of, resynthesize_from_example
from scenegraph.nio.target import feasible_target, joint_rms_deg, resample
from scenegraph.nio.theta import D_WEIGHT, N_THETA_FULL, d_penalty, style_from_theta

__all__ = ["NIO", "MultiNIO", "learn_multi", "NIOResult", "IterationRecord", "learn_style", "initial_style", "joint_rms_deg",
           "resynthesize_from_example", "example_of", "feasible_target", "resample", "style_from_theta",
           "d_penalty", "D_WEIGHT", "N_THETA_FULL"]
