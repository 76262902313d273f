"""Watch a run in progress against its plan: coverage so far, the model it shows, the rest.

A plan directory (``schedsyn plan``/``campaign``/``replan`` output) holds ``steps.csv``
(the chamber programme) and ``plan.json`` (``spec``: region and coverage target;
``limits``; ``tau_s``, ``dt0_c``). Given the log of the run so far,
:func:`monitor_run` reports:

* the elapsed time and the plan's time left;
* per 1 degC bin, the passes and distinct gradient levels measured so far, from the
  kinematic Kalman smoother's ``(T, g)`` resampled to the coverage metric's 0.1 min grid
  (:func:`schedsyn.compare.resample_run`; sampling gaps never count as a pass);
* ``tau_s`` and ``dt0_c`` identified from the log so far (the base fit of
  :mod:`schedsyn.discrepancy`; the first transit is a step test), with standard errors
  widened for correlated residuals by ``sqrt((1 + rho)/(1 - rho))`` (``rho`` the lag-1
  autocorrelation of the fit's residuals);
* the gap between the measured and the planned internal temperature;
* the coverage the run reaches if the plan goes on unchanged, predicted with the
  identified model from the smoother's state at the end of the log.

**A pass still in progress at the end of the log** (the smoothed T is inside a bin at the
last sample) is not counted in the passes *so far*: its mean gradient is not known yet.
It is reported on its own (``pass_in_progress``: bin, time it entered, mean gradient so
far). In the prediction, the measured and the predicted samples form one series on one
0.1 min grid, so the pass straddling "now" is one pass whose gradient is the mean over
its measured and predicted samples, exactly as the coverage metric would count it at the
end of the run.

**Prediction from the estimated state.** The identified first-order model is simulated
from the start (its fitted ``T0``) and its free response is corrected so that it starts
from the smoother's ``T_now``::

    T(t) = T_model(t) + d e^{-(t - t_now)/tau},   g(t) = g_model(t) - (d/tau) e^{-(t - t_now)/tau}
    d = T_est(t_now) - T_model(t_now)

(exact for the first-order lag, whose only state is T).
"""

from __future__ import annotations

import json
import math
import shlex
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .compare import resample_run
from .coverage import CoverageReport, coverage_report, distinct_levels, passes
from .effects import ModelSpec
from .errors import LogFormatError, ParameterError, SchedsynError
from .estimate import GradientEstimate, estimate_gradient
from .grid import BinGrid
from .io import strict_json as json_safe  # re-exported: NaN/inf to None
from .logs import MeasuredLog, log_from_frame
from .params import DT0_ABS_MAX_C, Limits, ThermalParams
from .programme import Programme, read_steps
from .simulate import Trajectory, dense_times

#: Step of the coverage metric's dense grid, min (as for plans).
DENSE_MIN = 0.1
#: An effect is material when it moves the predicted device temperature by more than this.
MATERIAL_C = 0.2
#: A predicted device temperature this far past a device limit calls for a re-plan, degC
#: (the planner's own plans may touch a limit; the identified model's noise is smaller).
DEVICE_LIMIT_TOL_C = 0.1


# --------------------------------------------------------------------------------------
# the plan directory
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class PlanRecord:
    """A plan as read back from its directory (``steps.csv`` + ``plan.json``).

    Attributes
    ----------
    path : Path
        The directory.
    programme : Programme
        The chamber programme of ``steps.csv``.
    name : str
        Experiment name.
    working_lo_c, working_hi_c, approx_lo_c, approx_hi_c : float
        Working and approximation regions, degC.
    levels_required : int
        Distinct gradient levels every bin needs.
    delta_c_per_min : float
        Minimum difference between two levels, degC/min.
    limits : Limits
        The plan's limits.
    params : ThermalParams
        The model the plan was made for (``tau_s``, ``dt0_c``).
    model : ModelSpec
        The same with the effect ``plan.json`` names under ``model`` (``none`` if absent).
    raw : dict
        ``plan.json`` as read (for writing a derived plan directory).
    """

    path: Path
    programme: Programme
    name: str
    working_lo_c: float
    working_hi_c: float
    approx_lo_c: float
    approx_hi_c: float
    levels_required: int
    delta_c_per_min: float
    limits: Limits
    params: ThermalParams
    model: ModelSpec
    raw: dict = field(repr=False)

    @property
    def grid(self) -> BinGrid:
        return BinGrid(self.working_lo_c, self.working_hi_c)

    @property
    def spec_dict(self) -> dict:
        return dict(self.raw["spec"])


def _plan_value(d: dict, key: str, where: str) -> float:
    if key not in d:
        raise ParameterError(f"{where}: missing key {key!r}; write plan.json with `schedsyn plan`")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise ParameterError(f"{where}: {key} must be a finite number, got {v!r}")
    return float(v)


def read_plan_dir(path: Path | str) -> PlanRecord:
    """Read and validate a plan directory (``steps.csv`` and ``plan.json``).

    Raises
    ------
    ParameterError
        The directory, a file or a key is missing or malformed (one line naming it).
    StepTableError
        ``steps.csv`` breaks the plan's own limits.
    """
    path = Path(path)
    if not path.is_dir():
        raise ParameterError(
            f"plan directory {path} does not exist; give the folder `schedsyn plan --out` wrote"
        )
    steps, meta = path / "steps.csv", path / "plan.json"
    for f in (steps, meta):
        if not f.is_file():
            raise ParameterError(
                f"plan directory {path} has no {f.name}; a plan directory holds steps.csv and "
                "plan.json (as `schedsyn plan --out DIR` writes them)"
            )
    try:
        raw = json.loads(meta.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{meta} is not valid JSON ({exc})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("spec"), dict):
        raise ParameterError(f"{meta}: expected an object with a 'spec' object (region, levels)")
    spec = raw["spec"]
    where = f"{meta} spec"
    lo, hi = _plan_value(spec, "working_lo_c", where), _plan_value(spec, "working_hi_c", where)
    alo = float(spec.get("approx_lo_c", lo))
    ahi = float(spec.get("approx_hi_c", hi))
    levels = _plan_value(spec, "levels_required", where)
    if levels != int(levels) or levels < 1:
        raise ParameterError(f"{where}: levels_required must be a whole number >= 1, got {levels}")
    delta = _plan_value(spec, "delta_c_per_min", where)
    if delta <= 0:
        raise ParameterError(f"{where}: delta_c_per_min must be > 0 °C/min, got {delta}")
    lim_raw = raw.get("limits", {})
    if not isinstance(lim_raw, dict):
        raise ParameterError(f"{meta}: 'limits' must be an object")
    try:
        limits = Limits(**{k: v for k, v in lim_raw.items() if k in Limits.__dataclass_fields__})
        params = ThermalParams(
            _plan_value(raw, "tau_s", str(meta)), _plan_value(raw, "dt0_c", str(meta))
        )
        model = (
            ModelSpec.from_json_dict(raw["model"])
            if isinstance(raw.get("model"), dict)
            else ModelSpec(params.tau_s, params.dt0_c)
        )
        BinGrid(lo, hi)
    except SchedsynError as exc:
        raise ParameterError(f"{meta}: {exc}") from None
    programme = read_steps(steps, limits)
    return PlanRecord(
        path=path,
        programme=programme,
        name=str(spec.get("name", raw.get("experiment", path.name))),
        working_lo_c=lo,
        working_hi_c=hi,
        approx_lo_c=alo,
        approx_hi_c=ahi,
        levels_required=int(levels),
        delta_c_per_min=delta,
        limits=limits,
        params=params,
        model=model,
        raw=raw,
    )


