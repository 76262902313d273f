"""Benchmark of gradient estimation on synthetic logs with known truth.

Accuracy: the baseline plan (data/baseline_exp1_steps.csv) simulated at 10 s sampling,
sensor noise 0.02 degC, quantisation 0.01 degC, several seeds; RMS error of the gradient
(degC/min) of a plain central finite difference, the kinematic Kalman smoother and the
model-based smoother (right model). Acceptance: smoother RMS < 0.01 degC/min and at least
5x smaller than the finite difference.

Speed: a 9-hour log at 1 s sampling (32 400 rows): median wall time of several runs of
each estimator, noise levels fitted by maximum likelihood included.

Run: python scripts/bench_estimate.py [--seeds 5] [--repeats 5] [--out out]
Writes OUT/bench_estimate.csv (accuracy) and OUT/bench_estimate_time.csv (speed) and
prints both as markdown tables.
"""

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

import schedsyn
from schedsyn.estimate import (
    estimate_gradient,
    estimate_gradient_model,
    finite_difference_gradient,
)
from schedsyn.logs import log_from_frame
from schedsyn.synth import synth_log

STEPS = Path(__file__).resolve().parents[1] / "data" / "baseline_exp1_steps.csv"


def markdown(frame: pd.DataFrame, fmt: str) -> str:
    """A DataFrame as a markdown table (no tabulate dependency)."""

    def cell(v):
        return format(v, fmt) if isinstance(v, float) else str(v)

    lines = [
        "| " + " | ".join(frame.columns) + " |",
        "|" + "|".join("---" for _ in frame.columns) + "|",
    ]
    lines += [
        "| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(index=False)
    ]
    return "\n".join(lines)


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def accuracy(programme, seeds: int) -> pd.DataFrame:
    rows = []
    for seed in range(seeds):
        frame = synth_log(programme, sample_s=10.0, noise_c=0.02, quant_c=0.01, seed=seed)
        log = log_from_frame(frame, source=f"synthetic seed {seed}")
        truth = frame["g_true_c_per_min"].to_numpy()
        kin = estimate_gradient(log)
        mod = estimate_gradient_model(log)
        fd = finite_difference_gradient(log.time_s, log.t_int_c)
        e_fd, e_kin, e_mod = (
            rms(fd - truth),
            rms(kin.g_est_c_per_min - truth),
            rms(mod.g_est_c_per_min - truth),
        )
        rows.append(
            {
                "seed": seed,
                "rows": log.n_rows,
                "rms_fd_c_per_min": e_fd,
                "rms_smoother_c_per_min": e_kin,
                "rms_model_c_per_min": e_mod,
                "fd_over_smoother": e_fd / e_kin,
                "q_fitted": kin.q,
                "r_fitted_c2": kin.r,
                "median_g_std_c_per_min": float(np.median(kin.g_std_c_per_min)),
            }
        )
    return pd.DataFrame(rows)


def speed(programme, repeats: int) -> pd.DataFrame:
    # the plan held at its end temperature up to 9 h: 32 401 rows at 1 s
    nine_h = schedsyn.Programme(
        np.append(programme.durations_min, 540.0 - programme.total_min),
        np.append(programme.rates_c_per_min, 0.0),
        programme.start_c,
    )
    frame = synth_log(nine_h, sample_s=1.0, noise_c=0.02, quant_c=0.01, seed=0)
    log = log_from_frame(frame)
    rows = []
    for name, fn in (
        ("kinematic (ML q, r)", estimate_gradient),
        ("model-based (ML q, r)", estimate_gradient_model),
        ("kinematic (q, r given)", lambda lg: estimate_gradient(lg, q=1e-3, r=4e-4)),
    ):
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(log)
            times.append(time.perf_counter() - t0)
        rows.append(
            {
                "estimator": name,
                "rows": log.n_rows,
                "median_s": float(np.median(times)),
                "min_s": float(np.min(times)),
                "max_s": float(np.max(times)),
                "repeats": repeats,
            }
        )
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default="out")
    args = ap.parse_args()
    programme = schedsyn.read_steps(STEPS)
    acc = accuracy(programme, args.seeds)
    spd = speed(programme, args.repeats)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    acc.to_csv(out / "bench_estimate.csv", index=False)
    spd.to_csv(out / "bench_estimate_time.csv", index=False)
    print("## Gradient RMS error, degC/min (10 s sampling, noise 0.02 degC, quant 0.01 degC)\n")
    print(markdown(acc, ".4g"))
    ok = (acc["rms_smoother_c_per_min"] < 0.01).all() and (acc["fd_over_smoother"] >= 5).all()
    print(
        f"\nacceptance (smoother < 0.01 and >= 5x better than FD, every seed): "
        f"{'PASS' if ok else 'FAIL'}"
    )
    print(
        f"\n## Run time, 32 400-row log ({platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()})\n"
    )
    print(markdown(spd, ".3f"))
    print(f"\nwrote {out}/bench_estimate.csv, {out}/bench_estimate_time.csv")


if __name__ == "__main__":
    main()
