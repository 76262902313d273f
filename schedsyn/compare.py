"""Compare a measured run with its plan: estimated vs simulated trajectories and coverage.

The plan is simulated through the planning model at the log's times (for residuals) and
densely (for the planned coverage); the run's gradient comes from the Kalman smoother of
:mod:`schedsyn.estimate`. The run's coverage uses THE coverage metric
(:func:`schedsyn.coverage.coverage_report`) on the estimated ``(T, g)``, resampled to the
same 0.1 min grid as the plan (linear interpolation of the smoothed states between log
rows, NaN inside sampling gaps, so a gap never counts as a pass): planned and achieved
coverage are directly comparable. (The metric depends on the sampling: the truth of a
synthetic 10 s log scores 40 % at its own rows but the planned 55 % on the 0.1 min grid.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .coverage import CoverageReport, coverage_report
from .errors import LogFormatError, ParameterError
from .estimate import GradientEstimate, estimate_gradient, estimate_gradient_model
from .grid import BinGrid
from .logs import GAP_FACTOR, MeasuredLog
from .params import ThermalParams
from .programme import Programme
from .simulate import Trajectory, dense_times, simulate


@dataclass(frozen=True, slots=True)
class RunComparison:
    """A measured run next to its plan.

    Attributes
    ----------
    log : MeasuredLog
        The run.
    estimate : GradientEstimate
        Smoothed internal temperature and gradient of the run.
    simulated : Trajectory
        The plan simulated at the log's times.
    planned : Trajectory
        The plan simulated densely (the coverage metric's 0.1 min grid).
    run_dense : Trajectory
        The run's smoothed ``(T, g)`` on the same grid (NaN inside gaps; ``tk_c`` is the
        logged setpoint where the log has one, else NaN).
    planned_coverage, run_coverage : CoverageReport
        Coverage of the same working region by the plan and by the run.
    params : ThermalParams
        Model used for the simulation.
    level_margin_c_per_min : float
        Twice the standard deviation of the difference of two passes' estimated
        gradients (median over the region's rows): how far a level separation measured
        from the log may be from the device's.
    run_coverage_low, run_coverage_high : CoverageReport or None
        The run's coverage with the level separation widened / narrowed by that margin:
        bins that flip between them are borderline, the run's true coverage most likely
        lies between the two (red team: a 120-s log read 35 % where the device did 25 %,
        two bins flipped by gradient errors of 1-2 sigma).
    notes : tuple of str
        Warnings about the comparison itself (a log without a setpoint whose device does
        not follow the table: :func:`device_follows_note`; a log starting away from the
        simulation's start: :func:`start_note`).
    t0_c, t0_source
        The device's temperature at the programme's start that the simulation begins
        from, degC, and where it came from (the plan's start, the log's own start, given).
    """

    log: MeasuredLog
    estimate: GradientEstimate
    simulated: Trajectory
    planned: Trajectory
    run_dense: Trajectory
    planned_coverage: CoverageReport
    run_coverage: CoverageReport
    params: ThermalParams
    level_margin_c_per_min: float = 0.0
    run_coverage_low: CoverageReport | None = None
    run_coverage_high: CoverageReport | None = None
    notes: tuple[str, ...] = ()
    t0_c: float = 20.0
    t0_source: str = "the plan's start"

    @property
    def borderline_bins(self) -> int:
        """Bins covered with the narrowed separation but not with the widened one."""
        if self.run_coverage_low is None or self.run_coverage_high is None:
            return 0
        return int((self.run_coverage_high.covered & ~self.run_coverage_low.covered).sum())

    @property
    def residual_c(self) -> np.ndarray:
        """Measured minus simulated internal temperature at the log's rows, degC (NaN kept)."""
        return self.log.t_int_c - self.simulated.t_c

    @property
    def rms_residual_c(self) -> float:
        r = self.residual_c
        return float(np.sqrt(np.nanmean(r**2)))

    @property
    def max_abs_residual_c(self) -> float:
        return float(np.nanmax(np.abs(self.residual_c)))

    def to_frame(self) -> pd.DataFrame:
        """One row per log row: measured, smoothed and simulated T and g."""
        return pd.DataFrame(
            {
                "time_s": self.log.time_s,
                "t_meas_c": self.log.t_int_c,
                "t_est_c": self.estimate.t_est_c,
                "t_sim_c": self.simulated.t_c,
                "residual_c": self.residual_c,
                "g_est_c_per_min": self.estimate.g_est_c_per_min,
                "g_std_c_per_min": self.estimate.g_std_c_per_min,
                "g_sim_c_per_min": self.simulated.g_c_per_min,
                "tk_sim_c": self.simulated.tk_c,
            }
        )

    def coverage_frame(self) -> pd.DataFrame:
        """Per bin: passes and distinct gradient levels, planned next to achieved."""
        p, r = self.planned_coverage, self.run_coverage
        lo = p.grid.lower_c
        return pd.DataFrame(
            {
                "bin_lo_c": lo,
                "bin_hi_c": lo + p.grid.bin_c,
                "planned_passes": p.pass_counts,
                "run_passes": r.pass_counts,
                "planned_levels": p.levels,
                "run_levels": r.levels,
                "planned_covered": p.covered,
                "run_covered": r.covered,
            }
        )

    def summary_dict(self) -> dict:
        est = self.estimate
        return {
            "log": self.log.source,
            "rows": self.log.n_rows,
            "tau_s": self.params.tau_s,
            "dt0_c": self.params.dt0_c,
            "t0_c": self.t0_c,
            "t0_source": self.t0_source,
            "rms_residual_c": self.rms_residual_c,
            "max_abs_residual_c": self.max_abs_residual_c,
            "estimator": est.method,
            "q": est.q,
            "r": est.r,
            "region_c": [self.planned_coverage.grid.lo_c, self.planned_coverage.grid.hi_c],
            "planned_coverage": self.planned_coverage.coverage,
            "run_coverage": self.run_coverage.coverage,
            "planned_min_levels": self.planned_coverage.min_levels,
            "run_min_levels": self.run_coverage.min_levels,
            "level_margin_c_per_min": self.level_margin_c_per_min,
            "run_coverage_low": None
            if self.run_coverage_low is None
            else self.run_coverage_low.coverage,
            "run_coverage_high": None
            if self.run_coverage_high is None
            else self.run_coverage_high.coverage,
            "borderline_bins": self.borderline_bins,
            "notes": list(self.notes),
            "run_coverage_range_meaning": (
                "the run's coverage with the level separation widened (low) and narrowed "
                "(high) by twice the standard deviation of the difference of two passes' "
                "estimated gradients: bins that flip between them are borderline"
            ),
        }

    def summary(self) -> str:
        t = self.log.t_int_c
        return "\n".join(
            [
                f"measured T {np.nanmin(t):.2f} .. {np.nanmax(t):.2f} °C; simulated "
                f"{self.simulated.t_c.min():.2f} .. {self.simulated.t_c.max():.2f} °C "
                f"(tau {self.params.tau_s:g} s, dT0 {self.params.dt0_c:g} °C)",
                f"measured - simulated T: RMS {self.rms_residual_c:.3f} °C, max "
                f"{self.max_abs_residual_c:.3f} °C",
                "planned: " + self.planned_coverage.summary(),
                "run:     " + self.run_coverage.summary(),
                *self._range_lines(),
                *(f"*** {n}" for n in self.notes),
            ]
        )

    def _range_lines(self) -> list[str]:
        lo, hi = self.run_coverage_low, self.run_coverage_high
        if lo is None or hi is None:
            return []
        return [
            f"run, allowing for the gradient estimate (levels {self.level_margin_c_per_min:.3f} "
            f"°C/min further apart or closer): {lo.coverage:.0%} .. {hi.coverage:.0%}; "
            f"{self.borderline_bins} borderline bin(s)"
        ]


#: The logged setpoint may differ from the step table's programme by this much (a
#: coarsely logged setpoint), degC ...
RUN_SETPOINT_TOL_C = 2.0
#: ... after allowing it to lag the programme by up to this (a controller's log of its
#: setpoint a few tens of seconds late), s.
RUN_SETPOINT_LAG_MAX_S = 120.0
#: Without a setpoint column: the device's readings must be a first-order lag of the
#: programme, its time constant anywhere in this range (s), its dT0 and its temperature at
#: the programme's start free, within ...
RUN_DEVICE_TAU_RANGE_S = (150.0, 9600.0)
#: ... this RMS residual, degC (red team: a log of another programme 6.1 degC, one shifted
#: by 30 min 8.7 degC at their best fits; the repository's sample run, tau and dT0 off the
#: plan's, 0.02 degC at its best, 1.7 degC at the plan's own tau and dT0).
RUN_DEVICE_FIT_RMS_MAX_C = 3.0
#: The device check needs this many minutes of readings inside the programme (and at
#: most this many readings are used, evenly strided).
RUN_DEVICE_MIN_SPAN_MIN = 30.0
RUN_DEVICE_MAX_ROWS = 5000


def device_fit_rms_c(log: MeasuredLog, programme: Programme) -> tuple[float, float] | None:
    """The best RMS residual, degC, of the log's ``t_int_c`` against a first-order lag of
    ``programme`` (``tau dT/dt + T = Tk + dT0``) and its time constant, s: ``tau`` searched
    over :data:`RUN_DEVICE_TAU_RANGE_S` (log-spaced grid, then refined), ``dT0`` and the
    temperature at the programme's start by least squares (the response is linear in
    both: ``T = T_0(t) + T0 e^(-t/tau) + dT0 (1 - e^(-t/tau))``, ``T_0`` the lag's response
    from 0 degC with dT0 = 0). None when the log has too little inside the programme
    (:data:`RUN_DEVICE_MIN_SPAN_MIN`)."""
    from scipy.optimize import minimize_scalar

    ok = np.isfinite(log.t_int_c) & (log.time_min <= programme.total_min)
    t, y = log.time_min[ok], log.t_int_c[ok]
    if t.size < 20 or float(t[-1] - t[0]) < RUN_DEVICE_MIN_SPAN_MIN:
        return None
    stride = max(1, -(-t.size // RUN_DEVICE_MAX_ROWS))
    t, y = t[::stride], y[::stride]

    def rms(log_tau_s: float) -> float:
        tau_s = math.exp(log_tau_s)
        base = simulate(programme, ThermalParams(tau_s=tau_s, dt0_c=0.0), times_min=t, t0_c=0.0)
        e = np.exp(-t / (tau_s / 60.0))
        a = np.column_stack((e, 1.0 - e))
        coef, *_ = np.linalg.lstsq(a, y - base.t_c, rcond=None)
        return float(np.sqrt(np.mean((y - base.t_c - a @ coef) ** 2)))

    lo, hi = (math.log(v) for v in RUN_DEVICE_TAU_RANGE_S)
    grid = np.linspace(lo, hi, 25)
    values = [rms(v) for v in grid]
    k = int(np.argmin(values))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    best = minimize_scalar(rms, bounds=(a, b), method="bounded", options={"xatol": 1e-3})
    if best.fun < values[k]:
        return float(best.fun), math.exp(float(best.x))
    return float(values[k]), math.exp(float(grid[k]))


def check_run_of(log: MeasuredLog, programme: Programme) -> None:
    """Raise :class:`LogFormatError` (one line) unless ``log`` can be a run of ``programme``:
    its ``time_s`` counts from the programme's start (it starts before the programme
    ends), and its logged setpoint (when it has one) follows the programme, allowing a
    lag of up to :data:`RUN_SETPOINT_LAG_MAX_S`. Red team: a log with Unix-epoch times,
    one shifted by 30 min and one of another programme (setpoint 23 °C apart) were
    compared without a word (residual RMS 52 °C; "run 25 %"). A log that begins some
    minutes into the programme is a run of it (verification: one starting at 12 min,
    refused at first with the advice to shift its times, which would have misaligned it)."""
    if float(log.time_min[0]) >= programme.total_min:
        raise LogFormatError(
            f"{log.source}: the log starts at time_s = {log.time_s[0]:g} s, after the step "
            f"table's programme has ended ({programme.total_min:g} min): time_s must count "
            "seconds from the programme's start (e.g. not clock or epoch time)"
        )
    if log.tk_set_c is None:
        return  # nothing to check the clock against: see device_follows_note
    ok = np.isfinite(log.tk_set_c) & (log.time_min <= programme.total_min)
    if not ok.any():
        return
    at = log.time_min[ok]
    logged = log.tk_set_c[ok]
    # the first lag that fits ends the search (lag 0 on a run logged on time: one pass)
    for lag_min in np.arange(0.0, RUN_SETPOINT_LAG_MAX_S + 1e-9, 5.0) / 60.0:
        if float(np.max(np.abs(logged - programme.chamber_at(at - lag_min)))) <= RUN_SETPOINT_TOL_C:
            return
    gap = np.abs(logged - programme.chamber_at(at))
    k = int(np.argmax(gap))
    planned = float(programme.chamber_at(at[k : k + 1])[0])
    raise LogFormatError(
        f"{log.source}: the logged setpoint tk_set_c = {logged[k]:.2f} °C at {at[k]:.1f} min "
        f"differs from the step table's programme ({planned:.2f} °C) by {gap[k]:.2f} °C "
        f"(> {RUN_SETPOINT_TOL_C:g} °C even allowing it to lag by up to "
        f"{RUN_SETPOINT_LAG_MAX_S:g} s): the log is not a run of this step table (another "
        "programme, or time_s not counted from its start; if tk_set_c holds each step's "
        "target rather than the ramping setpoint, leave that column out)"
    )


#: A log whose first reading is this close to the programme's start (min) holds the
#: device's start temperature (:func:`log_start_c`, read from a line through the readings
#: of its first LOG_START_FIT_MIN minutes).
LOG_START_WITHIN_MIN = 1.0
LOG_START_FIT_MIN = 2.0
#: A start this far from the simulation's start temperature (degC) gets :func:`start_note`.
START_NOTE_C = 1.0


def log_start_c(log: MeasuredLog) -> float:
    """The device's temperature at the programme's start (time 0), degC: a straight line
    through the log's readings within :data:`LOG_START_FIT_MIN` minutes of the start (from
    its first reading on, when that comes after the start), taken at the start: neither
    one reading's noise nor the first minutes' drift is taken for the start (two readings:
    the line through them; one: that reading). Raises :class:`ParameterError` when the
    log's first reading comes later than :data:`LOG_START_WITHIN_MIN` after the start (the
    start is then not in the log: give it as a number)."""
    ok = np.isfinite(log.t_int_c)
    t, y = log.time_min[ok], log.t_int_c[ok]
    if t.size == 0 or float(t[0]) > LOG_START_WITHIN_MIN:
        first = float(t[0]) if t.size else float("nan")
        raise ParameterError(
            f"{log.source}: the first reading of t_int_c is at {first:g} min, not within "
            f"{LOG_START_WITHIN_MIN:g} min of the programme's start, so the log does not "
            "hold the device's start temperature: give it as a number (--t0-c T)"
        )
    lo = max(float(t[0]), -LOG_START_FIT_MIN)
    near = (t >= lo) & (t <= max(float(t[0]), 0.0) + LOG_START_FIT_MIN)
    if near.sum() < 2:
        return float(y[near][0]) if near.any() else float(np.interp(0.0, t, y))
    _, intercept = np.polyfit(t[near], y[near], 1)
    return float(intercept)


def start_note(
    log: MeasuredLog, t0_c: float, params: ThermalParams, t0_source: str = "the plan's start"
) -> str | None:
    """A note when the log's start (:func:`log_start_c`) lies more than
    :data:`START_NOTE_C` from ``t0_c``, the temperature the simulation starts from (from
    ``t0_source``): the residual of the first hours is then partly that start, decaying
    with tau. None otherwise, or when the log begins later."""
    try:
        first = log_start_c(log)
    except ParameterError:
        return None
    if abs(first - t0_c) <= START_NOTE_C:
        return None
    return (
        f"the log starts at {first:.2f} °C, the simulation at {t0_c:g} °C ({t0_source}): "
        f"the residual of the first hours is partly that start (it decays with tau "
        f"{params.tau_s:g} s); the simulation can start at the log's own start (compare or "
        "report --t0-c log; API: t0_c=log_start_c(log))"
    )


def device_follows_note(log: MeasuredLog, programme: Programme) -> str | None:
    """Without a setpoint column, a warning when the device cannot be a first-order lag of
    the programme (:func:`device_fit_rms_c` above :data:`RUN_DEVICE_FIT_RMS_MAX_C`), else
    None. Red team: a log of another programme (residual RMS 24 degC) and one shifted by
    30 min (11.6 degC) were compared without a word. A warning, not a refusal: a genuine
    run with a strong effect beyond tau and dT0 leaves as much (simulated W1/W4 runs: a
    chamber heating at 1 and cooling at 0.5 degC/min 3.2-5.5 degC, a second time constant
    of 3000 s 3.7-4.2, a 600-s dead time 3.3-3.7), and that disagreement is what the
    comparison is for."""
    fit = device_fit_rms_c(log, programme)
    if fit is None or fit[0] <= RUN_DEVICE_FIT_RMS_MAX_C:
        return None
    return (
        "the log has no tk_set_c and its t_int_c does not follow the step table as a "
        f"first-order lag: the best one (tau {fit[1]:.0f} s in "
        f"{RUN_DEVICE_TAU_RANGE_S[0]:g}..{RUN_DEVICE_TAU_RANGE_S[1]:g} s, dT0 and start "
        f"temperature fitted) leaves {fit[0]:.1f} °C RMS (> {RUN_DEVICE_FIT_RMS_MAX_C:g} °C): "
        "a run of another programme, or time_s not counted from its start? check the step "
        "table and the log's clock, or add the chamber setpoint as tk_set_c (then it is "
        "checked); if it is this run, an effect beyond tau and dT0 is this large "
        "(schedsyn diagnose)"
    )


def reading_gaps_s(log: MeasuredLog) -> tuple[tuple[float, float], ...]:
    """``(start_s, end_s)`` between consecutive finite ``t_int_c`` readings further apart
    than a sampling gap (``GAP_FACTOR`` x the median step) with blank readings between
    them: the smoother only guesses the device there."""
    finite = np.flatnonzero(np.isfinite(log.t_int_c))
    if finite.size < 2:
        return ()
    t = np.asarray(log.time_s, dtype=float)
    step = GAP_FACTOR * log.report.median_step_s
    k = np.flatnonzero((np.diff(t[finite]) > step) & (np.diff(finite) > 1))
    return tuple((float(t[finite[i]]), float(t[finite[i + 1]])) for i in k)


def resample_run(log: MeasuredLog, estimate: GradientEstimate, dt_min: float = 0.1) -> Trajectory:
    """The smoothed run on a regular grid ``0, dt, ...`` over the log's span.

    Linear interpolation between the estimate's rows (the log's rows, or those kept by a
    decimated estimate); grid points inside a sampling gap (``log.gaps``) or a stretch of
    blank ``t_int_c`` readings as long as one (:func:`reading_gaps_s`) get NaN, so the
    coverage metric never counts a gap as a pass (red team: an hour of blank readings
    inside the region was counted as measured passes, 40 % where the device reached 25 %).
    """
    t_log = estimate.time_min
    grid = dense_times(float(t_log[-1]), dt_min)
    grid = grid[grid >= t_log[0]]
    temp = np.interp(grid, t_log, estimate.t_est_c)
    grad = np.interp(grid, t_log, estimate.g_est_c_per_min)
    for start_s, end_s in (*log.gaps, *reading_gaps_s(log)):
        inside = (grid > start_s / 60.0) & (grid < end_s / 60.0)
        temp[inside] = np.nan
        grad[inside] = np.nan
    tk = (
        np.interp(grid, log.time_min, log.tk_set_c)
        if log.tk_set_c is not None
        else np.full(grid.shape, np.nan)
    )
    return Trajectory(time_min=grid, tk_c=tk, t_c=temp, g_c_per_min=grad)


def compare_run(
    log: MeasuredLog,
    programme: Programme,
    params: ThermalParams | None = None,
    *,
    grid: BinGrid,
    levels_required: int = 6,
    delta_c_per_min: float = 0.05,
    method: str = "kinematic",
    chamber: str = "tk_set_c",
    q: float | None = None,
    r: float | None = None,
    t0_c: float = 20.0,
    dt_min: float = 0.1,
    t0_source: str = "the plan's start",
    plan_t0_c: float | None = None,
) -> RunComparison:
    """Estimate the run's gradient and compare it with the simulated plan.

    Parameters
    ----------
    log : MeasuredLog
        The measured run.
    programme : Programme
        The plan that was run (its step table).
    params : ThermalParams, optional
        Model for simulating the plan (and for ``method="model"``).
    grid : BinGrid
        Working region and bins of the coverage metric.
    levels_required, delta_c_per_min
        Coverage requirement (as for plans).
    method : {"kinematic", "model"}
        Gradient estimator; ``"kinematic"`` (default) does not lean on the model, so the
        run is judged independently of the simulation it is compared with.
    chamber : {"tk_set_c", "tk_air_c"}
        Logged chamber column driving the model-based estimator.
    q, r : float, optional
        Fixed noise levels (see :func:`schedsyn.estimate.estimate_gradient`).
    t0_c : float
        Internal temperature at the programme's start that the simulation begins from,
        degC: the plan's (its ``t_init_c``), or the log's own (:func:`log_start_c`). A
        start more than :data:`START_NOTE_C` from it is noted (:func:`start_note`).
    dt_min : float
        Step of the dense plan simulation, min.
    t0_source : str
        Where ``t0_c`` comes from, for the note.
    plan_t0_c : float, optional
        The plan's own start temperature, degC, for the planned coverage (what the plan
        promised; default ``t0_c``): the run is simulated from ``t0_c``, the plan from this.
    """
    params = ThermalParams() if params is None else params
    check_run_of(log, programme)
    if method == "kinematic":
        est = estimate_gradient(log, q=q, r=r)
    elif method == "model":
        est = estimate_gradient_model(log, params, chamber=chamber, q=q, r=r)
    else:
        raise ParameterError(f"method must be 'kinematic' or 'model', got {method!r}")
    if not math.isfinite(t0_c):
        raise ParameterError(f"t0_c must be finite, got {t0_c!r}")
    if plan_t0_c is None:
        plan_t0_c = t0_c
    if not math.isfinite(plan_t0_c):
        raise ParameterError(f"plan_t0_c must be finite, got {plan_t0_c!r}")
    simulated = simulate(programme, params, times_min=log.time_min, t0_c=t0_c)
    planned = simulate(programme, params, dt_min=dt_min, t0_c=plan_t0_c)
    planned_cov = coverage_report(
        planned.t_c, planned.g_c_per_min, grid, levels_required, delta_c_per_min
    )
    run_dense = resample_run(log, est, dt_min)
    run_cov = coverage_report(
        run_dense.t_c, run_dense.g_c_per_min, grid, levels_required, delta_c_per_min
    )
    inside = (est.t_est_c >= grid.lo_c) & (est.t_est_c <= grid.hi_c)
    sd = est.g_std_c_per_min[inside & np.isfinite(est.g_std_c_per_min)]
    margin = 2.0 * math.sqrt(2.0) * float(np.median(sd)) if sd.size else 0.0
    low = high = None
    if margin > 0:
        low = coverage_report(
            run_dense.t_c, run_dense.g_c_per_min, grid, levels_required, delta_c_per_min + margin
        )
        high = coverage_report(
            run_dense.t_c,
            run_dense.g_c_per_min,
            grid,
            levels_required,
            max(delta_c_per_min - margin, 0.05 * delta_c_per_min),
        )
    notes = [device_follows_note(log, programme) if log.tk_set_c is None else None]
    notes.append(start_note(log, t0_c, params, t0_source))
    return RunComparison(
        log,
        est,
        simulated,
        planned,
        run_dense,
        planned_cov,
        run_cov,
        params,
        margin,
        low,
        high,
        notes=tuple(n for n in notes if n is not None),
        t0_c=float(t0_c),
        t0_source=t0_source,
    )