# --------------------------------------------------------------------------------------
# does the log belong to the plan?
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class MonitorSettings:
    """Tolerances of :func:`check_log_belongs` and the estimator.

    Parameters
    ----------
    setpoint_tol_c : float
        Largest gap between the logged ``tk_set_c`` and the plan's programme, degC (the
        controller types 0.1 degC; its setpoint log may be coarser).
    start_tol_min : float
        The log's first row must lie within this of the programme's start, min.
    end_tol_min : float
        The log may run this much past the plan's end, min.
    envelope_c : float
        The measured internal temperature must stay within the chamber's range so far,
        widened by this, degC (a device lags its chamber plus a self-heating offset of a
        few degC; a log far outside is from another run).
    start_temp_tol_c : float
        The first reading must lie within this of the plan's ``t_init_c``, or of
        ``start_c + dT0`` (the plan's model: where a powered device soaked in the chamber
        at the start temperature sits), or between them, degC.
    """

    setpoint_tol_c: float = 0.3
    start_tol_min: float = 10.0
    end_tol_min: float = 5.0
    envelope_c: float = 10.0
    start_temp_tol_c: float = 5.0

    def __post_init__(self) -> None:
        for name in (
            "setpoint_tol_c",
            "start_tol_min",
            "end_tol_min",
            "envelope_c",
            "start_temp_tol_c",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be > 0, got {v!r}")


def check_log_start(log: MeasuredLog, settings: MonitorSettings | None = None) -> None:
    """Raise :class:`LogFormatError` (one line) if ``log`` does not start at the programme's
    start (``time_s`` counts from it, within ``start_tol_min``)."""
    s = MonitorSettings() if settings is None else settings
    if abs(log.time_min[0]) > s.start_tol_min:
        raise LogFormatError(
            f"{log.source}: the log starts at time_s = {log.time_s[0]:g} s, but time_s counts "
            f"from the start of the plan's programme (0 s); this log belongs to another start "
            f"time (shift time_s so the programme starts at 0)"
        )


def check_log_belongs(
    log: MeasuredLog, plan: PlanRecord, settings: MonitorSettings | None = None
) -> None:
    """Raise :class:`LogFormatError` (one line) if ``log`` is not a run of ``plan``.

    Checks, in order: the log starts at the programme's start (``time_s`` counts from it)
    and does not run past its end; the first reading is near the plan's start
    temperature; the logged setpoint follows the programme; the measured temperature stays
    within the chamber's range so far (a region the plan never visits means another run).
    """
    s = MonitorSettings() if settings is None else settings
    src = log.source
    t_min = log.time_min
    total = plan.programme.total_min
    check_log_start(log, s)
    if t_min[-1] > total + s.end_tol_min:
        raise LogFormatError(
            f"{src}: the log runs to {t_min[-1]:.1f} min, past the end of the plan "
            f"{plan.path} ({total:g} min); it does not belong to this plan"
        )
    finite = np.flatnonzero(np.isfinite(log.t_int_c))
    first = float(log.t_int_c[finite[0]])
    # a powered device soaked in the chamber at start_c sits dT0 above it, not at t_init_c
    # (dT0 6 degC: 26 degC, refused as another plan's log before): either start belongs
    soaked = plan.limits.start_c + plan.params.dt0_c
    lo = min(plan.limits.t_init_c, soaked) - s.start_temp_tol_c
    hi = max(plan.limits.t_init_c, soaked) + s.start_temp_tol_c
    if not lo <= first <= hi:
        raise LogFormatError(
            f"{src}: the first reading t_int_c = {first:.2f} °C is far from the plan's start "
            f"temperature {plan.limits.t_init_c:g} °C (or {soaked:g} °C, where the device "
            f"settles in the chamber at {plan.limits.start_c:g} °C with the plan's dT0); the "
            "log does not belong to this plan"
        )
    if log.tk_set_c is not None:
        ok = np.isfinite(log.tk_set_c)
        gap = np.abs(log.tk_set_c[ok] - plan.programme.chamber_at(t_min[ok]))
        if gap.size and float(gap.max()) > s.setpoint_tol_c:
            k = int(np.argmax(gap))
            logged = float(log.tk_set_c[ok][k])
            at = float(t_min[ok][k])
            planned = float(plan.programme.chamber_at(np.array([at]))[0])
            raise LogFormatError(
                f"{src}: the logged setpoint tk_set_c = {logged:.2f} °C at {at:.1f} min differs "
                f"from the plan's programme ({planned:.2f} °C) by "
                f"{gap[k]:.2f} °C > {s.setpoint_tol_c:g} °C: the log does not belong to "
                f"{plan.path} (another programme or start time)"
            )
    edges = np.concatenate(([0.0], np.cumsum(plan.programme.durations_min)))
    upto = float(min(t_min[-1], total))
    inside = edges[edges < upto]
    tk = np.concatenate(
        (plan.programme.chamber_at(inside), plan.programme.chamber_at(np.array([upto])))
    )
    lo = min(float(tk.min()), plan.limits.t_init_c) - s.envelope_c
    hi = max(float(tk.max()), plan.limits.t_init_c) + s.envelope_c
    y = log.t_int_c[finite]
    bad = np.flatnonzero((y < lo) | (y > hi))
    if bad.size:
        k = int(finite[bad[0]])
        raise LogFormatError(
            f"{src}: t_int_c = {log.t_int_c[k]:.2f} °C at {t_min[k]:.1f} min lies outside "
            f"{lo:.1f} .. {hi:.1f} °C, where the plan's chamber has been so far (±"
            f"{s.envelope_c:g} °C): the log visits a region the plan never visits"
        )


def plan_rate_changes(plan: PlanRecord) -> tuple[np.ndarray, np.ndarray]:
    """The plan programme's rate changes: times (s, the log's clock: 0 at the programme's
    start) and jumps (new rate minus old, degC/min), for the gradient estimate's end
    (:func:`schedsyn.estimate.estimate_gradient`: a change in the log's last minutes lets
    the gradient's rate jump there, the smoother alone extrapolates the old one; red team:
    g_now -0.127 +- 0.007 degC/min against the device's -0.165, 3 min after a change)."""
    prog = plan.programme
    times_s = 60.0 * np.cumsum(prog.durations_min)[:-1]
    jumps = np.diff(prog.rates_c_per_min)
    return times_s, jumps


def with_plan_setpoint(log: MeasuredLog, plan: PlanRecord) -> MeasuredLog:
    """``log`` with ``tk_set_c`` taken from the plan's programme where it is not logged,
    and, across a sampling gap that holds a corner of the programme, rows at the log's own
    cadence with no reading and the plan's setpoint: the fit draws the setpoint across a
    gap as a line or one guessed corner (red team: a 30-min gap over corners biased tau by
    3.7 and dT0 by 5 standard errors and named a false dT0 drift)."""
    t = np.asarray(log.time_min, dtype=float)
    steps = np.diff(t)
    fill: list[np.ndarray] = []
    if steps.size:
        step = float(np.median(steps))
        corners = np.concatenate(([0.0], np.cumsum(plan.programme.durations_min)))
        for i in np.flatnonzero(steps > 3.0 * step):
            a, b = t[i], t[i + 1]
            if np.any((corners > a + 1e-9) & (corners < b - 1e-9)):
                n = int(math.ceil((b - a) / step))
                fill.append(np.linspace(a, b, n + 1)[1:-1])
    times = np.concatenate(fill) if fill else np.zeros(0)
    complete = log.tk_set_c is not None and np.isfinite(log.tk_set_c).all()
    if complete and not times.size:
        return log
    frame = log.to_frame()
    sp = plan.programme.chamber_at(log.time_min)
    if log.tk_set_c is not None:
        sp = np.where(np.isfinite(log.tk_set_c), log.tk_set_c, sp)
    frame["tk_set_c"] = sp
    if times.size:
        extra = pd.DataFrame(
            {
                "time_s": 60.0 * times,
                "t_int_c": np.nan,
                "tk_set_c": plan.programme.chamber_at(times),
            }
        )
        frame = pd.concat([frame, extra], ignore_index=True).sort_values("time_s")
        frame = frame.reset_index(drop=True)
    return log_from_frame(frame, source=log.source)


# --------------------------------------------------------------------------------------
# identification and pass bookkeeping
# --------------------------------------------------------------------------------------
#: A fit whose tau is less certain than this share of itself, or dT0 than this, degC, or
#: whose dT0 lies this close to the edge of what a model accepts (50 degC), does not pin
#: the device down (:meth:`Identified.doubts`). Early fits are far inside: 5 min of a W3
#: log give tau ± 7 %, 15 min ± 1 %, dT0 ± 0.2 degC.
FIT_TAU_REL_STD_MAX = 0.5
FIT_DT0_STD_MAX_C = 2.0
FIT_DT0_EDGE_C = DT0_ABS_MAX_C - 1.0


@dataclass(frozen=True, slots=True)
class Identified:
    """``tau_s``, ``dt0_c`` and ``t0_c`` fitted to a log, with standard errors.

    The standard errors are the fit's (Jacobian, white residuals) times
    ``inflation = sqrt((1 + rho)/(1 - rho))`` for the residuals' lag-1 autocorrelation.
    ``rms_c`` is the RMS gap of the fitted model on the fit data (block means), degC.
    """

    tau_s: float
    tau_std_s: float
    dt0_c: float
    dt0_std_c: float
    t0_c: float
    t0_std_c: float
    rms_c: float
    lag1_autocorr: float
    inflation: float
    span_min: float

    @property
    def model(self) -> ModelSpec:
        return ModelSpec(self.tau_s, self.dt0_c)

    def doubts(self) -> tuple[str, ...]:
        """Why the fit does not pin the device down, or ``()``: a standard deviation that
        is not finite or larger than :data:`FIT_TAU_REL_STD_MAX` of tau or
        :data:`FIT_DT0_STD_MAX_C`, or an estimate at the edge of what a model accepts
        (the fit ran to its bound). Predictions from such a fit are guesses (red team: a
        device with a second thermal mass, 30 min: tau 16920 ± 35484 s, dT0 50.00 ± 140
        °C, reported as if identified)."""
        out = []
        if not (
            math.isfinite(self.tau_std_s) and self.tau_std_s <= FIT_TAU_REL_STD_MAX * self.tau_s
        ):
            out.append(f"tau {self.tau_s:.0f} ± {self.tau_std_s:.0f} s")
        if not (math.isfinite(self.dt0_std_c) and self.dt0_std_c <= FIT_DT0_STD_MAX_C):
            out.append(f"dT0 {self.dt0_c:.2f} ± {self.dt0_std_c:.2f} °C")
        if abs(self.dt0_c) >= FIT_DT0_EDGE_C:
            out.append(f"dT0 {self.dt0_c:.2f} °C at the edge of the fit's range")
        return tuple(out)

    def doubt_line(self) -> str | None:
        """One loud line when :meth:`doubts` has any, else None."""
        d = self.doubts()
        if not d:
            return None
        return (
            f"*** the log does not pin the device down yet ({'; '.join(d)}): what is "
            "predicted from it is a guess; re-plan or monitor again on a longer log ***"
        )

    def to_dict(self) -> dict[str, float]:
        return {
            "tau_s": self.tau_s,
            "tau_std_s": self.tau_std_s,
            "dt0_c": self.dt0_c,
            "dt0_std_c": self.dt0_std_c,
            "t0_c": self.t0_c,
            "t0_std_c": self.t0_std_c,
            "rms_c": self.rms_c,
            "residual_lag1_autocorr": self.lag1_autocorr,
            "stderr_inflation": self.inflation,
            "span_min": self.span_min,
        }


def identify(log: MeasuredLog) -> Identified:
    """Fit ``tau_s``, ``dt0_c``, ``t0_c`` to the log so far (needs ``tk_set_c``)."""
    from .discrepancy import fit_base_log

    fit, rho = fit_base_log(log)
    rho_c = float(np.clip(rho, -0.9, 0.98))
    infl = math.sqrt((1.0 + rho_c) / (1.0 - rho_c)) if rho_c > 0 else 1.0
    se = fit.stderr
    return Identified(
        tau_s=float(fit.values["tau_s"]),
        tau_std_s=float(se["tau_s"]) * infl,
        dt0_c=float(fit.values["dt0_c"]),
        dt0_std_c=float(se["dt0_c"]) * infl,
        t0_c=float(fit.values["t0_c"]),
        t0_std_c=float(se["t0_c"]) * infl,
        rms_c=float(fit.rms_c),
        lag1_autocorr=float(rho),
        inflation=infl,
        span_min=float(log.time_min[-1] - log.time_min[0]),
    )


@dataclass(frozen=True, slots=True)
class OpenPass:
    """A pass still in progress at the end of a series: bin, entry time, gradient so far."""

    bin_index: int
    bin_lo_c: float
    start_min: float
    mean_g_so_far_c_per_min: float

    def to_dict(self) -> dict[str, float]:
        return {
            "bin_lo_c": self.bin_lo_c,
            "bin_hi_c": self.bin_lo_c + 1.0,
            "entered_min": self.start_min,
            "mean_gradient_so_far_c_per_min": self.mean_g_so_far_c_per_min,
        }


#: The pass the smoothed run begins with counts only when the estimate at the log's first
#: reading lies at least this many of its standard deviations away from every bin edge.
START_PASS_SIGMAS = 3.0


def measured_run(log: MeasuredLog, estimate: GradientEstimate, grid: BinGrid) -> Trajectory:
    """The smoothed run on the metric's grid (:func:`schedsyn.compare.resample_run`),
    without a first pass whose bin the estimate does not resolve.

    The device starts where the plan puts it, ``t_init_c`` = 20 °C, a bin edge in a region
    that spans it. The smoothed estimate at the first reading lies either side of the edge
    by the sensor noise; just below it, it counts a pass through the bin below that the
    device never made (W3, 0.02 °C noise: a level of about 0.1 °C/min in [19, 20) on 5 of
    8 noise seeds, so a re-plan asked for one level too few there). When the first finite
    estimate lies within :data:`START_PASS_SIGMAS` of its standard deviation of a bin edge,
    the samples of the first pass get ``g = NaN``, which the coverage metric does not count
    (:func:`schedsyn.coverage.passes`): one level may be planned more than needed, never
    one less.
    """
    run = resample_run(log, estimate, DENSE_MIN)
    ok = np.flatnonzero(np.isfinite(estimate.t_est_c))
    if not ok.size:
        return run
    run = _without_unresolved_dips(run, log, estimate, grid)
    t_first = float(estimate.t_est_c[ok[0]])
    std_first = float(estimate.t_std_c[ok[0]])
    if not np.any(np.abs(grid.edges_c - t_first) <= START_PASS_SIGMAS * std_first):
        return run
    idx = grid.index(run.t_c)
    finite = np.flatnonzero(np.isfinite(run.t_c))
    if not finite.size or idx[finite[0]] < 0:
        return run
    first = int(finite[0])
    other = np.flatnonzero(idx[first:] != idx[first])
    end = first + int(other[0]) if other.size else idx.size
    grad = run.g_c_per_min.copy()
    grad[first:end] = np.nan
    return replace(run, g_c_per_min=grad)


def _without_unresolved_dips(
    run: Trajectory, log: MeasuredLog, estimate: GradientEstimate, grid: BinGrid
) -> Trajectory:
    """``run`` with ``g = NaN`` on the passes the estimate does not resolve: in and out
    through the same bin edge, never further from it than :data:`START_PASS_SIGMAS` of
    the estimate's standard deviation. A device soaking on a bin edge (23 °C = 20 °C +
    dT0 at the start of a run) has an estimate that dithers across it by the noise; each
    dip counted a near-zero level in a bin the device never crossed (a stress test: 73.3
    % claimed where the device made 70 %; 3 of 8 noise seeds in the test)."""
    t = run.t_c
    kb, _, first, last = passes(t, run.g_c_per_min, grid)
    if not kb.size:
        return run
    std = np.interp(run.time_min, log.time_min, estimate.t_std_c)
    grad = run.g_c_per_min
    for k, a, b in zip(kb.tolist(), first.tolist(), last.tolist(), strict=True):
        if a == 0 or b == t.size - 1 or not (np.isfinite(t[a - 1]) and np.isfinite(t[b + 1])):
            continue  # the run's ends: the start rule below, and the pass still open
        lo, hi = float(grid.edges_c[k]), float(grid.edges_c[k + 1])
        came_from_below, left_below = t[a - 1] < lo, t[b + 1] < lo
        if came_from_below != left_below:
            continue  # crossed the bin
        edge = lo if came_from_below else hi
        depth = float(np.nanmax(np.abs(t[a : b + 1] - edge)))
        if depth < START_PASS_SIGMAS * float(np.nanmedian(std[a : b + 1])):
            if grad is run.g_c_per_min:
                grad = grad.copy()
            grad[a : b + 1] = np.nan
    return run if grad is run.g_c_per_min else replace(run, g_c_per_min=grad)


def closed_passes(
    time_min: np.ndarray, t_c: np.ndarray, g_c_per_min: np.ndarray, grid: BinGrid
) -> tuple[tuple[np.ndarray, ...], OpenPass | None]:
    """Per bin, the mean gradients of the passes that have ended; and the open one.

    A pass is open when its run of samples reaches the last sample of the series (the
    device is still inside that bin "now"). Passes are those of
    :func:`schedsyn.coverage.passes`.
    """
    kb, mg, first, last = passes(t_c, g_c_per_min, grid)
    open_pass = None
    t_last = np.flatnonzero(np.isfinite(t_c))
    end = int(t_last[-1]) if t_last.size else -1
    if kb.size and int(last[-1]) == end and end == t_c.size - 1:
        open_pass = OpenPass(
            int(kb[-1]), float(grid.lower_c[kb[-1]]), float(time_min[first[-1]]), float(mg[-1])
        )
        kb, mg = kb[:-1], mg[:-1]
    grads = tuple(np.sort(mg[kb == i]) for i in range(grid.n_bins))
    return grads, open_pass


def report_from_gradients(
    grid: BinGrid, grads: tuple[np.ndarray, ...], levels_required: int, delta_c_per_min: float
) -> CoverageReport:
    """A :class:`CoverageReport` from per-bin pass gradients (the metric's own counting)."""
    counts = np.array([g.size for g in grads], dtype=np.int64)
    levels = np.array([distinct_levels(g, delta_c_per_min) for g in grads], dtype=np.int64)
    return CoverageReport(grid, levels_required, delta_c_per_min, counts, levels, grads)


def predict_from_state(
    model: ModelSpec,
    t0_c: float,
    programme: Programme,
    now_min: float,
    t_now_c: float,
    times_min: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """T and g at ``times_min`` (>= now) from the model, started at ``T(now) = t_now_c``.

    ``T = T_model + d e^{-(t-now)/tau}``, ``g = g_model - d/tau e^{-(t-now)/tau}``,
    ``d = t_now_c - T_model(now)`` (see the module docstring).
    """
    t = np.asarray(times_min, dtype=float)
    pred = model.predict(programme, np.concatenate(([now_min], t)), t0_c=t0_c)
    d = t_now_c - float(pred.t_c[0])
    tau_min = model.tau_s / 60.0
    e = np.exp(-(t - now_min) / tau_min)
    return pred.t_c[1:] + d * e, pred.g_c_per_min[1:] - d / tau_min * e


@dataclass(frozen=True, slots=True)
class RivalModel:
    """A model that fits the log up to M about as well as the one the rest is predicted
    with, but predicts the device over the rest of the plan up to ``gap_c`` degC apart
    from it: the log does not tell which future comes yet. ``t0_c`` is its fitted start."""

    effect: str
    model: ModelSpec
    t0_c: float
    gap_c: float


@dataclass(frozen=True, slots=True)
class EffectCheck:
    """The effect the diagnosis found on the log up to M, and whether it is material.

    ``stderr``: standard errors of the effect fit's parameters, ``tau_s`` and ``dt0_c``
    included (from its Jacobian; empty when no effect was found). ``rivals``: the effects
    the diagnosis could not tell from its choice (its choice included when the base model
    is used instead) whose prediction of the rest differs from the model used by more
    than ``material_c`` (:class:`RivalModel`)."""

    effect: str
    parameters: dict[str, float]
    max_shift_c: float
    material: bool
    model: ModelSpec
    t0_c: float
    warnings: tuple[str, ...] = ()
    stderr: dict[str, float] = field(default_factory=dict)
    rivals: tuple[RivalModel, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "parameters": dict(self.parameters),
            "max_shift_over_rest_c": self.max_shift_c,
            "material": self.material,
            "material_threshold_c": MATERIAL_C,
            "warnings": list(self.warnings),
            "rivals": [
                {
                    "effect": r.effect,
                    "parameters": dict(r.model.parameters),
                    "tau_s": r.model.tau_s,
                    "dt0_c": r.model.dt0_c,
                    "max_gap_over_rest_c": r.gap_c,
                }
                for r in self.rivals
            ],
        }


#: Two effects the diagnosis cannot tell apart that predict the rest differently are
#: still preferred to the base model when they differ from each other by at most this
#: share of how far the chosen one differs from the base (:func:`check_effect`).
RIVALS_AGREE_SHARE = 0.5


def check_effect(
    log: MeasuredLog,
    plan: PlanRecord,
    now_min: float,
    base: ModelSpec,
    base_t0_c: float,
    t_now_c: float,
    material_c: float = MATERIAL_C,
) -> EffectCheck:
    """Diagnose the log; the effect is material if, started from ``T(now) = t_now_c``,
    its model and the base fit predict device temperatures more than ``material_c``
    apart somewhere over the rest of the plan.

    An effect is not used (not material, with a warning saying why) when another effect
    the diagnosis could not tell apart from it (``ambiguous_with``) predicts the rest more
    than ``material_c`` differently: the log does not identify which future to plan for
    yet (a short log often cannot, e.g. a rate limit against a chamber lag in the first
    hour). Ambiguous effects that predict the same device temperatures (a chamber lag and
    a second time constant of the same length) leave the chosen one in use, and so do
    rivals that differ far less from each other than from the base model
    (:data:`RIVALS_AGREE_SHARE`): the base model is then the worst guess of the three.
    """
    from .discrepancy import diagnose

    d = diagnose(log)
    if d.effect == "none":
        return EffectCheck("none", {}, 0.0, False, base, base_t0_c, tuple(d.warnings))
    fits = {c.effect: c for c in d.candidates}
    t0 = fits[d.effect].t0_c
    times = np.arange(now_min, plan.programme.total_min + 1e-9, 0.5)
    warnings = list(d.warnings)
    shift, disagree, rival = 0.0, 0.0, ""
    # the rest predicted by the chosen effect and each effect it cannot be told from
    predicted: dict[str, np.ndarray] = {}
    t_base = np.zeros(0)
    if times.size:
        for name in (d.effect, *d.ambiguous_with):
            fit = fits.get(name)
            if fit is not None:
                predicted[name] = predict_from_state(
                    fit.model, fit.t0_c, plan.programme, now_min, t_now_c, times
                )[0]
        t_eff = predicted[d.effect]
        t_base, _ = predict_from_state(base, base_t0_c, plan.programme, now_min, t_now_c, times)
        shift = float(np.max(np.abs(t_eff - t_base)))
        for name in d.ambiguous_with:
            if name not in predicted:
                continue
            gap = float(np.max(np.abs(predicted[name] - t_eff)))
            if gap > disagree:
                disagree, rival = gap, name
    material = shift > material_c
    if material and disagree > material_c:
        if disagree <= RIVALS_AGREE_SHARE * shift:
            # the rivals differ, but far less from each other than from the base model,
            # which both fit much better than it: the base is the worst guess of the three
            # (red team, a second thermal mass: rivals 2.4 degC apart, the base 10.5 off)
            warnings.append(
                f"{d.effect} and {rival} fit the log nearly equally and predict the device "
                f"up to {disagree:.2f} °C apart over the rest of the plan, but both are "
                f"further from the base model (up to {shift:.2f} °C): {d.effect}, the "
                "better fit, is used; re-plan later to tell them apart"
            )
        else:
            material = False
            warnings.append(
                f"{d.effect} and {rival} fit the log nearly equally but predict the device "
                f"up to {disagree:.2f} °C apart over the rest of the plan: not identified "
                "yet, the base model is used"
            )
    used = d.effect if material else None
    rivals = _rivals(fits, predicted, used, predicted[d.effect] if material else t_base, material_c)
    return EffectCheck(
        d.effect,
        {k: float(v) for k, v in d.parameters.items()},
        shift,
        material,
        d.model,
        t0,
        tuple(warnings),
        {k: float(v) for k, v in d.stderr.items()},
        rivals,
    )


def _rivals(
    fits: Mapping[str, Any],
    predicted: Mapping[str, np.ndarray],
    used: str | None,
    t_used: np.ndarray,
    material_c: float,
) -> tuple[RivalModel, ...]:
    """The diagnosis' choice and the effects it could not tell from it (``predicted``:
    each one's device temperature over the rest), but for the effect in use (``used``;
    None: the base model), each kept where its prediction differs from the used model's
    (``t_used``) by more than ``material_c``. (A drift of dT0 against a slope of dT0 with
    temperature on the first hour of a W2 run: the rest was predicted 83 % apart in
    coverage; red team.)"""
    out = []
    for name, t_alt in predicted.items():
        if name == used:
            continue
        gap = float(np.max(np.abs(t_alt - t_used)))
        if gap > material_c:
            out.append(RivalModel(name, fits[name].model, float(fits[name].t0_c), gap))
    return tuple(out)


# --------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class MonitorReport:
    """What :func:`monitor_run` found (see the module docstring).

    Coverage reports: ``so_far`` (passes ended by the end of the log), ``predicted``
    (measured so far joined with the identified model's prediction of the rest of the
    plan, unchanged), ``planned`` (the plan on its own model). ``series`` is one row per
    log row (measured, smoothed, planned T; smoothed g and its std); ``dense`` the
    combined measured-then-predicted 0.1 min series the prediction was counted on.
    """

    plan: PlanRecord
    log_source: str
    elapsed_min: float
    plan_total_min: float
    identified: Identified
    effect: EffectCheck
    so_far: CoverageReport
    pass_in_progress: OpenPass | None
    predicted: CoverageReport
    planned: CoverageReport
    gap_rms_c: float
    gap_max_abs_c: float
    gap_now_c: float
    t_now_c: float
    t_now_std_c: float
    g_now_c_per_min: float
    g_now_std_c_per_min: float
    predicted_device_min_c: float
    predicted_device_max_c: float
    notes: tuple[str, ...]
    series: pd.DataFrame = field(repr=False)
    dense: pd.DataFrame = field(repr=False)
    planned_dense: pd.DataFrame = field(repr=False)

    @property
    def remaining_min(self) -> float:
        return max(self.plan_total_min - self.elapsed_min, 0.0)

    @property
    def replan_at_min(self) -> float | None:
        """Where to re-plan the rest from (the last whole minute of the log), when the run
        is predicted short of its target and time is left; None when it is on track.

        The sooner the better: a re-plan before the device's first turn can still reshape
        the first sweep (W3 on a device with tau 3000 s: complete re-planned from minute
        15, 97 % from minute 30; see :data:`schedsyn.closed_loop.EARLY_MIN`)."""
        if (self.predicted.complete and not self.leaves_device_limits) or self.remaining_min <= 0:
            return None
        m = float(math.floor(self.elapsed_min + 1e-9))
        return m if m > 0.0 else None

    @property
    def leaves_device_limits(self) -> bool:
        """The identified model takes the device more than :data:`DEVICE_LIMIT_TOL_C`
        outside its limits if the plan goes on unchanged: a re-plan is due even when the
        coverage is on track (``replan`` refuses such a plan unchanged)."""
        lim = self.plan.limits
        return (
            self.predicted_device_max_c > lim.device_max_c + DEVICE_LIMIT_TOL_C
            or self.predicted_device_min_c < lim.device_min_c - DEVICE_LIMIT_TOL_C
        )

    def to_frame(self) -> pd.DataFrame:
        """Per-bin status: planned, so far, in progress, predicted; and a one-word status."""
        lo = self.plan.grid.lower_c
        req = self.plan.levels_required
        open_bin = -1 if self.pass_in_progress is None else self.pass_in_progress.bin_index
        status = np.where(
            self.so_far.levels >= req,
            "covered",
            np.where(self.predicted.levels >= req, "on track", "short"),
        )
        return pd.DataFrame(
            {
                "bin_lo_c": lo,
                "bin_hi_c": lo + self.plan.grid.bin_c,
                "planned_levels": self.planned.levels,
                "passes_so_far": self.so_far.pass_counts,
                "levels_so_far": self.so_far.levels,
                "pass_in_progress": np.arange(lo.size) == open_bin,
                "predicted_passes": self.predicted.pass_counts,
                "predicted_levels": self.predicted.levels,
                "predicted_missing_levels": np.maximum(req - self.predicted.levels, 0),
                "status": status,
                "gradients_so_far_c_per_min": [
                    " ".join(f"{x:.4f}" for x in g) for g in self.so_far.gradients
                ],
            }
        )

    def to_json_dict(self) -> dict[str, Any]:
        p = self.plan
        short = [
            {"bin_lo_c": a, "bin_hi_c": b, "levels": n, "missing": p.levels_required - n}
            for a, b, n in self.predicted.short_bins()
        ]
        return {
            "plan": str(p.path),
            "experiment": p.name,
            "log": self.log_source,
            "region_c": [p.working_lo_c, p.working_hi_c],
            "levels_required": p.levels_required,
            "delta_c_per_min": p.delta_c_per_min,
            "elapsed_min": self.elapsed_min,
            "plan_total_min": self.plan_total_min,
            "remaining_min": self.remaining_min,
            "identified": self.identified.to_dict(),
            "effect": self.effect.to_dict(),
            "prediction_model": (
                self.effect.model if self.effect.material else self.identified.model
            ).to_json_dict(),
            "plan_model": {"tau_s": p.params.tau_s, "dt0_c": p.params.dt0_c},
            "state_now": {
                "t_c": self.t_now_c,
                "t_std_c": self.t_now_std_c,
                "g_c_per_min": self.g_now_c_per_min,
                "g_std_c_per_min": self.g_now_std_c_per_min,
                "tk_set_c": float(p.programme.chamber_at(np.array([self.elapsed_min]))[0]),
            },
            "gap_measured_minus_planned_c": {
                "rms": self.gap_rms_c,
                "max_abs": self.gap_max_abs_c,
                "now": self.gap_now_c,
            },
            "so_far": {
                "bins_covered": int(self.so_far.covered.sum()),
                "coverage": self.so_far.coverage,
                "min_levels": self.so_far.min_levels,
            },
            "pass_in_progress": None
            if self.pass_in_progress is None
            else self.pass_in_progress.to_dict(),
            "pass_in_progress_rule": (
                "a pass still inside its bin at the end of the log is not counted so far; "
                "the prediction joins its measured and predicted samples into one pass"
            ),
            "predicted_if_unchanged": {
                "coverage": self.predicted.coverage,
                "complete": self.predicted.complete,
                "min_levels": self.predicted.min_levels,
                "short_bins": short,
                "device_min_c": self.predicted_device_min_c,
                "device_max_c": self.predicted_device_max_c,
            },
            "planned": {
                "coverage": self.planned.coverage,
                "min_levels": self.planned.min_levels,
            },
            "replan_at_min": self.replan_at_min,
            "notes": list(self.notes),
        }

    def _effect_line(self) -> str:
        e = self.effect
        if e.effect == "none":
            return "effect beyond tau and dT0: none found"
        pars = ", ".join(f"{k} {v:.4g}" for k, v in e.parameters.items())
        if e.material:
            use = "used for the prediction"
        elif e.max_shift_c > MATERIAL_C:  # material, but rivals predict differently
            use = "not identified yet (a rival fits as well), not used"
        else:
            use = "not material, not used"
        return f"effect: {e.effect} ({pars}); moves T by up to {e.max_shift_c:.2f} °C: {use}"

    def summary(self) -> str:
        i = self.identified
        p = self.plan
        lines = [
            f"{p.name}: {self.elapsed_min:.0f} of {self.plan_total_min:g} min elapsed "
            f"({self.remaining_min:.0f} min left)",
            f"identified from the log: tau {i.tau_s:.0f} ± {i.tau_std_s:.0f} s, dT0 "
            f"{i.dt0_c:.2f} ± {i.dt0_std_c:.2f} °C (plan: {p.params.tau_s:g} s, "
            f"{p.params.dt0_c:g} °C)",
            *[x for x in (i.doubt_line(),) if x is not None],
            self._effect_line(),
            f"measured - planned T: now {self.gap_now_c:+.2f} °C, RMS {self.gap_rms_c:.2f} °C, "
            f"max {self.gap_max_abs_c:.2f} °C",
            f"so far: {int(self.so_far.covered.sum())}/{p.grid.n_bins} bins with "
            f">= {p.levels_required} levels",
        ]
        if self.pass_in_progress is not None:
            op = self.pass_in_progress
            lines.append(
                f"pass in progress: bin [{op.bin_lo_c:g}, {op.bin_lo_c + 1:g}) °C since "
                f"{op.start_min:.1f} min (not counted yet)"
            )
        lines.append(
            "if the plan goes on unchanged: "
            + self.predicted.summary().replace("degC", "°C")
            + f"; planned {self.planned.coverage:.0%}"
        )
        m = self.replan_at_min
        if m is not None:
            why = (
                "predicted short of the target"
                if not self.predicted.complete
                else "predicted to take the device outside its limits"
            )
            lines.append(
                f"{why}: re-plan the rest now (schedsyn replan "
                f"{shlex.quote(str(self.log_source))} {shlex.quote(str(p.path))} --at-min "
                f"{m:g}); the sooner, the more of the run a new programme can shape"
            )
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(lines)


#: The identified model's parameters are varied by this many standard errors for the
#: device-limit envelope of the prediction.
LIMIT_ENVELOPE_SIGMAS = 2.0


def _limit_envelope(
    ident: Identified, plan: PlanRecord, now: float, t_now: float, rest: np.ndarray
) -> tuple[float, float, str]:
    """Lowest and highest device temperature predicted over ``rest`` with tau and dT0 at
    the corners of +-``LIMIT_ENVELOPE_SIGMAS`` standard errors, and the corner of the
    highest excess in words."""
    k = LIMIT_ENVELOPE_SIGMAS
    lim = plan.limits
    lo, hi, worst, excess = math.inf, -math.inf, "", -math.inf
    for s_tau in (-k, k):
        for s_dt0 in (-k, k):
            tau = max(ident.tau_s + s_tau * ident.tau_std_s, 0.1 * ident.tau_s)
            dt0 = ident.dt0_c + s_dt0 * ident.dt0_std_c
            t_r, _ = predict_from_state(
                ModelSpec(tau, dt0), ident.t0_c, plan.programme, now, t_now, rest
            )
            lo, hi = min(lo, float(t_r.min())), max(hi, float(t_r.max()))
            e = max(float(t_r.max()) - lim.device_max_c, lim.device_min_c - float(t_r.min()))
            if e > excess:
                excess, worst = e, f"tau {tau:.0f} s, dT0 {dt0:.2f} °C"
    return lo, hi, worst


def monitor_run(
    log: MeasuredLog,
    plan: PlanRecord,
    settings: MonitorSettings | None = None,
    *,
    find_effect: bool = True,
) -> MonitorReport:
    """Coverage so far, identified model and predicted final coverage of a run in progress.

    Parameters
    ----------
    log : MeasuredLog
        The log so far (``time_s`` from the programme's start; ``tk_set_c`` optional:
        taken from the plan where missing).
    plan : PlanRecord
        From :func:`read_plan_dir`.
    settings : MonitorSettings, optional
        Tolerances of the belongs-to-the-plan checks.
    find_effect : bool
        Also diagnose an effect beyond tau and dT0 (:func:`check_effect`); a material one
        is used for the prediction.

    Raises
    ------
    LogFormatError
        The log does not belong to the plan (see :func:`check_log_belongs`) or is too
        short to identify the model.
    """
    settings = MonitorSettings() if settings is None else settings
    check_log_belongs(log, plan, settings)
    notes: list[str] = []
    if log.tk_set_c is None:
        notes.append("the log has no tk_set_c: the plan's programme is taken as the setpoint")
    fit_log = with_plan_setpoint(log, plan)
    ident = identify(fit_log)
    change_s, jump_c_per_min = plan_rate_changes(plan)
    est = estimate_gradient(
        log, rate_change_times_s=change_s, rate_change_jumps_c_per_min=jump_c_per_min
    )
    grid = plan.grid
    req, delta = plan.levels_required, plan.delta_c_per_min
    run = measured_run(log, est, grid)
    grads, open_pass = closed_passes(run.time_min, run.t_c, run.g_c_per_min, grid)
    so_far = report_from_gradients(grid, grads, req, delta)
    now = float(log.time_min[-1])
    total = plan.programme.total_min
    ok = np.flatnonzero(np.isfinite(est.t_est_c))
    k_now = int(ok[-1])
    t_now = float(est.t_est_c[k_now])
    # the rest: the plan's dense grid after the last resampled point
    full = dense_times(total, DENSE_MIN)
    rest = full[full > float(run.time_min[-1]) + 1e-9]
    if find_effect:
        effect = check_effect(fit_log, plan, now, ident.model, ident.t0_c, t_now)
    else:
        effect = EffectCheck("none", {}, 0.0, False, ident.model, ident.t0_c)
    model, t0 = (effect.model, effect.t0_c) if effect.material else (ident.model, ident.t0_c)
    if rest.size:
        t_rest, g_rest = predict_from_state(model, t0, plan.programme, now, t_now, rest)
    else:
        t_rest = g_rest = np.zeros(0)
    t_all = np.concatenate((run.time_min, rest))
    temp_all = np.concatenate((run.t_c, t_rest))
    g_all = np.concatenate((run.g_c_per_min, g_rest))
    predicted = coverage_report(temp_all, g_all, grid, req, delta)
    for rival in effect.rivals if rest.size else ():
        # a model that fits the log as well but predicts the rest differently
        t_r, g_r = predict_from_state(rival.model, rival.t0_c, plan.programme, now, t_now, rest)
        cov_r = coverage_report(
            np.concatenate((run.t_c, t_r)), np.concatenate((run.g_c_per_min, g_r)), grid, req, delta
        )
        if cov_r.coverage < predicted.coverage or cov_r.min_levels < predicted.min_levels:
            notes.append(
                f"*** {rival.effect} fits the log about as well (it predicts the device up to "
                f"{rival.gap_c:.2f} °C apart over the rest): with it the plan ends at "
                f"{cov_r.coverage:.0%} (min {cov_r.min_levels} levels), not "
                f"{predicted.coverage:.0%}; watch again when the log tells them apart"
            )
    planned_pred = plan.model.predict(plan.programme, full, t0_c=plan.limits.t_init_c)
    planned = coverage_report(planned_pred.t_c, planned_pred.g_c_per_min, grid, req, delta)
    at_log = plan.model.predict(plan.programme, log.time_min, t0_c=plan.limits.t_init_c)
    gap = log.t_int_c - at_log.t_c
    gap_est_now = t_now - float(at_log.t_c[k_now])
    dev_lo = float(np.nanmin(temp_all))
    dev_hi = float(np.nanmax(temp_all))
    if rest.size and (
        t_rest.min() < plan.limits.device_min_c or t_rest.max() > plan.limits.device_max_c
    ):
        notes.append(
            f"with the identified model the device would reach {t_rest.min():.1f} .. "
            f"{t_rest.max():.1f} °C, outside its limits {plan.limits.device_min_c:g} .. "
            f"{plan.limits.device_max_c:g} °C"
        )
    elif rest.size and not effect.material:
        # red team: at 30 min (tau 1937 +- 114 s, dT0 -0.53 +- 1.42 degC; the device's 3.0)
        # the prediction stayed inside the limits and the device went 3.9 degC past one;
        # the model within two standard errors of the fit already reached past it
        far_lo, far_hi, worst = _limit_envelope(ident, plan, now, t_now, rest)
        lim = plan.limits
        if (
            far_hi > lim.device_max_c + DEVICE_LIMIT_TOL_C
            or far_lo < lim.device_min_c - DEVICE_LIMIT_TOL_C
        ):
            notes.append(
                f"*** within two standard errors of the identified model ({worst}) the device "
                f"may reach {far_lo:.1f} .. {far_hi:.1f} °C over the rest, outside its limits "
                f"{lim.device_min_c:g} .. {lim.device_max_c:g} °C: the log does not yet rule "
                "out a breach; watch again soon, or re-plan the rest with a margin"
            )
    if ident.span_min < 0.75 * ident.tau_s / 60.0:
        notes.append(
            f"the log spans {ident.span_min:.0f} min, less than 3/4 of the identified tau: "
            "tau and dT0 are still poorly separated"
        )
    series = pd.DataFrame(
        {
            "time_s": log.time_s,
            "t_meas_c": log.t_int_c,
            "t_est_c": est.t_est_c,
            "t_planned_c": at_log.t_c,
            "gap_c": gap,
            "g_est_c_per_min": est.g_est_c_per_min,
            "g_std_c_per_min": est.g_std_c_per_min,
        }
    )
    dense = pd.DataFrame(
        {
            "time_min": t_all,
            "t_c": temp_all,
            "g_c_per_min": g_all,
            "predicted": t_all > float(run.time_min[-1]) + 1e-9,
        }
    )
    planned_dense = pd.DataFrame(
        {
            "time_min": full,
            "tk_c": plan.programme.chamber_at(full),
            "t_c": planned_pred.t_c,
            "g_c_per_min": planned_pred.g_c_per_min,
        }
    )
    return MonitorReport(
        plan=plan,
        log_source=log.source,
        elapsed_min=now,
        plan_total_min=total,
        identified=ident,
        effect=effect,
        so_far=so_far,
        pass_in_progress=open_pass,
        predicted=predicted,
        planned=planned,
        gap_rms_c=float(np.sqrt(np.nanmean(gap**2))),
        gap_max_abs_c=float(np.nanmax(np.abs(gap))),
        gap_now_c=gap_est_now,
        t_now_c=t_now,
        t_now_std_c=float(est.t_std_c[k_now]),
        g_now_c_per_min=float(est.g_est_c_per_min[k_now]),
        g_now_std_c_per_min=float(est.g_std_c_per_min[k_now]),
        predicted_device_min_c=dev_lo,
        predicted_device_max_c=dev_hi,
        notes=tuple(notes),
        series=series,
        dense=dense,
        planned_dense=planned_dense,
    )


__all__ = [
    "EffectCheck",
    "Identified",
    "MonitorReport",
    "MonitorSettings",
    "OpenPass",
    "PlanRecord",
    "check_log_belongs",
    "check_log_start",
    "measured_run",
    "check_effect",
    "closed_passes",
    "identify",
    "json_safe",
    "monitor_run",
    "predict_from_state",
    "read_plan_dir",
    "report_from_gradients",
    "with_plan_setpoint",
]
