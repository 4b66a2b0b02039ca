"""The example poses a learned style carries, and the paper's re-synthesis check from them."""
from __future__ import annotations

from scenegraph.model.body import N_ROOT, Character
from scenegraph.model.footsteps import Footstep
from scenegraph.model.motion import Motion
from scenegraph.problem import Result
from scenegraph.model.style import ExamplePoses, Style

__all__ = ["example_of", "resynthesize_from_example"]


def example_of(target: Motion, footsteps: tuple[Footstep, ...], fps: float = 60.0) -> ExamplePoses:
    """The example poses a learned style carries: X_T's joint angles at ``fps`` keyed by leg
    phase under its footsteps (the paper's initial motions for new footsteps, §7).  The poses
    are copied, not interpolated, so the rate matters: the initial motion for 07_01's own
    footprints is 1.11° from X_T at 60 fps, 1.80° at 30 fps."""
    from scenegraph.model.gait import example_poses

    t, q = target.sample(fps)
    return ExamplePoses.from_arrays(*example_poses(tuple(footsteps), t, q[:, N_ROOT:]))


def resynthesize_from_example(ch: Character, target: Motion, footsteps: tuple[Footstep, ...], style: Style, *,
                              max_iter: int = 300, hessian: str = "gauss_newton") -> Result:
    """The paper's re-synthesis check (§7, "Estimating style parameters"), with the paper's
    initialisation: for each time the joint angles of the pose of the example ``target`` (X_T)
    with the most similar footstep constraints (leg phases; ``gait.initial_motion(example=…)``),
    the root from the footprints; then the ordinary synthesis (kinematic pre-solve, spacetime
    solve of ``max_iter`` iterations) with ``style`` and the same ``footsteps``.  For X_T's own
    footprints the initial motion is close to X_T up to its root (0.42–1.11° joint RMS on the
    four shipped clips).  The poses are those a learned style carries (:func:`example_of`)."""
    from scenegraph.problem.synthesis import synthesize

    return synthesize(ch, style, tuple(footsteps), target.start, target.end,
                      example=example_of(target, footsteps).arrays(), max_iter=max_iter, hessian=hessian).result
