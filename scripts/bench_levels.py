"""Benchmark: how long the planner takes over the documented level range (issue 13 item 6).

``schedsyn plan --levels N`` is documented for N = 2..12. Counts the budget cannot hold
are answered by a graded plan (the most levels a complete plan reaches), whose search is
bounded (:func:`schedsyn.planner.plan_experiment`'s ``effort_s``, default 45 reference
seconds of LP work, stops the optional searches; the search for the requested plan always
runs to its end). For every experiment of the default campaign named with
``--experiments`` and every count, one plan with the default effort limit, timed (wall
clock, one process):

    level count, wall s, status, levels planned (graded), weakest bin, duration,
    whether the effort limit stopped a search

Writes ``out/bench_levels.csv`` and ``out/bench_levels.md`` and prints the table. The
target (< 60 s per answer) is checked in the summary line, not asserted. Usage::

    python scripts/bench_levels.py [--experiments W1 W3] [--levels 2 12] [--out out]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import time
from pathlib import Path

import pandas as pd

from schedsyn.campaign import default_campaign
from schedsyn.io import write_frame_atomic, write_text_atomic
from schedsyn.planner import plan_experiment

TARGET_S = 60.0


def _names(frame: pd.DataFrame) -> str:
    return ", ".join(f"{r.experiment}/{r.levels}" for r in frame.itertuples())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiments", nargs="+", default=["W1", "W3"])
    ap.add_argument("--levels", nargs=2, type=int, default=[2, 12], metavar=("LO", "HI"))
    ap.add_argument("--out", type=Path, default=Path("out"))
    args = ap.parse_args(argv)
    config = default_campaign()
    by_name = {e.name: e for e in config.experiments}
    unknown = [n for n in args.experiments if n not in by_name]
    if unknown:
        raise SystemExit(f"unknown experiment(s) {unknown}; the campaign has {sorted(by_name)}")
    rows = []
    for name in args.experiments:
        for levels in range(args.levels[0], args.levels[1] + 1):
            spec = dataclasses.replace(by_name[name], levels_required=levels)
            tic = time.perf_counter()
            plan = plan_experiment(spec, config.params, config.limits)
            wall = time.perf_counter() - tic
            row = {
                "experiment": name,
                "levels": levels,
                "wall_s": round(wall, 1),
                "status": plan.status,
                "levels_planned": plan.levels_planned or (levels if plan.complete else None),
                "min_levels": plan.coverage.min_levels,
                "duration_min": plan.programme.total_min,
                "effort_limit_hit": any("effort limit" in n for n in plan.notes),
            }
            rows.append(row)
            print(
                f"{name} levels {levels:2d}: {wall:6.1f} s {plan.status:<16} "
                f"planned {row['levels_planned']}, weakest bin {row['min_levels']}",
                flush=True,
            )
    df = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    write_frame_atomic(args.out / "bench_levels.csv", df)
    over = df[df.wall_s >= TARGET_S]
    summary = (
        f"- {len(df)} answers, median {statistics.median(df.wall_s):.1f} s, max "
        f"{df.wall_s.max():.1f} s; under {TARGET_S:g} s: {len(df) - len(over)} of {len(df)} "
        f"({'met' if over.empty else 'MISSED: ' + _names(over)})\n"
        f"- machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        "one process (other work on the machine makes times pessimistic)\n"
    )
    cells = [[str(v) if v is not None else "-" for v in r] for r in df.itertuples(index=False)]
    table = "\n".join(
        ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
        + ["| " + " | ".join(c) + " |" for c in cells]
    )
    write_text_atomic(args.out / "bench_levels.md", summary + "\n" + table + "\n")
    print(summary + "\n" + table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
