"""The ``compose`` command line."""
from __future__ import annotations

import argparse
import importlib
import sys

from scenarios.errors import ComposeError
from scenarios.versions import compose_version

__all__ = ["main", "build_parser"]

# Each module registers its sub-commands with ``register(subparsers)``; a sub-command sets
# ``func`` to a callable taking the parsed arguments and returning an exit code.
COMMAND_MODULES = (
    "schedules.cli_run",        # run, schedule
    "schedules.cli_scenario",   # validate, schema, list
    "schedules.cli_learn",      # learn
    "schedules.cli_preview",    # preview, export
    "schedules.cli_audit",      # audit
    "schedules.cli_sweep",      # sweep
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="compose", description=__doc__)
    parser.add_argument("--version", action="version", version=f"compose {compose_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except ComposeError as exc:
        print(f"compose: error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
