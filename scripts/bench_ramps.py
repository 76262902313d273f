"""Run the robust search's ramp rung on the red team's hand-made boxes and re-check it.

Requests: every table in ``data/robust_hand/`` (README.md there), read from its metadata:
region, levels, limits, nominal model and robust box. For each,
:func:`schedsyn.planner.ramps.ramp_search` (deterministic: a count of objective
evaluations, not a clock, bounds it); a found table goes to ``OUT/<table>/steps.csv`` and
is re-checked independently (tests/independent.py: scipy's ODE solver and a plain count)
on an ``N_TAU x N_DT0`` grid over the box, with its limits. Writes ``OUT/table.md`` and
``OUT/summary.csv``: per request the ramp table's duration against the hand table's, the
legs, the evaluations and seconds spent, and the independent check. Exit 1 when a found
table fails the independent check.

    PYTHONPATH=. python scripts/bench_ramps.py [--out out_ramps] [--only r10 ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import pandas as pd

from schedsyn.planner import ExperimentSpec
from schedsyn.planner.ramps import ramp_search
from schedsyn.programme import read_step_meta, read_steps

ROOT = Path(__file__).resolve().parents[1]
HAND = ROOT / "data" / "robust_hand"
N_TAU, N_DT0 = 13, 10


def _independent():
    spec = importlib.util.spec_from_file_location("independent", ROOT / "tests" / "independent.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def request(path: Path):
    """(spec, params, limits, tau range, dT0 range) recorded in a hand table's metadata."""
    meta = read_step_meta(path)
    spec = ExperimentSpec(
        name=path.stem.split("_")[0],
        working_lo_c=meta.working_lo_c,
        working_hi_c=meta.working_hi_c,
        approx_lo_c=meta.approx_lo_c,
        approx_hi_c=meta.approx_hi_c,
        levels_required=meta.levels_required,
        delta_c_per_min=meta.delta_c_per_min,
    )
    tau, dt0 = meta.robust_box
    return spec, meta.params(), meta.limits(), tau, dt0


def check(steps_csv: Path, spec, params, limits, tau, dt0, ind) -> dict:
    """The table over the box by independent code (tests/independent.py): fewest levels,
    device range, and every limit of the request."""
    got = ind.box_table_check(
        steps_csv,
        (spec.working_lo_c, spec.working_hi_c),
        spec.delta_c_per_min,
        tau or (params.tau_s, params.tau_s),
        dt0 or (params.dt0_c, params.dt0_c),
        limits.t_init_c,
        N_TAU,
        N_DT0,
    )
    (dev_lo, dev_hi), (rate_lo, rate_hi) = got["device_c"], got["rates"]
    (tk_lo, tk_hi), (start, end) = got["chamber_c"], got["ends_c"]
    ok = (
        got["fewest_levels"] >= spec.levels_required
        and limits.device_min_c - 1e-6 <= dev_lo
        and dev_hi <= limits.device_max_c + 1e-6
        and got["duration_min"] <= limits.duration_max_min + 1e-9
        and limits.rate_min_c_per_min - 1e-9 <= rate_lo
        and rate_hi <= limits.rate_max_c_per_min + 1e-9
        and limits.chamber_min_c - 1e-9 <= tk_lo
        and tk_hi <= limits.chamber_max_c + 1e-9
        and abs(start - limits.start_c) < 1e-9
        and abs(end - limits.end_c) <= limits.end_tol_c + 1e-9
    )
    return {
        "independent_min_levels": got["fewest_levels"],
        "device_min_c": round(dev_lo, 2),
        "device_max_c": round(dev_hi, 2),
        "independent_ok": bool(ok),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out_ramps"))
    ap.add_argument("--only", nargs="*", default=None, help="table name prefixes (r10 ...)")
    args = ap.parse_args(argv)
    ind = _independent()
    rows = []
    tables = sorted(HAND.glob("*.csv"))
    names = {p.stem.split("_")[0] for p in tables}
    unknown = sorted(set(args.only or ()) - names)
    if unknown:
        ap.error(f"--only: no hand table for {', '.join(unknown)} (there are {sorted(names)})")
    seen = set()
    for path in tables:
        name = path.stem.split("_")[0]
        if name in seen or (args.only and name not in args.only):
            continue  # (one request per name: r08 has two hand tables)
        seen.add(name)
        spec, params, limits, tau, dt0 = request(path)
        hand = min(read_steps(p).total_min for p in tables if p.stem.split("_")[0] == name)
        print(f"{name}: searching ...", flush=True)
        tic = time.perf_counter()
        found = ramp_search(spec, params, limits, tau, dt0)
        seconds = time.perf_counter() - tic
        row = {
            "request": name,
            "levels": spec.levels_required,
            "hand_min": hand,
            "ramp_min": None,
            "ratio": None,
            "legs": None,
            "solve_s": round(seconds, 1),
        }
        if found is not None:
            out = args.out / name
            out.mkdir(parents=True, exist_ok=True)
            csv = found.programme.to_csv(out / "steps.csv")
            row.update(
                ramp_min=found.programme.total_min,
                ratio=round(found.programme.total_min / hand, 2),
                legs=found.legs,
                evals=found.evals,
                box_full_share=found.box_check["full_share"],
                **check(csv, spec, params, limits, tau, dt0, ind),
            )
        rows.append(row)
        print(f"  {row}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    df = pd.DataFrame(rows)
    for col in ("legs", "evals", "independent_min_levels"):
        if col in df:
            df[col] = df[col].astype("Int64")
    df.to_csv(args.out / "summary.csv", index=False)
    cols = list(df.columns)
    md = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join("" if pd.isna(v) else str(v) for v in r) + " |" for r in df.values]
    (args.out / "table.md").write_text("\n".join(md) + "\n")
    print(df.to_string(index=False))
    found = df["ramp_min"].notna()
    ok = df["independent_ok"] if "independent_ok" in df else pd.Series(True, df.index)
    bad = found & (ok != True)  # noqa: E712 (NaN where nothing was found)
    return 1 if bad.any() else 0


if __name__ == "__main__":
    sys.exit(main())
