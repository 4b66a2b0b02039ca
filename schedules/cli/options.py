"""Command-line options shared by ``compose run`` and ``compose sweep``: how the steps are
solved (worker processes, Dask scheduler, step store), resumed and exported."""
from __future__ import annotations

import argparse

__all__ = ["add_solve_options", "add_scenario_argument"]


def add_scenario_argument(p: argparse.ArgumentParser) -> None:
    """The positional scenario: a file, or the name of a bundled scenario."""
    p.add_argument("file", metavar="NAME|FILE", help="scenario file or bundled scenario name")


def add_solve_options(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--jobs --resume --fps --fail-capped --scheduler --store --no-store``; ``what`` names
    the unit that ``--scheduler`` turns into Dask tasks ("steps" or "variants")."""
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="worker processes: independent steps in N processes (with --scheduler: N local workers)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run or sweep from its folder")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate of the exported stages (default 30)")
    p.add_argument("--fail-capped", action="store_true",
                   help="fail when a full step stops unconverged (its iteration cap, or a numerical breakdown such "
                        "as a failed restoration phase), even with every constraint satisfied (default: such a step "
                        "is kept, with its status in the report)")
    p.add_argument("--scheduler", metavar="local|processes|sync|ADDRESS",
                   help=f"run the {what} as a Dask task graph: local (LocalCluster of --jobs worker processes), "
                        "processes, sync, or a Dask scheduler address such as tcp://host:8786 (docs/distributed.md); "
                        + ("default: the plain executor" if what == "steps" else "default: one after another"))
    p.add_argument("--store", metavar="DIR", help="content-addressed step store used with --scheduler (default "
                                                  "$COMPOSE_STEP_STORE or ~/.cache/compose/steps)")
    p.add_argument("--no-store", action="store_true", help="with --scheduler: solve every step, store nothing")
