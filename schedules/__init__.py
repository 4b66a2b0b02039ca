"""How a scenario is solved: steps, schedule graphs, the compiler, the executor and the CLI."""
from schedules.plan.step import Step, StyleTimeline, Group, Schedule, KINDS, TIMEWARP, TIME_LAYERED, COUPLED, DECREASING_HORIZON, JOINT
from schedules.plan.compiler import compile_schedule

__all__ = ["Step", "StyleTimeline", "Group", "Schedule", "compile_schedule",
           "KINDS", "TIMEWARP", "TIME_LAYERED", "COUPLED", "DECREASING_HORIZON", "JOINT"]
