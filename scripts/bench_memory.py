"""Peak memory and wall time of `schedsyn estimate` and `schedsyn diagnose` on a big log.

Generates a 9-hour log of the paper-like baseline plan (data/baseline_exp1_steps.csv, held
at its end temperature to 9 h) sampled every 5.6 ms: 5.79 M rows, ~200 MB of CSV
(time_s, t_int_c with noise 0.02 degC quantised to 0.01, tk_set_c, tk_air_c), written to a
temporary directory. Then runs each case as its own `python -m schedsyn` subprocess and
records its peak resident memory (``os.wait4``'s ``ru_maxrss``: that child alone) and
wall time. Target (issue 13): a 200 MB log within 1 GB peak RSS for `schedsyn estimate`.

Run: python scripts/bench_memory.py [--rows 5800000] [--cases all] [--out out]
     [--src DIR]   (run the cases from another source tree, e.g. an older checkout:
                    PYTHONPATH=DIR; options it does not know make the case fail)
Writes OUT/bench_memory.csv and prints a markdown table. Timings are of one run on a
shared machine: read them as rough.
"""

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import schedsyn

ROOT = Path(__file__).resolve().parents[1]
STEPS = ROOT / "data" / "baseline_exp1_steps.csv"
#: name -> (subcommand arguments after LOG; "{out}" is the case's output directory)
CASES = {
    "estimate": ["estimate", "{log}", "--out", "{out}"],
    "estimate --every 1": ["estimate", "{log}", "--out", "{out}", "--every", "1"],
    "estimate --method model --every 1": [
        "estimate",
        "{log}",
        "--out",
        "{out}",
        "--method",
        "model",
        "--every",
        "1",
    ],
    "diagnose": ["diagnose", "{log}", "--out", "{out}"],
}
GEN_CHUNK_ROWS = 100_000


def nine_hour_plan() -> schedsyn.Programme:
    p = schedsyn.read_steps(STEPS)
    return schedsyn.Programme(
        np.append(p.durations_min, 540.0 - p.total_min),
        np.append(p.rates_c_per_min, 0.0),
        p.start_c,
    )


def write_big_log(path: Path, rows: int, seed: int = 0) -> float:
    """The baseline plan over 9 h at ``32400 / (rows - 1)`` s (rounded to 0.1 ms); returns
    the sampling step, s. Written chunk by chunk (bounded memory)."""
    plan = nine_hour_plan()
    step_s = round(32400.0 / (rows - 1), 4)
    rng = np.random.default_rng(seed)
    with path.open("w", newline="") as fh:
        for lo in range(0, rows, GEN_CHUNK_ROWS):
            k = np.arange(lo, min(lo + GEN_CHUNK_ROWS, rows))
            t_s = np.round(k * step_s, 4)
            traj = schedsyn.simulate(plan, times_min=t_s / 60.0)
            noisy = traj.t_c + 0.02 * rng.standard_normal(k.size)
            air = traj.tk_c + 0.02 * rng.standard_normal(k.size)
            frame = pd.DataFrame(
                {
                    "time_s": t_s,
                    "t_int_c": np.round(np.round(noisy / 0.01) * 0.01, 2),
                    "tk_set_c": np.round(traj.tk_c, 3),
                    "tk_air_c": np.round(air, 2),
                }
            )
            frame.to_csv(fh, header=lo == 0, index=False)
    return step_s


def run_case(args: list[str], env: dict, cwd: Path) -> tuple[int, float, float, str]:
    """(exit code, peak RSS MB, wall s, last stderr line) of one subprocess, run in
    ``cwd`` (not the checkout: ``python -m`` puts the working directory first on the path)."""
    with tempfile.TemporaryFile() as err, tempfile.TemporaryFile() as out:
        tic = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "schedsyn", *args], stdout=out, stderr=err, env=env, cwd=cwd
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - tic
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        lines = err.read().decode(errors="replace").strip().splitlines()
    return proc.returncode, usage.ru_maxrss / 1024.0, wall, lines[-1] if lines else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=5_800_000)
    ap.add_argument("--cases", default="all", help=f"comma list of: {', '.join(CASES)}")
    ap.add_argument("--out", default="out")
    ap.add_argument("--src", default=None, help="source tree to run (default: this one)")
    ap.add_argument("--keep-log", default=None, help="also copy the generated log here")
    args = ap.parse_args()
    names = list(CASES) if args.cases == "all" else [c.strip() for c in args.cases.split(",")]
    unknown = [c for c in names if c not in CASES]
    if unknown:
        ap.error(f"unknown case(s) {unknown}; known: {list(CASES)}")
    env = dict(os.environ)
    src = Path(args.src).resolve() if args.src else ROOT
    env["PYTHONPATH"] = str(src) + os.pathsep + env.get("PYTHONPATH", "")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as tmp:
        log = Path(tmp) / "big_log.csv"
        tic = time.perf_counter()
        step_s = write_big_log(log, args.rows)
        size_mb = log.stat().st_size / 1e6
        print(
            f"generated {args.rows} rows ({size_mb:.0f} MB, step {step_s:g} s) in "
            f"{time.perf_counter() - tic:.0f} s",
            file=sys.stderr,
        )
        if args.keep_log:
            import shutil

            shutil.copy(log, args.keep_log)
        for name in names:
            case_out = Path(tmp) / name.replace(" ", "_").replace("-", "")
            cmd = [a.format(log=log, out=case_out) for a in CASES[name]]
            print(f"running {name} ...", file=sys.stderr, flush=True)
            code, rss, wall, last = run_case(cmd, env, Path(tmp))
            grad = case_out / "gradient.csv"
            rows.append(
                {
                    "case": f"schedsyn {name}",
                    "log_rows": args.rows,
                    "log_mb": round(size_mb, 1),
                    "exit_code": code,
                    "peak_rss_mb": round(rss, 0),
                    "wall_s": round(wall, 1),
                    "gradient_csv_mb": round(grad.stat().st_size / 1e6, 1)
                    if grad.exists()
                    else None,
                    "source": "this tree" if args.src is None else str(src),
                    "stderr_tail": "" if code == 0 else last[:120],
                }
            )
            print(rows[-1], file=sys.stderr)
    table = pd.DataFrame(rows)
    table.to_csv(out / "bench_memory.csv", index=False)
    print(
        f"## Peak memory, {args.rows} rows ({platform.machine()}, Python "
        f"{platform.python_version()}, {os.cpu_count()} cores, shared)\n"
    )
    cols = ["case", "log_mb", "exit_code", "peak_rss_mb", "wall_s", "gradient_csv_mb"]
    print("| " + " | ".join(cols) + " |")
    print("|" + "|".join("---" for _ in cols) + "|")
    for r in rows:
        print("| " + " | ".join(str(r[c]) for c in cols) + " |")
    ok = all(
        r["exit_code"] == 0 and r["peak_rss_mb"] <= 1024
        for r in rows
        if r["case"].startswith("schedsyn estimate")
    )
    print(f"\ntarget (estimate within 1 GB peak RSS): {'PASS' if ok else 'FAIL'}")
    print(f"wrote {out}/bench_memory.csv")


if __name__ == "__main__":
    main()
