"""``schedsyn replan LOG.csv PLAN_DIR --at-min M``: re-plan the rest of a run in progress.

From the log up to minute ``M``: the steps executed so far, the chamber and device state
at ``M``, tau and dT0 (and an effect, where it is material) identified from the log, and
the gradient levels measured so far in each bin. The rest of the run is planned with the
identified model, requiring only the levels still missing (new ones ``delta`` away from
the measured ones) and ending at 20 °C within the plan's time limit. The new steps begin
where the sweep in progress has left the region (the plan runs on until then). If the
plan's own rest is predicted to complete the region, or nothing better fits, it is kept
unchanged (``--always-replan`` asks the planner anyway). An incomplete new rest that
does better than the plan unchanged is taken, unless ``--only-if-complete`` or below
``--min-coverage SHARE`` (for an early re-plan, whose model has seen little of the run: a
rest far from complete chosen on it can spend time a later, better-informed re-plan
would use better; the closed loop takes rests predicted to cover 90 % before minute 60).

Writes ``--out DIR`` (default ``out/replan``), itself a plan folder, so the run can be
re-planned again later: ``steps.csv`` (the whole run: the executed steps, then the new
ones), ``plan.json``, ``replan.json`` (what was identified, what is missing, whether the
rest completes the region and by how much it falls short) and ``bins.csv`` (per bin).

Exit codes: 0 the whole run is predicted to complete every bin, by a fit that pins the
device down; 1 it is not, or the fit does not pin the device down yet (a *** line says
so; the files are written, the short bins listed); 2 bad input (``M`` beyond the log or
the plan or not a whole minute, a gap in the log at ``M``, a log of another plan),
nothing written.
"""

from __future__ import annotations

import argparse
import time

from ..errors import ParameterError
from ..logs import read_log
from ..monitor import read_plan_dir
from ..replan import replan_run, write_replan_dir
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "replan",
        help="re-plan the rest of a run in progress from minute M (identified model)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("log", metavar="LOG.csv", help="log of the run (time_s, t_int_c, tk_set_c, ...)")
    p.add_argument("plan", metavar="PLAN_DIR", help="the plan being run (steps.csv, plan.json)")
    p.add_argument(
        "--at-min",
        type=float,
        required=True,
        metavar="M",
        help="re-plan from this minute of the run (a whole minute the log has reached)",
    )
    p.add_argument("--out", default=None, help="output plan folder (default out/replan)")
    p.add_argument(
        "--always-replan",
        action="store_true",
        help="plan new steps even when the plan's own rest is predicted to complete",
    )
    p.add_argument(
        "--only-if-complete",
        action="store_true",
        help="take new steps only when the whole run they make is predicted complete "
        "(otherwise the plan goes on unchanged)",
    )
    p.add_argument(
        "--min-coverage",
        type=float,
        default=0.0,
        metavar="SHARE",
        help="take incomplete new steps only when the whole run they make is predicted to "
        "cover at least this share of the bins, 0 to 1 (default 0: the better run)",
    )
    p.add_argument(
        "--lead-min",
        type=float,
        default=0.0,
        metavar="N",
        help="no new step before minute M + N: the minutes the re-plan (seconds to several "
        "minutes; a *** line says when it took longer) and loading the programme take while "
        "the chamber runs on with the plan; the planner then stops with what it has after "
        "60%% of N (default 0: no new step is held back, no time budget)",
    )
    p.add_argument(
        "--no-effect",
        action="store_true",
        help="identify tau and dT0 only (skip the search for other effects)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..campaign import stderr_progress

    if not 0.0 <= args.min_coverage <= 1.0:
        raise ParameterError(
            f"--min-coverage is a share of the bins, 0 to 1, got {args.min_coverage:g} "
            "(for 90 % write 0.9)"
        )
    out = _common.out_dir(args.out, "out/replan")
    plan = read_plan_dir(args.plan)
    if out.resolve() == plan.path.resolve():
        raise ParameterError(
            f"--out {out} is the plan folder being run (an input); write the re-plan to "
            "another folder"
        )
    log = read_log(args.log, live=True)
    _common.log_warnings(log)
    progress = None
    if not args.quiet:
        tic = time.perf_counter()

        def progress(message: str) -> None:
            stderr_progress(f"replan [{time.perf_counter() - tic:6.1f} s] {message}")

    result = replan_run(
        log,
        plan,
        args.at_min,
        find_effect=not args.no_effect,
        keep_if_complete=not args.always_replan,
        new_only_if_complete=args.only_if_complete,
        new_min_coverage=args.min_coverage,
        lead_min=args.lead_min,
        progress=progress,
    )
    inputs = [args.log, plan.path / "steps.csv", plan.path / "plan.json"]
    write_replan_dir(out, result, inputs, {"log_readings": _common.log_record(log)})
    print(result.summary())
    print(f"wrote {out}/steps.csv, plan.json, replan.json, bins.csv")
    # complete, and from a fit that pins the device down: a guess is not a promise
    return 0 if result.trusted_complete else 1
