"""The ``schedsyn`` command line: a thin layer over the API.

Each subcommand lives in its own module ``schedsyn.cli.<name>`` with ``register(sub)``
(adds its parser and sets ``func``); ``func(args) -> int`` calls the API and writes files.
A :class:`~schedsyn.errors.SchedsynError` becomes a one-line message and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import SchedsynError

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "simulate",
    "sweep",
    "estimate",
    "compare",
    "diagnose",
    "monitor",
    "replan",
    "plan",
    "campaign",
    "export",
    "sheet",
    "report",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="schedsyn",
        description="Plan thermal calibration tests of gyroscopes (chamber programmes with "
        "guaranteed temperature/gradient coverage).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: usage errors exit 2, --help exits 0
        return int(exc.code) if isinstance(exc.code, int) else 2
    try:
        return int(args.func(args) or 0)
    except SchedsynError as exc:
        print(f"schedsyn {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("schedsyn: interrupted", file=sys.stderr)
        return 130


def entry() -> None:
    sys.exit(main())
