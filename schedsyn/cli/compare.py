"""``schedsyn compare LOG.csv STEPS.csv``: a measured run against its plan.

Simulates the plan, estimates the run's gradient, overlays the phase trajectories,
plots measured and simulated temperature with the residual, and reports the coverage the
run achieved (same metric, on the estimated gradient) next to the planned coverage.
The working region, the model and the coverage requirement are the step table's (its
metadata) unless given; a table that records no working region needs --region.
"""

from __future__ import annotations

import argparse

from ..compare import compare_run
from ..grid import BinGrid
from ..io import write_frame_atomic, write_json_atomic
from ..logs import read_log
from ..programme import read_step_meta, read_steps
from . import _common
from .estimate import add_estimator_options, print_log_report


def register(sub) -> None:
    p = sub.add_parser(
        "compare",
        help="compare a measured log with its plan (phase portraits, residual, achieved coverage)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("log", metavar="LOG.csv", help="measured log (time_s, t_int_c, ...)")
    p.add_argument("steps", metavar="STEPS.csv", help="the step table that was run")
    p.add_argument("--out", default=None, help="output directory (default out/compare)")
    add_estimator_options(p)
    _common.add_model_options(p, default_from="the step table's")
    _common.add_region_option(p)
    _common.add_limit_options(p)
    _common.add_coverage_options(p)
    add_start_option(p)
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def add_start_option(p: argparse.ArgumentParser) -> None:
    """``--t0-c`` (compare, report): where the plan's simulation starts."""
    p.add_argument(
        "--t0-c",
        default=None,
        metavar="T0_C|log",
        help="the device's temperature at the programme's start, °C, that the simulation "
        "begins from, or 'log' for the log's own start (default: the step table's "
        "t_init_c, the start the plan assumed)",
    )


def start_temperature(value: str | None, log, default_c: float) -> tuple[float, str]:
    """``--t0-c``: a number, 'log' (:func:`schedsyn.compare.log_start_c`), or the plan's
    start temperature; and where it came from."""
    from ..compare import log_start_c
    from ..errors import ParameterError

    if value is None:
        return default_c, "the plan's start"
    if value.strip().lower() == "log":
        return log_start_c(log), "the log's own start"
    try:
        t0 = float(value)
    except ValueError:
        raise ParameterError(
            f"--t0-c must be a temperature in °C or 'log', got {value!r}"
        ) from None
    if not -100.0 <= t0 <= 200.0:
        raise ParameterError(f"--t0-c must be a temperature in -100 .. 200 °C, got {value!r}")
    return t0, "given by --t0-c"


NAMES = (
    "gradient.csv",
    "compare.csv",
    "coverage.csv",
    "summary.json",
    "phase_compare.png",
    "temperature_compare.png",
    "coverage_compare.png",
    "compare.png",
)


def run(args: argparse.Namespace) -> int:
    from .. import plots

    progress = _common.progress_of(args)
    meta = read_step_meta(args.steps)
    limits = _common.limits(args, meta.limits() if meta is not None else None)
    programme = read_steps(args.steps, limits)
    lo, hi = _common.region_from_table(args, programme.meta, args.steps)
    levels, delta = _common.coverage_settings(args, programme.meta)
    params, source = _common.model_from_table(args, programme.meta)
    recorded = programme.meta.model_json() if programme.meta is not None else None
    if recorded is not None and recorded.get("effect", "none") != "none":
        _common.stderr(
            f"note: {args.steps} was planned with the augmented model "
            f"{recorded.get('effect')}; compare simulates the plan with its base model "
            "(tau, dT0)"
        )
    out = _common.output_dir(args.out, "out/compare", [args.log, args.steps], NAMES)
    log = read_log(args.log)
    t0_c, t0_source = start_temperature(args.t0_c, log, limits.t_init_c)
    print_log_report(log)
    progress("estimating the run's gradient and simulating the plan")
    cmp = compare_run(
        log,
        programme,
        params,
        grid=BinGrid(lo, hi),
        levels_required=levels,
        delta_c_per_min=delta,
        method=args.method,
        chamber=args.chamber,
        q=args.q,
        r=args.r,
        t0_c=t0_c,
        t0_source=t0_source,
        plan_t0_c=limits.t_init_c,
    )
    progress("writing tables and plots")
    write_frame_atomic(out.path("gradient.csv"), cmp.estimate.to_frame())
    write_frame_atomic(out.path("compare.csv"), cmp.to_frame())
    write_frame_atomic(out.path("coverage.csv"), cmp.coverage_frame())
    write_json_atomic(out.path("summary.json"), cmp.summary_dict())
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
        out.path("phase_compare.png"),
    )
    plots.save_figure(
        plots.temperature_compare_plot(
            cmp.log.time_min,
            cmp.log.t_int_c,
            cmp.simulated.t_c,
            title="internal temperature: measured vs simulated",
        ),
        out.path("temperature_compare.png"),
    )
    plots.save_figure(
        plots.coverage_compare_plot(cmp.planned_coverage, cmp.run_coverage),
        out.path("coverage_compare.png"),
    )
    axes = plots.compare_panels(
        cmp,
        region=region,
        suptitle=f"{args.log} vs plan {args.steps} (tau {params.tau_s:g} s, "
        f"dT0 {params.dt0_c:g} °C)",
    )
    plots.save_figure(axes[0], out.path("compare.png"))
    out.commit()
    region_src = "given" if args.region is not None else "from the step table"
    _common.say(
        f"plan model: tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C ({source}); working "
        f"region [{lo:g}, {hi:g}] °C ({region_src}); simulated from {t0_c:.2f} °C "
        f"({t0_source})",
        cmp.estimate.summary(),
        cmp.summary(),
        f"wrote {out.target}/" + ", ".join(NAMES),
    )
    return 0
