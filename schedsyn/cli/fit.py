"""``schedsyn fit LOG.csv --region LO HI``: fit the drift polynomial b(T, g) to a run.

Writes ``coefficients.json`` (coefficients in physical units with standard errors,
condition number, noise model, term selection, held-out check), ``compensation.csv``
(``t_c, g_c_per_min, drift_dph`` over the gradients the run reached), ``residuals.csv``
and the plots ``residuals_t.png``, ``residuals_g.png``, ``surface.png``.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..driftfit import (
    ESTIMATORS,
    OUTLIER_POLICIES,
    OUTLIER_SIGMAS,
    WEIGHTINGS,
    FitSettings,
    fit_drift,
)
from ..io import write_frame_atomic, write_json_atomic
from ..logs import read_log
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "fit",
        help="fit the drift polynomial b(T, g) to a log with drift_dph",
        description=_common.plain(__doc__),
    )
    p.add_argument("log", metavar="LOG.csv", help="measured log with t_int_c and drift_dph")
    p.add_argument(
        "--region",
        nargs=2,
        type=float,
        required=True,
        metavar=("LO_C", "HI_C"),
        help="approximation region to fit over, °C",
    )
    p.add_argument(
        "--terms",
        default="auto",
        help="auto (select by BIC under a white + random-walk noise model among t-only, "
        "g1, g2, full; default), a set name, or a comma list of terms from "
        "1,t,g,t2,tg,g2,t3,t2g,tg2,g3",
    )
    p.add_argument("--holdout", metavar="LOG2.csv", default=None, help="a second run to check on")
    p.add_argument(
        "--estimator",
        choices=ESTIMATORS,
        default="auto",
        help="gradient estimator (auto: model-based when the log has tk_set_c)",
    )
    p.add_argument(
        "--no-eiv",
        action="store_true",
        help="plain least squares on the estimates (no errors-in-variables correction)",
    )
    p.add_argument(
        "--weighting",
        choices=WEIGHTINGS,
        default="gls",
        help="gls (default): weight the samples by the fitted white-noise + bias-walk model; "
        "ols: every sample alike (for comparison)",
    )
    p.add_argument(
        "--outliers",
        choices=OUTLIER_POLICIES,
        default="drop",
        help="drop (default): leave out drift readings that jump away from their neighbours "
        f"and back (glitches, more than {OUTLIER_SIGMAS:g} robust sigma) and list them; keep: "
        "fit every reading",
    )
    p.add_argument(
        "--min-points-per-bin",
        type=int,
        default=5,
        help="samples every 1 °C bin of the region needs (default 5)",
    )
    p.add_argument(
        "--trust-drift-units",
        action="store_true",
        help="drift_dph really is in °/h: skip the check that refuses a drift too small and "
        "too quiet to be any gyro's (it reads like °/s)",
    )
    p.add_argument("--out", default=None, help="output directory (default out/fit)")
    _common.add_model_options(p, "identified from each log for the model-based smoother")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


#: The files ``schedsyn fit`` writes into ``--out``.
FIT_OUTPUTS = (
    "coefficients.json",
    "compensation.csv",
    "residuals.csv",
    "residuals_t.png",
    "residuals_g.png",
    "surface.png",
)


def run(args: argparse.Namespace) -> int:
    from .. import fitplots

    settings = FitSettings(
        terms=args.terms,
        eiv="none" if args.no_eiv else "als",
        weighting=args.weighting,
        estimator=args.estimator,
        min_points_per_bin=args.min_points_per_bin,
        outliers=args.outliers,
        check_drift_units=not args.trust_drift_units,
    )
    inputs = [args.log] + ([args.holdout] if args.holdout else [])
    # every output is checked against the inputs before any work and written into a
    # staging folder that moves into place as a whole (a refusal leaves nothing written)
    out = _common.output_dir(args.out, "out/fit", inputs, FIT_OUTPUTS)
    log = read_log(args.log)
    holdout = read_log(args.holdout) if args.holdout else None
    for one in (log, holdout):
        if one is not None:
            _common.log_warnings(one)
            if one.report.gaps_s:  # fitted as they are, but the user should know
                a, b = max(one.report.gaps_s, key=lambda gap: gap[1] - gap[0])
                _common.stderr(
                    f"note: {one.source}: {len(one.report.gaps_s)} gap(s) in the sampling, the "
                    f"longest {(b - a) / 60:.1f} min ({a:g} .. {b:g} s); the fit uses the "
                    "readings on either side"
                )
    # the smoother's model: as given (either option; the other at its default), else
    # identified from each log
    given = args.tau_s is not None or args.dt0_c is not None
    params = _common.thermal_params(args) if given else None
    fit = fit_drift(log, tuple(args.region), settings, params, holdout=holdout)
    doc = fit.to_json_dict()
    doc["log_readings"] = _common.log_record(log)
    write_json_atomic(out.path("coefficients.json"), doc)
    write_frame_atomic(out.path("compensation.csv"), fit.compensation_frame())
    write_frame_atomic(out.path("residuals.csv"), fit.residual_frame())
    fitplots.save_figure(
        fitplots.fit_residual_plot(fit, "t", title="residuals against temperature"),
        out.path("residuals_t.png"),
    )
    fitplots.save_figure(
        fitplots.fit_residual_plot(fit, "g", title="residuals against gradient"),
        out.path("residuals_g.png"),
    )
    fitplots.save_figure(fitplots.fit_surface_plot(fit), out.path("surface.png"))
    out.commit()
    for line in fit.summary_lines():
        print(line)
    print(f"wrote {out.target}/{', '.join(FIT_OUTPUTS)}")
    return 0


# -- hooks in `schedsyn simulate` (gyro log and the drift-fit design report) ----------------
def add_simulate_options(p: argparse.ArgumentParser) -> None:
    """``--gyro``, ``--log-out``, ``--log-sample-s``, ``--seed``, ``--approx`` of simulate."""
    p.add_argument(
        "--gyro",
        default=None,
        metavar="GYRO.toml",
        help="write a synthetic gyro log of this run ([gyro] table: drift polynomial, noise)",
    )
    p.add_argument(
        "--log-out",
        default=None,
        metavar="LOG.csv",
        help="where the gyro log goes (default OUT/log.csv; needs --gyro)",
    )
    p.add_argument("--log-sample-s", type=float, default=10.0, help="log sampling period, s")
    p.add_argument("--seed", type=int, default=0, help="seed of the gyro log's noise")
    p.add_argument(
        "--approx",
        nargs=2,
        type=float,
        default=None,
        metavar=("LO_C", "HI_C"),
        help="approximation region of the drift-fit design report, °C (default: the "
        "working region widened by 10 °C each side, within the device limits)",
    )


def simulate_hook(
    args, programme, params, limits, traj, region, out, inputs
) -> tuple[list[str], list[str]]:
    """Design report of the simulated run and, with ``--gyro``, its log, written into the
    command's output folder ``out`` (an :class:`~schedsyn.io.OutputDir`; ``--log-out``
    anywhere). Returns the names of the files written and the lines to print."""
    from ..design import DesignSpace, design_report
    from ..errors import ParameterError
    from ..gyro import gyro_log, load_gyro

    if args.log_out is not None and args.gyro is None:
        raise ParameterError("--log-out needs --gyro GYRO.toml (the gyro to simulate)")
    lo, hi = region
    approx = tuple(args.approx) if args.approx else DesignSpace.default_approx(lo, hi, limits)
    written: list[str] = []
    lines: list[str] = []
    space: DesignSpace | None = None
    try:
        space = DesignSpace(lo, hi, approx[0], approx[1], params, limits)
    except ParameterError as exc:
        if args.approx:  # the user's own request: an error
            raise
        lines.append(f"drift-fit design: not reported ({exc}); give --approx LO HI")
    else:
        report = design_report(traj.t_c, traj.g_c_per_min, space)
        write_frame_atomic(out.path("design.csv"), report.to_frame())
        lines.append(report.summary())
        written.append("design.csv")
    if args.gyro is not None:
        if getattr(args, "model", None) is not None:
            raise ParameterError(
                "--gyro simulates the first-order model (--tau-s, --dt0-c); drop --model"
            )
        gyro = load_gyro(args.gyro)
        frame = gyro_log(
            programme,
            gyro,
            params,
            sample_s=args.log_sample_s,
            seed=args.seed,
            t0_c=limits.t_init_c,
        )
        if args.log_out is not None:
            path = write_frame_atomic(args.log_out, frame, [*inputs, args.gyro])
        else:
            path = write_frame_atomic(out.path("log.csv"), frame)
            path = out.final("log.csv")
        lines.append(
            f"gyro log {path}: {len(frame)} rows every {args.log_sample_s:g} s, drift of "
            f"{gyro.name} (truth columns t_true_c, g_true_c_per_min, drift_true_dph, "
            "bias_walk_dph for checks)"
        )
        written.append(str(path))
        if space is not None:
            lines.append(_predicted_error_line(traj, space, gyro))
    return written, lines


def _predicted_error_line(traj, space, gyro) -> str:
    """What the fit of this run can achieve with this gyro's noise (1-min samples of the
    simulated trajectory: the white noise averages alike over a minute's readings)."""
    from ..design import predicted_fit_error
    from ..errors import ParameterError

    time_min = np.arange(0.0, float(traj.time_min[-1]) + 1e-9, 1.0)
    try:
        pred = predicted_fit_error(
            time_min,
            np.interp(time_min, traj.time_min, traj.t_c),
            np.interp(time_min, traj.time_min, traj.g_c_per_min),
            space,
            gyro.white_noise_dph_per_rt_hz,
            gyro.bias_walk_dph_per_rt_h,
        )
    except ParameterError as exc:
        return f"predicted drift-fit error: not reported ({exc})"
    return pred.summary()
