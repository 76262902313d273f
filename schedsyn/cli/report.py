"""schedsyn report LOG.csv STEPS.csv: the report of a finished run, for filing.

Compares the measured log with the step table that was run (as schedsyn compare:
Kalman-smoothed gradient, the plan simulated through the model, the same coverage metric
on both) and writes one self-contained HTML page (printable to PDF): achieved vs planned
coverage, phase portraits and temperatures planned vs measured, the diagnosis
(--diagnosis DIR from schedsyn diagnose --out DIR) and the drift fit
(--fit DIR) where given, and what produced it: package versions, every input file
with its SHA-256, the command.

Region and model come from the step table's # key: value lines or the options.
Writes --out (default out/report): report.html, report.json (summary,
versions, input hashes) and coverage.csv. Exit codes: 0 written; 2 bad input.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import ParameterError
from . import _common
from .compare import add_start_option, start_temperature
from .estimate import add_estimator_options, print_log_report
from .export import add_check_options, check_for


def register(sub) -> None:
    p = sub.add_parser(
        "report",
        help="write the report of a finished run (planned vs measured, versions, hashes)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("log", metavar="LOG.csv", help="measured log (time_s, t_int_c, ...)")
    p.add_argument("steps", metavar="STEPS.csv", help="the step table that was run")
    p.add_argument("--diagnosis", default=None, metavar="DIR", help="schedsyn diagnose --out DIR")
    p.add_argument("--fit", default=None, metavar="DIR", help="output folder of the drift fit")
    p.add_argument("--out", default=None, help="output directory (default out/report)")
    add_check_options(p)
    add_estimator_options(p)
    add_start_option(p)
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..compare import compare_run
    from ..export import read_step_table
    from ..io import write_frame_atomic, write_json_atomic
    from ..logs import read_log
    from ..provenance import provenance
    from ..report import run_report
    from ..sheet import write_page

    for opt in ("diagnosis", "fit"):
        d = getattr(args, opt)
        if d is not None and not Path(d).is_dir():
            raise ParameterError(f"--{opt} {d} is not a folder; give the --out folder of that step")
    log = read_log(args.log)
    print_log_report(log)
    table = read_step_table(args.steps)
    check = check_for(args, table)
    t0_c, t0_source = start_temperature(args.t0_c, log, table.limits.t_init_c)
    cmp = compare_run(
        log,
        table.programme,
        check.params,
        grid=check.grid,
        levels_required=check.levels_required,
        delta_c_per_min=check.delta_c_per_min,
        method=args.method,
        chamber=args.chamber,
        q=args.q,
        r=args.r,
        t0_c=t0_c,
        t0_source=t0_source,
        plan_t0_c=table.limits.t_init_c,
    )
    prov = provenance(
        {"log": args.log, "step table": args.steps, "diagnosis": args.diagnosis, "fit": args.fit}
    )
    report = run_report(
        cmp,
        log_path=args.log,
        steps_path=args.steps,
        diagnosis_dir=args.diagnosis,
        fit_dir=args.fit,
        provenance=prov,
    )
    out = _common.out_dir(args.out, "out/report")
    inputs = [args.log, args.steps]
    write_page(out / "report.html", report.html, inputs)
    write_json_atomic(out / "report.json", report.summary, inputs)
    write_frame_atomic(out / "coverage.csv", report.to_frame(), inputs)
    print(cmp.summary())
    print(f"wrote {out}/report.html, report.json, coverage.csv")
    return 0
