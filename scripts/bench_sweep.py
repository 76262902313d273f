"""Benchmark: fixed-plan sweep of 169 (13 x 13) tau x dT0 points on each backend.

Rows: a naive loop (``simulate`` + ``coverage_report`` per point, the reference), the
vectorised ``sweep_fixed`` serially, on a local process pool (pool start-up included, as
a user pays it) and, when ``distributed`` is installed, on a 2-worker local Dask cluster
(cluster start-up not included, as for a running cluster). Each time is the median of
several runs. Writes ``out/bench_sweep.csv`` and prints a markdown table.

    python scripts/bench_sweep.py [--repeats 5] [--steps data/baseline_exp1_steps.csv]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import pandas as pd

from schedsyn import BinGrid, ThermalParams, coverage_report, read_steps, simulate
from schedsyn.io import write_frame_atomic
from schedsyn.sweep import parse_grid, sweep_fixed

REGION = (-50.0, -30.0)
DELTAS = (0.05, 0.1)


def naive(programme, taus, dt0s) -> None:
    grid = BinGrid(*REGION)
    for tau in taus:
        for dt0 in dt0s:
            traj = simulate(programme, ThermalParams(tau_s=float(tau), dt0_c=float(dt0)))
            for delta in DELTAS:
                coverage_report(traj.t_c, traj.g_c_per_min, grid, 6, delta)


def timed(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", default="data/baseline_exp1_steps.csv")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default="out/bench_sweep.csv")
    args = ap.parse_args()

    programme = read_steps(args.steps)
    taus, dt0s = parse_grid("1800:3000:13"), parse_grid("0:6:13")
    n_points = taus.size * dt0s.size
    cores = os.cpu_count() or 1

    def fixed(backend, workers=None):
        return lambda: sweep_fixed(
            programme, REGION, taus, dt0s, deltas_c_per_min=DELTAS, backend=backend, workers=workers
        )

    cases = [
        (
            "naive loop: simulate + coverage_report per point",
            "serial",
            1,
            lambda: naive(programme, taus, dt0s),
        ),
        ("sweep_fixed (vectorised), serial", "serial", 1, fixed("serial")),
        (f"sweep_fixed (vectorised), local pool of {cores}", "local", cores, fixed("local", cores)),
    ]
    fixed("serial")()  # warm-up (imports, caches)
    rows = []
    for name, backend, workers, fn in cases:
        times = timed(fn, args.repeats)
        rows.append((name, backend, workers, times))
    try:
        import distributed
    except ImportError:
        distributed = None
    if distributed is not None:
        with distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster:
            fn = fixed(cluster.scheduler_address)
            fn()  # warm-up: workers import schedsyn
            rows.append(
                (
                    "sweep_fixed (vectorised), Dask LocalCluster 2 processes",
                    "dask",
                    2,
                    timed(fn, args.repeats),
                )
            )

    table = pd.DataFrame(
        {
            "case": [r[0] for r in rows],
            "backend": [r[1] for r in rows],
            "workers": [r[2] for r in rows],
            "points": n_points,
            "repeats": args.repeats,
            "median_s": [statistics.median(r[3]) for r in rows],
            "min_s": [min(r[3]) for r in rows],
            "max_s": [max(r[3]) for r in rows],
        }
    )
    table["per_point_ms"] = 1000.0 * table["median_s"] / n_points
    table["cpu"] = platform.processor() or platform.machine()
    table["cores"] = cores
    write_frame_atomic(Path(args.out), table.round(4))
    print(
        f"fixed-plan sweep, {n_points} points ({taus.size} tau x {dt0s.size} dT0), "
        f"{args.steps}, region {REGION}, deltas {DELTAS}; {cores} cores; "
        f"median of {args.repeats} runs\n"
    )
    print("| case | median, s | min .. max, s | per point, ms |")
    print("|---|---:|---:|---:|")
    for _, r in table.iterrows():
        print(
            f"| {r['case']} | {r['median_s']:.3f} | {r['min_s']:.3f} .. {r['max_s']:.3f} | "
            f"{r['per_point_ms']:.2f} |"
        )
    print(f"\nwrote {args.out}")


if __name__ == "__main__":
    main()
