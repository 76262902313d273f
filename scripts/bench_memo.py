"""Benchmark of the sweep memo (a benchmark, not a test: a few minutes).

:func:`schedsyn.planner.search._place_sweep_once` answers a sweep search that a synthesis
already ran (same fixed rates, band, segment limit and timings) from memory. It matters
for requests that do not plan complete, whose stuck candidates are retried with slow
timings. This script plans such requests with the memo and with it bypassed (every
sweep searched again), alternating the two, and reports the median CPU time of each, their
ratio, the sweeps answered from memory, and whether the plans and the LP work counted
are identical (they must be: the memo counts the work a reused search stood for).

Writes ``OUT/bench_memo.csv`` and prints a markdown table. Usage::

    python scripts/bench_memo.py [--runs 3] [--out out]
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.io import write_frame_atomic
from schedsyn.params import Limits
from schedsyn.planner import ExperimentSpec, plan_experiment
from schedsyn.planner import lp as lp_module
from schedsyn.planner import search as search_module

#: Requests that do not plan complete (name, spec, limits, plan_experiment keywords).
REQUESTS = [
    (
        "[0, 6] degC, 4 levels, 150 min (ungraded)",
        ExperimentSpec("short", 0.0, 6.0, -5.0, 11.0, levels_required=4),
        Limits(duration_max_min=150.0),
        {"graded": False},
    ),
    (
        "[-5, 0] degC, 2 levels, 90 min, box tau 1800..3000 s x dT0 0..6 degC",
        ExperimentSpec("box", -5.0, 0.0, -15.0, 10.0, levels_required=2),
        Limits(duration_max_min=90.0),
        {"robust_tau_s": (1800.0, 3000.0), "robust_dt0_c": (0.0, 6.0)},
    ),
]


@contextlib.contextmanager
def _memo_bypassed():
    """Every sweep searched again: ``_place_sweep_once`` as plain ``place_sweep``."""
    old = search_module._place_sweep_once

    def every_time(ctx, u_fixed, d, band, max_seg, slow, every_sample=False):
        return search_module.place_sweep(
            ctx, u_fixed, d, band, max_seg, slow=slow, every_sample=every_sample
        )

    search_module._place_sweep_once = every_time
    try:
        yield
    finally:
        search_module._place_sweep_once = old


def _plan(spec, limits, kwargs, memo: bool):
    ctx = contextlib.nullcontext() if memo else _memo_bypassed()
    with ctx:
        n0, c0 = lp_module.lp_nonzeros_solved(), time.process_time()
        plan = plan_experiment(spec, limits=limits, **kwargs)
        return plan, time.process_time() - c0, lp_module.lp_nonzeros_solved() - n0


def _same(a, b) -> bool:
    pa, pb = a.programme, b.programme
    return bool(
        pa.n_segments == pb.n_segments
        and np.array_equal(pa.durations_min, pb.durations_min)
        and np.array_equal(pa.rates_c_per_min, pb.rates_c_per_min)
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="runs of each way (median)")
    ap.add_argument("--out", default="out")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    rows = []
    for label, spec, limits, kwargs in REQUESTS:
        cpu = {True: [], False: []}
        plans, work = {}, {}
        for run in range(args.runs):
            for memo in (True, False) if run % 2 == 0 else (False, True):
                plan, seconds, nonzeros = _plan(spec, limits, kwargs, memo)
                cpu[memo].append(seconds)
                plans[memo], work[memo] = plan, nonzeros
                print(f"{label}: memo {'on' if memo else 'off'}, {seconds:.1f} CPU s", flush=True)
        on, off = statistics.median(cpu[True]), statistics.median(cpu[False])
        rows.append(
            {
                "request": label,
                "memo on, CPU s": round(on, 1),
                "memo off, CPU s": round(off, 1),
                "off / on": round(off / on, 2),
                "sweeps reused": plans[True].lp.get("sweeps_reused", 0),
                "same plan": _same(plans[True], plans[False]),
                "same LP work": work[True] == work[False],
                "status": plans[True].status,
            }
        )
    frame = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_frame_atomic(out / "bench_memo.csv", frame)
    cols = list(frame.columns)
    print("| " + " | ".join(cols) + " |")
    print("|" + "|".join("---" for _ in cols) + "|")
    for row in frame.itertuples(index=False):
        print("| " + " | ".join(str(v) for v in row) + " |")
    where = out / "bench_memo.csv"
    print(f"\nmedian of {args.runs} runs each, CPU time of this process; wrote {where}")


if __name__ == "__main__":
    main()
