"""The plan as data: Steps and Schedules, the compiler, critical paths and sweep expansion.
Nothing here imports CasADi or builds a character."""
