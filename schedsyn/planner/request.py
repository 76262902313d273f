"""Stage 1: the request -- one experiment's regions and target, and the scenarios to meet.

An :class:`ExperimentSpec` says which working region must be covered, how (levels,
delta) and how the synthesis searches (segment length, objective, step limit). Together
with the device model (:class:`~schedsyn.params.ThermalParams`) and the chamber
(:class:`~schedsyn.params.Limits`) it is a request; :func:`check_request` refuses a
request no programme can meet before any LP is solved.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import ParameterError
from ..grid import BinGrid
from ..model import LinearThermalModel, lag_foh, lag_free
from ..params import Limits, ThermalParams
from ..programme import Programme

OBJECTIVES = ("shortest", "margin", "informative")
# a start excursion past a device limit by more than this is refused up front (the plan
# check's own tolerance is 1e-6 degC; the start check's lag grid is exact at its points)
DEVICE_START_TOL_C = 1e-6


@dataclass(frozen=True, slots=True)
class ExperimentSpec:
    """One experiment: its working and approximation regions and the coverage target.

    Parameters
    ----------
    name : str
        Experiment name (used for output folders).
    working_lo_c, working_hi_c : float
        Working region, degC: every 1 degC bin in it must be covered.
    approx_lo_c, approx_hi_c : float
        Approximation region, degC: the device stays inside it from the first sweep on.
    levels_required : int
        Distinct gradient levels per bin (paper: 6), 2..12.
    delta_c_per_min : float
        Minimum difference between two levels, degC/min, in (0, 1].
    segment_min : float
        Length of one decision segment, whole minutes, 2..30 (default 3: finer control
        follows the guided speed profiles closely; longer segments give fewer, longer
        steps and longer plans).
    objective : str
        ``"shortest"`` (shortest programme reaching the target), ``"margin"`` (largest
        margin within ``duration_max_min``) or ``"informative"`` (the shortest plan's
        sweeps, run on to ``duration_max_min`` with every rate chosen for the drift fit's
        information; see :mod:`schedsyn.planner.informative`).
    max_steps : int
        Most steps the exported step table may have (after merging equal rates), >= 2; the
        planner merges steps to meet it.
    min_step_min : float
        Shortest step the table may have, min (0: one segment); the planner merges
        shorter steps into a neighbour.
    edge_margin_c : float
        Each sweep passes the working edges by at least this, degC, in (0, 10] (default
        0.25: sweeps are slow near the edges, where every tenth of a degree costs time; a
        wider margin or ``objective = "margin"`` tolerates more model error).
    max_cool_c_per_min, max_heat_c_per_min : float
        Fastest cooling / heating gradient the bands use, degC/min, in [0.1, 3]. Fast
        sweeps cost long turnarounds and overshoot: the chamber cools at only 1 degC/min,
        so a cooling gradient close to that takes long to build up.
    """

    name: str
    working_lo_c: float
    working_hi_c: float
    approx_lo_c: float
    approx_hi_c: float
    levels_required: int = 6
    delta_c_per_min: float = 0.05
    segment_min: float = 3.0
    objective: str = "shortest"
    max_steps: int = 80
    min_step_min: float = 0.0
    edge_margin_c: float = 0.25
    max_cool_c_per_min: float = 0.85
    max_heat_c_per_min: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ParameterError("an experiment needs a non-empty name")
        for f in (
            "working_lo_c",
            "working_hi_c",
            "approx_lo_c",
            "approx_hi_c",
            "delta_c_per_min",
            "segment_min",
            "edge_margin_c",
            "min_step_min",
            "max_cool_c_per_min",
            "max_heat_c_per_min",
        ):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{self.name}: {f} must be a finite number, got {v!r}")
        BinGrid(self.working_lo_c, self.working_hi_c)  # validates the working region
        if not (self.approx_lo_c <= self.working_lo_c and self.working_hi_c <= self.approx_hi_c):
            raise ParameterError(
                f"{self.name}: the approximation region [{self.approx_lo_c:g}, "
                f"{self.approx_hi_c:g}] °C must contain the working region "
                f"[{self.working_lo_c:g}, {self.working_hi_c:g}] °C; widen it to reach at least "
                f"{self.working_lo_c:g} .. {self.working_hi_c:g} °C"
            )
        levels = self.levels_required
        if isinstance(levels, bool) or int(levels) != levels or not 2 <= levels <= 12:
            raise ParameterError(
                f"{self.name}: levels_required must be a whole number in 2..12, got {levels!r}"
            )
        if not 0 < self.delta_c_per_min <= 1:
            raise ParameterError(
                f"{self.name}: delta_c_per_min must be in (0, 1] °C/min, got "
                f"{self.delta_c_per_min!r}"
            )
        if self.segment_min != int(self.segment_min) or not 2 <= self.segment_min <= 30:
            raise ParameterError(
                f"{self.name}: segment_min must be a whole number of minutes in 2..30, got "
                f"{self.segment_min!r}"
            )
        if self.objective not in OBJECTIVES:
            raise ParameterError(
                f"{self.name}: objective must be one of {OBJECTIVES}, got {self.objective!r}"
            )
        steps = self.max_steps
        if isinstance(steps, bool) or int(steps) != steps or steps < 2:
            raise ParameterError(f"{self.name}: max_steps must be a whole number >= 2")
        if not 0 <= self.min_step_min <= 240:
            raise ParameterError(f"{self.name}: min_step_min must be in 0..240 min")
        if not 0 < self.edge_margin_c <= 10:
            raise ParameterError(f"{self.name}: edge_margin_c must be in (0, 10] °C")
        for f in ("max_cool_c_per_min", "max_heat_c_per_min"):
            if not 0.1 <= getattr(self, f) <= 3:
                raise ParameterError(f"{self.name}: {f} must be in 0.1..3 °C/min")

    @property
    def grid(self) -> BinGrid:
        return BinGrid(self.working_lo_c, self.working_hi_c)

    def to_dict(self) -> dict:
        return {f: getattr(self, f) for f in self.__dataclass_fields__}


def check_request(spec: ExperimentSpec, limits: Limits, *, check_start: bool = True) -> None:
    """Refuse, before any planning, a request that no programme can meet.

    The chamber must cool and heat. Every sweep passes the working edges by
    ``edge_margin_c``, so the device must be allowed there: the working region plus the
    margin must lie inside the device limits. The device must start inside its limits
    (``t_init_c``): a device already past a limit at t = 0 breaks it in every programme,
    and the search would otherwise run minutes to say "lengthen the duration".
    ``check_start=False`` for a continuation, whose start is the measured state of a
    running device, not ``t_init_c``.
    (A chamber that cannot reach part of the region still gets the best partial plan,
    with notes saying why; see :func:`explain_shortfall`.)
    """
    m = spec.edge_margin_c
    lo, hi = spec.working_lo_c - m, spec.working_hi_c + m
    name = spec.name
    if not limits.rate_min_c_per_min < 0.0 < limits.rate_max_c_per_min:
        raise ParameterError(
            f"{name}: the chamber must both cool and heat (every bin is passed in both "
            "directions and the run returns to its start temperature), got rates "
            f"{limits.rate_min_c_per_min:g} .. {limits.rate_max_c_per_min:g} °C/min; give "
            "rate_min_c_per_min < 0 < rate_max_c_per_min"
        )
    if lo < limits.device_min_c or hi > limits.device_max_c:
        raise ParameterError(
            f"{name}: the working region [{spec.working_lo_c:g}, {spec.working_hi_c:g}] °C "
            f"plus the edge margin {m:g} °C needs the device at {lo:g} .. {hi:g} °C, outside "
            f"its limits {limits.device_min_c:g} .. {limits.device_max_c:g} °C; move the "
            "region inside the device limits or, if the device is rated for it, widen them "
            "(--device-min-c / --device-max-c; device_min_c / device_max_c in a campaign's "
            "[limits])"
        )
    if check_start:
        check_device_start(limits, name)


def check_device_start(limits: Limits, name: str = "") -> None:
    """Refuse limits whose device starts (``t_init_c``) outside the device limits."""
    t0 = limits.t_init_c
    if limits.device_min_c <= t0 <= limits.device_max_c:
        return
    side = "above" if t0 > limits.device_max_c else "below"
    raise ParameterError(
        (f"{name}: " if name else "")
        + f"the device starts at {t0:g} °C (t_init_c), {side} its limits "
        f"{limits.device_min_c:g} .. {limits.device_max_c:g} °C, so every programme breaks "
        "them from t = 0; set the start temperature inside the limits (t_init_c in a "
        "campaign's [limits]) or, if the device is rated for it, widen them "
        "(--device-min-c / --device-max-c; device_min_c / device_max_c in [limits])"
    )


START_CHECK_STEP_MIN = 0.05  # grid of the start excursion's lag (exact at the grid points)


def start_excursion_c(params: ThermalParams, limits: Limits) -> tuple[float, float]:
    """The least every programme must reach from the start: ``(peak_c, trough_c)``.

    The device's temperature is monotone in the chamber's path, and the chamber's
    lowest path from ``start_c`` cools at ``rate_min_c_per_min`` down to ``chamber_min_c``
    and holds there. So at every time the device is at least where that path takes it, and
    its peak over the run is at least that path's peak, ``peak_c`` (above the start when
    ``start_c + dt0_c`` lies above ``t_init_c``: the device warms before the cooling
    reaches it). Likewise ``trough_c`` from the highest path (heating at
    ``rate_max_c_per_min`` up to ``chamber_max_c``): every programme goes at least that
    low. Over ``duration_max_min``.
    """
    tau = params.tau_min
    dur = limits.duration_max_min
    s, t0, d = limits.start_c, limits.t_init_c, params.dt0_c
    out = []
    for rate, bound in (
        (limits.rate_min_c_per_min, limits.chamber_min_c),
        (limits.rate_max_c_per_min, limits.chamber_max_c),
    ):
        t_kink = min(dur, (bound - s) / rate) if rate != 0.0 else dur
        n = max(1, math.ceil(t_kink / START_CHECK_STEP_MIN))
        h = t_kink / n if t_kink > 0 else START_CHECK_STEP_MIN
        ramp = lag_foh(s + rate * h * np.arange(n + 1) + d, t0, tau, h)
        held = ramp
        if t_kink < dur:  # then the chamber holds at its bound
            t_rest = np.linspace(0.0, dur - t_kink, 2 + math.ceil((dur - t_kink) / h))
            held = np.concatenate((ramp, lag_free(t_rest, bound + d, float(ramp[-1]), tau)[0]))
        out.append(float(held.max() if rate < 0 else held.min()))
    return out[0], out[1]


def check_start_excursion(
    scenarios: list[ThermalParams] | tuple[ThermalParams, ...], limits: Limits, name: str = ""
) -> None:
    """Refuse a start from which every programme takes the device past a limit.

    A device starting at (or near) a limit with the chamber's start plus ``dt0_c`` beyond
    it moves past the limit before any cooling or heating reaches it
    (:func:`start_excursion_c`, a proof over every programme); the search would otherwise
    run for minutes and end "infeasible" without naming the start.
    """
    worst: tuple[float, float, ThermalParams, int] | None = None  # excess, value, p, side
    for p in scenarios:
        peak, trough = start_excursion_c(p, limits)
        for past, value, side in (
            (peak - limits.device_max_c, peak, 0),
            (limits.device_min_c - trough, trough, 1),
        ):
            if past > DEVICE_START_TOL_C and (worst is None or past > worst[0]):
                worst = (past, value, p, side)
    if worst is None:
        return
    past, value, p, side = worst
    lim, key, path = (
        (limits.device_max_c, "device_max_c", f"cooling at {limits.rate_min_c_per_min:g}")
        if side == 0
        else (limits.device_min_c, "device_min_c", f"heating at {limits.rate_max_c_per_min:g}")
    )
    which = f" (tau {p.tau_s:g} s, dT0 {p.dt0_c:g} °C)" if len(scenarios) > 1 else ""
    dec = max(1, math.ceil(-math.log10(past)) + 1)  # enough digits to show the excess
    raise ParameterError(
        (f"{name}: " if name else "")
        + f"every programme takes the device past {key} = {lim:g} °C{which}: it starts at "
        f"{limits.t_init_c:g} °C with the chamber at {limits.start_c:g} °C and settles "
        f"dT0 = {p.dt0_c:g} °C from it, so even {path} °C/min from t = 0 it reaches "
        f"{value:.{dec}f} °C ({past:.2g} °C past the limit); start the device farther inside "
        "its limits (t_init_c, start_c in a campaign's [limits]) or, if it is rated for it, "
        "widen them (--device-min-c / --device-max-c)"
    )


# ----------------------------------------------------------------------------------
# Continuing a run: what has been executed and measured so far
# ----------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Continuation:
    """A run in progress: plan only the rest of it, counting what was measured.

    Parameters
    ----------
    prefix : Programme
        The steps executed so far, from the start of the run (its ``start_c`` is the
        chamber at t = 0); it must last a whole number of minutes, ``M``. The planner keeps
        it unchanged and plans new segments from ``M``, so the model's state at ``M``
        follows exactly from the executed chamber path.
    existing_gradients : sequence of arrays
        Per 1 degC bin of the working region, the mean gradients (degC/min) of the passes
        measured so far (a pass still open at ``M`` left out). New passes count only where
        they are ``delta`` apart from the levels already there.
    start_correction_c : float
        Measured minus modelled internal temperature at ``M``, degC; it decays with the
        model's time constant over the rest of the run.
    t0_c : float, optional
        The model's internal temperature at t = 0 (default: ``limits.t_init_c``).
    """

    prefix: Programme
    existing_gradients: tuple[np.ndarray, ...]
    start_correction_c: float = 0.0
    t0_c: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.prefix, Programme):
            raise ParameterError("a continuation's prefix must be a Programme")
        total = self.prefix.total_min
        if abs(total - round(total)) > 1e-6 or total <= 0:
            raise ParameterError(
                f"the executed steps last {total:g} min; a continuation starts at a whole "
                "minute > 0 (cut the run at a whole minute)"
            )
        grads = tuple(np.asarray(g, dtype=float).ravel() for g in self.existing_gradients)
        if any(not np.all(np.isfinite(g)) for g in grads):
            raise ParameterError("existing gradients must be finite numbers (°C/min)")
        object.__setattr__(self, "existing_gradients", grads)
        for name in ("start_correction_c", "t0_c"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not math.isfinite(float(v))):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")

    @property
    def at_min(self) -> float:
        """Minute from which the rest is planned (the end of the executed steps)."""
        return float(round(self.prefix.total_min))

    def check_grid(self, spec: ExperimentSpec) -> None:
        if len(self.existing_gradients) != spec.grid.n_bins:
            raise ParameterError(
                f"{spec.name}: existing_gradients has {len(self.existing_gradients)} entries, "
                f"one per 1 °C bin of the working region is needed ({spec.grid.n_bins})"
            )


# ----------------------------------------------------------------------------------
# Scenarios: the nominal point, or the corners and centre of a robust box
# ----------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Scenario:
    """One (model, dT0) the plan must satisfy."""

    params: ThermalParams
    model: LinearThermalModel


def robust_scenarios(
    params: ThermalParams,
    tau_s_range: tuple[float, float] | None,
    dt0_c_range: tuple[float, float] | None,
    n_tau: int = 3,
) -> list[ThermalParams]:
    """Scenarios that cover a (tau, dT0) box.

    T and g are affine in dT0 for fixed rates (dT0 only enters the free response), so a
    band constraint that holds at both ends of the dT0 range holds in between: the two
    dT0 extremes are exact. In tau the response is nonlinear, so ``n_tau`` values spread
    over the range (both ends included) are used and the plan is verified afterwards on
    a dense grid.
    """
    taus = (
        [params.tau_s]
        if tau_s_range is None
        else list(np.linspace(tau_s_range[0], tau_s_range[1], n_tau))
    )
    dt0s = [params.dt0_c] if dt0_c_range is None else [dt0_c_range[0], dt0_c_range[1]]
    for name, rng in (("tau_s", tau_s_range), ("dt0_c", dt0_c_range)):
        if rng is not None and not rng[0] <= rng[1]:
            raise ParameterError(f"robust {name} range must be LO:HI with LO <= HI, got {rng}")
    return [replace(params, tau_s=float(t), dt0_c=float(d)) for t in taus for d in dt0s]


# ----------------------------------------------------------------------------------
# The sweep structure: alternating monotone sweeps, which way the first one goes
# ----------------------------------------------------------------------------------
def sweep_directions(spec: ExperimentSpec, first: int, n_sweeps: int | None = None) -> list[int]:
    """Directions (+1 heating, -1 cooling) of ``n_sweeps`` (default ``levels_required``)
    alternating sweeps."""
    n = spec.levels_required if n_sweeps is None else n_sweeps
    return [first * (-1) ** k for k in range(n)]


def first_directions(
    spec: ExperimentSpec, limits: Limits, start_t_c: float | None = None
) -> list[int]:
    """Which way the first sweep may go: towards the region, or either way from inside it.

    ``start_t_c``: the device temperature where the sweeps start (default: at t = 0).
    """
    t = limits.t_init_c if start_t_c is None else start_t_c
    if spec.working_hi_c + spec.edge_margin_c <= t:
        return [-1]
    if spec.working_lo_c - spec.edge_margin_c >= t:
        return [+1]
    return [-1, +1]


def planning_effort(spec: ExperimentSpec, limits: Limits) -> float:
    """Rough relative cost of planning ``spec`` (for scheduling a campaign, longest first).

    A region that contains the start temperature is searched starting both ways (twice
    the structures), and wider regions need longer sweeps.
    """
    return len(first_directions(spec, limits)) * (spec.working_hi_c - spec.working_lo_c)
