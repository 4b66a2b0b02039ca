"""The ``compose`` command line."""
from __future__ import annotations

import argparse
import importlib
import os
import sys

from scenarios.errors import ComposeError
from scenarios.versions import compose_version

__all__ = ["main", "build_parser"]

# Each module registers its sub-commands with ``register(subparsers)``; a sub-command sets
# ``func`` to a callable taking the parsed arguments and returning an exit code.
COMMAND_MODULES = (
    "schedules.cli.run",        # run, schedule
    "schedules.cli.scenario",   # validate, schema, list
    "schedules.cli.learn",      # learn
    "schedules.cli.evaluate",   # evaluate-style
    "schedules.cli.preview",    # preview, export
    "schedules.cli.audit",      # audit
    "schedules.cli.sweep",      # sweep
    "schedules.cli.edit",       # edit
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="compose", description=__doc__)
    parser.add_argument("--version", action="version", version=f"compose {compose_version()}")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an unexpected error (also COMPOSE_DEBUG=1)")
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
    try:
        parser = build_parser()  # imports every command module (CasADi, USD): seconds
    except KeyboardInterrupt:
        print("compose: interrupted", file=sys.stderr)
        return 130
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    debug_before = os.environ.get("COMPOSE_DEBUG")
    if args.debug:
        os.environ["COMPOSE_DEBUG"] = "1"  # read by the executor (a step's crash) and below
    try:
        return _call(args)
    finally:
        if args.debug:  # main() may be called in-process (tests): leave the environment as it was
            if debug_before is None:
                os.environ.pop("COMPOSE_DEBUG", None)
            else:
                os.environ["COMPOSE_DEBUG"] = debug_before


def _call(args) -> int:
    """Run the sub-command; every error becomes one line on stderr and an exit code."""
    try:
        return int(args.func(args) or 0)
    except ComposeError as exc:
        print(f"compose: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("compose: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: one line, the traceback only on request
        from schedules.execution.interrupts import crash_message, debug_enabled, format_traceback
        if debug_enabled():
            print(format_traceback(exc), end="", file=sys.stderr)
        print(f"compose: internal error: {crash_message(exc)} (run with --debug or COMPOSE_DEBUG=1 for the "
              "traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
