"""Benchmark of the planner's LP machinery (a benchmark, not a test: minutes).

Two choices made in ``schedsyn.planner.lp``, each timed against its alternative in the
same run, on the paper's experiments (``--experiments``, default all four):

* **Clarabel's KKT factorisation** for the whole-programme LPs: the polish
  (:func:`~schedsyn.planner.polish.polish_tied`: the margin LP, then the fewest-changes
  LP) of the structure a real plan found, with ``direct_solve_method`` "qdldl"
  (schedsyn's :data:`~schedsyn.planner.lp.CLARABEL_SETTINGS`), "auto" (Clarabel's
  default) and "faer" on one thread; median CPU and wall time of ``--runs`` runs each,
  and the margins each reaches.
* **The plan as a whole** with each combination of the bounds proof
  (:func:`~schedsyn.planner.lp.bounds_prove_infeasible`, on/off) and the KKT method
  (qdldl/auto): CPU and wall time, LP solves, the share the bounds proved infeasible,
  the LP work (constraint nonzeros, the effort limit's measure) done per CPU second, and
  whether the plan is the same as schedsyn's (durations and rates).

CPU time is the process's (the machine may be shared; wall time is shown beside it).
Writes ``out/bench_lp.csv`` and prints markdown tables. Usage::

    python scripts/bench_lp.py [--experiments W2 W4] [--runs 5] [--out out]
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.campaign import default_campaign
from schedsyn.io import write_frame_atomic
from schedsyn.planner import lp as lp_module
from schedsyn.planner import plan_experiment
from schedsyn.planner import polish as polish_module

KKT_METHODS = {
    "qdldl": {"direct_solve_method": "qdldl"},
    "auto": {},
    "faer-1": {"direct_solve_method": "faer", "max_threads": 1},
}


class _Captured(Exception):
    pass


def capture_polish(spec, params, limits):
    """The (context, structure) of the plan's first whole-programme LP."""
    got = {}

    def grab(ctx, structure, ties):
        got["args"] = (ctx, structure)
        raise _Captured

    with _patched(polish_module, "polish_tied", grab), contextlib.suppress(_Captured):
        plan_experiment(spec, params, limits)
    return got["args"]


@contextlib.contextmanager
def _patched(obj, name, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


def time_kkt(ctx, structure, runs: int) -> list[dict]:
    """The polish (its margin LP, then its fewest-changes LP) under each KKT method."""
    rows = []
    for method, settings in KKT_METHODS.items():
        cpu, wall = [], []
        with _patched(lp_module, "CLARABEL_SETTINGS", settings):
            for _ in range(runs):
                c0, w0 = time.process_time(), time.perf_counter()
                res = polish_module.polish_tied(ctx, structure, frozenset())
                cpu.append(time.process_time() - c0)
                wall.append(time.perf_counter() - w0)
        rows.append(
            {
                "method": method,
                "constraints": ctx.size["constraints"],
                "cpu_s": statistics.median(cpu),
                "wall_s": statistics.median(wall),
                "margin_g_c_per_min": None if res is None else res[1],
                "margin_t_c": None if res is None else res[2],
            }
        )
    return rows


def plan_with(spec, params, limits, bounds: bool, kkt: str):
    patches = contextlib.ExitStack()
    if not bounds:
        patches.enter_context(_patched(lp_module, "bounds_prove_infeasible", lambda *a: False))
    patches.enter_context(_patched(lp_module, "CLARABEL_SETTINGS", KKT_METHODS[kkt]))
    with patches:
        n0, c0, w0 = lp_module.lp_nonzeros_solved(), time.process_time(), time.perf_counter()
        plan = plan_experiment(spec, params, limits)
        cpu = time.process_time() - c0
        work = lp_module.lp_nonzeros_solved() - n0
        return plan, cpu, time.perf_counter() - w0, work


def markdown(frame: pd.DataFrame) -> str:
    """A DataFrame as a markdown table (no tabulate dependency)."""

    def cell(v):
        return format(v, ".3g") if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(frame.columns) + " |", "|" + "|".join("---" for _ in frame) + "|"]
    lines += [
        "| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(index=False)
    ]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiments", nargs="*", default=None, help="names (default: all)")
    ap.add_argument("--runs", type=int, default=5, help="polish runs per KKT method (median)")
    ap.add_argument("--out", default="out")
    ns = ap.parse_args()
    if ns.runs < 1:
        ap.error(f"--runs must be at least 1, got {ns.runs}")
    cfg = default_campaign()
    specs = [e for e in cfg.experiments if ns.experiments is None or e.name in ns.experiments]
    if not specs:
        ap.error(
            f"no experiment named {ns.experiments}; the campaign has "
            f"{[e.name for e in cfg.experiments]}"
        )
    kkt_rows, plan_rows = [], []
    for spec in specs:
        print(f"{spec.name}: capturing the whole-programme LP", flush=True)
        ctx, structure = capture_polish(spec, cfg.params, cfg.limits)
        for row in time_kkt(ctx, structure, ns.runs):
            kkt_rows.append({"experiment": spec.name, **row})
        reference = None
        for bounds, kkt in ((True, "qdldl"), (False, "qdldl"), (True, "auto"), (False, "auto")):
            print(
                f"{spec.name}: planning, bounds proof {'on' if bounds else 'off'}, KKT {kkt}",
                flush=True,
            )
            plan, cpu, wall, work = plan_with(spec, cfg.params, cfg.limits, bounds, kkt)
            if reference is None:
                reference = plan
            same = bool(
                np.array_equal(plan.programme.durations_min, reference.programme.durations_min)
                and np.allclose(
                    plan.programme.rates_c_per_min, reference.programme.rates_c_per_min, atol=1e-9
                )
            )
            plan_rows.append(
                {
                    "experiment": spec.name,
                    "bounds_proof": bounds,
                    "kkt": kkt,
                    "cpu_s": cpu,
                    "wall_s": wall,
                    "lp_solves": plan.lp["lp_solves"],
                    "infeasible": plan.lp["infeasible"],
                    "infeasible_by_bounds": plan.lp["infeasible_by_bounds"],
                    # the effort limit's unit (core.LP_NONZEROS_PER_EFFORT_S) in CPU time
                    "lp_nonzeros_per_cpu_s": work / cpu,
                    "status": plan.status,
                    "duration_min": plan.duration_min,
                    "same_plan_as_first": same,
                }
            )
    kkt_t, plan_t = pd.DataFrame(kkt_rows), pd.DataFrame(plan_rows)
    for t in (kkt_t, plan_t):
        base = t.groupby("experiment")["cpu_s"].transform("first")
        t["cpu_ratio_to_first"] = t["cpu_s"] / base
    out = Path(ns.out)
    out.mkdir(parents=True, exist_ok=True)
    write_frame_atomic(out / "bench_lp_kkt.csv", kkt_t)
    write_frame_atomic(out / "bench_lp.csv", plan_t)
    print("\nwhole-programme polish (two LPs), median of", ns.runs, "runs:\n")
    print(markdown(kkt_t))
    print("\nwhole plans:\n")
    print(markdown(plan_t))


if __name__ == "__main__":
    main()
