"""Re-plan the rest of a run from its log (``schedsyn replan LOG.csv PLAN_DIR --at-min M``).

:func:`replan_run` is the whole command: :func:`prepare_replan` checks the inputs and
gathers what the log says up to ``M``; the rest is planned by
:func:`schedsyn.planner.plan_experiment` as a continuation (:func:`planner_request`);
:func:`write_replan_dir` writes the result as a plan folder.

What :func:`prepare_replan` establishes, in order:

1. **Inputs.** ``M`` is a whole minute inside the log and inside the plan; the log has
   data at ``M`` (no sampling gap or run of missing readings around it); the log up to
   ``M`` belongs to the plan (:func:`schedsyn.monitor.check_log_belongs`). Each failure
   is one line.
2. **The steps as executed up to M**: the plan's programme cut at ``M``
   (:func:`cut_programme`); the logged ``tk_set_c`` up to ``M`` must follow it (rows after
   ``M`` may already follow a new programme and are not used).
3. **The state at M**: the chamber setpoint, and the device temperature and gradient
   from the Kalman smoother of the log up to ``M`` (the smoother's last point is the
   filter's, so nothing after ``M`` is used), carried to ``M`` from the last sample by
   ``T(M) = T_k + g_k (M - t_k)``.
4. **The identified model**: ``tau_s``, ``dt0_c`` fitted to the log up to ``M``
   (:func:`schedsyn.monitor.identify`), and the effect :func:`schedsyn.discrepancy.diagnose`
   finds, kept where it is *material*: it moves the predicted device temperature over the
   rest of the plan by more than ``material_c`` (default 0.2 degC) against the base model,
   both started from the state at ``M``.
5. **Per bin**: the gradients of the passes ended by ``M`` (levels already measured), the
   levels still missing. A pass open at ``M`` is not counted (its gradient is not known
   yet; the continuation passes that bin again), and is reported.
6. ``start_correction_c = T_est(M) - T_model(M)``: the measured state minus where the
   chosen model, run from the start, puts the device at ``M``.

What :func:`replan_run` then decides:

* **The whole run is judged as it will end** (:func:`predict_run`): the smoothed log up to
  ``M`` joined with the identified model's prediction from the state at ``M``, counted by
  the coverage metric (a pass straddling ``M`` is one pass), checked against the plan's
  limits. The plan's own rest and the planner's continuation are judged the same way.
* **The plan is kept** when its own rest is predicted to complete every bin within the
  device's limits: nothing new to type in.
* **Otherwise the planner is asked for new steps, first from where the sweep in
  progress ends** (:func:`sweep_end_min`): the first whole minute from ``M`` at which the
  device, going on with the plan, is beyond the working region by the plan's edge margin
  (``M`` itself if it already is). The planner's sweeps start and end beyond the
  region's edges, so new steps begun in the middle of a sweep may abandon it and pass its
  bins once more; finishing it as planned can save a sweep. The passes between ``M`` and
  there count as measured (predicted by the identified model).
* **If that continuation is not predicted complete, from ``M`` itself**
  (:func:`continuation_starts`): a device slower or hotter than the plan's model turns
  back short of the edge margin, so the sweep end comes a whole sweep later (or only on
  the way home) and the rest no longer fits; new steps from ``M`` take the sweep in
  progress over.
* The best of the plan unchanged and the continuations tried is chosen
  (:meth:`RunPrediction.preference`: within limits, complete, coverage, lowest level
  count, fewest levels missing), the plan unchanged on a tie or when no continuation
  fits; every attempt is kept (``planner_attempts`` in ``replan.json``). A continuation
  whose table breaks a limit (``max_steps``...) is never chosen, nor, while the plan
  unchanged keeps the device's limits, one that covers less or leaves its weakest bin
  with fewer levels (:func:`refuse_continuation`). The device's limits come first: a
  continuation that breaks them less than the plan is taken whatever the coverage
  options say, and when every run at hand breaks them the chamber goes straight home
  (:func:`safe_return`) if that breaks them less.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .coverage import CoverageReport, coverage_report, distinct_levels
from .effects import ModelSpec
from .errors import LogFormatError, ParameterError
from .estimate import estimate_gradient
from .io import write_frame_atomic, write_json_atomic
from .logs import MeasuredLog, log_from_frame
from .model import affine_response
from .monitor import (
    DENSE_MIN,
    MATERIAL_C,
    EffectCheck,
    Identified,
    MonitorSettings,
    OpenPass,
    PlanRecord,
    check_effect,
    check_log_belongs,
    check_log_start,
    closed_passes,
    identify,
    json_safe,
    measured_run,
    plan_rate_changes,
    predict_from_state,
    with_plan_setpoint,
)
from .params import DT0_ABS_MAX_C, TAU_MAX_S, Limits
from .programme import Programme
from .simulate import dense_times


def cut_programme(programme: Programme, at_min: float) -> Programme:
    """The programme up to ``at_min`` (the step running at ``at_min`` is cut there)."""
    if not (math.isfinite(at_min) and 0.0 < at_min <= programme.total_min + 1e-9):
        raise ParameterError(
            f"cannot cut the programme at {at_min!r} min: it lasts {programme.total_min:g} min"
        )
    ends = np.cumsum(programme.durations_min)
    n = int(np.searchsorted(ends, at_min - 1e-9)) + 1  # segments touching [0, at_min]
    d = programme.durations_min[:n].copy()
    d[-1] = at_min - (ends[n - 2] if n > 1 else 0.0)
    return Programme(d, programme.rates_c_per_min[:n], programme.start_c)


def rest_of_programme(programme: Programme, at_min: float) -> Programme:
    """The programme after ``at_min``, starting at the chamber temperature there."""
    ends = np.cumsum(programme.durations_min)
    if not (math.isfinite(at_min) and 0.0 <= at_min < programme.total_min - 1e-9):
        raise ParameterError(
            f"nothing of the programme is left after {at_min!r} min (it lasts "
            f"{programme.total_min:g} min)"
        )
    k = int(np.searchsorted(ends, at_min + 1e-9, side="right"))
    d = programme.durations_min[k:].copy()
    d[0] = ends[k] - at_min
    return Programme(
        d, programme.rates_c_per_min[k:], float(programme.chamber_at(np.array([at_min]))[0])
    )


def join_programmes(prefix: Programme, rest: Programme) -> Programme:
    """``prefix`` then ``rest`` (which must start where ``prefix`` ends)."""
    if abs(rest.start_c - prefix.end_c) > 0.05 + 1e-9:
        raise ParameterError(
            f"the continuation starts at {rest.start_c:.2f} °C but the executed steps end at "
            f"{prefix.end_c:.2f} °C"
        )
    return Programme(
        np.concatenate((prefix.durations_min, rest.durations_min)),
        np.concatenate((prefix.rates_c_per_min, rest.rates_c_per_min)),
        prefix.start_c,
    )


@dataclass(frozen=True, slots=True)
class ReplanState:
    """Chamber and device state at ``at_min`` (device from the smoother, with std)."""

    at_min: float
    tk_set_c: float
    t_c: float
    t_std_c: float
    g_c_per_min: float
    g_std_c_per_min: float

    def to_dict(self) -> dict[str, float]:
        return {
            "at_min": self.at_min,
            "tk_set_c": self.tk_set_c,
            "t_c": self.t_c,
            "t_std_c": self.t_std_c,
            "g_c_per_min": self.g_c_per_min,
            "g_std_c_per_min": self.g_std_c_per_min,
        }


@dataclass(frozen=True, slots=True)
class ReplanRequest:
    """Everything the planner needs to plan the rest of a run from minute ``at_min``.

    ``prefix`` is the executed programme up to ``at_min``; ``model`` the model to plan the
    rest with (identified base, or with a material effect); ``existing_gradients`` the
    mean gradients of the passes ended by ``at_min`` per bin, degC/min; ``missing_levels``
    per bin; ``start_correction_c`` the measured minus the model's ``T(at_min)``.
    """

    plan: PlanRecord
    log_source: str
    at_min: float
    prefix: Programme
    state: ReplanState
    identified: Identified
    effect: EffectCheck
    model: ModelSpec
    model_t0_c: float
    start_correction_c: float
    existing_gradients: tuple[np.ndarray, ...] = field(repr=False)
    existing_levels: np.ndarray = field(repr=False)
    missing_levels: np.ndarray = field(repr=False)
    pass_in_progress: OpenPass | None = None
    notes: tuple[str, ...] = ()
    #: the smoothed run up to ``at_min`` on the metric's 0.1 min grid: ``(time_min, T, g)``
    measured: tuple[np.ndarray, np.ndarray, np.ndarray] = field(
        repr=False, default=(np.zeros(0), np.zeros(0), np.zeros(0))
    )

    def planning_fit(self) -> Identified:
        """The fit the rest is planned with: the base identification, or, where a
        material effect is used, the effect fit's tau and dT0 with their standard errors
        (inflated like the base fit's for correlated residuals)."""
        if not self.effect.material:
            return self.identified
        i, e = self.identified, self.effect
        return dataclasses.replace(
            i,
            tau_s=e.model.tau_s,
            tau_std_s=e.stderr.get("tau_s", math.nan) * i.inflation,
            dt0_c=e.model.dt0_c,
            dt0_std_c=e.stderr.get("dt0_c", math.nan) * i.inflation,
            t0_c=e.t0_c,
        )

    def doubts(self) -> tuple[str, ...]:
        """Why the fit the rest is planned with (:meth:`planning_fit`) does not pin the
        device down, or ``()``. Judged on the base fit while an effect model was in use,
        a chamber lag's log read 'dT0 -0.27 ± 6.44 °C: a guess' and exit code 1 where
        the effect fit was exact (stress test)."""
        return self.planning_fit().doubts()

    def base_doubts(self) -> tuple[str, ...]:
        """Where the rest is planned with an effect model whose fit is tight: why the
        first-order fit alone does not pin the device down (what ``monitor`` says), or
        ``()``. The effect fit's standard errors hold only if that effect is the device's:
        a device with a second thermal mass that started away from equilibrium was fitted
        as one on 60 min of log with tau ± 7 s, 20 sigma from the truth, its coverage
        claimed 50 % where the device reached 35 %, and replan said nothing while
        monitor said the log does not pin the device down (judge, session 52)."""
        if not self.effect.material or self.doubts():
            return ()
        return self.identified.doubts()

    def base_doubt_line(self) -> str | None:
        """A line for :meth:`base_doubts` (loud, ``***``, on a log shorter than the
        identified tau), else None."""
        d = self.base_doubts()
        if not d:
            return None
        fit = self.planning_fit()
        text = (
            f"the first-order fit alone does not pin the device down ({'; '.join(d)}); the "
            f"rest is planned with {self.effect.effect}, whose tight fit holds only if that is "
            "the device's effect"
        )
        if fit.span_min < TRUST_MIN_TAUS * fit.tau_s / 60.0:
            return (
                f"*** {text}: on {fit.span_min:.0f} min of log (less than tau, "
                f"{fit.tau_s / 60.0:.0f} min) the prediction is a guess; re-plan on a longer "
                "log ***"
            )
        return f"note: {text}"

    @property
    def remaining_min(self) -> float:
        """Time left in the original budget, min."""
        return self.plan.limits.duration_max_min - self.at_min

    @property
    def bins_missing(self) -> list[tuple[float, float, int]]:
        lo = self.plan.grid.lower_c
        return [
            (float(lo[i]), float(lo[i] + 1.0), int(self.missing_levels[i]))
            for i in np.flatnonzero(self.missing_levels > 0)
        ]

    def to_json_dict(self) -> dict[str, Any]:
        p = self.plan
        return json_safe(
            {
                "plan": str(p.path),
                "experiment": p.name,
                "log": self.log_source,
                "at_min": self.at_min,
                "remaining_budget_min": self.remaining_min,
                "executed_steps": self.prefix.n_segments,
                "state": self.state.to_dict(),
                "identified": self.identified.to_dict(),
                "effect": self.effect.to_dict(),
                "model": self.model.to_json_dict(),
                "start_correction_c": self.start_correction_c,
                "levels_required": p.levels_required,
                "delta_c_per_min": p.delta_c_per_min,
                "bins": [
                    {
                        "bin_lo_c": float(lo),
                        "bin_hi_c": float(lo + 1.0),
                        "gradients_c_per_min": [float(x) for x in g],
                        "levels": int(n),
                        "missing": int(m),
                    }
                    for lo, g, n, m in zip(
                        p.grid.lower_c,
                        self.existing_gradients,
                        self.existing_levels,
                        self.missing_levels,
                        strict=True,
                    )
                ],
                "bins_missing": [list(b) for b in self.bins_missing],
                "levels_missing_total": int(self.missing_levels.sum()),
                "pass_in_progress": None
                if self.pass_in_progress is None
                else self.pass_in_progress.to_dict(),
                "notes": list(self.notes),
            }
        )


def _check_at(log: MeasuredLog, plan: PlanRecord, at_min: float) -> None:
    src = log.source
    if not (isinstance(at_min, int | float) and math.isfinite(at_min) and at_min > 0):
        raise ParameterError(f"--at-min must be a time > 0 min into the run, got {at_min!r}")
    if abs(at_min - round(at_min)) > 1e-9:
        raise ParameterError(
            f"--at-min must be a whole number of minutes (step tables are typed in whole "
            f"minutes), got {at_min:g}; use {math.floor(at_min):g}"
        )
    total = plan.programme.total_min
    if at_min >= total:
        raise ParameterError(
            f"--at-min {at_min:g} is at or beyond the end of the plan {plan.path} "
            f"({total:g} min): nothing is left to re-plan"
        )
    t_min = log.time_min
    step_min = log.report.median_step_s / 60.0
    if at_min > float(t_min[-1]) + step_min:
        raise ParameterError(
            f"--at-min {at_min:g} is beyond the end of the log {src} ({t_min[-1]:.1f} min); "
            "re-plan at a time the log has reached"
        )
    at_s = at_min * 60.0
    for a, b in log.gaps:
        if a < at_s < b + log.report.median_step_s:
            raise LogFormatError(
                f"{src}: the log has a gap from {a:g} to {b:g} s around --at-min {at_min:g} "
                "(no state estimate there); re-plan at a time with data"
            )
    for a, b, _ in log.report.nan_spans_s:
        if a - log.report.median_step_s <= at_s <= b + log.report.median_step_s:
            raise LogFormatError(
                f"{src}: t_int_c is missing from {a:g} to {b:g} s, around --at-min {at_min:g} "
                "(no state estimate there); re-plan at a time with readings"
            )


def _cut_log(log: MeasuredLog, at_min: float) -> MeasuredLog:
    frame = log.to_frame()
    frame = frame[frame["time_s"] <= at_min * 60.0 + 1e-9]
    return log_from_frame(frame.reset_index(drop=True), source=log.source)


def prepare_replan(
    log: MeasuredLog,
    plan: PlanRecord,
    at_min: float,
    *,
    settings: MonitorSettings | None = None,
    find_effect: bool = True,
    material_c: float = MATERIAL_C,
) -> ReplanRequest:
    """Validate the inputs and gather the request for re-planning at ``at_min``.

    Parameters
    ----------
    log : MeasuredLog
        The run's log (it may run past ``at_min``: only the rows up to it are used).
    plan : PlanRecord
        The plan being run (:func:`schedsyn.monitor.read_plan_dir`).
    at_min : float
        Re-planning time, min from the programme's start, in (0, end of log and plan).
    find_effect : bool
        Run the diagnosis for an effect beyond tau and dT0 (seconds for a 9-hour log).
    material_c : float
        Threshold of a material effect, degC.

    Raises
    ------
    ParameterError
        ``at_min`` beyond the end of the log or of the plan.
    LogFormatError
        A gap at ``at_min``; a log that does not belong to the plan; a setpoint that left
        the plan's steps.
    """
    settings = MonitorSettings() if settings is None else settings
    _check_at(log, plan, at_min)
    # before the cut: a log starting after M would be cut to nothing and refused as empty
    check_log_start(log, settings)
    cut = _cut_log(log, at_min)
    # the log up to M must be a run of the plan: its setpoint follows the executed steps
    check_log_belongs(cut, plan, settings)
    prefix = cut_programme(plan.programme, at_min)
    notes: list[str] = []
    if log.tk_set_c is None:
        notes.append("the log has no tk_set_c: the plan's programme is taken as the setpoint")
    fit_log = with_plan_setpoint(cut, plan)
    ident = identify(fit_log)
    change_s, jump_c_per_min = plan_rate_changes(plan)
    est = estimate_gradient(
        cut, rate_change_times_s=change_s, rate_change_jumps_c_per_min=jump_c_per_min
    )
    ok = np.flatnonzero(np.isfinite(est.t_est_c))
    k = int(ok[-1])
    dt = at_min - float(cut.time_min[k])
    # carried to M along the gradient: T(M) = T_k + g_k dt; var = P11 + dt^2 P22 (+ cov, neglected)
    state = ReplanState(
        at_min=float(at_min),
        tk_set_c=float(plan.programme.chamber_at(np.array([at_min]))[0]),
        t_c=float(est.t_est_c[k] + est.g_est_c_per_min[k] * dt),
        t_std_c=float(math.hypot(est.t_std_c[k], dt * est.g_std_c_per_min[k])),
        g_c_per_min=float(est.g_est_c_per_min[k]),
        g_std_c_per_min=float(est.g_std_c_per_min[k]),
    )
    base = ident.model
    if find_effect:
        eff = check_effect(fit_log, plan, at_min, base, ident.t0_c, state.t_c, material_c)
    else:
        eff = EffectCheck("none", {}, 0.0, False, base, ident.t0_c)
    if eff.material:
        model, t0 = eff.model, eff.t0_c
        notes.append(
            f"{eff.effect} is material (moves T by up to {eff.max_shift_c:.2f} °C over the "
            "rest of the plan): the rest is planned with it"
        )
    else:
        model, t0 = base, ident.t0_c
        if eff.effect != "none" and eff.max_shift_c > material_c:  # not identified
            notes.append(eff.warnings[-1])
        elif eff.effect != "none":
            notes.append(
                f"{eff.effect} found but not material (moves T by at most "
                f"{eff.max_shift_c:.2f} °C <= {material_c:g} °C over the rest): the base "
                "model is used"
            )
    t_model_at = float(model.predict(prefix, np.array([at_min]), t0_c=t0).t_c[0])
    run = measured_run(cut, est, plan.grid)
    grads, open_pass = closed_passes(run.time_min, run.t_c, run.g_c_per_min, plan.grid)
    levels = np.array([distinct_levels(g, plan.delta_c_per_min) for g in grads], dtype=np.int64)
    missing = np.maximum(plan.levels_required - levels, 0)
    return ReplanRequest(
        plan=plan,
        log_source=log.source,
        at_min=float(at_min),
        prefix=prefix,
        state=state,
        identified=ident,
        effect=eff,
        model=model,
        model_t0_c=t0,
        start_correction_c=state.t_c - t_model_at,
        existing_gradients=grads,
        existing_levels=levels,
        missing_levels=missing,
        pass_in_progress=open_pass,
        notes=tuple(notes),
        measured=(run.time_min, run.t_c, run.g_c_per_min),
    )


# --------------------------------------------------------------------------------------
# the whole run predicted; the re-plan itself
# --------------------------------------------------------------------------------------
#: Slack of the device-limit check of a predicted run, degC (the prediction is an
#: estimate; the planner checks its own model exactly).
PREDICTED_DEVICE_TOL_C = 0.05


@dataclass(frozen=True, slots=True)
class RunPrediction:
    """A whole run as it will end: measured up to ``M``, then predicted.

    The smoothed run up to ``M`` (``ReplanRequest.measured``) and the model's prediction
    from the state at ``M`` (:func:`schedsyn.monitor.predict_from_state`) form one series
    on the metric's 0.1 min grid, so a pass straddling ``M`` is one pass, as the metric
    will count it at the end of the run. ``problems``: every limit of the plan the whole
    programme breaks, and a predicted device temperature after ``M`` outside the device
    limits (by more than :data:`PREDICTED_DEVICE_TOL_C`).
    """

    programme: Programme
    coverage: CoverageReport
    device_min_c: float
    device_max_c: float
    problems: tuple[str, ...]
    #: what of the plan's limits the *new* steps' table breaks (``max_steps``,
    #: ``min_step_min``, rates, duration: the planner's own check of a continuation,
    #: :func:`with_table_problems`); also in ``problems``. A rest with any is never
    #: chosen: the controller cannot be loaded with it (red team: W4 at minute 30, a
    #: 117-step rest against ``max_steps`` 80 was taken with ``problems`` empty).
    table_problems: tuple[str, ...] = ()
    #: the device's predicted temperature when the programme ends, degC
    device_end_c: float = math.nan

    @property
    def complete(self) -> bool:
        return self.coverage.complete and not self.problems

    @property
    def levels_missing(self) -> int:
        """Levels still missing over all bins at the end of the run."""
        c = self.coverage
        return int(np.maximum(c.levels_required - c.levels, 0).sum())

    def preference(self) -> tuple[bool, bool, float, int, int]:
        """Sort key, larger is better: within limits, complete, coverage, the lowest level
        count, the fewest levels missing. (Not the duration: a new programme only for a
        shorter run with the same coverage is not worth typing in mid-run.)"""
        c = self.coverage
        return (not self.problems, c.complete, c.coverage, c.min_levels, -self.levels_missing)

    def to_dict(self) -> dict[str, Any]:
        c = self.coverage
        return {
            "complete": self.complete,
            "coverage": c.coverage,
            "bins_covered": int(c.covered.sum()),
            "min_levels": c.min_levels,
            "levels_missing_total": self.levels_missing,
            "short_bins": [
                {"bin_lo_c": a, "bin_hi_c": b, "levels": n, "missing": c.levels_required - n}
                for a, b, n in c.short_bins()
            ],
            "duration_min": self.programme.total_min,
            "steps": self.programme.n_segments,
            "device_min_after_c": self.device_min_c,
            "device_max_after_c": self.device_max_c,
            "problems": list(self.problems),
        }


def run_series(
    request: ReplanRequest, programme: Programme
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(time_min, T, g)`` of the whole run on the metric's 0.1 min grid: the smoothed log
    up to ``M``, then the request's model started from the state at ``M``.

    After ``M``: ``T(t) = T_model(t) + d e^{-(t - M)/tau}``, ``g = g_model - (d/tau)
    e^{-(t - M)/tau}``, ``d = T_est(M) - T_model(M)``
    (:func:`schedsyn.monitor.predict_from_state`; the model with a material effect where
    one was found, nonlinear effects included).
    """
    tm, tt, tg = request.measured
    full = dense_times(programme.total_min, DENSE_MIN)
    last = float(tm[-1]) if tm.size else request.at_min
    rest = full[full > last + 1e-9]
    if rest.size:
        t_rest, g_rest = predict_from_state(
            request.model, request.model_t0_c, programme, request.at_min, request.state.t_c, rest
        )
    else:
        t_rest = g_rest = np.zeros(0)
    return (
        np.concatenate((tm, rest)),
        np.concatenate((tt, t_rest)),
        np.concatenate((tg, g_rest)),
    )


def device_excess_c(run: RunPrediction, limits: Limits) -> float:
    """How far past the device's limits the run is predicted to take it, degC (0 within)."""
    return max(0.0, limits.device_min_c - run.device_min_c, run.device_max_c - limits.device_max_c)


def safe_return(request: ReplanRequest, start_min: float) -> Programme | None:
    """The plan's steps up to ``start_min``, then the chamber straight back to the end
    temperature at the fastest rate the model allows and held there to the time limit;
    None when the ramp does not end in time.

    What a re-plan falls back on when no continuation fits and the plan unchanged is
    predicted to take the device past its limits: the device's excess is then the least
    a chamber turned round at once can give (red team: W4 at minute 240, a device 3 degC
    hotter and 25 % faster than the model, heading for 68.9 degC with the plan; 63.2 this
    way, its limit 62).
    """
    plan = request.plan
    limits = request.model.planner_limits(plan.limits)
    prefix = cut_programme(plan.programme, start_min)
    delta = plan.limits.end_c - prefix.end_c
    rate = limits.rate_max_c_per_min if delta > 0 else limits.rate_min_c_per_min
    ramp_min = float(math.ceil(abs(delta) / abs(rate) - 1e-9)) if abs(delta) > 1e-9 else 0.0
    hold_min = plan.limits.duration_max_min - start_min - ramp_min
    if hold_min < 0:
        return None
    steps = [(ramp_min, delta / ramp_min if ramp_min else 0.0), (hold_min, 0.0)]
    steps = [(d, r) for d, r in steps if d > 0]
    # the new steps rounded as a continuation's are (whole minutes, 0.1 degC)
    new = Programme(
        np.array([d for d, _ in steps]), np.array([r for _, r in steps]), prefix.end_c
    ).rounded(plan.limits, exact_start=True)
    # the plan's metadata (regions, limits: what simulate, compare and a later re-plan
    # read), with the model the rest was predicted with; its end soak is not known
    meta = plan.programme.meta
    if meta is not None:
        meta = dataclasses.replace(
            meta,
            tau_s=request.model.tau_s,
            dt0_c=request.model.dt0_c,
            end_soak_min=None,
            end_soak_included_min=None,
        )
    return Programme(
        np.concatenate((prefix.durations_min, new.durations_min)),
        np.concatenate((prefix.rates_c_per_min, new.rates_c_per_min)),
        prefix.start_c,
        meta,
    )


def predict_run(request: ReplanRequest, programme: Programme) -> RunPrediction:
    """The whole run ``programme`` (executed steps, then the rest) predicted as it will end
    (:func:`run_series`), counted by the coverage metric, and checked against the plan's
    limits."""
    plan = request.plan
    time_min, temp, grad = run_series(request, programme)
    cov = coverage_report(temp, grad, plan.grid, plan.levels_required, plan.delta_c_per_min)
    after = temp[time_min > request.at_min + 1e-9]
    lim = plan.limits
    problems = list(programme.violations(lim))
    lo = float(after.min()) if after.size else math.nan
    hi = float(after.max()) if after.size else math.nan
    if after.size and (
        lo < lim.device_min_c - PREDICTED_DEVICE_TOL_C
        or hi > lim.device_max_c + PREDICTED_DEVICE_TOL_C
    ):
        problems.append(
            f"the device is predicted to reach {lo:.2f} .. {hi:.2f} °C after minute "
            f"{request.at_min:g}, outside its limits {lim.device_min_c:g} .. "
            f"{lim.device_max_c:g} °C"
        )
    return RunPrediction(programme, cov, lo, hi, tuple(problems), device_end_c=float(temp[-1]))


def with_table_problems(run: RunPrediction, table: Sequence[str]) -> RunPrediction:
    """``run`` with ``table`` (what its new steps' table breaks) added to its problems."""
    table = tuple(x for x in table if x not in run.table_problems)
    if not table:
        return run
    return replace(
        run,
        problems=(*run.problems, *table),
        table_problems=(*run.table_problems, *table),
    )


def planner_table_problems(planned: Any) -> tuple[str, ...]:
    """What of the plan's limits the planner says its continuation's table breaks
    (``Plan.violations``: step count, step length, rates, duration), leaving out the
    device's limits, which :func:`predict_run` judges with the model used."""
    if planned is None:
        return ()
    return tuple(v for v in planned.violations if not v.startswith("the device reaches"))


#: A re-planned run is also predicted at the corners of the identified model's box: tau and
#: dT0 each this many standard deviations either side of the estimate.
UNCERTAINTY_SIGMAS = 2.0
#: A completion predicted from a log shorter than this many identified time constants is
#: not a promise (exit code 1): an effect the model lacks has not had time to show (red
#: team: at minutes 10-25, a tau that changes with temperature, a dT0 drift or a chamber
#: rate limit not yet reached; "complete", and 17-45 % on the true device).
TRUST_MIN_TAUS = 1.0
#: The box's corners stay inside what :class:`schedsyn.params.ThermalParams` accepts:
#: tau up to this, s, and |dT0| up to this, degC.
BOX_TAU_MAX_S = TAU_MAX_S
BOX_DT0_ABS_MAX_C = DT0_ABS_MAX_C


@dataclass(frozen=True, slots=True)
class UncertaintyCheck:
    """The chosen run predicted at the four corners of the identified model's box
    (``tau_s`` and ``dt0_c`` ranges, ± ``sigmas`` standard deviations of the fit the
    model comes from, ``sigma_source``: the base fit, or the effect's own fit when the
    rest is planned with an effect; tau kept above a tenth of its estimate and the box
    inside what a model accepts, :data:`BOX_TAU_MAX_S` and :data:`BOX_DT0_ABS_MAX_C`,
    the whole of it where a standard deviation is not finite): the worst
    corner's coverage and where it is. An early re-plan rests on a young estimate (5 min
    of a W3 log: tau ± 200 s); where the run does not complete at every corner, a later
    re-plan, on a longer log, should look again."""

    sigmas: float
    tau_s: tuple[float, float]
    dt0_c: tuple[float, float]
    worst: RunPrediction
    worst_tau_s: float
    worst_dt0_c: float
    complete_everywhere: bool
    sigma_source: str = "the base fit"

    def to_dict(self) -> dict[str, Any]:
        c = self.worst.coverage
        return {
            "sigmas": self.sigmas,
            "sigma_source": self.sigma_source,
            "tau_s": list(self.tau_s),
            "dt0_c": list(self.dt0_c),
            "complete_at_every_corner": self.complete_everywhere,
            "worst_coverage": c.coverage,
            "worst_min_levels": c.min_levels,
            "worst_tau_s": self.worst_tau_s,
            "worst_dt0_c": self.worst_dt0_c,
            "worst_problems": list(self.worst.problems),
        }

    def line(self) -> str:
        box = (
            f"on the identified model's ±{self.sigmas:g} sigma box (tau {self.tau_s[0]:.0f}"
            f"..{self.tau_s[1]:.0f} s, dT0 {self.dt0_c[0]:.2f}..{self.dt0_c[1]:.2f} °C, "
            f"sigma of {self.sigma_source})"
        )
        if self.complete_everywhere:
            return f"{box}: complete at every corner"
        c = self.worst.coverage
        # a corner may cover every bin and still fail on a limit: say which
        broken = f", but {self.worst.problems[0]}" if self.worst.problems else ""
        return (
            f"{box}: worst {c.coverage:.0%} (min {c.min_levels} levels) at tau "
            f"{self.worst_tau_s:.0f} s, dT0 {self.worst_dt0_c:.2f} °C{broken}; re-plan "
            "again once the log has pinned the model down"
        )


def check_uncertainty(
    request: ReplanRequest, programme: Programme, sigmas: float = UNCERTAINTY_SIGMAS
) -> UncertaintyCheck:
    """``programme`` (the whole run) predicted as :func:`predict_run` does, with the
    request's model at each corner of the identified box (the effect, if any, kept)."""
    i, m, e = request.identified, request.model, request.effect
    tau_std, dt0_std, source = i.tau_std_s, i.dt0_std_c, "the base fit"
    if m.effect != "none" and m.effect == e.effect:  # planned with the effect: its own fit
        se_tau, se_dt0 = e.stderr.get("tau_s", math.nan), e.stderr.get("dt0_c", math.nan)
        if se_tau > 0.0 and se_dt0 > 0.0:  # (False for NaN)
            tau_std, dt0_std, source = se_tau, se_dt0, f"the {m.effect} fit"
    # an unknown spread is the widest box; the box is kept inside the range a model
    # accepts (ThermalParams): a fit that has not converged (dT0 50 +- 140 degC on 30 min
    # of a device with a second thermal mass) must give a wide box, not a crash
    tau_std = tau_std if math.isfinite(tau_std) else math.inf
    dt0_std = dt0_std if math.isfinite(dt0_std) else math.inf
    tau = (
        max(m.tau_s - sigmas * tau_std, 0.1 * m.tau_s),
        min(m.tau_s + sigmas * tau_std, max(BOX_TAU_MAX_S, m.tau_s)),
    )
    dt0 = (
        max(m.dt0_c - sigmas * dt0_std, -BOX_DT0_ABS_MAX_C),
        min(m.dt0_c + sigmas * dt0_std, BOX_DT0_ABS_MAX_C),
    )
    corners = [
        (predict_run(replace(request, model=replace(m, tau_s=t, dt0_c=d)), programme), t, d)
        for t in tau
        for d in dt0
    ]
    worst, wt, wd = min(corners, key=lambda c: c[0].preference())
    every = all(c[0].complete for c in corners)
    return UncertaintyCheck(sigmas, tau, dt0, worst, wt, wd, every, source)


def sweep_end_min(
    request: ReplanRequest, edge_margin_c: float, from_min: float | None = None
) -> float | None:
    """The first whole minute from ``M`` (or ``from_min``) at which the device, going on
    with the plan, is outside the working region by ``edge_margin_c`` (that minute itself
    if it already is).

    New sweeps begin there: a sweep in progress at ``M`` is finished as planned rather
    than abandoned (the planner's sweeps start beyond the region's edges, so one begun
    from inside the region would pass its bins once more for nothing). ``None`` if the
    device stays inside until the plan's end.
    """
    plan = request.plan
    time_min, temp, _ = run_series(request, plan.programme)
    lo = plan.working_lo_c - edge_margin_c
    hi = plan.working_hi_c + edge_margin_c
    first = request.at_min if from_min is None else max(float(from_min), request.at_min)
    minutes = np.arange(first, math.floor(plan.programme.total_min) + 0.5, 1.0)
    # T at whole minutes (the 0.1 min grid holds them up to rounding)
    at = np.interp(minutes, time_min, temp)
    out = np.flatnonzero((at <= lo) | (at >= hi))
    return float(minutes[out[0]]) if out.size else None


def plan_spec(plan: PlanRecord) -> Any:
    """The :class:`schedsyn.planner.ExperimentSpec` of a plan folder's ``plan.json``."""
    from .planner import ExperimentSpec

    fields = ExperimentSpec.__dataclass_fields__
    raw = {k: v for k, v in plan.spec_dict.items() if k in fields}
    raw["name"] = str(raw.get("name") or plan.name)
    try:
        return ExperimentSpec(**raw)
    except TypeError as exc:  # a key the spec needs is missing
        raise ParameterError(f"{plan.path}/plan.json spec: {exc}") from None


def planner_request(request: ReplanRequest, from_min: float | None = None) -> tuple[Any, ...]:
    """What :func:`schedsyn.planner.plan_experiment` is called with for the rest of a run.

    Returns ``(spec, params, limits, model, continuation)``: the plan's
    :class:`~schedsyn.planner.ExperimentSpec`; the identified model's first-order
    equivalent (it shapes the bands and the decay of the start correction); the plan's
    limits with the rates the model allows (a rate limit lowers them); the model's exact
    linear part; and the :class:`~schedsyn.planner.Continuation`.

    ``from_min`` (a whole minute >= ``M``, default ``M``): the new steps begin there; the
    plan's steps run until then. The continuation's fixed steps are the plan's programme
    up to ``from_min``, its existing gradients the passes ended by then (measured up to
    ``M``, predicted after it, :func:`run_series`; a pass open at ``from_min`` left out),
    and its start correction is the predicted ``T(from_min)`` minus where the planner's
    linear model, run over the fixed steps from the fitted ``T0``, puts it.
    """
    from .planner import Continuation

    plan = request.plan
    spec = plan_spec(plan)
    start = request.at_min if from_min is None else float(from_min)
    if start == request.at_min:
        prefix, grads, t_start = request.prefix, request.existing_gradients, request.state.t_c
    else:
        prefix = cut_programme(plan.programme, start)
        time_min, temp, grad = run_series(request, plan.programme)
        upto = time_min <= start + 1e-9
        grads, _ = closed_passes(time_min[upto], temp[upto], grad[upto], plan.grid)
        t_start = float(np.interp(start, time_min, temp))
    model = request.model
    # a time constant that changes with temperature is planned with its value in the
    # working region (the prediction that judges the plan keeps the whole model)
    around_c = 0.5 * (spec.working_lo_c + spec.working_hi_c)
    linear = model.linear_model(around_c)
    # the planner's state at the start: its linear part run over the fixed steps
    t_lin = affine_response(
        linear, prefix.durations_min, np.array([start]), prefix.start_c, request.model_t0_c
    ).evaluate(prefix.rates_c_per_min)[0]
    continuation = Continuation(
        prefix, grads, start_correction_c=t_start - float(t_lin[0]), t0_c=request.model_t0_c
    )
    params = model.planner_params(around_c)
    return spec, params, model.planner_limits(plan.limits), linear, continuation


def continuation_starts(
    request: ReplanRequest, edge_margin_c: float, lead_min: float = 0.0
) -> list[float]:
    """Whole minutes from which the planner is asked for new steps, in the order tried.

    First where the sweep in progress ends (:func:`sweep_end_min`): finishing it as
    planned saves a sweep when the device still leaves the region by the edge margin.
    Then ``M`` itself: where the device turns back short of that (a device slower or
    hotter than the plan's model, say), the sweep end comes a whole sweep later or never,
    and the time left no longer holds the sweeps still needed; new steps from ``M`` take
    the sweep in progress over. Starts at or beyond the time limit are left out.

    ``lead_min`` (whole minutes): no new step before ``M + lead_min``, the time the
    re-plan and loading the controller take while the chamber runs on with the plan;
    ``M + lead_min`` then takes the place of ``M``.
    """
    plan = request.plan
    out = []
    earliest = request.at_min + float(lead_min)
    end = sweep_end_min(request, edge_margin_c, earliest)
    for start in (end, earliest):
        if start is not None and start < plan.limits.duration_max_min and start not in out:
            out.append(float(start))
    return out


@dataclass(frozen=True, slots=True)
class PlannerAttempt:
    """One call of the planner for the rest of a run: new steps from ``start_min``; the
    whole run it returned predicted to its end (``None`` and ``error`` when nothing
    fitted), and the seconds it took. ``planned_with``: ``"identified"`` (the model the
    rest is predicted with) or the effect of a rival model (:class:`RivalPrediction`)
    the steps were planned for; the prediction is then the rival's."""

    start_min: float
    plan: Any  # schedsyn.planner.Plan or None
    prediction: RunPrediction | None
    error: str | None
    planner_s: float
    planned_with: str = "identified"

    def to_dict(self) -> dict[str, Any]:
        pr = self.prediction
        return {
            "planned_with": self.planned_with,
            "new_steps_from_min": self.start_min,
            "predicted_complete": None if pr is None else pr.complete,
            "predicted_coverage": None if pr is None else pr.coverage.coverage,
            "predicted_min_levels": None if pr is None else pr.coverage.min_levels,
            "duration_min": None if pr is None else pr.programme.total_min,
            "steps": None if pr is None else pr.programme.n_segments,
            "problems": [] if pr is None else list(pr.problems),
            "error": self.error,
            "planner_s": self.planner_s,
        }


def _plan_from(
    request: ReplanRequest,
    start: float,
    progress: Callable[[str], None] | None,
    say: Callable[[str], None],
    planned_with: str = "identified",
    stop: Callable[[], bool] | None = None,
) -> PlannerAttempt:
    """Ask the planner for new steps from ``start`` and predict the whole run it returns
    (``stop``: the planner's cancellation, :func:`~schedsyn.planner.plan_experiment`)."""
    from .errors import InfeasiblePlanError
    from .planner import plan_experiment

    plan = request.plan
    spec, params, limits, linear, continuation = planner_request(request, start)
    rival = "" if planned_with == "identified" else f" for the rival model {planned_with}"
    say(
        f"{plan.name}: planning new steps from minute {start:g}{rival} "
        f"({int(request.missing_levels.sum())} levels missing at minute {request.at_min:g}, "
        f"{plan.limits.duration_max_min - start:g} min left)"
    )
    tic = time.perf_counter()
    try:
        planned = plan_experiment(
            spec,
            params,
            limits,
            model=linear,
            continuation=continuation,
            progress=progress,
            stop=stop,
        )
    except InfeasiblePlanError as exc:
        return PlannerAttempt(start, None, None, str(exc), time.perf_counter() - tic, planned_with)
    seconds = time.perf_counter() - tic
    prediction = with_table_problems(
        predict_run(request, planned.programme), planner_table_problems(planned)
    )
    return PlannerAttempt(start, planned, prediction, None, seconds, planned_with)


Key = tuple[bool, bool, float, int, int]

#: With ``lead_min`` > 0 the planner calls of a re-plan stop, with what they have, once
#: this share of the lead has passed since the re-plan began: the rest of the lead is
#: for predicting the runs, writing the folder and loading the programme.
LEAD_PLANNER_SHARE = 0.6


def refuse_continuation(
    run: RunPrediction, key: Key, unchanged: RunPrediction, unchanged_key: Key
) -> str | None:
    """Why a continuation ``run`` (judged ``key``, :meth:`RunPrediction.preference` at its
    worst over the model used and its rivals) may not be chosen over the plan unchanged
    (judged ``unchanged_key``), or ``None``.

    * A table that breaks a limit of the plan (:attr:`RunPrediction.table_problems`:
      ``max_steps`` above all) cannot be loaded: never chosen.
    * While the plan unchanged is within the device's limits (under every model), a rest
      predicted to cover less is never chosen, nor one that leaves its weakest bin with
      fewer levels than the plan unchanged leaves its own (up to the requirement): a bin
      with no level at all cannot be calibrated, and more complete bins elsewhere do not
      make up for it (red team: W3, tau 3000 s, at minute 60, 73 % with bins 0..6 at 0
      levels was taken over 53 % with every bin at 1 or more). Only a plan unchanged that
      breaks a limit can make a worse rest the better choice (and the reason says so).
    """
    if run.table_problems:
        return f"its new steps break a limit ({run.table_problems[0]})"
    if not unchanged_key[0]:
        return None
    if not key[0]:
        return "it is predicted to break a limit the plan unchanged keeps"
    if not key[1] and key[2] < unchanged_key[2] - 1e-12:
        return (
            f"it is predicted to cover {key[2]:.0%} of the bins, the plan unchanged "
            f"{unchanged_key[2]:.0%}"
        )
    floor = min(unchanged_key[3], unchanged.coverage.levels_required)
    if key[3] < floor:
        return (
            f"it leaves its weakest bin with {key[3]} levels, the plan unchanged {unchanged_key[3]}"
        )
    return None


def fewer_levels_bins(run: RunPrediction, unchanged: RunPrediction) -> list[tuple[float, int, int]]:
    """``(bin_lo_c, levels, unchanged levels)`` of each bin ``run`` leaves short with fewer
    levels than the plan unchanged would give it (up to the requirement)."""
    c, u = run.coverage, unchanged.coverage
    cap = np.minimum(u.levels, u.levels_required)
    return [
        (float(c.grid.lower_c[i]), int(c.levels[i]), int(u.levels[i]))
        for i in np.flatnonzero(c.levels < cap)
    ]


#: Rival models a re-plan also plans new steps for (the ones that disagree most with the
#: model used); every rival still judges every run.
MAX_RIVAL_PLANS = 1


@dataclass(frozen=True, slots=True)
class RivalPrediction:
    """The chosen run predicted with a rival model (:class:`schedsyn.monitor.RivalModel`:
    one that fits the log about as well as the model used, but predicts the rest
    ``gap_c`` degC apart from it)."""

    effect: str
    gap_c: float
    prediction: RunPrediction

    def to_dict(self) -> dict[str, Any]:
        c = self.prediction.coverage
        return {
            "effect": self.effect,
            "max_gap_over_rest_c": self.gap_c,
            "complete": self.prediction.complete,
            "coverage": c.coverage,
            "min_levels": c.min_levels,
            "problems": list(self.prediction.problems),
        }

    def line(self) -> str:
        c = self.prediction.coverage
        broken = f"; {self.prediction.problems[0]}" if self.prediction.problems else ""
        return (
            f"*** the log fits {self.effect} about as well (it predicts the device up to "
            f"{self.gap_c:.2f} °C apart over the rest); with it the run ends at "
            f"{c.coverage:.0%} (min {c.min_levels} levels){broken}: not a promise yet, "
            "re-plan when the log tells them apart"
        )


def predict_rivals(request: ReplanRequest, programme: Programme) -> tuple[RivalPrediction, ...]:
    """``programme`` (the whole run) predicted with each rival model of the request's
    effect check, from the same state at ``M``."""
    return tuple(
        RivalPrediction(
            r.effect,
            r.gap_c,
            predict_run(replace(request, model=r.model, model_t0_c=r.t0_c), programme),
        )
        for r in request.effect.rivals
    )


@dataclass(frozen=True, slots=True)
class ReplanResult:
    """A re-plan at ``M``: the whole run chosen, its predicted end, and the alternatives.

    ``choice`` is ``"new"`` (the planner's continuation, whose steps differ from the
    plan's from ``new_steps_from_min`` on) or ``"keep"`` (the plan's own rest, unchanged:
    it is predicted to complete, or nothing better was found);
    ``prediction`` the chosen run predicted to its end (:func:`predict_run`);
    ``unchanged`` the same for the plan's own rest; ``planned`` the planner's
    continuation (``None`` when it was not needed or nothing fitted, then
    ``planner_error`` says why); ``replan_s`` the wall time of the whole re-plan and
    ``planner_s`` of the planner call, s.
    """

    request: ReplanRequest
    choice: str
    reason: str
    prediction: RunPrediction
    unchanged: RunPrediction
    planned: Any = None  # schedsyn.planner.Plan (imported lazily: cvxpy)
    planner_error: str | None = None
    new_steps_from_min: float | None = None
    replan_s: float = 0.0
    planner_s: float = 0.0
    attempts: tuple[PlannerAttempt, ...] = ()
    #: why continuations the planner returned were not taken (:func:`refuse_continuation`)
    refused: tuple[str, ...] = ()
    uncertainty: UncertaintyCheck | None = None
    rivals: tuple[RivalPrediction, ...] = ()
    lead_min: float = 0.0
    #: the planner was stopped (or not asked again) at the lead's time budget
    #: (:data:`LEAD_PLANNER_SHARE` of ``lead_min``)
    planner_cut_at_lead: bool = False

    @property
    def programme(self) -> Programme:
        """The whole run: the executed steps, then the rest."""
        return self.prediction.programme

    @property
    def complete(self) -> bool:
        """The run is predicted to complete every bin within the limits."""
        return self.prediction.complete

    @property
    def trusted_complete(self) -> bool:
        """:attr:`complete`, from a fit that pins the device down
        (:meth:`~schedsyn.monitor.Identified.doubts` empty), on a log of at least
        :data:`TRUST_MIN_TAUS` time constants, complete too at every corner of the
        identified model's box (:attr:`uncertainty`) and with every model that fits the
        log about as well (:attr:`rivals`): what exit code 0 says."""
        return self.complete and not self.untrusted_reasons()

    def untrusted_reasons(self) -> tuple[str, ...]:
        """Why a predicted completion is not a promise (see :attr:`trusted_complete`)."""
        out = []
        if self.request.doubts():
            out.append("the log does not pin the device down yet")
        i = self.request.planning_fit()
        if i.span_min < TRUST_MIN_TAUS * i.tau_s / 60.0:
            out.append(
                f"the log spans {i.span_min:.0f} min, less than the identified tau "
                f"({i.tau_s / 60.0:.0f} min): effects the model lacks cannot show yet"
            )
        if self.uncertainty is not None and not self.uncertainty.complete_everywhere:
            out.append("not complete at every corner of the identified model's box")
        if not all(r.prediction.complete for r in self.rivals):
            out.append("not complete with a model that fits the log about as well")
        return tuple(out)

    def to_frame(self) -> pd.DataFrame:
        """Per bin: levels at ``M``, missing at ``M``, predicted at the end (chosen run and
        the plan unchanged), and missing at the end."""
        r = self.request
        lo = r.plan.grid.lower_c
        c, u = self.prediction.coverage, self.unchanged.coverage
        frame = pd.DataFrame(
            {
                "bin_lo_c": lo,
                "bin_hi_c": lo + r.plan.grid.bin_c,
                "levels_at_m": r.existing_levels,
                "missing_at_m": r.missing_levels,
                "predicted_passes": c.pass_counts,
                "predicted_levels": c.levels,
                "predicted_missing": np.maximum(c.levels_required - c.levels, 0),
                "unchanged_plan_levels": u.levels,
            }
        )
        if self.planned is not None:
            frame["planner_levels"] = self.planned.coverage.levels
        return frame

    def _planner_dict(self) -> dict[str, Any] | None:
        p = self.planned
        if p is None:
            return None if self.planner_error is None else {"error": self.planner_error}
        return {
            "status": p.status,
            "complete": p.complete,
            "coverage": p.coverage.coverage,
            "min_levels": p.coverage.min_levels,
            "short_bins": [list(b) for b in p.coverage.short_bins()],
            "duration_min": p.duration_min,
            "steps": p.steps,
            "continued_from_min": p.continued_from_min,
            "lp_solves": p.n_lp,
            "violations": list(p.violations),
            "notes": list(p.notes),
            "solve_s": p.solve_s,
        }

    def to_json_dict(self) -> dict[str, Any]:
        out = self.request.to_json_dict()
        out.update(
            {
                "choice": self.choice,
                "reason": self.reason,
                "complete": self.complete,
                "identification_doubts": list(self.request.doubts()),
                "base_fit_doubts": list(self.request.base_doubts()),
                "predicted": self.prediction.to_dict(),
                "unchanged_plan": self.unchanged.to_dict(),
                "planner": self._planner_dict(),
                "planner_attempts": [a.to_dict() for a in self.attempts],
                "refused_continuations": list(self.refused),
                "bins_fewer_levels_than_unchanged": [
                    {"bin_lo_c": lo, "levels": n, "unchanged_plan_levels": u}
                    for lo, n, u in self.fewer_levels_bins()
                ],
                "new_steps_from_min": self.new_steps_from_min,
                "end": self.end_state(),
                "lead_min": self.lead_min,
                "planner_cut_at_lead": self.planner_cut_at_lead,
                "replan_s": self.replan_s,
                "planner_s": self.planner_s,
                "uncertainty_box": None if self.uncertainty is None else self.uncertainty.to_dict(),
                "rival_models": [r.to_dict() for r in self.rivals],
                "trusted_complete": self.trusted_complete,
                "untrusted_reasons": list(self.untrusted_reasons()) if self.complete else [],
            }
        )
        return json_safe(out)

    def summary(self) -> str:
        r = self.request
        p = r.plan
        i = r.identified
        c = self.prediction.coverage
        if self.choice == "keep":
            what = "the plan goes on unchanged"
        elif self.new_steps_from_min == r.at_min:
            what = f"new steps from minute {r.at_min:g}"
        else:
            what = (
                f"the plan goes on to minute {self.new_steps_from_min:g} (the sweep in progress "
                "ends), then new steps"
            )
        lines = [
            f"{p.name}: re-planned at minute {r.at_min:g} ({r.remaining_min:g} min left of "
            f"{p.limits.duration_max_min:g})",
            f"identified from the log: tau {i.tau_s:.0f} ± {i.tau_std_s:.0f} s, dT0 "
            f"{i.dt0_c:.2f} ± {i.dt0_std_c:.2f} °C (plan: {p.params.tau_s:g} s, "
            f"{p.params.dt0_c:g} °C); model for the rest: {_model_text(r.model)}",
            *[x for x in (r.planning_fit().doubt_line(), r.base_doubt_line()) if x is not None],
            f"measured by minute {r.at_min:g}: {int((r.missing_levels == 0).sum())}/"
            f"{p.grid.n_bins} bins with >= {p.levels_required} levels, "
            f"{int(r.missing_levels.sum())} levels missing",
            f"{what}: {self.reason}",
            f"predicted at the end: {c.coverage:.0%} ({int(c.covered.sum())}/{p.grid.n_bins} "
            f"bins, min {c.min_levels} levels), the run lasts {self.programme.total_min:g} min"
            + ("" if self.complete else " -- NOT COMPLETE"),
        ]
        short = self.prediction.to_dict()["short_bins"]
        if short:
            lines.append(
                "short: "
                + ", ".join(
                    f"[{b['bin_lo_c']:g}, {b['bin_hi_c']:g}) {b['levels']} levels "
                    f"(missing {b['missing']})"
                    for b in short[:10]
                )
                + (f" and {len(short) - 10} more" if len(short) > 10 else "")
            )
        lines.extend(f"problem: {x}" for x in self.prediction.problems)
        if self.choice == "new" and not self.complete and self.planned is not None:
            # why the planner's best fell short, in its own words (red team: an incomplete
            # continuation said only NOT COMPLETE)
            lines.extend(f"planner: {n}" for n in self.planned.notes)
        end = self.end_line()
        if end is not None:
            lines.append(end)
        fewer = self.fewer_levels_bins()
        if fewer:
            lines.append(
                f"*** the new steps leave {len(fewer)} bin(s) with fewer levels than the plan "
                "unchanged would: "
                + ", ".join(
                    f"[{lo:g}, {lo + p.grid.bin_c:g}) {n} (plan {u})" for lo, n, u in fewer[:10]
                )
                + (f" and {len(fewer) - 10} more" if len(fewer) > 10 else "")
            )
        lines.extend(f"not taken: {x}" for x in self.refused)
        if self.uncertainty is not None:
            lines.append(self.uncertainty.line())
        if self.complete and not self.trusted_complete:
            lines.append(
                "*** predicted complete, but not a promise (exit code 1): "
                + "; ".join(self.untrusted_reasons())
                + "; re-plan again later in the run ***"
            )
        lines.extend(x.line() for x in self.rivals if not x.prediction.complete)
        late = self.late_line()
        if late is not None:
            lines.append(late)
        if self.planner_cut_at_lead:
            budget_s = LEAD_PLANNER_SHARE * self.lead_min * 60.0
            lines.append(
                f"note: the planner was stopped with what it had after {self.planner_s:.0f} s "
                f"(the re-plan's budget: {budget_s:.0f} s, {LEAD_PLANNER_SHARE:.0%} of "
                f"--lead-min {self.lead_min:g}); a longer lead may find a better rest"
            )
        lines.extend(f"note: {n}" for n in r.notes)
        return "\n".join(lines)

    def end_state(self) -> dict[str, float]:
        """Where the chosen run leaves the device: its predicted temperature when the
        programme ends, where it settles with the chamber held at the end temperature
        (``end + dT0`` of the model for the rest) and the minutes that takes to come within
        the plan's end tolerance, ``tau ln(|T_end - settle| / tol)`` (first order, the
        model's tau; 0 when already within). Red team: a rest that ended with the device
        at 41 degC against 20 + dT0 said nothing of the 2-3 h it still needed."""
        limits = self.request.plan.limits
        t_end = self.prediction.device_end_c  # (predict_run's series, not run again)
        settle = float(self.programme.end_c) + self.request.model.dt0_c
        gap = abs(t_end - settle)
        tol = limits.end_tol_c
        soak = 0.0 if gap <= tol else self.request.model.tau_s / 60.0 * math.log(gap / tol)
        return {"device_end_c": t_end, "settles_at_c": settle, "end_soak_min": math.ceil(soak)}

    def end_line(self) -> str | None:
        """The end-soak line of :meth:`summary` (None when the device ends settled)."""
        e = self.end_state()
        if e["end_soak_min"] <= 0:
            return None
        return (
            f"end: the device is predicted at {e['device_end_c']:.1f} °C when the programme "
            f"ends; with the chamber held at {self.programme.end_c:g} °C it needs about "
            f"{e['end_soak_min']:g} min more to come within ±"
            f"{self.request.plan.limits.end_tol_c:g} °C of where it settles "
            f"({e['settles_at_c']:.1f} °C, the model for the rest)"
        )

    def fewer_levels_bins(self) -> list[tuple[float, int, int]]:
        """Bins the chosen new steps leave short with fewer levels than the plan unchanged
        would give them (:func:`fewer_levels_bins`); ``[]`` when the plan is kept."""
        if self.choice != "new":
            return []
        return fewer_levels_bins(self.prediction, self.unchanged)

    def late_line(self) -> str | None:
        """A ``***`` line when the re-plan took longer than the time before its new steps
        begin: a chamber that ran on with the plan has passed where they start."""
        start = self.new_steps_from_min
        if self.choice != "new" or start is None:
            return None
        took_min = self.replan_s / 60.0
        if self.request.at_min + took_min <= start:
            return None
        lead = math.ceil(took_min) + 2
        return (
            f"*** the re-plan took {took_min:.1f} min and its new steps begin at minute "
            f"{start:g}: a chamber that ran on with the plan since minute "
            f"{self.request.at_min:g} is past them; re-plan with --lead-min {lead} (the "
            "minutes the re-plan and loading the programme take), or hold the chamber"
        )


def _model_text(model: ModelSpec) -> str:
    base = f"tau {model.tau_s:.0f} s, dT0 {model.dt0_c:.2f} °C"
    if model.effect == "none":
        return base
    pars = ", ".join(f"{k} {v:.4g}" for k, v in model.parameters.items())
    return f"{base} + {model.effect} ({pars})"


def _limit_text(unchanged: RunPrediction, rivals: Sequence[tuple[str, ReplanRequest]]) -> str:
    """Which limit the plan unchanged is predicted to break, and with which model."""
    if unchanged.problems:
        return f"{unchanged.problems[0]} (the model used)"
    for label, rq in rivals:
        broken = predict_run(rq, unchanged.programme).problems
        if broken:
            return f"{broken[0]} (with the rival model {label})"
    return "it breaks a limit"


def replan_run(
    log: MeasuredLog,
    plan: PlanRecord,
    at_min: float,
    *,
    settings: MonitorSettings | None = None,
    find_effect: bool = True,
    material_c: float = MATERIAL_C,
    keep_if_complete: bool = True,
    new_only_if_complete: bool = False,
    new_min_coverage: float = 0.0,
    lead_min: float = 0.0,
    progress: Callable[[str], None] | None = None,
) -> ReplanResult:
    """Re-plan the rest of a run at minute ``at_min`` (what ``schedsyn replan`` does).

    :func:`prepare_replan` (inputs checked, state and model at ``M``, levels so far), then
    the plan's own rest is predicted with the identified model (:func:`predict_run`). If
    it completes every bin within the limits and ``keep_if_complete``, it is kept (no new
    steps to type in). Otherwise :func:`schedsyn.planner.plan_experiment` plans new steps
    as a continuation from where the sweep in progress ends and, unless that one is
    predicted complete, from ``M`` itself (:func:`continuation_starts`,
    :func:`planner_request`); each whole run it returns is predicted the same way; the
    best (:meth:`RunPrediction.preference`) is chosen, the unchanged plan on a tie or when
    no continuation fits (the planner's reasons are kept in the result).

    The device's limits come first, whatever ``keep_if_complete``,
    ``new_only_if_complete`` and ``new_min_coverage`` say: a plan predicted to take the
    device past them is not kept as complete; a continuation that breaks them less (or
    not at all) is taken over it; and when every run at hand breaks them,
    :func:`safe_return` brings the chamber straight home if that breaks them less.

    Parameters
    ----------
    log, plan, at_min, settings, find_effect, material_c
        As for :func:`prepare_replan`; ``at_min`` a whole minute.
    keep_if_complete : bool
        Keep the plan's own rest when it is predicted to complete (default); ``False``
        always asks the planner.
    new_only_if_complete : bool
        Take new steps only when the whole run they make is predicted complete (for an
        early re-plan, whose model has seen little of the run: an incomplete new rest
        chosen on it can spend time a later, better-informed re-plan would have used
        better). Default ``False``: the better run is taken.
    new_min_coverage : float, share 0..1
        Take new steps that do not complete the run only when it is predicted to cover at
        least this share of the bins (a milder form of ``new_only_if_complete`` for an
        early re-plan: a rest predicted nearly complete is worth taking on a young
        model, one far from complete is not). Default 0: the better run is taken.
    lead_min : float, whole minutes >= 0
        No new step begins before ``at_min + lead_min``: the minutes the re-plan takes
        (seconds to several minutes; ``replan_s`` says) and loading the new programme,
        while the chamber runs on with the plan. When > 0 it is also the re-plan's time
        budget: the planner calls stop with what they have once
        :data:`LEAD_PLANNER_SHARE` of it has passed (wall time: on a slower or busier
        machine the answer can be another). Default 0 (no budget; the chamber waits, or
        the log ends well before the present).
    progress : callable(str), optional
        Receives short progress messages (the planner's too).

    Raises
    ------
    ParameterError, LogFormatError
        As :func:`prepare_replan` (bad ``at_min``, gaps, a log of another plan).
    """
    if not 0.0 <= new_min_coverage <= 1.0:
        raise ParameterError(
            f"new_min_coverage is a share of the bins, 0 to 1, got {new_min_coverage!r}"
        )
    if not (math.isfinite(lead_min) and lead_min >= 0 and lead_min == int(lead_min)):
        raise ParameterError(
            f"lead_min must be a whole number of minutes >= 0, got {lead_min!r} (the minutes "
            "the re-plan and loading the programme take while the chamber runs on)"
        )
    tic = time.perf_counter()
    deadline = tic + LEAD_PLANNER_SHARE * lead_min * 60.0 if lead_min > 0 else math.inf
    cut = [False]

    def past_deadline() -> bool:
        late = time.perf_counter() > deadline
        cut[0] = cut[0] or late
        return late

    say = progress if progress is not None else (lambda _msg: None)
    say(f"{plan.name}: the log up to minute {at_min:g}: state, levels so far, model")
    request = prepare_replan(
        log, plan, at_min, settings=settings, find_effect=find_effect, material_c=material_c
    )
    unchanged = predict_run(request, plan.programme)
    # models that fit the log as well but predict the rest differently: a run is judged
    # at its worst over them and the model used (red team: a dT0 drifting 0.5 degC/h
    # read as a slope of dT0 with temperature on the first hour; the plan kept as
    # "complete" ended at 83 %)
    rivals = [
        (r.effect, replace(request, model=r.model, model_t0_c=r.t0_c))
        for r in request.effect.rivals
    ]

    def judged(run: RunPrediction) -> tuple[bool, bool, float, int, int]:
        keys = [run.preference()]
        keys.extend(predict_run(rq, run.programme).preference() for _, rq in rivals)
        return min(keys)

    unchanged_key = judged(unchanged)
    worst_text = " at its worst over the model used and the rivals" if rivals else ""
    planned, error, planner_s, new_from = None, None, 0.0, None
    attempts: list[PlannerAttempt] = []
    refused: list[str] = []
    if keep_if_complete and unchanged_key[0] and unchanged_key[1]:
        choice = "keep"
        reason = (
            "the plan's own rest is predicted to complete every bin with the identified "
            f"model{' and its rivals' if rivals else ''}; no new steps"
        )
        chosen = unchanged
    else:
        before = (
            ("completes" if unchanged_key[0] else "completes but breaks a limit")
            if unchanged_key[1]
            else f"reaches {unchanged_key[2]:.0%}{worst_text}"
        )
        if not unchanged_key[0]:  # say which limit, and under which model
            before += f", and {_limit_text(unchanged, rivals)}"
        best: tuple[RunPrediction, Any, float] | None = None
        best_key = None
        # new steps for the rival that disagrees most only: several rivals (4 on a W4 log
        # of the first hour) would each cost a planner call; all still judge every run
        planned_for = sorted(request.effect.rivals, key=lambda r: -r.gap_c)[:MAX_RIVAL_PLANS]
        plan_rivals = [
            (label, rq) for label, rq in rivals if label in {r.effect for r in planned_for}
        ]
        for label, rq in (("identified", request), *plan_rivals):
            starts = continuation_starts(rq, plan_spec(plan).edge_margin_c, lead_min)
            # a rival's steps from M only: the sweep-end starts cost several times more
            # and, on the red team's drifting device, all ended short (45 s each)
            for start in starts if rq is request else starts[-1:]:
                if past_deadline():
                    break  # (the lead's time budget is spent: a note says so)
                attempt = _plan_from(
                    rq,
                    start,
                    progress,
                    say,
                    label,
                    stop=past_deadline if lead_min > 0 else None,
                )
                attempts.append(attempt)
                planner_s += attempt.planner_s
                if attempt.prediction is None:
                    continue
                run = (
                    attempt.prediction
                    if rq is request
                    else with_table_problems(
                        predict_run(request, attempt.prediction.programme),
                        attempt.prediction.table_problems,
                    )
                )
                key = judged(run)
                refusal = refuse_continuation(run, key, unchanged, unchanged_key)
                if refusal is not None:
                    from_text = f"from minute {start:g}" + (
                        "" if label == "identified" else f" (planned for {label})"
                    )
                    refused.append(f"the continuation {from_text} is not taken: {refusal}")
                    continue
                if best_key is None or key > best_key:
                    best, best_key = (run, attempt.plan, start), key
                if best_key[0] and best_key[1]:
                    break  # a later start cannot do better than complete within limits
            if best_key is not None and best_key[0] and best_key[1]:
                break
        if not attempts:
            error = (
                f"the re-plan's time budget ({LEAD_PLANNER_SHARE:.0%} of --lead-min "
                f"{lead_min:g}) was spent before the planner could be asked"
                if cut[0]
                else "the device stays inside the working region until the end of the plan "
                "and no time is left: no new sweep can begin"
                if lead_min == 0
                else f"no time is left after minute {at_min + lead_min:g} (lead {lead_min:g} "
                "min): no new sweep can begin"
            )
        elif best is None:
            error = "; ".join(
                [f"from minute {a.start_min:g}: {a.error}" for a in attempts if a.error] + refused
            )
        none_fits = "no continuation is taken" if refused else "no continuation fits"
        if best is not None:
            planned = best[1]
        new = None if best is None else best[0]
        # the device's limits come first (before --only-if-complete and the coverage
        # floor): when every run at hand breaks them, the chamber goes straight home if
        # that breaks them less; a new rest within them is taken over a plan that is not
        excess = device_excess_c(unchanged, plan.limits)
        new_excess = math.inf if new is None else device_excess_c(new, plan.limits)
        least = min(excess, new_excess)
        safe = None
        if least > PREDICTED_DEVICE_TOL_C:
            start = request.at_min + float(lead_min)
            programme = (
                safe_return(request, start) if start < plan.limits.duration_max_min else None
            )
            safe = None if programme is None else predict_run(request, programme)
        if safe is not None and device_excess_c(safe, plan.limits) < least - PREDICTED_DEVICE_TOL_C:
            choice, chosen, new_from = "new", safe, request.at_min + float(lead_min)
            why = (
                f"{none_fits} ({error}) and the plan unchanged is predicted to "
                f"take the device {excess:.1f} °C past its limit"
                if new is None
                else "the planner's best continuation is predicted to take the device "
                f"{new_excess:.1f} °C past its limit, the plan unchanged {excess:.1f} °C"
            )
            reason = (
                f"{why}: the chamber goes straight back "
                f"to {plan.limits.end_c:g} °C from minute {new_from:g} (the device "
                f"{device_excess_c(safe, plan.limits):.1f} °C past, the least a chamber "
                f"turned round at once can give; {safe.coverage.coverage:.0%} of the bins)"
            )
        elif (
            new is not None
            and best_key is not None
            and excess > PREDICTED_DEVICE_TOL_C
            and new_excess < excess - PREDICTED_DEVICE_TOL_C
        ):
            choice, chosen, new_from = "new", new, best[2]  # type: ignore[index]
            reason = (
                f"the plan unchanged is predicted to take the device {excess:.1f} °C past "
                "its limit, the planner's continuation "
                + (
                    f"{new_excess:.1f} °C"
                    if new_excess > PREDICTED_DEVICE_TOL_C
                    else "keeps it within its limits"
                )
                + "; it reaches "
                f"{best_key[2]:.0%} (min {best_key[3]} levels){worst_text} in "
                f"{new.programme.total_min:g} min"
            )
        elif (
            new is not None
            and best_key is not None
            and best_key > unchanged_key
            and (best_key[1] or (not new_only_if_complete and best_key[2] >= new_min_coverage))
        ):
            choice, chosen, new_from = "new", new, best[2]  # type: ignore[index]
            reason = (
                f"the planner's continuation is predicted to reach {best_key[2]:.0%}"
                f" (min {best_key[3]} levels){worst_text} in {new.programme.total_min:g} "
                f"min; the plan unchanged {before}"
            )
            if not unchanged_key[0] and best_key[0]:
                # a rest covering less is taken only for the device's limits: say so
                worse = (
                    f", less than the plan unchanged ({unchanged_key[2]:.0%}), "
                    if best_key[2] < unchanged_key[2]
                    else ""
                )
                reason = (
                    f"the plan unchanged {before}; the planner's continuation keeps the "
                    f"device within its limits{' under every model' if rivals else ''} and "
                    f"is predicted to reach {best_key[2]:.0%} (min {best_key[3]} levels)"
                    f"{worst_text}{worse or ' '}in {new.programme.total_min:g} min"
                    + (": taken for the device's limits" if worse else "")
                )
        else:
            choice, chosen = "keep", unchanged
            why = (
                f"{none_fits} ({error})"
                if new is None or best_key is None
                else f"the planner's continuation would reach only {best_key[2]:.0%}"
                f" (min {best_key[3]} levels){worst_text}"
                + (
                    ", and new steps are taken only when complete"
                    if new_only_if_complete
                    else f", and incomplete new steps are taken only from {new_min_coverage:.0%}"
                    if best_key[2] < new_min_coverage
                    else ""
                )
            )
            reason = f"{why}; the plan unchanged {before}"
    return ReplanResult(
        request=request,
        choice=choice,
        reason=reason,
        prediction=chosen,
        unchanged=unchanged,
        planned=planned,
        planner_error=error,
        new_steps_from_min=new_from,
        replan_s=time.perf_counter() - tic,
        planner_s=planner_s,
        attempts=tuple(attempts),
        refused=tuple(refused),
        uncertainty=check_uncertainty(request, chosen.programme),
        rivals=predict_rivals(request, chosen.programme),
        lead_min=float(lead_min),
        planner_cut_at_lead=cut[0],
    )


def write_replan_dir(
    out: Path | str,
    result: ReplanResult,
    inputs: Sequence[Path | str] = (),
    extra: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write ``DIR`` as a plan directory of the whole run, plus ``replan.json`` (with
    ``extra``'s items added, e.g. what was excluded from the log).

    The directory holds ``steps.csv`` (the whole run in the usual step-table format: the
    executed steps, then the new ones), ``plan.json`` (the original ``spec`` and
    ``limits``; ``tau_s``, ``dt0_c`` and ``model``: the model the rest was planned with;
    the predicted coverage; where it came from), ``replan.json``
    (:meth:`ReplanResult.to_json_dict`: what was identified, what is still missing, the
    predicted end of the run and the alternatives) and ``bins.csv``
    (:meth:`ReplanResult.to_frame`). :func:`schedsyn.monitor.read_plan_dir` reads it back,
    so a run can be re-planned again later. Nothing is written if the programme does not
    begin with the executed steps or breaks a limit of the plan.
    """
    out = Path(out)
    request = result.request
    programme = result.programme
    prefix = request.prefix
    # the same chamber path up to M (at every breakpoint of either, and between them)
    knots = np.concatenate(
        (prefix.starts_min, programme.starts_min[programme.starts_min < request.at_min])
    )
    t = np.unique(np.concatenate((knots, [request.at_min], np.linspace(0, request.at_min, 200))))
    worst = float(np.max(np.abs(programme.chamber_at(t) - prefix.chamber_at(t))))
    if programme.total_min <= request.at_min or worst > 0.01:
        raise ParameterError(
            "the whole-run programme must begin with the steps executed up to "
            f"{request.at_min:g} min (it departs from them by {worst:.2f} °C)"
        )
    problems = programme.violations(request.plan.limits)
    if problems:
        raise ParameterError("the whole-run programme breaks a limit: " + problems[0])
    inputs = list(inputs)
    raw = dict(request.plan.raw)
    pred = result.prediction
    meta = {
        "experiment": request.plan.name,
        "tau_s": request.model.tau_s,
        "dt0_c": request.model.dt0_c,
        "model": request.model.to_json_dict(),
        "spec": raw["spec"],
        "limits": request.plan.limits.to_dict(),
        "status": "complete" if pred.complete else "incomplete",
        "complete": pred.complete,
        "coverage": pred.coverage.coverage,
        "min_levels": pred.coverage.min_levels,
        "short_bins": [list(b) for b in pred.coverage.short_bins()],
        "coverage_basis": (
            f"predicted: measured up to minute {request.at_min:g}, then the identified model"
        ),
        "duration_min": programme.total_min,
        "steps": programme.n_segments,
        "continued_from_min": result.new_steps_from_min,
        "replanned_from": {
            "plan": str(request.plan.path),
            "at_min": request.at_min,
            "log": request.log_source,
            "choice": result.choice,
        },
    }
    written = [
        programme.to_csv(out / "steps.csv", inputs),
        write_json_atomic(out / "plan.json", json_safe(meta), inputs),
        write_json_atomic(out / "replan.json", {**result.to_json_dict(), **(extra or {})}, inputs),
        write_frame_atomic(out / "bins.csv", result.to_frame(), inputs),
    ]
    return written
