"""Several clips of one person in one NIO (issue #18, item 2): minimise Σ_c G_c(θ) + D(θ).

Each clip c is its own NIO problem (:class:`scenegraph.nio.NIO`: its target X_T,c, its
footsteps C_c, its transcription and counterexamples); the style θ is shared.  Since every
G_c(θ) = E(X_T,c; θ) − min_{X ∈ C_c} E(X; θ) ≥ 0, the sum is what a style that makes each
performance optimal under its own constraints drives to zero, and its Eq. 21 gradient is the
sum of the clips' gradients; D(θ) (Eq. 18) is counted once.  The bundle method
(:mod:`.bundle`) keeps every clip's counterexamples apart: a counterexample of clip c bounds
G_c only, so the cutting-plane model is Σ_c max(0, max_{i ∈ c} L_ci) — one LP epigraph
variable per clip — which is tighter than one max over all cuts.

A single clip is ``MultiNIO((nio,))``: that is how ``NIO.run_bundle`` and ``learn_style`` run,
so the one-clip learning is this code with one part.  Energies are those of :mod:`.energy`
(dimensionless, each clip on its own grid), so a longer clip weighs more.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from scenegraph.model.motion import Motion
from scenegraph.nio.records import Evaluation
from scenegraph.nio.theta import d_penalty

__all__ = ["MultiNIO", "MultiEvaluation"]


@dataclass(frozen=True)
class MultiEvaluation:
    """Σ_c G_c(θ), D(θ), the summed energies, the gradient of Σ G_c + D, and each clip's own
    :class:`.records.Evaluation` (``parts``, with its D left in)."""

    theta: np.ndarray
    G: float
    D: float
    E_T: float
    E_S: float
    grad: np.ndarray
    parts: tuple[Evaluation, ...]

    @property
    def motion_S(self) -> Motion:
        """The first clip's counterexample (what a one-clip result reports)."""
        return self.parts[0].motion_S


class MultiNIO:
    """The NIO problem of several clips sharing one style: ``clips`` are NIO problems (one per
    clip, built on the same character).  ``alpha_floor`` and ``verbose`` are the first clip's
    / shared; ``target`` is the first clip's X_T (the style's example poses come from it)."""

    def __init__(self, clips: Sequence):
        if not clips:
            raise ValueError("MultiNIO needs at least one clip")
        self.clips = tuple(clips)
        self.alpha_floor = max(c.alpha_floor for c in self.clips)
        self.verbose = any(getattr(c, "verbose", False) for c in self.clips)

    @property
    def target(self) -> Motion:
        return self.clips[0].target

    def evaluate(self, theta: np.ndarray, candidates: Sequence[Sequence[Motion]] = ()) -> MultiEvaluation:
        """Every clip's G_c(θ) (``NIO.evaluate`` with that clip's ``candidates[c]``), summed."""
        theta = np.asarray(theta, float)
        cands = list(candidates) + [()] * (len(self.clips) - len(candidates))
        parts = tuple(c.evaluate(theta, tuple(cd)) for c, cd in zip(self.clips, cands))
        D, gD = d_penalty(theta)
        grad = sum(p.grad - gD for p in parts) + gD  # each part's gradient carries D's once
        return MultiEvaluation(theta, float(sum(p.G for p in parts)), D, float(sum(p.E_T for p in parts)),
                               float(sum(p.E_S for p in parts)), grad, parts)
