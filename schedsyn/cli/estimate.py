"""``schedsyn estimate LOG.csv``: Kalman-smoothed gradient of a measured run, and its plots.

Logs of any length: the log is read and filtered in chunks (memory grows with the log at
~32 bytes per row plus ~48 per row written), with progress on stderr; ``--every S``
writes one row every S seconds.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..compare import resample_run
from ..errors import ParameterError
from ..estimate import (
    SENSOR_TAU_MAX_S,
    GradientEstimate,
    estimate_gradient,
    estimate_gradient_model,
)
from ..io import write_atomic
from ..logs import read_log
from . import _common
from ._progress import StderrProgress

#: Rows of gradient.csv formatted at a time.
WRITE_ROWS = 200_000
#: The plots draw at most about this many rows of the estimate.
PLOT_ROWS = 20_000


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
    p.add_argument(
        "--every",
        type=float,
        default=None,
        metavar="S",
        help="write one row every S seconds to gradient.csv (default: every log row; "
        "every row is filtered either way)",
    )
    p.add_argument(
        "--order",
        type=int,
        choices=(2, 3),
        default=None,
        help="kinematic model: 3 = the gradient's rate a random walk (default; smooth "
        "gradients that bend where the chamber changes rate), 2 = the gradient a random walk",
    )
    p.add_argument(
        "--sensor-tau-s",
        type=float,
        default=0.0,
        metavar="S",
        help="the temperature sensor's own time constant, s (kinematic estimator, order 3): "
        "T and g are then the device's, T = Ts + S dTs/dt (default 0: the readings are the "
        "device's temperature; schedsyn diagnose names such a lag second_time_constant)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    p.set_defaults(func=run)


def write_gradient_csv(path: Path, est: GradientEstimate, inputs, progress=None) -> None:
    """``est.to_frame()`` as CSV, formatted ``WRITE_ROWS`` rows at a time (atomically)."""

    def writer(tmp: Path) -> None:
        with tmp.open("w", newline="") as fh:
            for lo in range(0, est.n_rows, WRITE_ROWS):
                hi = min(lo + WRITE_ROWS, est.n_rows)
                est.take(slice(lo, hi)).to_frame().to_csv(fh, header=lo == 0, index=False)
                if progress is not None:
                    progress("writing", hi, est.n_rows)

    write_atomic(path, writer, inputs)


def _check_options(args: argparse.Namespace) -> None:
    """Refuse options the chosen estimator would ignore (red team: --tau-s and --dt0-c
    with the kinematic default, --order with --method model, were dropped without a word)."""
    if not 0.0 <= args.sensor_tau_s <= SENSOR_TAU_MAX_S:
        raise ParameterError(
            f"--sensor-tau-s {args.sensor_tau_s:g}: a temperature sensor's own lag is 0 .. "
            f"{SENSOR_TAU_MAX_S:g} s (seconds to minutes); a lag that long is the device's own "
            "(--tau-s with --method model): check the unit (seconds)"
        )
    if args.method == "model":
        if args.sensor_tau_s:
            raise ParameterError(
                "--sensor-tau-s is for the kinematic estimator; the model-based one would need "
                "the sensor in its thermal model (drop --method model)"
            )
        if args.order is not None:
            raise ParameterError(
                f"--order {args.order} is the kinematic estimator's model; the model-based one "
                "uses the thermal model (drop --order, or --method model)"
            )
        return
    given = [f"--{n.replace('_', '-')}" for n in ("tau_s", "dt0_c") if getattr(args, n) is not None]
    if args.chamber != "tk_set_c":
        given.append(f"--chamber {args.chamber}")
    if given:
        raise ParameterError(
            f"{' and '.join(given)} {'is' if len(given) == 1 else 'are'} for the model-based "
            "estimator; the kinematic one (the default) uses no thermal model and would ignore "
            f"{'it' if len(given) == 1 else 'them'}: add --method model, or drop "
            f"{'it' if len(given) == 1 else 'them'}"
        )


def run(args: argparse.Namespace) -> int:
    from .. import plots

    if args.region is not None and not args.region[0] < args.region[1]:
        raise ParameterError(
            f"--region {args.region[0]:g} {args.region[1]:g}: LO must be below HI (°C); "
            f"give the working region as --region {min(args.region):g} {max(args.region):g}"
        )
    _check_options(args)
    names = ("gradient.csv", "phase.png", "gradient.png")
    out = _common.output_dir(args.out, "out/estimate", [args.log], names)
    progress = None if args.quiet else StderrProgress("estimate")
    log = read_log(args.log, keep_extra=False, progress=progress)
    print_log_report(log)
    if args.method == "model":
        params = _common.thermal_params(args)
        est = estimate_gradient_model(
            log,
            params,
            chamber=args.chamber,
            q=args.q,
            r=args.r,
            every_s=args.every,
            progress=progress,
        )
    else:
        est = estimate_gradient(
            log,
            q=args.q,
            r=args.r,
            every_s=args.every,
            progress=progress,
            order=3 if args.order is None else args.order,
            sensor_tau_s=args.sensor_tau_s,
        )
    write_gradient_csv(out.path("gradient.csv"), est, [args.log], progress)
    if progress is not None:
        progress.close()
    for w in est.warnings():
        _common.stderr(f"warning: {log.source}: {w}")
    region = tuple(args.region) if args.region else None
    # plots of at most ~PLOT_ROWS rows (the smoothed estimate changes slowly)
    view = est.take(slice(None, None, max(1, math.ceil(est.n_rows / PLOT_ROWS))))
    dense = resample_run(log, view)  # the same estimate, with the line broken at gaps
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
        plots.gradient_plot(view, title="estimated gradient"), out.path("gradient.png")
    )
    out.commit()
    every = "" if args.every is None else f", one every {args.every:g} s"
    _common.say(
        est.summary(),
        f"wrote {out.target}/gradient.csv ({est.n_rows} rows{every}), phase.png, gradient.png",
    )
    return 0
