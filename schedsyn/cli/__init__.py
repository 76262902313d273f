"""The ``schedsyn`` command line: a thin layer over the API.

Each subcommand lives in its own module ``schedsyn.cli.<name>`` with ``register(sub)``
(adds its parser and sets ``func``); ``func(args) -> int`` calls the API and writes files.

Exit codes (every command):

* 0 done (a plan: complete);
* 1 a plan was made but is incomplete (``plan``, ``campaign``);
* 2 bad input: a :class:`~schedsyn.errors.SchedsynError`, one line on stderr;
* 3 a fault of the environment: an output cannot be written (permissions, disk full), a
  worker process was killed, out of memory; one line on stderr;
* 4 an internal error (a bug): one line; ``SCHEDSYN_DEBUG=1`` shows the traceback.

Never a traceback otherwise; 130 after Ctrl-C.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import sys

from ..errors import EnvironmentFaultError, SchedsynError

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "simulate",
    "sweep",
    "estimate",
    "compare",
    "diagnose",
    "fit",
    "monitor",
    "replan",
    "plan",
    "campaign",
    "split",
    "chambers",
    "export",
    "sheet",
    "report",
    "examples",
)

EXIT_OK, EXIT_INCOMPLETE, EXIT_BAD_INPUT, EXIT_FAULT, EXIT_BUG = 0, 1, 2, 3, 4


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="schedsyn",
        description="Plan thermal calibration tests of gyroscopes (chamber programmes with "
        "guaranteed temperature/gradient coverage).",
        epilog="Exit codes: 0 done, 1 plan incomplete, 2 bad input, 3 environment fault "
        "(cannot write, worker killed), 4 internal error.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"schedsyn {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    return parser


def _fail(command: str, kind: str, message: str) -> None:
    from ._common import units_text

    text = " ".join(units_text(str(message)).split())  # one line, whatever it held
    print(f"schedsyn {command}: {kind}: {text}", file=sys.stderr)


#: An option's value that argparse takes for an option: a range or grid starting with a
#: negative number ("-3:-1", "-.5:2", "-30:-10:5"); plain negative numbers it knows.
_NEGATIVE_RANGE = re.compile(r"^-(\d|\.\d)[^\s]*:")


def join_negative_ranges(argv: list[str]) -> list[str]:
    """``--opt -3:-1`` as ``--opt=-3:-1``: argparse reads a value starting with "-" that
    is not a plain number as an option and stops with its usage (red team:
    ``--robust-dt0-c -1:4`` printed 20 lines of usage and no hint)."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        if (
            arg.startswith("--")
            and "=" not in arg
            and nxt is not None
            and _NEGATIVE_RANGE.match(nxt)
        ):
            out.append(f"{arg}={nxt}")
            i += 2
            continue
        out.append(arg)
        i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    from concurrent.futures.process import BrokenProcessPool

    from ..io import os_error_text

    parser = build_parser()
    try:
        args = parser.parse_args(join_negative_ranges(sys.argv[1:] if argv is None else argv))
    except SystemExit as exc:  # argparse: usage errors exit 2, --help exits 0
        return int(exc.code) if isinstance(exc.code, int) else EXIT_BAD_INPUT
    command = args.command
    try:
        return _run(args)
    except EnvironmentFaultError as exc:
        _fail(command, "fault", str(exc))
        return EXIT_FAULT
    except SchedsynError as exc:
        _fail(command, "error", str(exc))
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader of stdout went away (e.g. `| head`)
        try:
            sys.stdout = open(os.devnull, "w")  # nothing more is written to the closed pipe
        except OSError:
            pass
        return EXIT_FAULT
    except OSError as exc:
        _fail(command, "fault", os_error_text(exc))
        return EXIT_FAULT
    except MemoryError:
        _fail(command, "fault", "out of memory; give the run more memory or smaller input")
        return EXIT_FAULT
    except BrokenProcessPool as exc:
        _fail(command, "fault", f"a worker process died ({exc})")
        return EXIT_FAULT
    except KeyboardInterrupt:
        print("schedsyn: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if os.environ.get("SCHEDSYN_DEBUG"):
            raise
        _fail(
            command,
            "internal error",
            f"{type(exc).__name__}: {exc} (a bug in schedsyn; run again with "
            "SCHEDSYN_DEBUG=1 for the traceback and report it)",
        )
        return EXIT_BUG


def _run(args: argparse.Namespace) -> int:
    from ._common import discard_uncommitted

    try:
        return int(args.func(args) or 0)
    finally:  # outputs of a command that failed midway never reach their folder
        discard_uncommitted()


def entry() -> None:
    sys.exit(main())
