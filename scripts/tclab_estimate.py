"""Run the gradient estimator on the real TCLab logs in tests/data/tclab/.

Each file (columns Time, T1, T2, Q1, Q2) becomes a log with time_s = Time and
t_int_c = T1 (the heated thermistor, quantised in ~0.32 degC steps). Prints one row per
file: detected quantisation, fitted r against step^2/12, fitted q, median gradient std,
largest |smoothed - reading|, and the spread of a plain finite difference around the
smoothed gradient; writes docs/img/estimate_tclab.png (the step test) unless --no-plot.

A second table tries the model-based estimator with a crude "chamber" built from the
heater: Tk = T1[0] + 0.78 * Q1 (0.78 degC per % from the step test's rise of ~39 degC at
50 %), tau 180 s, dT0 0, and compares its likelihood and gradient with the kinematic one.

Run: python scripts/tclab_estimate.py [DIR] [--no-plot]
"""

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.estimate import estimate_gradient, estimate_gradient_model, finite_difference_gradient
from schedsyn.logs import log_from_frame
from schedsyn.params import ThermalParams

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "tests" / "data" / "tclab"


HEATER_GAIN_C_PER_PCT = 0.78
HEATER_MODEL = ThermalParams(tau_s=180.0, dt0_c=0.0)


def tclab_log(path: Path, with_heater: bool = False):
    raw = pd.read_csv(path)
    cols = {"time_s": raw["Time"], "t_int_c": raw["T1"]}
    if with_heater:
        cols["tk_set_c"] = raw["T1"].iloc[0] + HEATER_GAIN_C_PER_PCT * raw["Q1"]
    return log_from_frame(pd.DataFrame(cols), source=path.name)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", nargs="?", default=str(DEFAULT))
    ap.add_argument("--no-plot", action="store_true")
    args = ap.parse_args()
    rows = []
    for path in sorted(Path(args.dir).glob("*.csv")):
        log = tclab_log(path)
        est = estimate_gradient(log)
        fd = finite_difference_gradient(log.time_s, log.t_int_c)
        step = est.noise.quant_c
        rows.append(
            {
                "file": path.name,
                "rows": log.n_rows,
                "quant_c": round(step, 3),
                "r_over_quant2_12": est.r / (step**2 / 12) if step else float("nan"),
                "q": est.q,
                "median_g_std_c_per_min": float(np.median(est.g_std_c_per_min)),
                "max_abs_t_resid_c": float(np.max(np.abs(est.t_est_c - log.t_int_c))),
                "fd_spread_c_per_min": float(np.std(fd - est.g_est_c_per_min)),
                "g_range_c_per_min": f"{est.g_est_c_per_min.min():.1f} .. "
                f"{est.g_est_c_per_min.max():.1f}",
            }
        )
    table = pd.DataFrame(rows)
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    rows = []
    for path in sorted(Path(args.dir).glob("*.csv")):
        log = tclab_log(path, with_heater=True)
        kin = estimate_gradient(log)
        mod = estimate_gradient_model(log, HEATER_MODEL)
        rows.append(
            {
                "file": path.name,
                "m2ll_kinematic": kin.minus2_log_likelihood,
                "m2ll_model": mod.minus2_log_likelihood,
                "q_kinematic": kin.q,
                "q_model": mod.q,
                "g_std_kinematic": float(np.median(kin.g_std_c_per_min)),
                "g_std_model": float(np.median(mod.g_std_c_per_min)),
                "rms_g_difference": float(
                    np.sqrt(np.mean((kin.g_est_c_per_min - mod.g_est_c_per_min) ** 2))
                ),
            }
        )
    print("\nmodel-based with Tk = T1[0] + 0.78 Q1, tau 180 s (g in degC/min):")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(pd.DataFrame(rows).to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    if not args.no_plot:
        from schedsyn import plots

        log = tclab_log(Path(args.dir) / "tclab_step_test.csv")
        est = estimate_gradient(log)
        ax = plots.gradient_plot(est, title="TCLab step test (real data, T1 quantised 0.32 °C)")
        fd = finite_difference_gradient(log.time_s, log.t_int_c)
        ax.plot(log.time_min, fd, color="0.6", lw=0.4, zorder=0, label="finite difference")
        ax.set_ylim(-3, 16)
        ax.legend(loc="upper right")
        out = plots.save_figure(ax, ROOT / "docs" / "img" / "estimate_tclab.png")
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
