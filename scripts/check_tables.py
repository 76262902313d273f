"""Re-check exported step tables with separate code (scipy's ODE solver, own counting).

For every ``<name>/steps.csv`` of a campaign output folder, builds the chamber temperature
from the table alone, integrates ``tau dT/dt + T = Tk + dT0`` with ``solve_ivp``, counts
the distinct gradient levels per 1 degC bin with its own code (not ``schedsyn.coverage``)
and compares with ``summary.csv``. Also checks the limits a chamber operator cares about.

Usage::

    python scripts/check_tables.py out [--tau-s 2400] [--dt0-c 3]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp


def levels_per_bin(temp_c, grad, lo_c, hi_c, delta):
    """Distinct mean-gradient levels of the passes through each 1 degC bin."""
    out = []
    for b in np.arange(lo_c, hi_c):
        idx = np.flatnonzero((temp_c >= b) & (temp_c < b + 1))
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []
        means = sorted(float(grad[r].mean()) for r in runs if r.size)
        count, last = 0, -np.inf
        for x in means:
            if x - last >= delta - 1e-12:
                count, last = count + 1, x
        out.append(count)
    return np.array(out)


def check(
    steps_csv: Path,
    tau_s: float,
    dt0_c: float,
    lo_c: float,
    hi_c: float,
    levels: int,
    delta: float,
    t0_c: float | None = None,
) -> dict:
    """Simulate the table and count; ``t0_c``: device at t = 0 (default: the chamber's start)."""
    df = pd.read_csv(steps_csv, comment="#")  # the metadata lines at the top
    start = df["start_min"].to_numpy(float)
    dur = df["duration_min"].to_numpy(float)
    tk0, tk1 = df["tk_start_c"].to_numpy(float), df["tk_end_c"].to_numpy(float)
    end = float(start[-1] + dur[-1])
    knots_t, knots_tk = np.r_[start, end], np.r_[tk0, tk1[-1]]
    tau = tau_s / 60.0
    t = np.arange(0.0, end + 1e-9, 0.05)

    def tk(x):
        return np.interp(x, knots_t, knots_tk)

    sol = solve_ivp(
        lambda x, y: [(tk(x) + dt0_c - y[0]) / tau],
        (0.0, end),
        [tk0[0] if t0_c is None else t0_c],
        t_eval=t,
        max_step=0.05,
        rtol=1e-9,
        atol=1e-9,
    )
    temp = sol.y[0]
    grad = (tk(t) + dt0_c - temp) / tau
    lev = levels_per_bin(temp, grad, lo_c, hi_c, delta)
    rates = np.diff(knots_tk) / dur
    return {
        "duration_min": end,
        "steps": len(df),
        "coverage": float(np.mean(lev >= levels)),
        "min_levels": int(lev.min()),
        "device_min_c": float(temp.min()),
        "device_max_c": float(temp.max()),
        "device_end_c": float(temp[-1]),
        "chamber_min_c": float(knots_tk.min()),
        "chamber_max_c": float(knots_tk.max()),
        "rate_min": float(rates.min()),
        "rate_max": float(rates.max()),
        "chamber_start_c": float(tk0[0]),
        "chamber_end_c": float(tk1[-1]),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="campaign output folder (has summary.csv)")
    ap.add_argument("--tau-s", type=float, default=None)
    ap.add_argument("--dt0-c", type=float, default=None)
    args = ap.parse_args()
    if not (args.out / "summary.csv").is_file():
        print(
            f"check_tables: error: {args.out / 'summary.csv'} not found; give the folder "
            "`schedsyn campaign --out DIR` wrote",
            file=sys.stderr,
        )
        return 2
    summary = pd.read_csv(args.out / "summary.csv")
    bad = 0
    for _, row in summary.iterrows():
        folder = args.out / str(row["experiment"])
        if not (folder / "steps.csv").exists():
            print(
                f"{row['experiment']}: no step table (status {row.get('status', '?')}), "
                "nothing to check"
            )
            continue
        plan = json.loads((folder / "plan.json").read_text())
        spec = plan["spec"]
        res = check(
            folder / "steps.csv",
            args.tau_s or plan["tau_s"],
            plan["dt0_c"] if args.dt0_c is None else args.dt0_c,
            spec["working_lo_c"],
            spec["working_hi_c"],
            spec["levels_required"],
            spec["delta_c_per_min"],
            plan["limits"]["t_init_c"],
        )
        same = abs(res["coverage"] - row["coverage"]) < 1e-9
        bad += not same
        print(
            f"{row['experiment']}: coverage {res['coverage']:.1%} (summary "
            f"{row['coverage']:.1%}{'' if same else ', DIFFERENT'}), min levels "
            f"{res['min_levels']}, {res['duration_min']:g} min, {res['steps']} steps, "
            f"device {res['device_min_c']:.3f}..{res['device_max_c']:.3f} degC, chamber "
            f"{res['chamber_min_c']:g}..{res['chamber_max_c']:g} degC, rates "
            f"{res['rate_min']:.3f}..{res['rate_max']:.3f} degC/min, chamber "
            f"{res['chamber_start_c']:g} -> {res['chamber_end_c']:g} degC"
        )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
