"""Run `diagnose` on the real TCLab logs in tests/data/tclab/ (see its README).

Mapping: time_s = Time, t_int_c = T1 (quantised 0.32 degC), and the heater acts as a
pseudo chamber setpoint tk_set_c = Ta + K * Q1 with Ta = T1 at t = 0 and the gain K
(degC per % heater) fitted per file with the base model (tau scan, K, dT0, T0 by linear
least squares), so the base model is the best first-order lag of T1 on Q1. No air
channel. Real time (tau ~ 2-3 min); no stretching is needed, the diagnosis scales its
starting guesses with the fitted tau.

    python scripts/tclab_diagnose.py [DIR] [--out out/tclab_diagnose]

Prints one row per file and writes DIR_OUT/tclab_diagnose.csv.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.discrepancy import DiagnoseSettings, diagnose, setpoint_programme
from schedsyn.effects import LinearEffectModel
from schedsyn.logs import log_from_frame
from schedsyn.model import affine_response

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "tests" / "data" / "tclab"
#: 5 s blocks (tau ~ 150 s); the pseudo setpoint reconstructed to 0.2 degC (T1 steps 0.32)
SETTINGS = DiagnoseSettings(fit_step_s=5.0, setpoint_tol_c=0.2)


def heater_gain(time_s: np.ndarray, t1_c: np.ndarray, q1_pct: np.ndarray) -> float:
    """Gain K (degC/%) of the best first-order lag of T1 on Q1.

    ``T = e T0 + (1 - e) c + K F_q`` with ``F_q`` the lag's response to Q1 from 0, affine
    in (T0, c, K) for each tau of a log-spaced scan.
    """
    prog = setpoint_programme(time_s, q1_pct, tol_c=0.01)
    t = (time_s - time_s[0]) / 60.0
    best = None
    for tau_s in np.geomspace(20.0, 2000.0, 60):
        resp = affine_response(
            LinearEffectModel(float(tau_s), 0.0), prog.durations_min, t, prog.start_c, 0.0
        )
        forced = resp.a_t @ prog.rates_c_per_min + resp.b_t  # the lag of Q1 from 0
        e = np.exp(-t / (tau_s / 60.0))
        a = np.column_stack((e, 1.0 - e, forced))
        coef, *_ = np.linalg.lstsq(a, t1_c, rcond=None)
        sse = float(np.sum((a @ coef - t1_c) ** 2))
        if best is None or sse < best[0]:
            best = (sse, float(coef[2]))
    return best[1]


def tclab_log(path: Path):
    """A schedsyn log from one TCLab file, with the pseudo setpoint from the heater."""
    raw = pd.read_csv(path)
    time_s = raw["Time"].to_numpy(dtype=float)
    t1 = raw["T1"].to_numpy(dtype=float)
    q1 = raw["Q1"].to_numpy(dtype=float)
    k = heater_gain(time_s, t1, q1)
    frame = pd.DataFrame({"time_s": time_s, "t_int_c": t1, "tk_set_c": t1[0] + k * q1})
    return log_from_frame(frame, source=path.name), k


def run(directory: Path, pattern: str = "*.csv") -> pd.DataFrame:
    rows = []
    for path in sorted(directory.glob(pattern)):
        log, k = tclab_log(path)
        d = diagnose(log, SETTINGS)
        rows.append(
            {
                "file": path.name,
                "k_c_per_pct": k,
                "tau_base_s": d.base.tau_s,
                "effect": d.effect,
                "parameters": "; ".join(f"{a}={b:.3g}" for a, b in d.parameters.items()),
                "rms_before_c": d.rms_before_c,
                "rms_after_c": d.rms_after_c,
                "holdout_before_c": d.holdout_rms_before_c,
                "holdout_after_c": d.holdout_rms_after_c,
                "runner_up": next(
                    (
                        c.effect
                        for c in d.candidates
                        if c.effect not in (d.effect, *d.ambiguous_with)
                    ),
                    "",
                ),
                "warnings": len(d.warnings),
                "ambiguous_with": ",".join(d.ambiguous_with),
                "white_before": d.residuals_before.white,
            }
        )
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", nargs="?", default=str(DEFAULT))
    ap.add_argument("--out", default="out/tclab_diagnose")
    args = ap.parse_args()
    table = run(Path(args.dir))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "tclab_diagnose.csv", index=False)
    with pd.option_context(
        "display.width", 250, "display.max_columns", 20, "display.max_colwidth", 60
    ):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))


if __name__ == "__main__":
    main()
