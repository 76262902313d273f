"""``schedsyn diagnose LOG.csv``: find where the model and a measured log disagree, name the
missing effect, write the augmented model (``DIR/model.json``) and plots."""

from __future__ import annotations

import argparse
import json
import sys

from ..discrepancy import DIAGNOSE_MAX_ROWS, DiagnoseSettings, diagnose
from ..io import write_frame_atomic, write_json_atomic
from ..logs import read_log, thin_log
from ..models_io import write_model
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="name the effect a measured log shows that the model "
        "lacks, and write the augmented model",
        description=__doc__,
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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    full = read_log(args.log, keep_extra=False)
    n_rows = full.n_rows
    # a long log is diagnosed on every k-th row (bounded memory); the full one is freed
    log, stride = thin_log(full, DIAGNOSE_MAX_ROWS)
    del full
    settings = DiagnoseSettings(
        fit_step_s=args.fit_step_s,
        effects=tuple(args.effects) if args.effects is not None else None,
    )
    d = diagnose(log, settings)
    out = _common.out_dir(args.out, "out/diagnose")
    inputs = [args.log]
    write_model(out / "model.json", d.model, inputs)
    write_json_atomic(out / "diagnosis.json", d.to_json_dict(), inputs)
    write_frame_atomic(out / "candidates.csv", d.to_frame(), inputs)
    write_frame_atomic(out / "residual_segments.csv", d.residuals_before.segments, inputs)
    write_frame_atomic(
        out / "residual_by_temperature.csv", d.residuals_before.by_temperature, inputs
    )
    written = [
        "model.json",
        "diagnosis.json",
        "candidates.csv",
        "residual_segments.csv",
        "residual_by_temperature.csv",
    ]
    if not args.no_plots:
        written += _plots(d, log, out, inputs, args.log)
    msg = sys.stderr if args.json else sys.stdout
    if stride > 1:
        print(
            f"note: the log has {n_rows} rows; diagnosed on every {stride}th row "
            f"({log.n_rows} rows)",
            file=msg,
        )
    if args.json:
        print(json.dumps(d.to_json_dict()))
    else:
        print(d.summary())
        print(
            d.to_frame()[["effect", "delta_bic_vs_none", "rms_c", "parameters"]].to_string(
                index=False, float_format=lambda v: f"{v:.4g}"
            )
        )
    print(f"wrote {out}/" + ", ".join(written), file=msg)
    return 0


def _plots(d, log, out, inputs, name) -> list[str]:
    from .. import plots
    from ..errors import SchedsynError
    from ..estimate import estimate_gradient

    plots.save_figure(
        plots.residual_plot(
            d.time_min,
            d.before_c - d.measured_c,
            d.after_c - d.measured_c,
            title=f"{name}: residuals, base vs {d.effect}",
            labels=("base model", f"with {d.effect}"),
        ),
        out / "residuals.png",
        inputs,
    )
    ax = plots._axes(None)
    try:  # the measured gradient from the Kalman smoother
        est = estimate_gradient(log)
        ok = log.finite
        plots.phase_plot(
            est.t_est_c[ok], est.g_est_c_per_min[ok], ax=ax, label="measured", color="k"
        )
    except SchedsynError as exc:
        print(f"note: no measured phase portrait ({exc})", file=sys.stderr)
    plots.phase_plot(d.before_c, d.before_g_c_per_min, ax=ax, label="base model", color="tab:red")
    plots.phase_plot(
        d.after_c,
        d.after_g_c_per_min,
        ax=ax,
        label=f"with {d.effect}",
        color="tab:blue",
        title=f"{name}: phase portraits",
    )
    plots.save_figure(ax, out / "phase.png", inputs)
    return ["residuals.png", "phase.png"]
