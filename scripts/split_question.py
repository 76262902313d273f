"""Issue 12's question: do three experiments cover -50 .. +60 °C, and with which chamber?

For each chamber variant below, ``schedsyn.split.split_range`` proves the fewest
experiments any split needs (lower bound) and searches the fewest it can verify by
complete plans, stopping once ``--max-experiments`` (default 3) experiments do not cover
the range. Writes ``out/split_question.csv`` and ``out/split_question.md`` (a markdown
table: variant, chamber, proven minimum, experiments verified, covered, regions). Slow:
tens of minutes per variant on 2 cores (every width tried is a full plan).

Usage::

    python scripts/split_question.py [--variants default cool-2 ...] [--max-experiments 3]
        [--workers 2] [--out out]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import pandas as pd

from schedsyn.campaign import stderr_progress
from schedsyn.io import write_frame_atomic, write_text_atomic
from schedsyn.params import Limits
from schedsyn.split import SplitSettings, split_range

#: Chamber variants: name -> changes to the default Limits (the paper's ESPEC rates,
#: -70 .. +80 °C air).
VARIANTS = {
    "default": {},
    "floor-90": {"chamber_min_c": -90.0},
    "cool-1.5": {"rate_min_c_per_min": -1.5},
    "cool-2": {"rate_min_c_per_min": -2.0},
    "cool-2-floor-90-ceiling-100": {
        "rate_min_c_per_min": -2.0,
        "chamber_min_c": -90.0,
        "chamber_max_c": 100.0,
    },
    "rates-3-3": {"rate_min_c_per_min": -3.0, "rate_max_c_per_min": 3.0},
}


def _markdown(frame: pd.DataFrame) -> str:
    """A markdown table (no tabulate dependency)."""
    head = "| " + " | ".join(frame.columns) + " |"
    rule = "|" + "---|" * len(frame.columns)
    body = ["| " + " | ".join(str(v) for v in row) + " |" for row in frame.itertuples(False)]
    return "\n".join([head, rule, *body]) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--range", nargs=2, type=float, default=(-50.0, 60.0))
    ap.add_argument("--max-experiments", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--budget-s", type=float, default=7200.0)
    ap.add_argument("--out", default="out")
    args = ap.parse_args(argv)
    rows = []
    for name in args.variants:
        limits = dataclasses.replace(Limits(), **VARIANTS[name])
        tic = time.perf_counter()
        res = split_range(
            args.range[0],
            args.range[1],
            None,
            limits,
            {},
            settings=SplitSettings(
                max_experiments=args.max_experiments, time_budget_s=args.budget_s
            ),
            workers=args.workers,
            progress=stderr_progress,
        )
        regions = " ".join(
            f"[{e.spec.working_lo_c:g},{e.spec.working_hi_c:g}]" for e in res.experiments
        )
        rows.append(
            {
                "variant": name,
                "rate_min_c_per_min": limits.rate_min_c_per_min,
                "rate_max_c_per_min": limits.rate_max_c_per_min,
                "chamber_min_c": limits.chamber_min_c,
                "chamber_max_c": limits.chamber_max_c,
                "proven_min_experiments": res.min_experiments,
                "experiments_verified": len(res.experiments),
                "covered": res.covered,
                "covered_to_c": res.covered_to_c,
                "regions": regions,
                "durations_min": " ".join(f"{e.plan.duration_min:g}" for e in res.experiments),
                "plans": res.plans,
                "wall_s": round(time.perf_counter() - tic, 1),
            }
        )
        print("\n".join([f"== {name}", *res.lines()]), flush=True)
        frame = pd.DataFrame(rows)
        out = Path(args.out)
        write_frame_atomic(out / "split_question.csv", frame)
        write_text_atomic(out / "split_question.md", _markdown(frame))
    return 0


if __name__ == "__main__":
    sys.exit(main())
