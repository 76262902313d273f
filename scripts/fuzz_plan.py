"""Plan random requests through the command line and re-check every answer with separate code.

Each request draws a working region (-50 .. +60 degC, 5-30 degC wide), an approximation
region around it, tau 600-3600 s, dT0 0-6 degC, 3-8 levels, delta 0.05-0.1 degC/min,
budgets of 4-12 h, 5-15 min segments, chamber rates from -0.5/+1.5 to -3/+3 degC/min and,
often, a chamber floor or ceiling close to the region, and runs ``schedsyn plan`` on it
with an effort limit. The exported step table is re-simulated by
``scripts/check_tables.py`` (scipy's ODE solver, its own level counting), and a problem
is reported when:

* the command crashed (a traceback, or an exit code other than 0, 1 or 2), or a
  refusal (exit 2) took more than three lines;
* the coverage plan.json reports differs from the re-check by more than one bin in
  twenty, or a plan called complete is not complete by the re-check;
* the table breaks the budget, the rate limits or the return to the end temperature;
* a complete plan is shorter than its proven lower bound, or the exit code disagrees
  with plan.json's ``complete``;
* with ``--end-soak``: the device is not within the end tolerance (0.5 degC) of where it
  settles (the end temperature plus dT0) when the table ends (a soak that does not fit is
  a refusal, exit 2, held to the three lines above).

``--objective informative`` plans every request with that objective (the shortest plan
run on to the budget for the drift fit); ``--end-soak`` appends the soak.

One JSON line per request on stdout (the request, exit code, wall time, coverage both
ways, duration, bound and problems); a summary on stderr; exit 1 when any request had a
problem. Found so far (2026-11-26, seed 7, 30 requests): an error that said "lengthen the
duration" for a bin the chamber floor cannot reach, and a ceiling request stuck with
every band design (both fixed); 2026-11-28, seed 45, 8 requests, ``--objective informative
--end-soak``: "no complete plan exists within 111 min" for a 240-min request whose soak
did not fit, and graded plans that ignored the end soak (both fixed).

Usage::

    python scripts/fuzz_plan.py [--seed 7] [--requests 30] [--effort-s 15] [--out DIR]
        [--objective shortest|margin|informative] [--end-soak]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_tables import check  # noqa: E402  (the separate re-check, next to this file)


def draw(rng: np.random.Generator, i: int) -> dict:
    """One random request, as the ``schedsyn plan`` options' values."""
    width = float(rng.choice([5, 8, 10, 15, 20, 25, 30]))
    lo = float(np.round(rng.uniform(-50, 60 - width)))
    hi = lo + width
    floor = float(rng.choice([-70.0, -70.0, np.round(lo - rng.uniform(2, 10), 1)]))
    ceiling = float(rng.choice([80.0, 80.0, np.round(hi + rng.uniform(2, 10), 1)]))
    return {
        "name": f"r{i}",
        "working": (lo, hi),
        "approx": (lo - float(rng.choice([0, 2, 5, 10])), hi + float(rng.choice([0, 2, 5, 10]))),
        "levels": int(rng.choice([3, 4, 5, 6, 6, 6, 8])),
        "delta_c_per_min": float(rng.choice([0.05, 0.05, 0.08, 0.1])),
        "segment_min": float(rng.choice([5, 5, 10, 15])),
        "duration_max_min": float(rng.choice([240, 360, 480, 540, 720])),
        "tau_s": float(rng.choice([600, 1200, 1800, 2400, 3000, 3600])),
        "dt0_c": float(np.round(rng.uniform(0, 6), 1)),
        "rate_min_c_per_min": float(rng.choice([-0.5, -1, -1, -2, -3])),
        "rate_max_c_per_min": float(rng.choice([1.5, 3, 3, 3])),
        # the start (20 degC) must lie within the chamber's range
        "chamber_min_c": min(floor, 19.0),
        "chamber_max_c": max(ceiling, 21.0),
    }


def arguments(
    req: dict, effort_s: float, out: Path, objective: str = "shortest", end_soak: bool = False
) -> list[str]:
    args = ["plan", "--name", req["name"], "--effort-s", f"{effort_s:g}", "--out", str(out)]
    args += ["--objective", objective] + (["--end-soak"] if end_soak else [])
    for key, value in req.items():
        if key == "name":
            continue
        values = value if isinstance(value, tuple) else (value,)
        args += [f"--{key.replace('_', '-')}", *(f"{v:g}" for v in values)]
    return args + ["--quiet"]


