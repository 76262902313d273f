"""Red team of `schedsyn replan`: devices that differ from the model, simulated here.

    python scripts/redteam_replan.py PLAN_DIR --at-min 30 [60 ...] [--device NAME ...]
        [--second-min M2] [--seed N] [--out out/redteam_replan] [--timeout-s 2400]

For each device and minute M: the plan's programme is simulated on the device up to M
and logged (noise, quantisation, sampling, a few missing rows), `schedsyn replan` runs on
that log as an operator would (a subprocess, `--quiet`), and the whole new step table it
writes (executed steps, then the new ones) is simulated on the same device from t = 0
and counted. With `--second-min M2` the replanned folder is re-planned once more at M2
on the log of the new programme.

Independent of schedsyn's own code: the device is integrated with scipy's `solve_ivp`
(LSODA) piecewise over the steps, the step table is parsed as text, and the coverage is
counted by a plain loop (a pass is a maximal run of 0.1 min samples inside a 1 °C bin,
its gradient the mean dT/dt over the run; levels greedy from the smallest, `delta`
apart), the definition of `schedsyn/coverage.py`.

Devices (`DEVICES`): tau and dT0 off nominal; a second thermal mass (`tau2 dM/dt + M =
Tk_air`, the device driven by M); tau depending on temperature; dT0 drifting; the
chamber air lagging its setpoint; coarse or fine sampling. Each row prints what replan
claimed (exit code, predicted coverage, the uncertainty box) against the coverage the
device reaches, and whether the table keeps the executed steps, the rate limits, the
device limits and the 20 °C end. Writes DIR/redteam.csv.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ the step table
@dataclass
class Table:
    """A step table as typed in: start, duration, chamber at both ends, rate."""

    start_min: np.ndarray
    dur_min: np.ndarray
    tk0_c: np.ndarray
    tk1_c: np.ndarray
    rate_c_per_min: np.ndarray
    meta: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)

    @property
    def end_min(self) -> float:
        return float(self.start_min[-1] + self.dur_min[-1])

    def _step(self, t_min: np.ndarray) -> np.ndarray:
        i = np.searchsorted(self.start_min, t_min, side="right") - 1
        return np.clip(i, 0, self.start_min.size - 1)

    def tk_set(self, t_min) -> np.ndarray:
        t = np.asarray(t_min, dtype=float)
        i = self._step(t)
        return self.tk0_c[i] + self.rate_c_per_min[i] * np.clip(
            t - self.start_min[i], 0, self.dur_min[i]
        )

    def rate_at(self, t_min) -> np.ndarray:
        t = np.asarray(t_min, dtype=float)
        i = self._step(t)
        inside = (t >= self.start_min[i]) & (t < self.start_min[i] + self.dur_min[i])
        return np.where(inside, self.rate_c_per_min[i], 0.0)


def read_table(path: Path) -> Table:
    """Parse a step CSV as text; list what breaks the table's own metadata limits."""
    meta, rows = {}, []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            key, _, value = line[1:].partition(":")
            meta[key.strip()] = value.strip()
        elif line.strip():
            rows.append(line.split(","))
    frame = pd.DataFrame(rows[1:], columns=rows[0])
    col = lambda name: frame[name].astype(float).to_numpy()  # noqa: E731
    tab = Table(
        col("start_min"),
        col("duration_min"),
        col("tk_start_c"),
        col("tk_end_c"),
        col("rate_c_per_min"),
        meta,
    )
    p = tab.problems
    ends = tab.start_min[:-1] + tab.dur_min[:-1]
    if abs(tab.start_min[0]) > 1e-9 or np.any(np.abs(tab.start_min[1:] - ends) > 1e-6):
        p.append("steps are not contiguous from 0")
    if np.any(np.abs(tab.tk0_c[1:] - tab.tk1_c[:-1]) > 1e-6):
        p.append("chamber jumps between steps")
    if np.any(np.abs(tab.tk0_c + tab.rate_c_per_min * tab.dur_min - tab.tk1_c) > 0.051):
        p.append("rate x duration disagrees with tk_end - tk_start")
    lo, hi = float(meta.get("rate_min_c_per_min", -1)), float(meta.get("rate_max_c_per_min", 3))
    if tab.rate_c_per_min.min() < lo - 1e-6 or tab.rate_c_per_min.max() > hi + 1e-6:
        u = tab.rate_c_per_min
        p.append(f"rates {u.min():.3f}..{u.max():.3f} degC/min outside {lo}..{hi}")
    if abs(tab.tk1_c[-1] - float(meta.get("end_c", 20))) > float(meta.get("end_tol_c", 0.5)) + 1e-9:
        p.append(f"ends at {tab.tk1_c[-1]} degC")
    if tab.end_min > float(meta.get("duration_max_min", 540)) + 1e-6:
        p.append(f"lasts {tab.end_min:g} min")
    return tab


