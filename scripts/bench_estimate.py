"""Benchmark of gradient estimation on synthetic logs with known truth.

Accuracy (10 s): the baseline plan (data/baseline_exp1_steps.csv) simulated at 10 s
sampling, sensor noise 0.02 degC, quantisation 0.01 degC, several seeds; RMS error of the
gradient (degC/min) of a plain central finite difference, the kinematic Kalman smoother
(order 3, the default, and order 2) and the model-based smoother (right model).
Acceptance: smoother RMS < 0.01 degC/min and at least 5x smaller than the finite
difference.

Accuracy (coarse): logs sampled every 30 s and quantised to 0.0625 degC (a DS18B20-type
sensor; noise 0.01 degC) of the baseline, two planner plans with many rate changes
(tests/data/plans), a blind-test programme and a programme of random reversals; each
estimator's RMS error, the finite difference's, and their ratio. Acceptance (issue 14):
RMS < 0.01 degC/min and >= 5x below the finite difference, with the chamber column
(model-based, right model and tau 15 % / dT0 1 degC off) and without it (kinematic).

Speed: a 9-hour log at 1 s sampling (32 400 rows): median wall time of several runs of
each estimator, noise levels fitted by maximum likelihood included. With
``--before-src DIR`` the same timings are taken of the source tree DIR (e.g. an older
checkout: ``git archive REV schedsyn | tar -x -C DIR``) in alternating subprocesses, so
before and after share the machine's load.

Run: python scripts/bench_estimate.py [--seeds 5] [--repeats 5] [--out out]
     [--before-src DIR] [--skip-accuracy]
Writes OUT/bench_estimate.csv (10 s accuracy), OUT/bench_estimate_coarse.csv and
OUT/bench_estimate_time.csv, and prints them as markdown tables.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
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
from schedsyn.params import ThermalParams
from schedsyn.synth import blind_programmes, synth_log

ROOT = Path(__file__).resolve().parents[1]
STEPS = ROOT / "data" / "baseline_exp1_steps.csv"
PLANS = ROOT / "tests" / "data" / "plans"
#: The model-based estimator with a wrong model: tau 15 % long, dT0 1 degC low.
WRONG = ThermalParams(tau_s=2760.0, dt0_c=2.0)


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
        kin2 = estimate_gradient(log, order=2)
        mod = estimate_gradient_model(log)
        fd = finite_difference_gradient(log.time_s, log.t_int_c)
        e_fd, e_kin, e_kin2, e_mod = (
            rms(fd - truth),
            rms(kin.g_est_c_per_min - truth),
            rms(kin2.g_est_c_per_min - truth),
            rms(mod.g_est_c_per_min - truth),
        )
        rows.append(
            {
                "seed": seed,
                "rows": log.n_rows,
                "rms_fd_c_per_min": e_fd,
                "rms_smoother_c_per_min": e_kin,
                "rms_order2_c_per_min": e_kin2,
                "rms_model_c_per_min": e_mod,
                "fd_over_smoother": e_fd / e_kin,
                "q_fitted": kin.q,
                "r_fitted_c2": kin.r,
                "median_g_std_c_per_min": float(np.median(kin.g_std_c_per_min)),
            }
        )
    return pd.DataFrame(rows)


def reversals(seed: int) -> schedsyn.Programme:
    """Reversals between random chamber levels in [-40, 40] degC at random feasible rates
    (heating 0.5..3, cooling 0.3..1 degC/min), back at 20 degC within 540 min."""
    rng = np.random.default_rng(seed)
    durations, rates = [], []
    t, level = 0.0, 20.0
    while True:
        target = float(rng.uniform(-40.0, 40.0))
        rate = float(rng.uniform(0.5, 3.0)) if target > level else -float(rng.uniform(0.3, 1.0))
        dur = (target - level) / rate
        back = abs(20.0 - target) / (1.0 if target > 20.0 else 2.0)
        if t + dur + back > 530.0:
            break
        durations.append(dur)
        rates.append(rate)
        t += dur
        level = target
    durations.append(abs(20.0 - level) / (1.0 if level > 20.0 else 2.0))
    rates.append(-1.0 if level > 20.0 else 2.0)
    return schedsyn.Programme(np.array(durations), np.array(rates), 20.0)


def coarse_accuracy(seeds: int) -> pd.DataFrame:
    programmes = {
        "baseline": schedsyn.read_steps(STEPS),
        "plan W2": schedsyn.read_steps(PLANS / "w2_steps.csv"),
        "plan W3": schedsyn.read_steps(PLANS / "w3_steps.csv"),
        "blind cold": blind_programmes()["cold"],
        "reversals": reversals(0),
    }
    methods = {
        "kinematic (order 3, default)": lambda lg: estimate_gradient(lg),
        "kinematic order 2": lambda lg: estimate_gradient(lg, order=2),
        "model, right model": lambda lg: estimate_gradient_model(lg),
        "model, tau +15 %, dT0 -1 degC": lambda lg: estimate_gradient_model(lg, WRONG),
    }
    rows = []
    for name, prog in programmes.items():
        for seed in range(seeds):
            frame = synth_log(prog, sample_s=30.0, noise_c=0.01, quant_c=0.0625, seed=seed)
            truth = frame["g_true_c_per_min"].to_numpy()
            with_chamber = log_from_frame(frame)
            without = log_from_frame(frame[["time_s", "t_int_c"]])
            fd = rms(finite_difference_gradient(without.time_s, without.t_int_c) - truth)
            for method, fn in methods.items():
                log = with_chamber if method.startswith("model") else without
                err = rms(fn(log).g_est_c_per_min - truth)
                rows.append(
                    {
                        "programme": name,
                        "seed": seed,
                        "method": method,
                        "rms_c_per_min": err,
                        "rms_fd_c_per_min": fd,
                        "fd_over_estimate": fd / err,
                        "pass": bool(err < 0.01 and fd >= 5.0 * err),
                    }
                )
    return pd.DataFrame(rows)


#: Speed cases: name -> call of the estimator on `log` (`order` only where the tree has it).
SPEED_CASES = {
    "kinematic, default (ML q, r)": "estimate_gradient(log)",
    "kinematic order 2 (ML q, r)": "estimate_gradient(log, **o2)",
    "kinematic order 2 (q, r given)": "estimate_gradient(log, q=1e-3, r=4e-4, **o2)",
    "model-based (ML q, r)": "estimate_gradient_model(log)",
}
_TIMER = """
import inspect, json, sys, time
import numpy as np
import schedsyn
from schedsyn.estimate import estimate_gradient, estimate_gradient_model
from schedsyn.logs import log_from_frame
from schedsyn.synth import synth_log
p = schedsyn.read_steps(sys.argv[1])
nine = schedsyn.Programme(np.append(p.durations_min, 540.0 - p.total_min),
                          np.append(p.rates_c_per_min, 0.0), p.start_c)
