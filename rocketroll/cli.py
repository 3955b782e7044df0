"""The ``rocketroll`` command line.

Each layer registers its own subcommands; handlers import their heavy
dependencies lazily so ``rocketroll --help`` stays fast.  Errors a user can
cause (:class:`identification.errors.RocketrollError`) become one line on
stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from agents import evaluate as agents_evaluate
from agents import train as agents_train
from disturbances import cli as disturbances_cli
from identification import cli as identification_cli
from rocketroll import __version__
from rocketroll_common.errors import RocketrollError
from rollenv import cli as rollenv_cli

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The full ``rocketroll`` argument parser."""
    parser = argparse.ArgumentParser(
        prog="rocketroll",
        description="Rocket roll dynamics under turbulence: virtual wind tunnel, recordings, "
        "identification (Minimal modelling approach ..., eq. 36/49), disturbance database, "
        "RocketRoll-v0 environment, PID/PPO/oracle baselines and their evaluation.",
    )
    parser.add_argument("--version", action="version", version=f"rocketroll {__version__}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    identification_cli.register(subparsers)
    disturbances_cli.register(subparsers)
    rollenv_cli.register(subparsers)
    agents_train.register(subparsers)
    agents_evaluate.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = build_parser()
    ns = parser.parse_args(argv)
    try:
        code: int = ns.handler(ns)
    except RocketrollError as exc:
        print(f"rocketroll {ns.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        sys.stderr.close()
        return 0
    except OSError as exc:  # a file the user named cannot be read or written
        where = f": {exc.filename}" if exc.filename else ""
        print(f"rocketroll {ns.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":
    sys.exit(main())