# ------------------------------------------------------------------ the device
@dataclass(frozen=True)
class Device:
    """tau(T) dT/dt + T = M + dT0(t); tau2 dM/dt + M = A; tau_air dA/dt + A = Tk_set."""

    name: str
    tau_s: float = 2400.0
    dt0_c: float = 3.0
    tau2_min: float = 0.0  # second thermal mass (case, mount); 0: none
    air_lag_min: float = 0.0  # chamber air behind its setpoint; 0: none
    tau_per_c: float = 0.0  # relative change of tau per degC from 20 degC
    dt0_drift_c_per_h: float = 0.0
    t0_c: float = 20.0
    noise_c: float = 0.02
    quant_c: float = 0.01
    sample_s: float = 10.0
    missing_rows: int = 0


DEVICES = {
    d.name: d
    for d in (
        Device("nominal"),
        Device("fast_cold", tau_s=1800, dt0_c=0),
        Device("slow_hot", tau_s=3600, dt0_c=6),
        Device("fast_hot", tau_s=1800, dt0_c=6),
        Device("tau2800_dt0_1", tau_s=2800, dt0_c=1),
        Device("case10_tau3000_dt0_1", tau_s=3000, dt0_c=1, tau2_min=10),
        Device("case15", tau2_min=15),
        Device("air_lag3", air_lag_min=3),
        Device("tau_of_t", tau_per_c=-0.006),
        Device("dt0_drift", dt0_drift_c_per_h=0.5),
        Device("warm_start", t0_c=23.0),
        Device(
            "coarse_log",
            tau_s=2800,
            dt0_c=5,
            noise_c=0.05,
            quant_c=0.1,
            sample_s=60,
            missing_rows=5,
        ),
        Device("fine_log", tau_s=2000, dt0_c=1, noise_c=0.01, sample_s=1),
        Device(
            "combined",
            tau_s=3300,
            dt0_c=4.5,
            tau2_min=8,
            air_lag_min=2,
            dt0_drift_c_per_h=0.3,
            noise_c=0.03,
            quant_c=0.05,
            sample_s=30,
            missing_rows=3,
        ),
    )
}


def simulate(dev: Device, tab: Table, t_end_min: float):
    """Piecewise LSODA over the steps; returns f(t_min) -> (T, dT/dt per min, air)."""

    def rhs(t, y):
        air, mass, temp = y
        d_air = (tab.tk_set(t) - air) / dev.air_lag_min if dev.air_lag_min > 0 else tab.rate_at(t)
        d_mass = (air - mass) / dev.tau2_min if dev.tau2_min > 0 else d_air
        tau_min = dev.tau_s / 60.0 * max(0.3, 1.0 + dev.tau_per_c * (temp - 20.0))
        dt0 = dev.dt0_c + dev.dt0_drift_c_per_h * t / 60.0
        return [float(d_air), float(d_mass), (mass + dt0 - temp) / tau_min]

    knots = np.unique(np.concatenate(([0.0, t_end_min], tab.start_min, [tab.end_min])))
    knots = knots[knots <= t_end_min]
    y = np.array([tab.tk_set(0.0), tab.tk_set(0.0), dev.t0_c], dtype=float)
    pieces = []
    for a, b in zip(knots[:-1], knots[1:], strict=True):
        sol = solve_ivp(rhs, (a, b), y, method="LSODA", rtol=1e-9, atol=1e-9, dense_output=True)
        if not sol.success:
            raise RuntimeError(sol.message)
        pieces.append((a, b, sol.sol))
        y = sol.y[:, -1]
    starts = np.array([p[0] for p in pieces])

    def at(t_min):
        t = np.atleast_1d(np.asarray(t_min, dtype=float))
        k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(pieces) - 1)
        state = np.empty((3, t.size))
        for j in np.unique(k):
            a, b, f = pieces[j]
            state[:, k == j] = f(np.clip(t[k == j], a, b))
        grad = np.array([rhs(tt, state[:, i])[2] for i, tt in enumerate(t)])
        return state[2], grad, state[0]

    return at


def coverage(temp_c, grad_c_per_min, lo_c, hi_c, levels, delta_c_per_min):
    """Share of 1 degC bins with >= levels distinct pass gradients; per-bin levels."""
    n_bins = int(round(hi_c - lo_c))
    passes: dict[int, list[float]] = {b: [] for b in range(n_bins)}
    bins = np.where((temp_c >= lo_c) & (temp_c < hi_c), np.floor(temp_c - lo_c), -1).astype(int)
    i = 0
    while i < bins.size:
        j = i
        while j + 1 < bins.size and bins[j + 1] == bins[i]:
            j += 1
        if bins[i] >= 0:
            passes[int(bins[i])].append(float(np.mean(grad_c_per_min[i : j + 1])))
        i = j + 1
    per_bin = {}
    for b, grads in passes.items():
        count, last = 0, -math.inf
        for g in sorted(grads):
            if g - last >= delta_c_per_min - 1e-12:
                count, last = count + 1, g
        per_bin[lo_c + b] = count
    covered = sum(v >= levels for v in per_bin.values())
    return covered / n_bins, {k: v for k, v in per_bin.items() if v < levels}