def problems_of(
    req: dict, proc: subprocess.CompletedProcess, out: Path, end_soak: bool = False
) -> tuple[list, dict]:
    """The problems of one answer, and the figures reported for it."""
    problems: list[str] = []
    seen: dict = {}
    if "Traceback" in proc.stderr or proc.returncode not in (0, 1, 2):
        problems.append(f"crash (exit {proc.returncode}): {proc.stderr.strip()[-600:]}")
        return problems, seen
    if proc.returncode == 2:
        seen["error"] = proc.stderr.strip()
        if len(proc.stderr.strip().splitlines()) > 3:
            problems.append("a refusal of more than three lines")
        return problems, seen
    plan = json.loads((out / "plan.json").read_text(encoding="utf-8"))
    lo, hi = req["working"]
    res = check(
        out / "steps.csv",
        req["tau_s"],
        req["dt0_c"],
        lo,
        hi,
        req["levels"],
        req["delta_c_per_min"],
        t0_c=20.0,
    )
    bound = plan["duration_lower_bound_min"]
    seen.update(
        coverage=plan["coverage"],
        coverage_recheck=res["coverage"],
        duration_min=res["duration_min"],
        bound_min=bound,
        complete=plan["complete"],
    )
    if abs(res["coverage"] - plan["coverage"]) > 0.051:
        problems.append(f"coverage {plan['coverage']:.2f}, re-check {res['coverage']:.2f}")
    if plan["complete"] and res["coverage"] < 1.0:
        problems.append("called complete, the re-check is not")
    if res["duration_min"] > req["duration_max_min"] + 1e-6:
        problems.append(f"{res['duration_min']:g} min over the {req['duration_max_min']:g}")
    if (
        res["rate_min"] < req["rate_min_c_per_min"] - 1e-3
        or res["rate_max"] > req["rate_max_c_per_min"] + 1e-3
    ):
        problems.append(f"rates {res['rate_min']:.3f} .. {res['rate_max']:.3f} out of limits")
    if abs(res["chamber_end_c"] - 20.0) > 0.05:
        problems.append(f"ends at {res['chamber_end_c']:g} degC")
    if plan["complete"] and bound is not None and bound > res["duration_min"] + 1e-6:
        problems.append(f"complete in {res['duration_min']:g} min, below its bound {bound:.1f}")
    if (proc.returncode == 0) != bool(plan["complete"]):
        problems.append(f"exit {proc.returncode} but complete = {plan['complete']}")
    if end_soak:
        settled_c = 20.0 + req["dt0_c"]
        seen.update(device_end_c=res["device_end_c"], informative=plan.get("informative"))
        if abs(res["device_end_c"] - settled_c) > 0.5 + 0.02:
            problems.append(
                f"--end-soak: the device ends at {res['device_end_c']:.2f} degC, "
                f"{settled_c:g} when settled"
            )
    return problems, seen


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--requests", type=int, default=30)
    ap.add_argument("--effort-s", type=float, default=15.0, help="each plan's effort limit")
    ap.add_argument("--out", type=Path, default=None, help="keep the plans here")
    ap.add_argument(
        "--objective", default="shortest", choices=("shortest", "margin", "informative")
    )
    ap.add_argument("--end-soak", action="store_true", help="append the end soak (plan --end-soak)")
    args = ap.parse_args()
    if args.requests < 1 or not args.effort_s > 0:
        ap.error("--requests must be >= 1 and --effort-s > 0")
    exe = shutil.which("schedsyn") or ""
    command = [exe] if exe else [sys.executable, "-m", "schedsyn"]
    rng = np.random.default_rng(args.seed)
    root = args.out or Path(tempfile.mkdtemp(prefix="schedsyn-fuzz-"))
    bad = 0
    for i in range(args.requests):
        req = draw(rng, i)
        out = root / req["name"]
        tic = time.perf_counter()
        proc = subprocess.run(
            command + arguments(req, args.effort_s, out, args.objective, args.end_soak),
            capture_output=True,
            text=True,
        )
        problems, seen = problems_of(req, proc, out, args.end_soak)
        bad += bool(problems)
        row = {"request": req, "exit": proc.returncode, "wall_s": time.perf_counter() - tic}
        print(json.dumps({**row, **seen, "problems": problems}), flush=True)
        print(
            f"{req['name']}: exit {proc.returncode}, {row['wall_s']:.0f} s"
            + (f", PROBLEMS: {problems}" if problems else ""),
            file=sys.stderr,
        )
    if args.out is None:
        shutil.rmtree(root, ignore_errors=True)
    print(f"{bad} of {args.requests} requests with a problem", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
