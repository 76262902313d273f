"""Benchmark of the planner on the paper's campaign (a benchmark, not a test: minutes).

For every experiment of the default campaign (or CONFIG.toml):

* problem size of the final LP (variables, constraints), number of LP solves, binaries
  (none: the structure search fixes the combinatorial part, every solve is an LP);
* solve time per experiment (serial, median of ``--runs``) and wall time of the whole
  campaign planned in parallel over the local cores (median of ``--runs``);
* the shortest duration that still reaches full coverage, for segment lengths 5 and
  10 min (objective "shortest" gives it directly; "-" when the plan is incomplete);
* one typical search probe LP solved straight by Clarabel vs through cvxpy (median).

Writes ``out/bench_plan.csv`` and prints a markdown table. Usage::

    python scripts/bench_plan.py [CONFIG.toml] [--runs 3] [--segments 5 10] [--out out]
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

from schedsyn.campaign import default_campaign, load_campaign, plan_campaign


def _with_segment(config, segment_min: float):
    exps = tuple(
        dataclasses.replace(e, segment_min=segment_min, objective="shortest")
        for e in config.experiments
    )
    return dataclasses.replace(config, experiments=exps)


def _fmt(x, spec=".1f"):
    return "-" if x is None or x != x else format(x, spec)


def probe_lp_timing(repeats: int = 30) -> dict:
    """Median time of one search probe LP solved directly by Clarabel vs through cvxpy.

    The probe is a typical one: W1's first cooling sweep window over the first 100 min
    (chamber and device limits, band, knot and edge rows), the same LP both ways.
    """
    import cvxpy as cp
    import numpy as np

    from schedsyn import Limits, ThermalParams
    from schedsyn.model import FirstOrderLag
    from schedsyn.planner import ExperimentSpec, Scenario, make_bands
    from schedsyn.planner.lp import Context, LpStats, Responses, SubLP, Window

    spec = ExperimentSpec("W1", -50, -30, -52, -20)
    p, lim = ThermalParams(), Limits()
    ctx = Context(spec, lim, Responses([Scenario(p, FirstOrderLag(p))], 40, 5.0, lim), LpStats())
    band = make_bands(spec, 3, -1, 0.062, [p], lim)[2]
    steps = np.maximum(1, np.round(band.timing_options()[0][::-1])).astype(int)  # at its top
    s0 = 60
    bounds = s0 + np.concatenate(([0], np.cumsum(steps)))
    win = Window(-1, band, s0, int(bounds[-1]), tuple(int(c) for c in bounds[1:-1]))
    j1 = int(np.ceil(bounds[-1] / 5.0))

    def build():
        lp = SubLP(ctx, np.zeros(0), j1, extra=1)
        lp.chamber()
        lp.device()
        lp.window(win)
        lp.exit_speed(win, 0)
        return lp

    cost = np.zeros(j1 + 1)
    cost[-1] = 1.0
    out = {}
    for name, run in (
        ("direct", lambda: build().solve_direct(cost, l1_weight=1e-4)),
        ("cvxpy", lambda: build().solve(lambda v: v[-1] + 1e-4 * cp.norm1(v[:-1]))),
    ):
        times = []
        for _ in range(repeats):
            tic = time.perf_counter()
            run()
            times.append(time.perf_counter() - tic)
        out[name] = statistics.median(times)
    size = build()
    out["rows"] = int(sum(len(h) for h in size.h_rows))
    out["variables"] = j1 + 1
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config", nargs="?", default=None)
    ap.add_argument("--runs", type=int, default=3, help="repetitions for the medians")
    ap.add_argument(
        "--segments",
        type=float,
        nargs="+",
        default=[5.0, 10.0],
        help="segment lengths, min, for the shortest-duration columns",
    )
    ap.add_argument("--out", default="out")
    args = ap.parse_args()
    config = default_campaign() if args.config is None else load_campaign(args.config)
    names = [e.name for e in config.experiments]

    # per-experiment solve times (serial: one experiment per process at a time)
    serial = [plan_campaign(config, backend="serial") for _ in range(args.runs)]
    # whole campaign, parallel over the local cores
    campaign_s = []
    for _ in range(args.runs):
        tic = time.perf_counter()
        plan_campaign(config, backend="local")
        campaign_s.append(time.perf_counter() - tic)
    # shortest complete duration per segment length
    shortest: dict[float, list] = {}
    reached: dict[float, list] = {}
    for seg in args.segments:
        res = plan_campaign(_with_segment(config, seg), backend="local")
        shortest[seg] = [
            p.duration_min if p is not None and p.complete else float("nan") for p in res.plans
        ]
        reached[seg] = [p.coverage.coverage if p is not None else 0.0 for p in res.plans]

    rows = []
    for i, name in enumerate(names):
        plans = [r.plans[i] for r in serial]
        ok = [p for p in plans if p is not None]
        first = ok[0] if ok else None
        size = first.problem_size if first else {}
        row = {
            "experiment": name,
            "variables": size.get("variables", float("nan")),
            "constraints": size.get("constraints", float("nan")),
            "binaries": 0,
            "lp_solves": first.n_lp if first else float("nan"),
            "solve_s_median": statistics.median(p.solve_s for p in ok) if ok else float("nan"),
            "runs": len(ok),
            "coverage": first.coverage.coverage if first else 0.0,
            "complete": bool(first and first.complete),
            "duration_min": first.duration_min if first else float("nan"),
        }
        for seg in args.segments:
            row[f"shortest_full_min_seg{seg:g}"] = shortest[seg][i]
            row[f"coverage_seg{seg:g}"] = reached[seg][i]
        rows.append(row)
    probe = probe_lp_timing()
    frame = pd.DataFrame(rows)
    frame["probe_lp_direct_ms"] = 1e3 * probe["direct"]
    frame["probe_lp_cvxpy_ms"] = 1e3 * probe["cvxpy"]
    frame["campaign_wall_s_median"] = statistics.median(campaign_s)
    frame["cores"] = os.cpu_count()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out / "bench_plan.csv", index=False)

    seg_cols = [f"shortest_full_min_seg{s:g}" for s in args.segments]
    head = [
        "experiment",
        "variables",
        "constraints",
        "binaries",
        "LP solves",
        "solve s (median)",
        "coverage",
        *[f"shortest full, seg {s:g} min" for s in args.segments],
    ]
    print(
        f"planner benchmark: {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, medians of {args.runs} runs\n"
    )
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        cells = [
            r["experiment"],
            _fmt(r["variables"], ".0f"),
            _fmt(r["constraints"], ".0f"),
            "0",
            _fmt(r["lp_solves"], ".0f"),
            _fmt(r["solve_s_median"]),
            f"{r['coverage']:.0%}",
            *[
                _fmt(r[c], ".0f") if r[c] == r[c] else f"not full ({r[f'coverage_seg{s:g}']:.0%})"
                for c, s in zip(seg_cols, args.segments, strict=True)
            ],
        ]
        print("| " + " | ".join(cells) + " |")
    print(
        f"\nwhole campaign in parallel over {os.cpu_count()} cores: "
        f"{statistics.median(campaign_s):.1f} s (median of {args.runs}; runs "
        + ", ".join(f"{x:.1f}" for x in campaign_s)
        + " s)"
    )
    print(
        f"one search probe LP ({probe['variables']} variables, {probe['rows']} rows): "
        f"{1e3 * probe['direct']:.1f} ms straight to Clarabel vs {1e3 * probe['cvxpy']:.1f} "
        f"ms through cvxpy (median of 30; ratio {probe['cvxpy'] / probe['direct']:.1f})"
    )
    print(f"wrote {out / 'bench_plan.csv'}")


if __name__ == "__main__":
    main()
