"""``schedsyn compare LOG.csv STEPS.csv``: a measured run against its plan.

Simulates the plan, estimates the run's gradient, overlays the phase trajectories,
plots measured and simulated temperature with the residual, and reports the coverage the
run achieved (same metric, on the estimated gradient) next to the planned coverage.
"""

from __future__ import annotations

import argparse

from ..compare import compare_run
from ..grid import BinGrid
from ..io import write_frame_atomic, write_json_atomic
from ..logs import read_log
from ..programme import read_steps
from . import _common
from .estimate import add_estimator_options, print_log_report


def register(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="compare a measured log with its plan (phase portraits, residual, achieved coverage)",
        description=__doc__,
    )
    p.add_argument("log", metavar="LOG.csv", help="measured log (time_s, t_int_c, ...)")
    p.add_argument("steps", metavar="STEPS.csv", help="the step table that was run")
    p.add_argument("--out", default=None, help="output directory (default out/compare)")
    add_estimator_options(p)
    _common.add_model_options(p)
    _common.add_region_option(p)
    _common.add_limit_options(p)
    p.add_argument("--levels", type=int, default=6, help="required distinct gradient levels")
    p.add_argument(
        "--delta-c-per-min",
        type=float,
        default=0.05,
        help="minimum gradient difference between levels, °C/min",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import plots

    params = _common.thermal_params(args)
    limits = _common.limits(args)
    log = read_log(args.log)
    print_log_report(log)
    programme = read_steps(args.steps, limits)
    lo, hi = args.region
    cmp = compare_run(
        log,
        programme,
        params,
        grid=BinGrid(lo, hi),
        levels_required=args.levels,
        delta_c_per_min=args.delta_c_per_min,
        method=args.method,
        chamber=args.chamber,
        q=args.q,
        r=args.r,
        t0_c=limits.t_init_c,
    )
    out = _common.out_dir(args.out, "out/compare")
    inputs = [args.log, args.steps]
    write_frame_atomic(out / "gradient.csv", cmp.estimate.to_frame(), inputs)
    write_frame_atomic(out / "compare.csv", cmp.to_frame(), inputs)
    write_frame_atomic(out / "coverage.csv", cmp.coverage_frame(), inputs)
    write_json_atomic(out / "summary.json", cmp.summary_dict(), inputs)
    region = (lo, hi)
    plots.save_figure(
        plots.phase_overlay_plot(
            cmp.planned.t_c,
            cmp.planned.g_c_per_min,
            cmp.run_dense.t_c,
            cmp.run_dense.g_c_per_min,
            region=region,
            title="phase portrait: measured over simulated",
        ),
        out / "phase_compare.png",
        inputs,
    )
    plots.save_figure(
        plots.temperature_compare_plot(
            cmp.log.time_min,
            cmp.log.t_int_c,
            cmp.simulated.t_c,
            title="internal temperature: measured vs simulated",
        ),
        out / "temperature_compare.png",
        inputs,
    )
    plots.save_figure(
        plots.coverage_compare_plot(cmp.planned_coverage, cmp.run_coverage),
        out / "coverage_compare.png",
        inputs,
    )
    axes = plots.compare_panels(cmp, region=region, suptitle=f"{args.log} vs plan {args.steps}")
    plots.save_figure(axes[0], out / "compare.png", inputs)
    print(cmp.estimate.summary())
    print(cmp.summary())
    print(
        f"wrote {out}/gradient.csv, compare.csv, coverage.csv, summary.json, "
        "phase_compare.png, temperature_compare.png, coverage_compare.png, compare.png"
    )
    return 0