log = log_from_frame(synth_log(nine, sample_s=1.0, noise_c=0.02, quant_c=0.01, seed=0))
o2 = {"order": 2} if "order" in inspect.signature(estimate_gradient).parameters else {}
call, repeats = sys.argv[2], int(sys.argv[3])
eval(call)  # warm up
times = []
for _ in range(repeats):
    t0 = time.perf_counter()
    eval(call)
    times.append(time.perf_counter() - t0)
print(json.dumps({"times": times, "rows": log.n_rows, "src": schedsyn.__file__}))
"""


def _time_in(src: Path, call: str, repeats: int) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(src) + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory() as cwd:  # not the checkout: it would come first
        out = subprocess.run(
            [sys.executable, "-c", _TIMER, str(STEPS), call, str(repeats)],
            capture_output=True,
            text=True,
            env=env,
            cwd=cwd,
            check=True,
        )
    return json.loads(out.stdout)


def speed(repeats: int, before: Path | None) -> pd.DataFrame:
    """Median wall times; with a `before` tree, alternating subprocesses of both."""
    rows = []
    trees = [("after", ROOT)] + ([("before", before)] if before is not None else [])
    for name, call in SPEED_CASES.items():
        times: dict[str, list[float]] = {tag: [] for tag, _ in trees}
        n_rows = 0
        for _ in range(3):  # alternate: before and after see the same load
            for tag, src in trees:
                res = _time_in(src, call, max(1, repeats // 3 + 1))
                times[tag] += res["times"]
                n_rows = res["rows"]
        row = {"estimator": name, "rows": n_rows}
        for tag, _ in trees:
            row[f"median_{tag}_s"] = float(np.median(times[tag]))
            row[f"min_{tag}_s"] = float(np.min(times[tag]))
        if before is not None:
            row["after_over_before"] = row["median_after_s"] / row["median_before_s"]
        row["repeats"] = len(times["after"])
        rows.append(row)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--out", default="out")
    ap.add_argument("--before-src", default=None, help="source tree to time for comparison")
    ap.add_argument("--skip-accuracy", action="store_true", help="speed only")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    if not args.skip_accuracy:
        acc = accuracy(schedsyn.read_steps(STEPS), args.seeds)
        acc.to_csv(out / "bench_estimate.csv", index=False)
        written.append("bench_estimate.csv")
        print("## Gradient RMS error, °C/min (10 s sampling, noise 0.02 °C, quant 0.01 °C)\n")
        print(markdown(acc, ".4g"))
        ok = (acc["rms_smoother_c_per_min"] < 0.01).all() and (acc["fd_over_smoother"] >= 5).all()
        print(
            f"\nacceptance (smoother < 0.01 and >= 5x better than FD, every seed): "
            f"{'PASS' if ok else 'FAIL'}"
        )
        coarse = coarse_accuracy(max(1, min(args.seeds, 3)))
        coarse.to_csv(out / "bench_estimate_coarse.csv", index=False)
        written.append("bench_estimate_coarse.csv")
        summary = (
            coarse.groupby(["programme", "method"], sort=False)
            .agg(
                rms_c_per_min=("rms_c_per_min", "max"),
                rms_fd_c_per_min=("rms_fd_c_per_min", "min"),
                fd_over_estimate=("fd_over_estimate", "min"),
                seeds_passing=("pass", "sum"),
                seeds=("pass", "size"),
            )
            .reset_index()
        )
        print(
            "\n## Coarse logs: 30 s sampling, 0.0625 °C quantisation, noise 0.01 °C "
            "(worst seed: largest RMS, smallest ratio), °C/min\n"
        )
        print(markdown(summary, ".4g"))
        needed = coarse[~coarse["method"].str.contains("order 2")]
        print(
            "\nacceptance (RMS < 0.01 and >= 5x below FD; kinematic default and model-based, "
            f"every programme and seed): {'PASS' if needed['pass'].all() else 'FAIL'}"
        )
    spd = speed(args.repeats, Path(args.before_src).resolve() if args.before_src else None)
    spd.to_csv(out / "bench_estimate_time.csv", index=False)
    written.append("bench_estimate_time.csv")
    print(
        f"\n## Run time, 32 401-row log ({platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, {os.cpu_count()} cores, shared machine)\n"
    )
    print(markdown(spd, ".3f"))
    print(f"\nwrote {', '.join(f'{out}/{w}' for w in written)}")


if __name__ == "__main__":
    main()
