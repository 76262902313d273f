"""Is the gradient's stated sigma honest near the chamber's rate changes? (independent check)

Synthetic logs with known truth, simulated here without schedsyn's simulator: the chamber
follows a piecewise-constant rate ``U`` and the device the exact first-order lag
``tau dT/dt + T = Tk + dT0``; on a segment with ``Tk = Tk_0 + U t`` the solution is
``T = Tp + (T_0 - Tp_0) exp(-t/tau)`` with ``Tp = Tk + dT0 - U tau`` and
``g = dT/dt = U - (T_0 - Tp_0) exp(-t/tau) / tau`` (closed form, checked against
``scipy.integrate.solve_ivp`` on the first case when run).

Programmes: random ones (rates in [-1, +3] degC/min, segments 10-60 min, some holds) and
the repo's plans (data/baseline_exp1_steps.csv, tests/data/plans/*_steps.csv). Devices:
tau 1500-3600 s, dT0 0-5 degC, starting at equilibrium or off it by up to 3 degC; the log
starts at the programme's start or somewhere inside it. Sensor: white noise 0.005-0.05
degC, quantised to 0.01 or 0.0625 degC (or not); sampling 1-60 s, regular, jittered
(irregular steps) or with gaps (and a few NaN readings).

Each estimator's error ``e = g_est - g_true`` over the rows of three windows: ``start``
(the first 15 min of the log), ``change`` (within 15 min after a rate change, outside the
start window) and ``elsewhere``; and, overlapping them, ``core`` (within 2.5 min of a
change on either side, where the smoother's bias at a kink is largest). Per window:
coverage of +-2 sigma (share of |e| <= 2 sigma, about 95 % when sigma is honest), RMS of
``z = e / sigma`` (1 when honest), the largest |z|, the RMS error and the median sigma.

Estimators: kinematic order 3 and 2, and the model-based one with the right model and with
a wrong one (tau 15 % long, dT0 1 degC low, as users often have).

Run: python scripts/bench_sigma.py [--cases 40] [--seed 0] [--save out/sigma.npz]
     [--estimators "model-based,model-based (wrong model)"]
     python scripts/bench_sigma.py --compare OLD.npz NEW.npz
``--save`` keeps every row's (window, error, sigma) per estimator; ``--compare`` prints the
coverage of both, the median sigma ratio new/old per window and the RMS errors.
(To take OLD from an older tree: PYTHONPATH=DIR python scripts/bench_sigma.py --save ...)
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
PLAN_FILES = [
    ROOT / "data" / "baseline_exp1_steps.csv",
    *sorted((ROOT / "tests" / "data" / "plans").glob("*_steps.csv")),
]
WINDOW_MIN = 15.0
WINDOWS = ("start", "change", "elsewhere")
#: The smoother's bias is largest within a few minutes of a kink, on both sides; that core
#: is reported too (its rows also count in one of the three windows).
KINK_CORE_MIN = 2.5
ESTIMATORS = ("kinematic order 3", "kinematic order 2", "model-based", "model-based (wrong model)")
#: The wrong model users often have: tau 15 % long, dT0 1 degC low.
WRONG_TAU_FACTOR = 1.15
WRONG_DT0_OFFSET_C = -1.0


# -- truth ----------------------------------------------------------------------------------
def lag_truth(durations_min, rates_c_per_min, tk0_c, tau_min, dt0_c, t_dev0_c, times_min):
    """Exact ``(T, g, Tk)`` of the lag at ``times_min`` (closed form per segment)."""
    starts = np.concatenate(([0.0], np.cumsum(durations_min)))
    t_out = np.full(times_min.size, np.nan)
    g_out = np.full(times_min.size, np.nan)
    tk_out = np.full(times_min.size, np.nan)
    tk, temp = tk0_c, t_dev0_c
    for i, (dur, u) in enumerate(zip(durations_min, rates_c_per_min, strict=True)):
        lo, hi = starts[i], starts[i + 1]
        last = i == len(durations_min) - 1
        sel = (times_min >= lo) & ((times_min < hi) | (last & (times_min <= hi + 1e-9)))
        s = times_min[sel] - lo
        off = temp - (tk + dt0_c - u * tau_min)  # T_0 - Tp_0
        decay = np.exp(-s / tau_min)
        t_out[sel] = tk + u * s + dt0_c - u * tau_min + off * decay
        g_out[sel] = u - off * decay / tau_min
        tk_out[sel] = tk + u * s
        temp = tk + u * dur + dt0_c - u * tau_min + off * math.exp(-dur / tau_min)
        tk = tk + u * dur
    return t_out, g_out, tk_out


def check_truth_against_ode() -> float:
    """Largest |T| difference (degC) of :func:`lag_truth` vs solve_ivp on a test programme."""
    from scipy.integrate import solve_ivp

    dur, rate = np.array([30.0, 20.0, 45.0]), np.array([2.0, 0.0, -1.0])
    tau, dt0, tk0, t0 = 40.0, 3.0, 20.0, 21.0
    times = np.linspace(0.0, dur.sum(), 400)
    t_exact, g_exact, _ = lag_truth(dur, rate, tk0, tau, dt0, t0, times)
    starts = np.concatenate(([0.0], np.cumsum(dur)))

    def tk_at(t):
        i = min(int(np.searchsorted(starts, t, side="right")) - 1, dur.size - 1)
        base = tk0 + float(np.sum(dur[:i] * rate[:i]))
        return base + rate[i] * (t - starts[i])

    sol = solve_ivp(
        lambda t, x: [(tk_at(t) + dt0 - x[0]) / tau],
        (0.0, dur.sum()),
        [t0],
        t_eval=times,
        rtol=1e-10,
        atol=1e-10,
        max_step=0.5,
    )
    g_ode = np.array([(tk_at(t) + dt0 - x) / tau for t, x in zip(times, sol.y[0], strict=True)])
    return float(max(np.max(np.abs(sol.y[0] - t_exact)), np.max(np.abs(g_ode - g_exact))))


# -- programmes and logs --------------------------------------------------------------------
def random_programme(rng, total_min):
    """Rates in [-1, 3] degC/min, segments 10-60 min, a hold now and then; the chamber
    kept within [-60, 90] degC (the rate's sign chosen to stay inside)."""
    durs, rates = [], []
    tk, t = 20.0, 0.0
    while t < total_min:
        d = float(rng.uniform(10.0, 60.0))
        if rng.random() < 0.2:
            u = 0.0
        else:
            u = (
                float(rng.uniform(0.1, 3.0))
                if rng.random() < 0.5
                else -float(rng.uniform(0.1, 1.0))
            )
            if tk + u * d > 90.0 or tk + u * d < -60.0:
                u = -u if -1.0 <= -u <= 3.0 else 0.0
            if tk + u * d > 90.0 or tk + u * d < -60.0:
                u = 0.0
        durs.append(d)
        rates.append(u)
        tk += u * d
        t += d
    return np.array(durs), np.array(rates), 20.0


def read_plan(path):
    frame = pd.read_csv(path, comment="#")
    return (
        frame["duration_min"].to_numpy(float),
        frame["rate_c_per_min"].to_numpy(float),
        float(frame["tk_start_c"].iloc[0]),
    )


def sample_times_min(rng, kind, h_s, t_lo_min, t_hi_min):
    """Sample times: regular, jittered (each step 0.3..1.7 h) or regular with 1-3 gaps."""
    span_s = (t_hi_min - t_lo_min) * 60.0
    if kind == "jitter":
        steps = h_s * rng.uniform(0.3, 1.7, size=int(span_s / h_s * 1.2) + 10)
        t = np.concatenate(([0.0], np.cumsum(steps)))
        t = np.round(t[t <= span_s], 3)
    else:
        t = h_s * np.arange(int(span_s // h_s) + 1)
        if kind == "gaps":
            for _ in range(int(rng.integers(1, 4))):
                g0 = rng.uniform(0.1, 0.9) * span_s
                t = t[(t < g0) | (t > g0 + rng.uniform(120.0, 1200.0))]
    return t_lo_min + t / 60.0


def make_case(rng, name, programme):
    durs, rates, tk0 = programme
    total = float(durs.sum())
    tau_min = float(rng.uniform(1500.0, 3600.0)) / 60.0
    dt0 = float(rng.uniform(0.0, 5.0))
    t_dev0 = tk0 + dt0 + (0.0 if rng.random() < 0.5 else float(rng.uniform(-3.0, 3.0)))
    h_s = float(rng.choice([1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0]))
    kind = str(rng.choice(["regular", "regular", "jitter", "gaps"]))
    noise = float(math.exp(rng.uniform(math.log(0.005), math.log(0.05))))
    quant = float(rng.choice([0.0, 0.01, 0.0625]))
    t_lo = 0.0 if rng.random() < 0.6 else float(rng.uniform(0.0, 0.3 * total))
    times = sample_times_min(rng, kind, h_s, t_lo, total)
    temp, g, tk = lag_truth(durs, rates, tk0, tau_min, dt0, t_dev0, times)
    y = temp + noise * rng.standard_normal(times.size)
    if quant > 0:
        y = quant * np.round(y / quant)
    if kind != "regular" and times.size > 100:  # a few missing readings
        y[rng.choice(times.size - 20, size=3, replace=False) + 10] = np.nan
    starts = np.concatenate(([0.0], np.cumsum(durs)))[:-1]
    prev = np.concatenate(([np.nan], rates[:-1]))
    changes = starts[(np.abs(rates - prev) > 1e-9) & (starts > t_lo)]
    since = times[:, None] - changes[None, :]
    near = np.any((since >= 0.0) & (since < WINDOW_MIN), axis=1)
    window = np.where(times - times[0] < WINDOW_MIN, 0, np.where(near, 1, 2))
    # diagnostic, overlapping the others: within KINK_CORE_MIN of a change, either side
    core = np.any(np.abs(since) <= KINK_CORE_MIN, axis=1) if changes.size else times < -1.0
    window = window + 10 * core
    frame = pd.DataFrame({"time_s": np.round(times * 60.0, 3), "t_int_c": y, "tk_set_c": tk})
    meta = dict(name=name, tau_s=tau_min * 60.0, dt0_c=dt0, h_s=h_s, kind=kind, noise_c=noise,
                quant_c=quant, rows=times.size, changes_min=changes)  # fmt: skip
    return frame, g, window, meta


def cases(n_random, seed):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_random):
        prog = random_programme(rng, float(rng.uniform(240.0, 540.0)))
        out.append(make_case(rng, f"random {i}", prog))
    for path in PLAN_FILES:
        for j in range(2):
            out.append(make_case(rng, f"{path.stem} #{j}", read_plan(path)))
    return out


# -- evaluation -----------------------------------------------------------------------------
def _estimate(name, log_kin, log_mod, params, wrong):
    from schedsyn.estimate import estimate_gradient, estimate_gradient_model

    if name == "kinematic order 3":
        return estimate_gradient(log_kin)
    if name == "kinematic order 2":
        return estimate_gradient(log_kin, order=2)
    return estimate_gradient_model(log_mod, params if name == "model-based" else wrong)


def run(n_random, seed, estimators=ESTIMATORS):
    from schedsyn.logs import log_from_frame
    from schedsyn.params import ThermalParams

    rows = {e: {"window": [], "err": [], "std": [], "case": []} for e in estimators}
    metas = []
    for ci, (frame, g, window, meta) in enumerate(cases(n_random, seed)):
        log_kin = log_from_frame(frame[["time_s", "t_int_c"]], source=meta["name"])
        log_mod = log_from_frame(frame, source=meta["name"])
        params = ThermalParams(tau_s=meta["tau_s"], dt0_c=meta["dt0_c"])
        wrong = ThermalParams(
            tau_s=meta["tau_s"] * WRONG_TAU_FACTOR, dt0_c=meta["dt0_c"] + WRONG_DT0_OFFSET_C
        )
        ests = {name: _estimate(name, log_kin, log_mod, params, wrong) for name in estimators}
        for name, est in ests.items():
            r = rows[name]
            r["window"].append(window)
            r["err"].append(est.g_est_c_per_min - g)
            r["std"].append(est.g_std_c_per_min)
            r["case"].append(np.full(g.size, ci))
        metas.append(meta)
    out = {}
    for name, r in rows.items():
        out[name] = {k: np.concatenate(v) for k, v in r.items()}
    return out, metas


def table(data):
    lines = []
    for name, r in data.items():
        for wi, wname in enumerate((*WINDOWS, f"core +-{KINK_CORE_MIN:g} min")):
            sel = r["window"] % 10 == wi if wi < 3 else r["window"] >= 10
            e, s = r["err"][sel], r["std"][sel]
            z = e / s
            lines.append(
                {
                    "estimator": name,
                    "window": wname,
                    "rows": int(sel.sum()),
                    "coverage_2sigma": float(np.mean(np.abs(z) <= 2.0)),
                    "rms_z": float(np.sqrt(np.mean(z * z))),
                    "max_abs_z": float(np.max(np.abs(z))),
                    "rms_err_c_per_min": float(np.sqrt(np.mean(e * e))),
                    "median_std_c_per_min": float(np.median(s)),
                }
            )
    return pd.DataFrame(lines)


def per_case_worst(data, estimator):
    """Lowest per-case coverage in each window (cases with >= 30 rows in it)."""
    r = data[estimator]
    out = {}
    for wi, wname in enumerate(WINDOWS):
        worst = 1.0
        for c in np.unique(r["case"]):
            sel = (r["case"] == c) & (r["window"] % 10 == wi)
            if sel.sum() >= 30:
                worst = min(worst, float(np.mean(np.abs(r["err"][sel]) <= 2.0 * r["std"][sel])))
        out[wname] = worst
    return out


def save(path, data):
    flat = {f"{e}|{k}": v for e, r in data.items() for k, v in r.items()}
    np.savez_compressed(path, **flat)


def load(path):
    z = np.load(path)
    data: dict = {}
    for key in z.files:
        e, k = key.split("|")
        data.setdefault(e, {})[k] = z[key]
    return data


def compare(old_path, new_path):
    old, new = load(old_path), load(new_path)
    lines = []
    for name in old:
        for wi, wname in enumerate((*WINDOWS, f"core +-{KINK_CORE_MIN:g} min")):
            w = old[name]["window"]
            so = w % 10 == wi if wi < 3 else w >= 10
            o_e, o_s = old[name]["err"][so], old[name]["std"][so]
            n_e, n_s = new[name]["err"][so], new[name]["std"][so]
            lines.append(
                {
                    "estimator": name,
                    "window": wname,
                    "cov_old": float(np.mean(np.abs(o_e) <= 2 * o_s)),
                    "cov_new": float(np.mean(np.abs(n_e) <= 2 * n_s)),
                    "rms_z_old": float(np.sqrt(np.mean((o_e / o_s) ** 2))),
                    "rms_z_new": float(np.sqrt(np.mean((n_e / n_s) ** 2))),
                    "max_z_old": float(np.max(np.abs(o_e / o_s))),
                    "max_z_new": float(np.max(np.abs(n_e / n_s))),
                    "median_std_ratio_new_old": float(np.median(n_s / o_s)),
                    "rms_err_old": float(np.sqrt(np.mean(o_e**2))),
                    "rms_err_new": float(np.sqrt(np.mean(n_e**2))),
                }
            )
    return pd.DataFrame(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=40, help="random programmes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save", default=None)
    ap.add_argument("--compare", nargs=2, default=None, metavar=("OLD", "NEW"))
    ap.add_argument(
        "--estimators",
        default=",".join(ESTIMATORS),
        help="comma-separated subset of: " + ", ".join(ESTIMATORS) + " (default: all)",
    )
    args = ap.parse_args()
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 20)
    if args.compare:
        print(compare(*args.compare).to_string(index=False, float_format="%.4g"))
        return
    print(f"closed-form lag vs solve_ivp: max difference {check_truth_against_ode():.2e}")
    estimators = tuple(e.strip() for e in args.estimators.split(","))
    unknown = sorted(set(estimators) - set(ESTIMATORS))
    if unknown:
        ap.error(f"unknown estimator(s): {unknown}")
    data, metas = run(args.cases, args.seed, estimators)
    print(f"{len(metas)} logs, {sum(m['rows'] for m in metas)} rows")
    print(table(data).to_string(index=False, float_format="%.4g"))
    for name in estimators:
        print(f"worst per-log coverage, {name}: {per_case_worst(data, name)}")
    if args.save:
        Path(args.save).parent.mkdir(parents=True, exist_ok=True)
        save(args.save, data)
        print(f"wrote {args.save}", file=sys.stderr)


if __name__ == "__main__":
    main()
