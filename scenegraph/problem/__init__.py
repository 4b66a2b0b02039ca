"""One spacetime subproblem (a Step's unit of work for one character), in four parts:

- :mod:`.subproblem`: what to solve (``Subproblem`` and its terms: plain frozen data);
- :mod:`.transcription`: how it becomes an NLP (``transcribe(sp) -> NLP``, with a named x/p layout);
- :mod:`.solver`: how the NLP is solved (IPOPT options, iteration callbacks, ``make_solver``, ``solve``);
- :mod:`.result`: what comes out (``Result``, ``SolveTiming``, ``read_solution``, ``violations``).

The physics kernels the transcription evaluates live below, in :mod:`scenegraph.model.residual`.
"""
from scenegraph.problem.result import Result, SolveTiming, read_solution, violations
from scenegraph.problem.solver import (STALL_RATE, STALL_VIOL, Built, IterationCallback, StallMonitor, build, create_nlpsol,
                     make_solver, solve, solver_options)
from scenegraph.problem.subproblem import HESSIAN_MODES, Avoid, HandleTarget, PoseTarget, Spring, Subproblem, VelocityTarget
from scenegraph.problem.transcription import KIN_WEIGHT, NLP, OBJ_SCALE, transcribe, window_mask

__all__ = ["Subproblem", "HandleTarget", "PoseTarget", "VelocityTarget", "Spring", "Avoid", "HESSIAN_MODES",
           "NLP", "transcribe", "window_mask", "OBJ_SCALE", "KIN_WEIGHT",
           "Built", "IterationCallback", "StallMonitor", "STALL_RATE", "STALL_VIOL", "solver_options",
           "create_nlpsol", "make_solver", "build", "solve",
           "Result", "SolveTiming", "read_solution", "violations"]