def evaluate(dev: Device, tab: Table) -> dict:
    m = tab.meta
    lo, hi = float(m["working_lo_c"]), float(m["working_hi_c"])
    t = np.round(np.arange(0.0, tab.end_min + 1e-9, 0.1), 6)
    temp, grad, _ = simulate(dev, tab, tab.end_min)(t)
    cov, short = coverage(
        temp, grad, lo, hi, int(m.get("levels_required", 6)), float(m.get("delta_c_per_min", 0.05))
    )
    over = max(
        float(m.get("device_min_c", -52)) - temp.min(),
        temp.max() - float(m.get("device_max_c", 62)),
        0,
    )
    return {
        "coverage": cov,
        "short": short,
        "device_excess_c": float(over),
        "t_range_c": (round(float(temp.min()), 2), round(float(temp.max()), 2)),
    }


def make_log(dev: Device, tab: Table, upto_min: float, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    time_s = np.arange(0.0, upto_min * 60 + 1e-9, dev.sample_s)
    temp, _, air = simulate(dev, tab, upto_min)(time_s / 60.0)
    meas = temp + rng.normal(0, dev.noise_c, time_s.size)
    if dev.quant_c > 0:
        meas = np.round(meas / dev.quant_c) * dev.quant_c
    log = pd.DataFrame(
        {
            "time_s": time_s,
            "t_int_c": np.round(meas, 4),
            "tk_set_c": np.round(tab.tk_set(time_s / 60.0), 3),
            "tk_air_c": np.round(air + rng.normal(0, 0.05, time_s.size), 2),
        }
    )
    if dev.missing_rows:  # isolated rows, away from the start and the last 5 min
        pool = np.flatnonzero((time_s > 120) & (time_s < upto_min * 60 - 300))
        if pool.size:
            log = log.drop(index=rng.choice(pool, min(dev.missing_rows, pool.size), replace=False))
    return log.reset_index(drop=True)


# ------------------------------------------------------------------ one re-plan
def replan_case(
    dev: Device, plan_dir: Path, at_min: int, out: Path, seed: int, timeout_s: float
) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    before = read_table(plan_dir / "steps.csv")
    log_path = out / "log.csv"
    make_log(dev, before, at_min, seed).to_csv(log_path, index=False)
    tic = time.perf_counter()
    cmd = [
        sys.executable,
        "-m",
        "schedsyn",
        "replan",
        str(log_path),
        str(plan_dir),
        "--at-min",
        str(at_min),
        "--out",
        str(out / "replan"),
        "--quiet",
    ]
    try:
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {"device": dev.name, "at_min": at_min, "exit": "timeout"}
    row = {
        "device": dev.name,
        "at_min": at_min,
        "exit": proc.returncode,
        "seconds": round(time.perf_counter() - tic, 1),
        "open_loop": evaluate(dev, before)["coverage"],
    }
    if proc.returncode not in (0, 1):
        row["error"] = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        return row
    claim = json.loads((out / "replan" / "replan.json").read_text())
    box = claim.get("uncertainty_box") or {}
    after = read_table(out / "replan" / "steps.csv")
    t = np.arange(0.0, at_min + 1e-9, 0.05)
    true = evaluate(dev, after)
    row.update(
        {
            "choice": claim["choice"],
            "claimed_complete": claim["complete"],
            "claimed_coverage": claim["predicted"]["coverage"],
            "box_complete": box.get("complete_at_every_corner"),
            "box_worst": box.get("worst_coverage"),
            "true_coverage": true["coverage"],
            "true_short": true["short"],
            "device_excess_c": true["device_excess_c"],
            "t_range_c": true["t_range_c"],
            "table_problems": after.problems,
            "history_mismatch_c": float(np.max(np.abs(after.tk_set(t) - before.tk_set(t)))),
            "duration_min": after.end_min,
        }
    )
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("plan_dir", type=Path)
    ap.add_argument("--at-min", type=int, nargs="+", default=[30, 60])
    ap.add_argument(
        "--device",
        nargs="+",
        default=["fast_cold", "slow_hot", "tau_of_t", "dt0_drift"],
        choices=sorted(DEVICES),
    )
    ap.add_argument("--second-min", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout-s", type=float, default=2400.0)
    ap.add_argument("--out", type=Path, default=Path("out/redteam_replan"))
    args = ap.parse_args(argv)
    rows = []
    for name in args.device:
        for m in args.at_min:
            case = args.out / f"{name}_m{m}"
            row = replan_case(
                DEVICES[name], args.plan_dir.resolve(), m, case.resolve(), args.seed, args.timeout_s
            )
            rows.append(row)
            print(json.dumps(row, default=str), flush=True)
            if args.second_min and row.get("exit") in (0, 1) and args.second_min > m:
                again = replan_case(
                    DEVICES[name],
                    (case / "replan").resolve(),
                    args.second_min,
                    (case / f"second_m{args.second_min}").resolve(),
                    args.seed + 1,
                    args.timeout_s,
                )
                again["first_at_min"] = m
                rows.append(again)
                print(json.dumps(again, default=str), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(args.out / "redteam.csv", index=False)
    claimed_but_short = [
        r for r in rows if r.get("claimed_complete") and r.get("true_coverage", 1) < 1
    ]
    print(
        f"{len(rows)} re-plans; claimed complete but short on the device: {len(claimed_but_short)}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
