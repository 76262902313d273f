"""What would meet a request that is not planned complete: the least change of one knob.

For a request (:class:`~schedsyn.planner.ExperimentSpec`, model, chamber limits) whose
plan is not complete, :func:`advise` searches, one knob at a time, the smallest change
that makes it feasible, and **verifies** it by a complete plan (the planner's own dense
re-simulation of the exported step table). The knobs:

============  ===============================  =========================================
knob          what changes                     grid (increasingly generous)
============  ===============================  =========================================
duration      ``duration_max_min``             whole ``duration_step_min`` steps up
floor         ``chamber_min_c``                ``temp_step_c`` steps down
ceiling       ``chamber_max_c``                ``temp_step_c`` steps up
rates         both chamber rates, one factor   ``rate_step`` (10 %) steps up
levels        ``levels_required``              one level fewer at a time, down to 2
============  ===============================  =========================================

The search for one knob, on its grid ``x_0`` (the request, known to fail) ``< x_1 < ... <
x_n`` (the most generous value searched):

1. **Screen with the proven bound** (:func:`~schedsyn.planner.duration_lower_bound`,
   < 1 s): a value whose bound exceeds its duration limit cannot work. Bisection finds
   the first value the bound does not exclude; the one before it is *proven* not to work.
   If even ``x_n`` is excluded, no value in the range works (proven), and nothing is
   planned.
2. **Plan the most generous value** ``x_n``. If schedsyn finds no complete plan there
   either, the knob alone does not help (as far as schedsyn can plan) and the search
   stops after one plan.
3. **Bisect** between the last value known to fail and the first known to work. A
   complete plan verifies more than the value it was planned at: it also meets the
   request at the least value its own programme needs (its duration, its coldest and
   warmest chamber temperature, its fastest ramps, the distinct levels its bins got) --
   checked again with :func:`~schedsyn.planner.check_programme` -- so each success
   jumps as far down the grid as the plan allows.

The answer is the least grid value verified by a complete plan, next to the value one
step less generous, which either the bound proves impossible or schedsyn planned and found
incomplete (not a proof: the planner is a heuristic; the line says which). A knob that does
not bind (moving it changes neither the bound nor :func:`explain_shortfall`'s notes) is
skipped. The search is bounded by a number of plans per knob and a time budget
(checked before each plan: a plan under way is finished); the knobs run in parallel on
the local cores (``backend``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from .errors import InfeasiblePlanError, ParameterError
from .params import Limits, ThermalParams
from .planner import (
    ExperimentSpec,
    Plan,
    check_programme,
    duration_lower_bound,
    explain_shortfall,
    plan_experiment,
)

#: The knobs, in the order they are reported.
KNOBS = ("duration", "floor", "ceiling", "rates", "levels")
#: Bound changes smaller than this (min) count as "the knob does not move the bound".
BOUND_TOL_MIN = 0.5

#: Statuses of one knob's search.
VERIFIED = "verified"  # a complete plan at ``value``; ``failing_value`` does not work
PROVEN_IMPOSSIBLE = "proven_impossible"  # the bound excludes every value searched
NOT_FOUND = "not_found"  # no complete plan found in the range (or within the budget)
NOT_BINDING = "not_binding"  # moving the knob changes neither the bound nor the notes
SKIPPED = "skipped"  # nothing to search (e.g. already 2 levels)


@dataclass(frozen=True, slots=True)
class AdviceSettings:
    """How far and how long :func:`advise` searches.

    Parameters
    ----------
    knobs : tuple of str
        Which of :data:`KNOBS` to search.
    duration_step_min : float
        Grid of the duration, whole minutes, 1..60 (default 5).
    duration_factor : float
        The duration is searched up to this multiple of the request's limit, > 1
        (default 2; never beyond 10080 min).
    temp_step_c : float
        Grid of the chamber floor and ceiling, degC, > 0 (default 1).
    floor_reach_c, ceiling_reach_c : float
        How far below the floor / above the ceiling to search, degC, > 0 (default 40).
    rate_step : float
        Grid of the common factor on both chamber rates, > 0 (default 0.1, i.e. 10 %).
    rate_factor : float
        The rates are searched up to this multiple, > 1 (default 3).
    max_plans : int
        Plans per knob, >= 1 (default 8).
    time_budget_s : float
        Wall time for the whole search, s, > 0 (default 900); checked before each plan.
    """

    knobs: tuple[str, ...] = KNOBS
    duration_step_min: float = 5.0
    duration_factor: float = 2.0
    temp_step_c: float = 1.0
    floor_reach_c: float = 40.0
    ceiling_reach_c: float = 40.0
    rate_step: float = 0.1
    rate_factor: float = 3.0
    max_plans: int = 8
    time_budget_s: float = 900.0

    def __post_init__(self) -> None:
        knobs = tuple(self.knobs)
        bad = [k for k in knobs if k not in KNOBS]
        if bad or not knobs:
            raise ParameterError(f"knobs must be some of {KNOBS}, got {list(knobs)}")
        object.__setattr__(self, "knobs", knobs)
        checks = (
            ("duration_step_min", 1.0, 60.0),
            ("duration_factor", 1.0, 100.0),
            ("temp_step_c", 0.0, 50.0),
            ("floor_reach_c", 0.0, 500.0),
            ("ceiling_reach_c", 0.0, 500.0),
            ("rate_step", 0.0, 10.0),
            ("rate_factor", 1.0, 100.0),
            ("time_budget_s", 0.0, 1e6),
        )
        for name, lo, hi in checks:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{name} must be a finite number, got {v!r}")
            if not lo < v <= hi and not (name == "duration_step_min" and v == lo):
                raise ParameterError(f"{name} must be in ({lo:g}, {hi:g}], got {v!r}")
        if self.duration_step_min != int(self.duration_step_min):
            raise ParameterError(
                f"duration_step_min must be whole minutes, got {self.duration_step_min!r}"
            )
        n = self.max_plans
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ParameterError(f"max_plans must be a whole number >= 1, got {n!r}")


@dataclass(frozen=True, slots=True)
class KnobAdvice:
    """What one knob would need.

    ``value`` is the least value (on the knob's grid) verified by a complete plan, in the
    knob's unit (min, degC, the rate factor, levels); ``failing_value`` the value one step
    less generous and ``failing_reason`` why it fails: ``"proven"`` (the bound excludes
    it), ``"planned"`` (schedsyn planned it and found no complete plan) or ``"request"``
    (it is the request itself). ``changes`` are the settings to use (``Limits`` and
    ``ExperimentSpec`` field names); ``adjacent`` says whether ``failing_value`` is the
    grid's neighbour of ``value`` (False when the search stopped at its budget).
    """

    knob: str
    status: str
    current: float
    value: float | None = None
    failing_value: float | None = None
    failing_reason: str = ""
    adjacent: bool = False
    changes: dict[str, float] = field(default_factory=dict)
    plan_duration_min: float | None = None
    plan_steps: int | None = None
    bound_min: float | None = None
    plans: int = 0
    solve_s: float = 0.0
    line: str = ""
    #: the complete plan made at ``value`` (not in ``to_dict``)
    plan: Plan | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        return {f: getattr(self, f) for f in ADVICE_COLUMNS}


ADVICE_COLUMNS = tuple(f.name for f in dataclasses.fields(KnobAdvice) if f.name != "plan")


@dataclass(frozen=True, slots=True)
class Advice:
    """:func:`advise`'s answer: one :class:`KnobAdvice` per knob searched."""

    experiment: str
    complete: bool
    bound_min: float
    items: tuple[KnobAdvice, ...]
    wall_s: float

    def lines(self) -> list[str]:
        """One line per knob, in words (what to change, proven or verified)."""
        if self.complete:
            return [f"{self.experiment}: the request is planned complete; nothing to change"]
        return [f"{self.experiment}: {k.line}" for k in self.items]

    def verified(self) -> list[KnobAdvice]:
        return [k for k in self.items if k.status == VERIFIED]

    def to_frame(self) -> pd.DataFrame:
        rows = [{**k.to_dict(), "changes": _changes_text(k.changes)} for k in self.items]
        return pd.DataFrame(rows, columns=list(ADVICE_COLUMNS))

    def to_dict(self) -> dict[str, Any]:
        return {
            "experiment": self.experiment,
            "complete": self.complete,
            "duration_lower_bound_min": self.bound_min,
            "wall_s": self.wall_s,
            "knobs": [k.to_dict() for k in self.items],
        }


def _changes_text(changes: dict[str, float]) -> str:
    return " ".join(f"{k}={v:g}" for k, v in changes.items())


# ---------------------------------------------------------------------------------------
# the knobs: a grid of requests, increasingly generous
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Knob:
    """One knob's grid: ``values[0]`` is the request, later values are more generous."""

    name: str
    values: tuple[float, ...]
    spec: ExperimentSpec
    limits: Limits

    def request(self, i: int) -> tuple[ExperimentSpec, Limits]:
        """The request with the knob at ``values[i]``."""
        v = self.values[i]
        spec, lim = self.spec, self.limits
        if self.name == "duration":
            return spec, dataclasses.replace(lim, duration_max_min=v)
        if self.name == "floor":
            return spec, dataclasses.replace(lim, chamber_min_c=v)
        if self.name == "ceiling":
            return spec, dataclasses.replace(lim, chamber_max_c=v)
        if self.name == "rates":
            return spec, dataclasses.replace(
                lim,
                rate_min_c_per_min=lim.rate_min_c_per_min * v,
                rate_max_c_per_min=lim.rate_max_c_per_min * v,
            )
        return dataclasses.replace(spec, levels_required=int(v)), lim

    def changes(self, i: int) -> dict[str, float]:
        spec, lim = self.request(i)
        if self.name == "duration":
            return {"duration_max_min": lim.duration_max_min}
        if self.name == "floor":
            return {"chamber_min_c": lim.chamber_min_c}
        if self.name == "ceiling":
            return {"chamber_max_c": lim.chamber_max_c}
        if self.name == "rates":
            return {
                "rate_min_c_per_min": round(lim.rate_min_c_per_min, 6),
                "rate_max_c_per_min": round(lim.rate_max_c_per_min, 6),
            }
        return {"levels_required": spec.levels_required}

    def needed(self, plan: Plan) -> int:
        """The least generous index whose request the plan's own programme may meet
        (a hint, to be checked by :func:`_meets`)."""
        prog = plan.programme
        vals = np.asarray(self.values)
        idx = np.arange(vals.size)
        if self.name == "duration":
            ok = vals >= prog.total_min - 1e-9
        elif self.name == "floor":
            ok = vals <= float(prog.boundary_temps_c.min()) + 1e-9
        elif self.name == "ceiling":
            ok = vals >= float(prog.boundary_temps_c.max()) - 1e-9
        elif self.name == "rates":
            u = prog.rates_c_per_min
            lim = self.limits
            ok = (lim.rate_min_c_per_min * vals <= u.min() + 1e-9) & (
                lim.rate_max_c_per_min * vals >= u.max() - 1e-9
            )
        else:
            ok = vals <= plan.coverage.min_levels
        ok &= idx >= 1
        return int(idx[ok][0]) if ok.any() else len(vals) - 1


def _grid(start: float, stop: float, step: float) -> list[float]:
    """``start, start + step, ...`` up to ``stop`` (inclusive), either direction."""
    n = int(math.floor(abs(stop - start) / step + 1e-9))
    sign = 1.0 if stop >= start else -1.0
    return [round(start + sign * step * k, 9) for k in range(1, n + 1)]


def _knobs(spec: ExperimentSpec, limits: Limits, settings: AdviceSettings) -> dict[str, _Knob]:
    out: dict[str, _Knob] = {}
    for name in (k for k in KNOBS if k in settings.knobs):  # reported in KNOBS order
        if name == "duration":
            step = settings.duration_step_min
            cur = limits.duration_max_min
            top = min(cur * settings.duration_factor, 10080.0)
            first = step * math.floor(cur / step + 1e-9) + step
            vals = [first + step * k for k in range(int(math.floor((top - first) / step)) + 1)]
            values = [cur, *vals]
        elif name == "floor":
            cur = limits.chamber_min_c
            top = min(cur - settings.floor_reach_c, limits.start_c, limits.end_c)
            values = [cur, *_grid(cur, top, settings.temp_step_c)]
            values = [v for v in values if v <= min(limits.start_c, limits.end_c)]
        elif name == "ceiling":
            cur = limits.chamber_max_c
            values = [cur, *_grid(cur, cur + settings.ceiling_reach_c, settings.temp_step_c)]
        elif name == "rates":
            cur = 1.0
            values = [1.0, *_grid(1.0, settings.rate_factor, settings.rate_step)]
        else:
            cur = spec.levels_required
            values = [float(v) for v in range(int(cur), 1, -1)]
        out[name] = _Knob(name, tuple(float(v) for v in values), spec, limits)
    return out


# ---------------------------------------------------------------------------------------
# the search of one knob
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Job:
    knob: _Knob
    params: ThermalParams
    deadline: float  # time.time() after which no new plan is started
    max_plans: int
    request_failure: str  # "planned" or "proven": why the request itself fails
    notes: tuple[str, ...]


def _bound(knob: _Knob, params: ThermalParams, i: int) -> float:
    spec, lim = knob.request(i)
    # without the levels' dual: the bisection over a knob's values assumes the bound
    # moves one way with it, which the dual's subgradient search does not promise
    return duration_lower_bound(spec, params, lim, tighten=False).lower_bound_min


def _excluded(knob: _Knob, params: ThermalParams, i: int) -> bool:
    """The bound proves no complete plan exists at ``values[i]``."""
    _, lim = knob.request(i)
    return _bound(knob, params, i) > lim.duration_max_min + 1e-9


def _meets(plan: Plan, knob: _Knob, i: int, params: ThermalParams) -> bool:
    """Does the plan's programme meet the request at ``values[i]`` (independent dense
    check: coverage at its levels, every limit)?"""
    spec, lim = knob.request(i)
    cov, _, problems, _, _ = check_programme(plan.programme, spec, lim, [params])
    return cov.complete and not problems and plan.steps <= spec.max_steps


def _attempt(knob: _Knob, params: ThermalParams, i: int) -> Plan | None:
    """Plan the request at ``values[i]``; the plan if complete, else None."""
    spec, lim = knob.request(i)
    try:
        # not graded: a plan for fewer levels never meets the request, so not searched
        plan = plan_experiment(spec, params, lim, graded=False)
    except InfeasiblePlanError:
        return None
    return plan if plan.complete else None


def _search(job: _Job, progress: Callable[[str], None] | None = None) -> KnobAdvice:
    knob, params = job.knob, job.params
    tic = time.perf_counter()
    vals = knob.values
    n = len(vals) - 1
    label = _LABELS[knob.name]

    def say(msg: str) -> None:
        if progress is not None:
            progress(f"advice, {label}: {msg}")

    def done(status: str, **kw: Any) -> KnobAdvice:
        adv = KnobAdvice(
            knob.name, status, vals[0], solve_s=time.perf_counter() - tic, plans=plans, **kw
        )
        return dataclasses.replace(adv, line=_line(knob, adv, job.notes))

    plans = 0
    if n < 1:
        return done(SKIPPED)
    bound_0 = _bound(knob, params, 0)
    # 1. the proven bound: the first value it does not exclude (bisection)
    if _excluded(knob, params, n):
        return done(PROVEN_IMPOSSIBLE, bound_min=_bound(knob, params, n))
    if knob.name in ("floor", "ceiling"):
        moved = abs(_bound(knob, params, n) - bound_0) > BOUND_TOL_MIN
        word = "floor" if knob.name == "floor" else "ceiling"
        if not moved and not any(word in note for note in job.notes):
            return done(NOT_BINDING)
    lo, hi = 0, n  # lo: known to fail; hi: not excluded by the bound
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _excluded(knob, params, mid):
            lo = mid
        else:
            hi = mid
    reason = {lo: "proven" if lo > 0 else job.request_failure}
    if lo > 0:
        say(f"the bound excludes {_fmt(knob, vals[lo])}; planning {_fmt(knob, vals[n])}")
    # 2. the most generous value; 3. bisection. A complete plan's own programme hints at
    # the least value it needs: that value is planned next (and verified only by a plan
    # made at it, so that the user's own run of the planner reproduces it)
    best: tuple[int, Plan] | None = None
    probe = n
    while plans < job.max_plans and time.time() <= job.deadline:
        plan = _attempt(knob, params, probe)
        plans += 1
        if plan is None:
            say(f"{_fmt(knob, vals[probe])}: no complete plan")
            reason[probe] = "planned"
            lo = max(lo, probe)
            if best is None:
                break  # even the most generous value fails: the knob alone does not help
        else:
            say(f"{_fmt(knob, vals[probe])}: complete ({plan.duration_min:g} min)")
            best = (probe, plan)
        hi_idx = best[0] if best is not None else n
        if hi_idx - lo <= 1:
            break
        # lo >= (first value the bound leaves open) - 1: the probe is never excluded
        probe = (lo + hi_idx) // 2
        hint = knob.needed(plan) if plan is not None else -1
        if lo < hint < probe and plan is not None and _meets(plan, knob, hint, params):
            probe = hint  # a longer jump than bisection, likely to succeed
    if best is None:
        return done(
            NOT_FOUND,
            failing_value=vals[lo],
            failing_reason=reason.get(lo, "planned"),
            bound_min=bound_0,
        )
    j, plan = best
    return done(
        VERIFIED,
        plan=plan,
        value=vals[j],
        failing_value=vals[lo],
        failing_reason=reason.get(lo, "planned"),
        adjacent=j - lo == 1,
        changes=knob.changes(j),
        plan_duration_min=plan.duration_min,
        plan_steps=plan.steps,
        bound_min=_bound(knob, params, j),
    )


# ---------------------------------------------------------------------------------------
# words
# ---------------------------------------------------------------------------------------
_LABELS = {
    "duration": "duration",
    "floor": "chamber floor",
    "ceiling": "chamber ceiling",
    "rates": "chamber rates",
    "levels": "levels",
}


def _fmt(knob: _Knob, v: float) -> str:
    if knob.name == "duration":
        return f"{v:g} min"
    if knob.name in ("floor", "ceiling"):
        return f"{v:g} °C"
    if knob.name == "rates":
        lim = knob.limits
        return (
            f"{lim.rate_min_c_per_min * v:.2f} / +{lim.rate_max_c_per_min * v:.2f} °C/min (x{v:g})"
        )
    return f"{int(v)} levels"


def _line(knob: _Knob, a: KnobAdvice, notes: Sequence[str]) -> str:
    label = _LABELS[knob.name]
    vals = knob.values
    fail = ""
    if a.failing_value is not None:
        why = {
            "proven": "cannot (proven by the lower bound)",
            "planned": "gave no complete plan (schedsyn's search; not a proof)",
        }.get(a.failing_reason, "")
        fail = f"; {_fmt(knob, a.failing_value)} {why}"
    if a.status == VERIFIED:
        assert a.value is not None
        head = {
            "duration": f"a complete plan exists within {_fmt(knob, a.value)}",
            "floor": f"a chamber floor of {_fmt(knob, a.value)} would do",
            "ceiling": f"a chamber ceiling of {_fmt(knob, a.value)} would do",
            "rates": f"chamber rates of {_fmt(knob, a.value)} would do",
            "levels": f"{int(a.value)} levels per bin would do",
        }[knob.name]
        text = (
            f"{label}: {head}: verified by a complete plan ({a.plan_duration_min:g} min, "
            f"{a.plan_steps} steps){fail}"
        )
        if knob.name == "duration" and a.bound_min is not None and math.isfinite(a.bound_min):
            text = (
                f"{label}: needs at least {a.bound_min:.0f} min (proven); " + text.split(": ", 1)[1]
            )
        if not a.adjacent:
            text += " (search stopped at its budget: a smaller change may also do)"
        return text
    if a.status == PROVEN_IMPOSSIBLE:
        bound = a.bound_min if a.bound_min is not None else math.inf
        why = (
            "some bin cannot be crossed at all"
            if not math.isfinite(bound)
            else f"the lower bound stays at {bound:.0f} min, above the limit"
        )
        return f"{label}: not even {_fmt(knob, vals[-1])} makes it feasible (proven: {why})"
    if a.status == NOT_BINDING:
        return (
            f"{label}: does not bind here (moving it to {_fmt(knob, vals[-1])} changes "
            "neither the lower bound nor the notes)"
        )
    if a.status == NOT_FOUND:
        if a.plans == 0:
            return f"{label}: not searched (time budget used up)"
        return (
            f"{label}: schedsyn found no complete plan up to {_fmt(knob, vals[-1])} "
            f"within {a.plans} plan(s) (the lower bound does not exclude it)"
        )
    return f"{label}: nothing to search"


# ---------------------------------------------------------------------------------------
def advise(
    spec: ExperimentSpec,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    plan: Plan | None = None,
    assume_incomplete: bool = False,
    settings: AdviceSettings | None = None,
    backend: Any = "local",
    workers: int | None = None,
    progress: Callable[[str], None] | None = None,
) -> Advice:
    """What would meet a request that is not planned complete (see the module doc).

    Parameters
    ----------
    spec, params, limits
        The request (nominal model; robust boxes and augmented models are not searched).
    plan : Plan, optional
        The request's plan, if made already (else it is planned first; a complete plan
        means nothing needs to change).
    assume_incomplete : bool
        The request is known not to plan complete (e.g. it raised
        :class:`InfeasiblePlanError`): do not plan it again.
    settings : AdviceSettings, optional
        Knobs, grids, search ranges and budgets.
    backend, workers
        Where the knobs are searched in parallel (:func:`schedsyn.sweep.run_map`:
        ``"local"`` process pool, ``"serial"``, a Dask address).
    progress : callable(str), optional
        Short progress messages (must be picklable for the ``"local"`` backend).

    Returns
    -------
    Advice
        One :class:`KnobAdvice` per knob, each with its line in words.
    """
    from .sweep import run_map

    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    settings = AdviceSettings() if settings is None else settings
    tic = time.perf_counter()
    deadline = time.time() + settings.time_budget_s
    bound = duration_lower_bound(spec, params, limits).lower_bound_min
    if plan is None and not assume_incomplete and bound <= limits.duration_max_min:
        try:  # is the request itself complete? (a graded plan for fewer levels is not)
            plan = plan_experiment(spec, params, limits, graded=False)
        except InfeasiblePlanError:
            plan = None
    if plan is not None and plan.complete:
        return Advice(spec.name, True, bound, (), time.perf_counter() - tic)
    failure = "proven" if bound > limits.duration_max_min else "planned"
    notes = tuple(explain_shortfall(spec, params, limits))
    jobs = [
        _Job(k, params, deadline, settings.max_plans, failure, notes)
        for k in _knobs(spec, limits, settings).values()
    ]
    items = run_map(
        partial(_search, progress=progress),
        jobs,
        backend,
        workers=workers,
        progress=False,
    )
    return Advice(spec.name, False, bound, tuple(items), time.perf_counter() - tic)
