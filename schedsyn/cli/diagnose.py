"""``schedsyn diagnose LOG.csv``: find where the model and a measured log disagree, name the
missing effect, write the augmented model (``DIR/model.json``) and plots.

Prints the fitted device model (tau and dT0 with their standard errors), the chosen effect
and its parameters, the RMS gap before and after, and the ranking of the candidates."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..discrepancy import DIAGNOSE_MAX_ROWS, DiagnoseSettings, diagnose
from ..io import strict_json, write_frame_atomic, write_json_atomic
from ..logs import read_log, thin_log
from ..models_io import write_model
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="name the effect a measured log shows that the model "
        "lacks, and write the augmented model",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "log", metavar="LOG.csv", help="measured log (time_s, t_int_c, tk_set_c [, tk_air_c])"
    )
    p.add_argument("--out", default=None, help="output directory (default out/diagnose)")
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object to stdout (messages go to stderr)",
    )
    p.add_argument(
        "--fit-step-s",
        type=float,
        default=None,
        help="averaging block of the fit, s (default: log length/1500, at most 20 s)",
    )
    p.add_argument(
        "--effects",
        nargs="+",
        default=None,
        metavar="EFFECT",
        help="candidates to try (default: the whole library)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


TABLES = (
    "model.json",
    "diagnosis.json",
    "candidates.csv",
    "residual_segments.csv",
    "residual_by_temperature.csv",
)
PLOTS = ("residuals.png", "phase.png")


def _pm(value: float, stderr: float | None, digits: str = ".4g") -> str:
    """``value ± stderr`` (the stderr left out when not identified)."""
    if stderr is None or not np.isfinite(stderr):
        return f"{value:{digits}} (uncertainty not identified)"
    return f"{value:{digits}} ± {stderr:.2g}"


def findings(d) -> list[str]:
    """The main finding in words: the fitted model with its uncertainties (the effect and
    its parameters follow in ``Diagnosis.summary()``)."""
    se = d.stderr
    lines = [
        f"fitted device model: tau {_pm(d.model.tau_s, se.get('tau_s'), '.1f')} s, "
        f"dT0 {_pm(d.model.dt0_c, se.get('dt0_c'), '.3f')} °C"
        + (" (with the effect below)" if d.effect != "none" else ""),
        # red team: a sensor reading 0.5 degC high came out as dT0 3.5 without a word
        "dT0 includes any constant offset of the temperature sensor (the log cannot tell "
        "them apart; a reference thermometer can)",
    ]
    if d.effect != "none":
        base = d.base_fit
        lines.append(
            f"base model alone: tau {_pm(base.values['tau_s'], base.stderr.get('tau_s'), '.1f')}"
            f" s, dT0 {_pm(base.values['dt0_c'], base.stderr.get('dt0_c'), '.3f')} °C"
        )
    if d.ambiguous_with:
        lines.append(f"cannot be told apart from: {', '.join(d.ambiguous_with)}")
    return lines


def run(args: argparse.Namespace) -> int:
    progress = _common.progress_of(args)
    names = TABLES + (() if args.no_plots else PLOTS)
    out = _common.output_dir(args.out, "out/diagnose", [args.log], names)
    full = read_log(args.log, keep_extra=False)
    _common.log_warnings(full)
    readings = _common.log_record(full)
    n_rows = full.n_rows
    # a long log is diagnosed on every k-th row (bounded memory); the full one is freed
    log, stride = thin_log(full, DIAGNOSE_MAX_ROWS)
    del full
    settings = DiagnoseSettings(
        fit_step_s=args.fit_step_s,
        effects=tuple(args.effects) if args.effects is not None else None,
    )
    progress("fitting the base model and every candidate effect")
    d = diagnose(log, settings)
    progress("writing the model, tables and plots")
    write_model(out.path("model.json"), d.model)
    doc = {**d.to_json_dict(), "log_readings": readings}
    write_json_atomic(out.path("diagnosis.json"), doc)
    write_frame_atomic(out.path("candidates.csv"), d.to_frame())
    write_frame_atomic(out.path("residual_segments.csv"), d.residuals_before.segments)
    write_frame_atomic(out.path("residual_by_temperature.csv"), d.residuals_before.by_temperature)
    if not args.no_plots:
        _plots(d, log, out, args.log)
    out.commit()
    wrote = f"wrote {out.target}/" + ", ".join(names)
    if stride > 1:  # on stdout with the findings; on stderr when stdout is the JSON
        note = (
            f"note: the log has {n_rows} rows; diagnosed on every {stride}th row "
            f"({log.n_rows} rows)"
        )
        if args.json:
            _common.stderr(note)
        else:
            print(note)
    if args.json:
        print(json.dumps(strict_json(doc), allow_nan=False))
        _common.stderr(wrote)
    else:
        _common.say(
            *findings(d),
            d.summary(),
            d.to_frame()[["effect", "delta_bic_vs_none", "rms_c", "parameters"]].to_string(
                index=False, float_format=lambda v: f"{v:.4g}"
            ),
            wrote,
        )
    return 0


def _plots(d, log, out, name) -> None:
    from .. import plots
    from ..errors import SchedsynError
    from ..estimate import estimate_gradient

    found = d.effect != "none"
    plots.save_figure(
        plots.residual_plot(
            d.time_min,
            d.before_c - d.measured_c,
            d.after_c - d.measured_c if found else None,
            title=f"{name}: residuals\n"
            + (f"base model vs with {d.effect}" if found else "base model (no effect found)")
            + f"; fitted tau {d.model.tau_s:.0f} s, dT0 {d.model.dt0_c:.2f} °C",
            labels=("base model", f"with {d.effect}"),
        ),
        out.path("residuals.png"),
    )
    ax = plots._axes(None, figsize=(8.5, 5))
    try:  # the measured gradient from the Kalman smoother
        from ..compare import resample_run

        est = estimate_gradient(log)
        dense = resample_run(log, est)  # NaN inside logging gaps: no line across them
        plots.phase_plot(dense.t_c, dense.g_c_per_min, ax=ax, label="measured", color="k")
    except SchedsynError as exc:
        _common.stderr(f"note: no measured phase portrait ({exc})")
    # NaN inserted at logging gaps: no line across them
    _, before_c, before_g, after_c, after_g = plots._break_at_gaps(
        d.time_min, d.before_c, d.before_g_c_per_min, d.after_c, d.after_g_c_per_min
    )
    plots.phase_plot(before_c, before_g, ax=ax, label="base model", color="tab:red")
    plots.phase_plot(
        after_c,
        after_g,
        ax=ax,
        label=f"with {d.effect}",
        color="tab:blue",
        title=f"{name}: phase portraits\n(fitted tau {d.model.tau_s:.0f} s, "
        f"dT0 {d.model.dt0_c:.2f} °C)",
    )
    plots.save_figure(ax, out.path("phase.png"))
