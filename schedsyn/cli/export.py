"""schedsyn export STEPS.csv --controller C: the step table as a controller programme.

Controllers: espec-p300 and espec-scp220 (JSON: ChamberConnectLibrary's
set_program(N, dict) dictionaries), watlow-f4t (JSON, same library), binder-mb (CSV
segment table after auger-prime-sde/ess binder.py), csv (the step table, whole
minutes and 0.1 °C, for typing in by hand).

The programme is rounded to the controller's resolution, split into chained programmes
when one holds too few steps, encoded, read back by a strict reader that checks the
controller's limits, and re-simulated: the coverage of the exported programme is printed
next to the coverage of the step table. Region and model come from the table's
# key: value lines (working_lo_c, working_hi_c, tau_s, dt0_c, ...) or
from the options.

Writes --out (default: beside the table, STEM.<controller>.json or .csv; STEM.typed.csv
for csv).
Exit codes: 0 written, and the export covers what the table covers and meets every limit
the table meets; 1 written, but the rounding cost coverage or broke a limit (the end
temperature, the device range: read the *** lines); 2 bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..export import CONTROLLER_KEYS
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "export",
        help="write a step table as a chamber-controller programme (ESPEC, Watlow, Binder)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("steps", metavar="STEPS.csv", help="step table (e.g. from schedsyn plan)")
    p.add_argument(
        "--controller", required=True, choices=CONTROLLER_KEYS, help="controller to write for"
    )
    p.add_argument(
        "--out", default=None, help="output file (default: beside STEPS.csv, named after it)"
    )
    add_check_options(p)
    p.add_argument(
        "--first-programme",
        type=int,
        default=1,
        help="number of the first programme written (default 1; the next parts follow)",
    )
    p.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="steps one programme holds, from your controller's manual (overrides the "
        "built-in figure)",
    )
    p.add_argument(
        "--programmes",
        type=int,
        default=None,
        help="programmes the controller stores (overrides the built-in figure)",
    )
    p.add_argument(
        "--end-mode",
        default=None,
        help="end mode of the last programme (P-300: STANDBY, OFF, CONSTANT; F4T: hold, user, off)",
    )
    p.add_argument(
        "--name", default=None, help="programme name on the controller (default: experiment)"
    )
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def add_check_options(p: argparse.ArgumentParser) -> None:
    """Region and model of the re-simulation (default: the table's metadata)."""
    p.add_argument(
        "--region",
        nargs=2,
        type=float,
        default=None,
        metavar=("LO_C", "HI_C"),
        help="working region, °C (default: the table's working_lo_c / working_hi_c lines)",
    )
    p.add_argument(
        "--tau-s", type=float, default=None, help="device time constant, s (default: table, 2400)"
    )
    p.add_argument(
        "--dt0-c", type=float, default=None, help="self-heating offset, °C (default: table, 3.0)"
    )
    p.add_argument(
        "--levels", type=int, default=None, help="distinct gradient levels (default: table, 6)"
    )
    p.add_argument(
        "--delta-c-per-min",
        type=float,
        default=None,
        help="minimum gradient difference between levels, °C/min (default: table, 0.05)",
    )


def check_for(args: argparse.Namespace, table):
    """The coverage check from the options, else the table's metadata."""
    from ..export import check_from_meta

    return check_from_meta(
        table.meta,
        region=None if args.region is None else (args.region[0], args.region[1]),
        tau_s=args.tau_s,
        dt0_c=args.dt0_c,
        levels_required=args.levels,
        delta_c_per_min=args.delta_c_per_min,
        limits=table.limits,
        source=str(table.path),
    )


def export_name(table) -> str:
    """The experiment's name: its metadata, else the folder of a ``steps.csv`` (as
    written by plan/campaign), else the file's stem."""
    import re

    path = Path(table.path)
    name = table.meta.get("experiment") or (path.parent.name if path.stem == "steps" else "")
    name = name or path.stem or "schedsyn"
    return re.sub(r"[^A-Za-z0-9_\-]", "_", name)[:64] or "schedsyn"


def run(args: argparse.Namespace) -> int:
    from .. import __version__
    from ..export import (
        ExportSettings,
        default_export_path,
        export_programme,
        planned_for_notes,
        read_step_table,
        write_export,
    )

    table = read_step_table(args.steps)
    check = check_for(args, table)
    settings = ExportSettings(
        controller=args.controller,
        first_programme=args.first_programme,
        max_steps=args.max_steps,
        programmes=args.programmes,
        end_mode=args.end_mode,
        name=args.name if args.name is not None else export_name(table),
    )
    out = Path(args.out) if args.out else default_export_path(args.steps, args.controller)
    if out.exists() and out.is_dir():
        from ..errors import ParameterError

        raise ParameterError(f"--out {out} is a directory; give a file name")
    planned_for = planned_for_notes(table.meta, table.programme, str(args.steps))
    header = {
        "schedsyn_version": __version__,
        "source": str(args.steps),
        "source_sha256": table.sha256,
        "experiment": table.meta.get("experiment", ""),
        # the file carries it too: it may be passed on without this summary
        **({"planned_for": planned_for} if planned_for else {}),
    }
    result = export_programme(
        table.programme, settings, limits=table.limits, check=check, header=header
    )
    write_export(out, result, [args.steps])
    for note in planned_for:
        print(f"*** {note} ***")
    print("\n".join(result.summary()))
    print(f"wrote {out}")
    return 0 if result.faithful else 1
