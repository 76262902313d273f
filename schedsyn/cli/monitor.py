"""``schedsyn monitor LOG.csv PLAN_DIR``: a run in progress against its plan.

Reports the elapsed time, per-bin passes and distinct gradient levels measured so far,
tau and dT0 identified from the log so far, the gap between measured and planned
temperature, and the coverage the run reaches if the plan goes on unchanged (predicted
with the identified model from the estimated state). Writes ``monitor.json``,
``bins.csv`` (per-bin status), ``series.csv`` (per log row) and ``monitor.png``.
A log that does not belong to the plan is refused before anything is written.
"""

from __future__ import annotations

import argparse

from ..io import write_frame_atomic, write_json_atomic
from ..logs import read_log
from ..monitor import json_safe, monitor_run, read_plan_dir
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "monitor",
        help="watch a run in progress: coverage so far, identified model, predicted coverage",
        description=_common.plain(__doc__),
    )
    p.add_argument("log", metavar="LOG.csv", help="log of the run so far (time_s, t_int_c, ...)")
    p.add_argument("plan", metavar="PLAN_DIR", help="the plan's folder (steps.csv, plan.json)")
    p.add_argument("--out", default=None, help="output directory (default out/monitor)")
    p.add_argument("--no-plots", action="store_true", help="skip monitor.png")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    plan = read_plan_dir(args.plan)
    log = read_log(args.log, live=True)
    if not log.report.clean or log.report.warnings:
        # blank readings and gaps are not counted as passes: say where they are
        _common.stderr(f"log {log.source}: {log.report.summary()}")
    report = monitor_run(log, plan)
    out = _common.out_dir(args.out, "out/monitor")
    inputs = [args.log, plan.path / "steps.csv", plan.path / "plan.json"]
    doc = {**report.to_json_dict(), "log_readings": _common.log_record(log)}
    write_json_atomic(out / "monitor.json", json_safe(doc), inputs)
    write_frame_atomic(out / "bins.csv", report.to_frame(), inputs)
    write_frame_atomic(out / "series.csv", report.series, inputs)
    written = ["monitor.json", "bins.csv", "series.csv"]
    if not args.no_plots:
        from .. import loopplots, plots

        axes = loopplots.monitor_panels(report, suptitle=f"{args.log} against {args.plan}")
        plots.save_figure(axes[0], out / "monitor.png", inputs)
        written.append("monitor.png")
    print(report.summary())
    print(f"wrote {out}/" + ", ".join(written))
    return 0
