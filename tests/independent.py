"""Independent re-checks of step tables for the tests: scipy's ODE solver and own counting.

Nothing here uses schedsyn's model maths, simulator or coverage code: a step table is
read as plain numbers from its CSV, the chamber path is built from its typed start/end
temperatures, ``tau dT/dt + T = Tk + dT0`` is integrated with ``solve_ivp`` (one state per
(tau, dT0) scenario, all integrated together, segment by segment so the solver never
steps across a kink), and passes and distinct levels are counted by a plain loop.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp


def chamber_knots(steps_csv: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Times (min) and chamber temperatures (degC) at the step boundaries, as typed."""
    df = pd.read_csv(steps_csv, comment="#")
    dur = df["duration_min"].to_numpy(float)
    times = np.concatenate(([0.0], np.cumsum(dur)))
    temps = np.concatenate(([df["tk_start_c"].iloc[0]], df["tk_end_c"].to_numpy(float)))
    return times, temps


def ode_trajectories(
    knots_t: np.ndarray,
    knots_tk: np.ndarray,
    tau_s: np.ndarray | float,
    dt0_c: np.ndarray | float,
    t0_c: float = 20.0,
    dt_min: float = 0.1,
    tau2_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Device temperature and gradient every ``dt_min`` for each scenario (tau_s, dt0_c).

    ``tau dT/dt + T = M + dT0`` with ``M = Tk`` (the planning model), or with a second
    thermal mass ``tau2 dM/dt + M = Tk`` (``M(0) = Tk(0)``) when ``tau2_s > 0``.
    Returns ``(time_min (m,), temp_c (s, m), grad_c_per_min (s, m))`` for ``s`` scenarios.
    """
    tau = np.atleast_1d(np.asarray(tau_s, dtype=float)) / 60.0
    dt0 = np.atleast_1d(np.asarray(dt0_c, dtype=float))
    tau, dt0 = np.broadcast_arrays(tau, dt0)
    n = tau.size
    tau2 = tau2_s / 60.0
    end = float(knots_t[-1])
    t = dt_min * np.arange(int(np.floor(end / dt_min + 1e-9)) + 1)

    def chamber(x):
        return np.interp(x, knots_t, knots_tk)

    def rhs(x, v):  # v = [T (n), M (n) if tau2 > 0]
        drive = v[n:] if tau2 > 0 else chamber(x)
        dtemp = (drive + dt0 - v[:n]) / tau
        return dtemp if tau2 == 0 else np.concatenate((dtemp, (chamber(x) - v[n:]) / tau2))

    temp = np.empty((n, t.size))
    mass = np.empty((n, t.size))
    y = np.full(n, float(t0_c))
    if tau2 > 0:
        y = np.concatenate((y, np.full(n, float(knots_tk[0]))))
    temp[:, 0] = y[:n]
    mass[:, 0] = knots_tk[0]
    for a, b in zip(knots_t[:-1], knots_t[1:], strict=True):
        inside = (t > a) & (t <= b)
        pts = t[inside]
        # the samples, and the knot the next piece starts from (unless it is a sample)
        evals = pts if pts.size and pts[-1] >= b else np.append(pts, b)
        sol = solve_ivp(rhs, (a, b), y, t_eval=evals, method="DOP853", rtol=1e-12, atol=1e-12)
        temp[:, inside] = sol.y[:n, : pts.size]
        mass[:, inside] = sol.y[n:, : pts.size] if tau2 > 0 else chamber(pts)[None, :]
        y = sol.y[:, -1]
    grad = (mass + dt0[:, None] - temp) / tau[:, None]
    return t, temp, grad


def levels_per_bin(
    temp_c: np.ndarray, grad_c_per_min: np.ndarray, lo_c: float, hi_c: float, delta: float
) -> np.ndarray:
    """Distinct gradient levels of each 1 degC bin ``[lo + k, lo + k + 1)``, counted plainly.

    A pass is a maximal run of consecutive samples inside the bin, its gradient the mean
    over the run; levels are the largest set of passes pairwise ``delta`` apart (taken
    greedily from the smallest, which is optimal on a line).
    """
    n_bins = int(round(hi_c - lo_c))
    means: list[list[float]] = [[] for _ in range(n_bins)]
    current, run = -1, 0.0
    count = 0
    for temp, g in zip(temp_c.tolist(), grad_c_per_min.tolist(), strict=True):
        k = int(np.floor(temp - lo_c)) if lo_c <= temp < hi_c else -1
        if k != current:  # a run ends: its mean gradient is one pass of its bin
            if current >= 0:
                means[current].append(run / count)
            current, run, count = k, 0.0, 0
        run += g
        count += 1
    if current >= 0:
        means[current].append(run / count)
    levels = []
    for passes in means:
        n, last = 0, -np.inf
        for m in sorted(passes):
            if m - last >= delta - 1e-12:
                n, last = n + 1, m
        levels.append(n)
    return np.array(levels)


def table_check(
    steps_csv: Path | str,
    region: tuple[float, float],
    levels_required: int,
    tau_s: float = 2400.0,
    dt0_c: float = 3.0,
    delta: float = 0.05,
    tau2_s: float = 0.0,
) -> dict:
    """Coverage, fewest levels and device range of a step table for one (tau, dT0)."""
    knots_t, knots_tk = chamber_knots(steps_csv)
    _, temp, grad = ode_trajectories(knots_t, knots_tk, tau_s, dt0_c, tau2_s=tau2_s)
    lev = levels_per_bin(temp[0], grad[0], region[0], region[1], delta)
    return {
        "coverage": float(np.mean(lev >= levels_required)),
        "min_levels": int(lev.min()),
        "levels": lev,
        "device_min_c": float(temp[0].min()),
        "device_max_c": float(temp[0].max()),
        "chamber_start_c": float(knots_tk[0]),
        "chamber_end_c": float(knots_tk[-1]),
        "duration_min": float(knots_t[-1]),
        "rates_c_per_min": np.diff(knots_tk) / np.diff(knots_t),
    }


def assert_plan_complete(plan, tmp_path: Path) -> dict:
    """Export ``plan``'s step table, re-check it (:func:`table_check`) and assert it is
    complete and within every limit of its request: coverage, levels, duration, device
    range, end temperature, rates. Returns the re-check."""
    spec, params, limits = plan.spec, plan.params, plan.limits
    steps = plan.programme.to_csv(tmp_path / "steps.csv")
    res = table_check(
        steps,
        (spec.working_lo_c, spec.working_hi_c),
        spec.levels_required,
        tau_s=params.tau_s,
        dt0_c=params.dt0_c,
        delta=spec.delta_c_per_min,
    )
    assert res["coverage"] == 1.0, res["levels"]
    assert res["min_levels"] >= spec.levels_required
    assert res["duration_min"] <= limits.duration_max_min + 1e-9
    assert res["device_min_c"] >= limits.device_min_c
    assert res["device_max_c"] <= limits.device_max_c
    assert abs(res["chamber_end_c"] - limits.end_c) <= limits.end_tol_c
    rates = res["rates_c_per_min"]
    assert rates.min() >= limits.rate_min_c_per_min - 1e-3
    assert rates.max() <= limits.rate_max_c_per_min + 1e-3
    res["steps_csv"] = steps
    return res


def box_table_check(
    steps_csv: Path | str,
    region: tuple[float, float],
    delta: float,
    tau_range_s: tuple[float, float],
    dt0_range_c: tuple[float, float],
    t0_c: float = 20.0,
    n_tau: int = 9,
    n_dt0: int = 7,
) -> dict:
    """A step table over a tau x dT0 grid (ends included), all scenarios integrated
    together: the fewest levels of any bin at any point, the device's range over the box,
    and the table's duration, rate range, chamber range and end temperatures."""
    knots_t, knots_tk = chamber_knots(steps_csv)
    taus, dt0s = np.meshgrid(np.linspace(*tau_range_s, n_tau), np.linspace(*dt0_range_c, n_dt0))
    _, temp, grad = ode_trajectories(knots_t, knots_tk, taus.ravel(), dt0s.ravel(), t0_c=t0_c)
    fewest = min(
        int(levels_per_bin(temp[i], grad[i], region[0], region[1], delta).min())
        for i in range(temp.shape[0])
    )
    rates = np.diff(knots_tk) / np.diff(knots_t)
    return {
        "fewest_levels": fewest,
        "device_c": (float(temp.min()), float(temp.max())),
        "duration_min": float(knots_t[-1]),
        "rates": (float(rates.min()), float(rates.max())),
        "chamber_c": (float(knots_tk.min()), float(knots_tk.max())),
        "ends_c": (float(knots_tk[0]), float(knots_tk[-1])),
    }
