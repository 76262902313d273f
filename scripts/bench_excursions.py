"""Sensor dropouts (``schedsyn.logs.excursion_runs``): false finds on clean logs and finds
of planted dropouts, with and without the chamber column.

Clean logs, simulated here (exact first-order lag under a piecewise-linear chamber, no
schedsyn simulator): tau 60-4000 s, sampling 1-120 s, white noise 0-0.1 degC, quantised
to 0-0.5 degC, chambers ramping at up to 3, 10 or 20 degC/min with segments of 2-60 min.
Every log is judged with its chamber column and without. Planted: 9-h logs of a device
(tau 600-4000 s) under a slow sinusoidal chamber, 1-30 s rows, noise 0.005-0.05 degC,
with one run of 3, 8 or 20 readings offset by 1 or 3 degC, or read as 0.0 degC.

    python scripts/bench_excursions.py [--clean 400] [--planted 360] [--seed 1]
        [--out out/bench_excursions]

Prints and writes DIR/clean.csv (false finds per judging) and DIR/planted.csv (share
found per chamber column, sampling step and fault). docs/estimate.md quotes a run with
the defaults.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.io import write_frame_atomic
from schedsyn.logs import excursion_runs, glitch_rows


def _lag(t_s: np.ndarray, tk_c: np.ndarray, tau_s: float, t0_c: float) -> np.ndarray:
    """Exact first-order lag of a chamber linear between the rows, from ``t0_c``."""
    out = np.empty(t_s.size)
    y = t0_c
    for j in range(t_s.size):
        if j:
            h = t_s[j] - t_s[j - 1]
            s = (tk_c[j] - tk_c[j - 1]) / h
            y = tk_c[j] - s * tau_s + (y - tk_c[j - 1] + s * tau_s) * np.exp(-h / tau_s)
        out[j] = y
    return out


def _judge(t_s, v, chamber):
    """Runs found after the glitch readings are blanked, as the reader does."""
    rows, _, limit_c = glitch_rows(t_s, v)
    v = v.copy()
    v[rows] = np.nan
    return excursion_runs(t_s, v, limit_c, chamber)


def clean_logs(n: int, rng: np.random.Generator) -> pd.DataFrame:
    found = {"with chamber": 0, "without chamber": 0}
    for _ in range(n):
        tau = rng.uniform(60, 4000)
        dt = float(rng.choice([1, 5, 10, 30, 60, 120]))
        noise, quant = rng.choice([0, 0.005, 0.02, 0.1]), rng.choice([0, 0.01, 0.1, 0.5])
        rmax = float(rng.choice([3, 10, 20]))
        t = np.arange(int(rng.uniform(120, 600) * 60 / dt)) * dt
        tk, x, i = np.empty(t.size), 20.0, 0
        while i < t.size:
            seg = int(rng.uniform(2, 60) * 60 / dt) + 1
            r = rng.uniform(-rmax / 3, rmax) / 60 * (1 if rng.random() < 0.5 else -1)
            for j in range(i, min(t.size, i + seg)):
                x = float(np.clip(x + r * dt, -60, 120))
                tk[j] = x
            i += seg
        v = _lag(t, tk, tau, 20.0)
        if noise:
            v = v + rng.normal(0, noise, t.size)
        if quant:
            v = np.round(v / quant) * quant
        found["with chamber"] += bool(_judge(t, v, tk))
        found["without chamber"] += bool(_judge(t, v, None))
    return pd.DataFrame(
        {"judged": list(found), "logs": n, "logs_with_a_find": list(found.values())}
    )


def planted_logs(n: int, rng: np.random.Generator) -> pd.DataFrame:
    rows = []
    for _ in range(n):
        tau, dt = rng.uniform(600, 4000), float(rng.choice([1, 10, 30]))
        t = np.arange(int(9 * 3600 / dt)) * dt
        tk = 20 + 20 * np.sin(t / 3000)
        v = _lag(t, tk, tau, 20.0) + rng.normal(0, rng.choice([0.005, 0.02, 0.05]), t.size)
        k, fault = int(rng.choice([3, 8, 20])), str(rng.choice(["+1 °C", "+3 °C", "0 °C"]))
        at = int(rng.integers(50, t.size - 50))
        v[at : at + k] = 0.0 if fault == "0 °C" else v[at : at + k] + float(fault[:2])
        for column, chamber in (("with chamber", tk), ("without chamber", None)):
            runs = _judge(t, v, chamber)
            hit = any(a <= at and b >= at + k - 1 for a, b, _, _ in runs)
            rows.append((column, dt, fault, hit))
    frame = pd.DataFrame(rows, columns=["judged", "step_s", "fault", "found"])
    return (
        frame.groupby(["judged", "step_s", "fault"])["found"]
        .agg(logs="size", share_found="mean")
        .reset_index()
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clean", type=int, default=400, help="clean logs")
    ap.add_argument("--planted", type=int, default=360, help="logs with one planted run")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="out/bench_excursions")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    clean = clean_logs(args.clean, rng)
    planted = planted_logs(args.planted, rng)
    write_frame_atomic(out / "clean.csv", clean)
    write_frame_atomic(out / "planted.csv", planted)
    print(clean.to_string(index=False))
    print()
    print(planted.to_string(index=False, float_format="{:.2f}".format))
    print(f"\nwrote {out}/clean.csv, planted.csv")


if __name__ == "__main__":
    main()
