"""Re-plan the rest of a run from its log: everything the planner needs, checked.

``schedsyn replan LOG.csv PLAN_DIR --at-min M`` re-plans a run at minute ``M``. This
module prepares the request (:func:`prepare_replan`) and writes the result
(:func:`write_replan_dir`); the continuation itself is planned by
``schedsyn.planner.plan_experiment`` with a fixed prefix (the one call is in
:func:`plan_continuation` once the planner offers it).

What :func:`prepare_replan` establishes, in order:

1. **Inputs.** ``M`` lies inside the log and inside the plan; the log has data at ``M``
   (no sampling gap or run of missing readings around it); the log up to ``M`` belongs to
   the plan (:func:`schedsyn.monitor.check_log_belongs`). Each failure is one line.
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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .compare import resample_run
from .coverage import distinct_levels
from .effects import ModelSpec
from .errors import LogFormatError, ParameterError
from .estimate import estimate_gradient
from .io import write_json_atomic
from .logs import MeasuredLog, log_from_frame
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
    closed_passes,
    identify,
    json_safe,
    with_plan_setpoint,
)
from .programme import Programme


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
    cut = _cut_log(log, at_min)
    # the log up to M must be a run of the plan: its setpoint follows the executed steps
    check_log_belongs(cut, plan, settings)
    prefix = cut_programme(plan.programme, at_min)
    notes: list[str] = []
    if log.tk_set_c is None:
        notes.append("the log has no tk_set_c: the plan's programme is taken as the setpoint")
    fit_log = with_plan_setpoint(cut, plan)
    ident = identify(fit_log)
    est = estimate_gradient(cut)
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
        if eff.effect != "none":
            notes.append(
                f"{eff.effect} found but not material (moves T by at most "
                f"{eff.max_shift_c:.2f} °C <= {material_c:g} °C over the rest): the base "
                "model is used"
            )
    t_model_at = float(model.predict(prefix, np.array([at_min]), t0_c=t0).t_c[0])
    run = resample_run(cut, est, DENSE_MIN)
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
    )


def write_replan_dir(
    out: Path | str,
    request: ReplanRequest,
    programme: Programme,
    *,
    continuation: dict[str, Any] | None = None,
    inputs: Sequence[Path | str] = (),
) -> list[Path]:
    """Write ``DIR`` as a plan directory of the whole run, plus ``replan.json``.

    ``programme`` is the whole run: ``request.prefix`` then the new steps (checked). The
    directory holds ``steps.csv`` (the usual step table), ``plan.json`` (the original
    ``spec`` and ``limits``, the model the rest was planned with, and where it came from)
    and ``replan.json`` (:meth:`ReplanRequest.to_json_dict` and ``continuation``: what
    the planner reported). :func:`schedsyn.monitor.read_plan_dir` reads it back, so a
    run can be re-planned again later.
    """
    out = Path(out)
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
    meta = {
        "experiment": request.plan.name,
        "tau_s": request.model.tau_s,
        "dt0_c": request.model.dt0_c,
        "model": request.model.to_json_dict(),
        "spec": raw["spec"],
        "limits": request.plan.limits.to_dict(),
        "duration_min": programme.total_min,
        "steps": programme.n_segments,
        "replanned_from": {
            "plan": str(request.plan.path),
            "at_min": request.at_min,
            "log": request.log_source,
        },
    }
    report = request.to_json_dict()
    report["continuation"] = continuation
    written = [
        programme.to_csv(out / "steps.csv", inputs),
        write_json_atomic(out / "plan.json", json_safe(meta), inputs),
        write_json_atomic(out / "replan.json", json_safe(report), inputs),
    ]
    return written
