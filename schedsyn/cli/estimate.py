"""``schedsyn estimate LOG.csv``: Kalman-smoothed gradient of a measured run, and its plots."""

from __future__ import annotations

import argparse

from ..compare import resample_run
from ..estimate import estimate_gradient, estimate_gradient_model
from ..io import write_frame_atomic
from ..logs import read_log
from . import _common


def add_estimator_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--q",
        type=float,
        default=None,
        help="gradient random-walk density, (°C/min²)²/min (default: maximum likelihood)",
    )
    p.add_argument(
        "--r",
        type=float,
        default=None,
        help="measurement variance, °C² (default: maximum likelihood, at least "
        "the quantisation step²/12)",
    )
    p.add_argument(
        "--method",
        choices=("kinematic", "model"),
        default="kinematic",
        help="kinematic: (T, g) random walk, no model (default); model: thermal "
        "model driven by the logged chamber plus a random-walk correction",
    )
    p.add_argument(
        "--chamber",
        choices=("tk_set_c", "tk_air_c"),
        default="tk_set_c",
        help="chamber column that drives the model-based estimate (default tk_set_c)",
    )


def print_log_report(log) -> None:
    _common.say(f"log {log.source}: {log.report.summary()}")


def register(sub) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate the internal-temperature gradient of a measured log (Kalman smoother)",
        description=_common.plain(__doc__),
    )
    p.add_argument("log", metavar="LOG.csv", help="measured log (time_s, t_int_c, ...)")
    p.add_argument("--out", default=None, help="output directory (default out/estimate)")
    add_estimator_options(p)
    _common.add_model_options(p)
    p.add_argument(
        "--region",
        nargs=2,
        type=float,
        metavar=("LO_C", "HI_C"),
        default=None,
        help="working region to shade in the phase portrait, °C",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import plots

    names = ("gradient.csv", "phase.png", "gradient.png")
    out = _common.output_dir(args.out, "out/estimate", [args.log], names)
    log = read_log(args.log)
    print_log_report(log)
    if args.method == "model":
        params = _common.thermal_params(args)
        est = estimate_gradient_model(log, params, chamber=args.chamber, q=args.q, r=args.r)
    else:
        est = estimate_gradient(log, q=args.q, r=args.r)
    write_frame_atomic(out.path("gradient.csv"), est.to_frame())
    region = tuple(args.region) if args.region else None
    dense = resample_run(log, est)  # the same estimate, with the line broken at gaps
    plots.save_figure(
        plots.phase_plot(
            dense.t_c,
            dense.g_c_per_min,
            region=region,
            color="tab:red",
            label="measured (smoothed)",
            title=f"measured phase portrait ({log.source})",
        ),
        out.path("phase.png"),
    )
    plots.save_figure(
        plots.gradient_plot(est, title="estimated gradient"), out.path("gradient.png")
    )
    out.commit()
    _common.say(est.summary(), f"wrote {out.target}/" + ", ".join(names))
    return 0
