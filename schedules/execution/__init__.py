"""Running a plan: lowering a Step to subproblems, the executor and its checkpoints, the Dask
task graph and schedulers, the step store, interrupts, the run's stage audit, sweep outputs."""
