"""Write data/sample_run_exp1.csv: a SYNTHETIC "measured" run of the baseline programme.

It is not measured data. The baseline step table is run through the planning model with
a device that differs mildly from the one the plan assumed (tau 2700 s instead of 2400 s,
self-heating 2.0 degC instead of 3.0 degC), read by a sensor with 0.02 degC noise and
0.01 degC quantisation every 10 s. To show the reader's reports it has a 2-minute
dropout of the internal sensor (blank t_int_c cells) and a 10-minute logging gap. The
truth columns t_true_c and g_true_c_per_min are kept (a real log would not have them).

Run: python scripts/make_sample_log.py [OUT.csv]
"""

import sys
from pathlib import Path

import numpy as np

import schedsyn
from schedsyn.io import write_frame_atomic
from schedsyn.synth import synth_log

STEPS = Path(__file__).resolve().parents[1] / "data" / "baseline_exp1_steps.csv"
OUT = Path(__file__).resolve().parents[1] / "data" / "sample_run_exp1.csv"
DEVICE = schedsyn.ThermalParams(tau_s=2700.0, dt0_c=2.0)


def main(out: Path) -> None:
    programme = schedsyn.read_steps(STEPS)
    frame = synth_log(programme, DEVICE, sample_s=10.0, noise_c=0.02, quant_c=0.01, seed=2024)
    minutes = frame["time_s"] / 60.0
    dropout = (minutes >= 150.0) & (minutes < 152.0)
    frame.loc[dropout, "t_int_c"] = np.nan
    gap = (minutes > 320.0) & (minutes < 330.0)
    frame = frame.loc[~gap].reset_index(drop=True)
    for col in ("t_int_c", "tk_air_c"):
        frame[col] = frame[col].round(2)
    for col in ("tk_set_c", "t_true_c"):
        frame[col] = frame[col].round(4)
    frame["g_true_c_per_min"] = frame["g_true_c_per_min"].round(5)
    write_frame_atomic(out, frame)
    print(f"wrote {out}: {len(frame)} rows")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
