"""The fewest experiments that cover a temperature range, each verified by a complete plan.

The paper splits -50 .. +60 degC into four working regions by hand. :func:`split_range`
does it by search: experiments with consecutive working regions ``[x_0, x_1], [x_1, x_2],
...`` (whole degrees, no gap, no overlap), each as wide as a complete plan within the
budget allows, each with its approximation region (the working region widened by
``approx_margin_c``, 10 degC as in the paper, but not beyond the ends of the range).

**Proven minimum.** :func:`~schedsyn.planner.duration_lower_bound` screens in under a
second: if the bound of ``[a, b]`` exceeds the duration limit, no complete plan exists for
``[a, b]`` nor for any region containing it (a plan covering the larger region covers the
smaller one). So from a point ``x`` no experiment whose region contains ``x`` reaches past
``R(x)``, the last ``b`` before the bound's first excluded one. Greedily jumping ``x ->
R(x)`` from the cold end counts the fewest experiments any split needs (an exchange
argument: the ``i``-th jump is never behind the ``i``-th region of any split). The
bound's one assumption holds for the planner's plans: sweeps cross the whole region.

**Verified split.** From the cold end, each experiment takes the widest working region
that schedsyn plans complete: its upper edge is searched between the previous success
and ``R(x)`` by bisection (several widths at a time on the local cores), then the next
experiment starts there. With feasibility monotone in the width (true of complete plans,
nearly so of the planner) this greedy needs the fewest experiments; when its count equals
the proven minimum it is optimal, else the gap is reported.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import pandas as pd

from .errors import InfeasiblePlanError, ParameterError
from .params import Limits, ThermalParams
from .planner import ExperimentSpec, Plan, check_request, duration_lower_bound, plan_experiment

#: The settings of :class:`ExperimentSpec` a split passes on to every experiment.
SETTING_KEYS = tuple(
    f.name
    for f in dataclasses.fields(ExperimentSpec)
    if f.name not in ("name", "working_lo_c", "working_hi_c", "approx_lo_c", "approx_hi_c")
)


@dataclass(frozen=True, slots=True)
class SplitSettings:
    """How :func:`split_range` searches.

    Parameters
    ----------
    approx_margin_c : float
        The approximation region extends the working region by this on each side,
        degC, in [0, 50] (paper: 10), but never beyond the ends of the range.
    max_experiments : int, optional
        Stop once this many experiments do not cover the range (saves planning when the
        question is "do N experiments do?").
    max_plans : int
        Most plans over the whole search, >= 1 (default 60).
    time_budget_s : float
        Wall time, s, > 0 (default 7200); checked before each round of plans.
    name_prefix : str
        Experiments are named ``<prefix>1, <prefix>2, ...`` (default ``"S"``).
    """

    approx_margin_c: float = 10.0
    max_experiments: int | None = None
    max_plans: int = 60
    time_budget_s: float = 7200.0
    name_prefix: str = "S"

    def __post_init__(self) -> None:
        m = self.approx_margin_c
        if isinstance(m, bool) or not isinstance(m, int | float) or not 0 <= m <= 50:
            raise ParameterError(f"approx_margin_c must be in 0..50 °C, got {m!r}")
        for name in ("max_plans",):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ParameterError(f"{name} must be a whole number >= 1, got {v!r}")
        n = self.max_experiments
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise ParameterError(f"max_experiments must be a whole number >= 1, got {n!r}")
        t = self.time_budget_s
        if isinstance(t, bool) or not isinstance(t, int | float) or not (0 < t < math.inf):
            raise ParameterError(f"time_budget_s must be a finite number > 0 s, got {t!r}")
        p = self.name_prefix
        if not isinstance(p, str) or not p or any(c in p for c in "/\\ "):
            raise ParameterError(
                f"name_prefix must be a non-empty name without '/', '\\\\' or blanks, got {p!r}"
            )


@dataclass(frozen=True, slots=True)
class SplitExperiment:
    """One experiment of a split: its request, its complete plan, the bound's reach."""

    spec: ExperimentSpec
    plan: Plan
    reach_bound_c: float  # the widest upper edge the bound leaves open from its start

    def to_row(self) -> dict[str, Any]:
        s, p = self.spec, self.plan
        return {
            "experiment": s.name,
            "working_lo_c": s.working_lo_c,
            "working_hi_c": s.working_hi_c,
            "approx_lo_c": s.approx_lo_c,
            "approx_hi_c": s.approx_hi_c,
            "width_c": s.working_hi_c - s.working_lo_c,
            "complete": p.complete,
            "duration_min": p.duration_min,
            "steps": p.steps,
            "duration_lower_bound_min": p.duration_lower_bound_min,
            "reach_bound_c": self.reach_bound_c,
        }


SPLIT_COLUMNS = (
    "experiment",
    "working_lo_c",
    "working_hi_c",
    "approx_lo_c",
    "approx_hi_c",
    "width_c",
    "complete",
    "duration_min",
    "steps",
    "duration_lower_bound_min",
    "reach_bound_c",
)


@dataclass(frozen=True, slots=True)
class SplitResult:
    """The experiments found, in order from the cold end, and what is proven.

    ``covered`` says whether they cover the whole range (each complete by the planner's
    independent check); ``covered_to_c`` how far they reach. ``min_experiments`` is the
    proven fewest any split needs (``None`` if some bin cannot be covered at all, with
    ``uncoverable_bin_c`` its lower edge). ``optimal``: the count found equals it.
    """

    range_c: tuple[float, float]
    experiments: tuple[SplitExperiment, ...]
    covered: bool
    covered_to_c: float
    min_experiments: int | None
    uncoverable_bin_c: float | None
    proven_reaches: tuple[tuple[float, float], ...]
    params: ThermalParams
    limits: Limits
    settings: Mapping[str, Any]
    plans: int
    wall_s: float
    notes: tuple[str, ...] = field(default=())

    @property
    def optimal(self) -> bool:
        return self.covered and self.min_experiments == len(self.experiments)

    def to_frame(self) -> pd.DataFrame:
        """One row per experiment."""
        return pd.DataFrame([e.to_row() for e in self.experiments], columns=list(SPLIT_COLUMNS))

    def lines(self) -> list[str]:
        """The answer in words."""
        lo, hi = self.range_c
        n = len(self.experiments)
        out = []
        if self.min_experiments is None:
            out.append(
                f"no split can cover [{lo:g}, {hi:g}] °C: the bin from "
                f"{self.uncoverable_bin_c:g} °C cannot be covered by any experiment within "
                f"{self.limits.duration_max_min:g} min (proven by the lower bound)"
            )
        else:
            out.append(
                f"at least {self.min_experiments} experiment(s) are needed for [{lo:g}, "
                f"{hi:g}] °C within {self.limits.duration_max_min:g} min each (proven by the "
                "lower bound)"
            )
        if self.covered:
            verdict = (
                "the fewest possible" if self.optimal else "the fewest schedsyn's greedy found"
            )
            out.append(f"{n} experiment(s) cover it, each verified by a complete plan ({verdict}):")
        elif n == 0:  # (not "0 verified experiment(s) reach [-20, -20] °C")
            out.append(
                f"NOT COVERED: no experiment could be verified (no complete plan found) for "
                f"[{lo:g}, {hi:g}] °C, after {self.plans} plan(s) in {self.wall_s:.0f} s:"
            )
        else:
            out.append(
                f"NOT COVERED: {n} verified experiment(s) reach [{lo:g}, {self.covered_to_c:g}] "
                f"of [{lo:g}, {hi:g}] °C:"
            )
        for e in self.experiments:
            s = e.spec
            out.append(
                f"  {s.name}: working [{s.working_lo_c:g}, {s.working_hi_c:g}] °C, "
                f"approximation [{s.approx_lo_c:g}, {s.approx_hi_c:g}] °C, "
                f"{e.plan.duration_min:g} min, {e.plan.steps} steps"
            )
        out += [f"  note: {n}" for n in self.notes]
        return out

    def campaign_toml(self) -> str:
        """A campaign file that plans these experiments again (``schedsyn campaign``)."""
        lines = [
            "# written by schedsyn split: the fewest experiments found for "
            f"[{self.range_c[0]:g}, {self.range_c[1]:g}] °C",
            "",
            "[model]",
            f"tau_s = {_toml(self.params.tau_s)}",
            f"dt0_c = {_toml(self.params.dt0_c)}",
            "",
            "[limits]",
        ]
        lines += [f"{k} = {_toml(v)}" for k, v in self.limits.to_dict().items()]
        lines += ["", "[settings]"]
        lines += [f"{k} = {_toml(v)}" for k, v in self.settings.items()]
        for e in self.experiments:
            s = e.spec
            lines += [
                "",
                "[[experiment]]",
                f'name = "{s.name}"',
                f"working_lo_c = {_toml(s.working_lo_c)}",
                f"working_hi_c = {_toml(s.working_hi_c)}",
                f"approx_lo_c = {_toml(s.approx_lo_c)}",
                f"approx_hi_c = {_toml(s.approx_hi_c)}",
            ]
        return "\n".join(lines) + "\n"


def _toml(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


# ---------------------------------------------------------------------------------------
# the search
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Request:
    lo_c: float
    hi_c: float
    params: ThermalParams
    limits: Limits
    settings: Mapping[str, Any]
    margin_c: float

    def spec(self, a: float, b: float, name: str = "probe") -> ExperimentSpec:
        m = self.margin_c
        return ExperimentSpec(
            name=name,
            working_lo_c=a,
            working_hi_c=b,
            approx_lo_c=max(a - m, self.lo_c),
            approx_hi_c=min(b + m, self.hi_c),
            **self.settings,
        )

    def excluded(self, a: float, b: float) -> bool:
        """The bound proves that no complete plan covers ``[a, b]``."""
        # without the levels' dual: the bisections here assume that a wider region is
        # never less excluded, which the dual's subgradient search does not promise
        bound = duration_lower_bound(self.spec(a, b), self.params, self.limits, tighten=False)
        return bound.lower_bound_min > self.limits.duration_max_min


def _reach(req: _Request, a: float) -> float:
    """Upper bound on how far an experiment containing ``[a, a + 1]`` can reach: the
    last edge before one the bound excludes (``a`` itself if ``[a, a + 1]`` is excluded).
    Bisection finds *an* excluded edge; every edge from it on is excluded too."""
    top = req.hi_c
    if not req.excluded(a, top):
        return top
    if req.excluded(a, a + 1):
        return a
    ok, bad = a + 1, top  # [a, ok] not excluded, [a, bad] excluded
    while bad - ok > 1:
        mid = ok + (bad - ok) // 2
        if req.excluded(a, mid):
            bad = mid
        else:
            ok = mid
    return ok


#: Seconds between the "still planning" lines of one plan of the split.
HEARTBEAT_S = 20.0


class _Heartbeat:
    """Progress of one plan of the split: a line when it starts, then one at most every
    ``HEARTBEAT_S`` while the planner reports (its progress lines) or polls (its ``stop``),
    naming the region, the time so far, the time budget and the planner's last line
    (red team: one line, then nothing for 9 min). Picklable: made in the worker."""

    def __init__(self, progress, a: float, b: float, deadline: float | None) -> None:
        self.progress, self.region, self.deadline = progress, f"[{a:g}, {b:g}] °C", deadline
        self.tic = self.last = time.time()
        self.said = ""
        progress(f"split: planning {self.region}")

    def line(self, now: float) -> str:
        budget = ""
        if self.deadline is not None:
            left = self.deadline - now
            budget = (
                f", {left:.0f} s of the time budget left"
                if left >= 0
                else f", {-left:.0f} s past the time budget (a plan under way is finished)"
            )
        last = f"; last: {self.said}" if self.said else ""
        return f"split: {self.region} still planning, {now - self.tic:.0f} s{budget}{last}"

    def beat(self) -> None:
        now = time.time()
        if now - self.last >= HEARTBEAT_S:
            self.last = now
            self.progress(self.line(now))

    def say(self, msg: str) -> None:
        self.said = msg if len(msg) <= 120 else msg[:117] + "..."
        self.beat()

    def stop(self) -> bool:  # asked before each candidate structure: never stops
        self.beat()
        return False


def _plan_job(
    job: tuple[_Request, float, float] | tuple[_Request, float, float, float | None], progress
) -> tuple[float, Plan | None]:
    req, a, b, *rest = job
    deadline = rest[0] if rest else None
    spec = req.spec(a, b, name=f"[{a:g}, {b:g}]")
    heart = None if progress is None else _Heartbeat(progress, a, b, deadline)
    try:
        # no effort limit: the split asks whether a complete plan exists, so the search
        # for the requested levels runs to its end even where the bound says it is unlikely;
        # not graded: a plan for fewer levels is of no use to it
        plan = plan_experiment(
            spec,
            req.params,
            req.limits,
            effort_s=None,
            graded=False,
            progress=None if heart is None else heart.say,
            stop=None if heart is None else heart.stop,
        )
    except InfeasiblePlanError:
        plan = None
    if progress is not None:
        state = "complete" if plan is not None and plan.complete else "not complete"
        took = "" if heart is None else f" ({time.time() - heart.tic:.0f} s)"
        progress(f"split: [{a:g}, {b:g}] °C {state}{took}")
    return b, plan if plan is not None and plan.complete else None


def _probes(ok: float, bad: float, n: int, widest: bool) -> list[float]:
    """Up to ``n`` upper edges strictly between ``ok`` and ``bad``, evenly spread (the
    widest, ``bad - 1``, among them if ``widest``: it may end the split)."""
    inside = [ok + k for k in range(1, int(round(bad - ok)))]
    if len(inside) <= n:
        return inside
    picks = [inside[round((len(inside) - 1) * (k + 1) / (n + 1))] for k in range(n)]
    if widest:
        picks[-1] = inside[-1]
    return sorted(set(picks))


def split_range(
    lo_c: float,
    hi_c: float,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    spec_settings: Mapping[str, Any] | None = None,
    *,
    settings: SplitSettings | None = None,
    backend: Any = "local",
    workers: int | None = None,
    progress: Callable[[str], None] | None = None,
) -> SplitResult:
    """The fewest experiments covering ``[lo_c, hi_c]`` (see the module doc).

    Parameters
    ----------
    lo_c, hi_c : float
        The range, degC, whole degrees apart (1 degC bins), inside the device limits.
    params, limits
        Model and chamber (default: the paper's); ``limits.duration_max_min`` is each
        experiment's budget.
    spec_settings : mapping, optional
        :class:`ExperimentSpec` settings shared by every experiment (``levels_required``,
        ``delta_c_per_min``, ``segment_min``, ``objective``, ``max_steps``, ...).
    settings : SplitSettings, optional
        Approximation margin, early stop, plan and time budgets, names.
    backend, workers
        Where the widths of one experiment are planned in parallel
        (:func:`schedsyn.sweep.run_map`); ``workers`` widths per round (default: the
        number of cores).
    progress : callable(str), optional
        Short progress messages (picklable for the ``"local"`` backend).

    Returns
    -------
    SplitResult
        ``covered`` is False when the budget ran out, ``max_experiments`` was reached or
        some part of the range cannot be planned complete.
    """
    import os

    from .sweep import run_map

    tic = time.perf_counter()
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    settings = SplitSettings() if settings is None else settings
    spec_settings = dict(spec_settings or {})
    unknown = sorted(set(spec_settings) - set(SETTING_KEYS))
    if unknown:
        raise ParameterError(f"unknown experiment setting(s) {unknown}; allowed: {SETTING_KEYS}")
    for name, v in (("lo_c", lo_c), ("hi_c", hi_c)):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ParameterError(f"the range's {name} must be a finite number, got {v!r}")
    if hi_c <= lo_c:
        raise ParameterError(
            f"the range [{lo_c:g}, {hi_c:g}] °C runs backwards: give the low end first "
            f"(--range {hi_c:g} {lo_c:g})"
        )
    if not hi_c - lo_c >= 1 or abs((hi_c - lo_c) - round(hi_c - lo_c)) > 1e-9:
        raise ParameterError(
            f"the range [{lo_c:g}, {hi_c:g}] °C must span a whole number (>= 1) of degrees"
        )
    lo_c, hi_c = float(lo_c), float(hi_c)
    req = _Request(lo_c, hi_c, params, limits, spec_settings, settings.approx_margin_c)
    check_request(req.spec(lo_c, hi_c), limits)  # the range inside the device limits
    # widths planned per round: one (plain bisection) in this process, else one per core
    n_par = int(workers) if workers else (1 if backend == "serial" else os.cpu_count() or 1)

    def say(msg: str) -> None:
        if progress is not None:
            progress(msg)

    # 1. the proven fewest: greedy jumps x -> R(x)
    min_n, reaches, uncoverable = _proven(req)
    say(
        f"split: at least {min_n} experiment(s) needed (proven)"
        if min_n is not None
        else f"split: the bin from {uncoverable:g} °C cannot be covered (proven)"
    )
    reach_at = dict(reaches)

    # 2. the verified greedy
    deadline = time.time() + settings.time_budget_s
    experiments: list[SplitExperiment] = []
    notes: list[str] = []
    plans = 0
    x = lo_c
    stopped = ""
    while x < hi_c and min_n is not None:
        if settings.max_experiments is not None and len(experiments) >= settings.max_experiments:
            stopped = f"stopped after {settings.max_experiments} experiment(s) (max_experiments)"
            break
        r = reach_at.get(x)
        if r is None:
            r = _reach(req, x)
        if r <= x:
            stopped = f"the bin from {x:g} °C cannot be covered (proven by the lower bound)"
            break
        ok, bad = x, r + 1
        best: Plan | None = None
        first = True
        while bad - ok > 1:
            if plans >= settings.max_plans or time.time() > deadline:
                break
            # the widest width first only where it would end the split (elsewhere the
            # bound's reach is optimistic and its plan slow to fail)
            probes = _probes(ok, bad, min(n_par, settings.max_plans - plans), first and r >= hi_c)
            first = False
            results = run_map(
                partial(_plan_job, progress=progress),
                [(req, x, b, deadline) for b in probes],
                backend,
                workers=min(n_par, len(probes)),
                progress=False,
            )
            plans += len(probes)
            for b, plan in sorted(results, key=lambda bp: bp[0]):
                if plan is not None and b > ok:
                    ok, best = b, plan
            fails = [b for b, plan in results if plan is None and b > ok]
            bad = min([bad, *fails])
        if best is None:
            stopped = (
                f"no complete plan found for any region starting at {x:g} °C"
                if bad - ok <= 1
                else "the plan or time budget ran out"
            )
            break
        name = f"{settings.name_prefix}{len(experiments) + 1}"
        spec = req.spec(x, ok, name=name)
        plan = dataclasses.replace(best, spec=spec)
        experiments.append(SplitExperiment(spec, plan, r))
        say(f"split: {name} = [{x:g}, {ok:g}] °C, {plan.duration_min:g} min")
        if bad - ok > 1:
            notes.append(
                f"{name}: the budget ran out before the widest region from {x:g} °C was "
                f"pinned down (complete at {ok:g}, open up to {bad - 1:g} °C)"
            )
        x = ok
    if stopped:
        notes.append(stopped)
    covered = bool(experiments) and experiments[-1].spec.working_hi_c >= hi_c
    return SplitResult(
        range_c=(lo_c, hi_c),
        experiments=tuple(experiments),
        covered=covered,
        covered_to_c=experiments[-1].spec.working_hi_c if experiments else lo_c,
        min_experiments=min_n,
        uncoverable_bin_c=uncoverable,
        proven_reaches=tuple(reaches),
        params=params,
        limits=limits,
        settings=spec_settings,
        plans=plans,
        wall_s=time.perf_counter() - tic,
        notes=tuple(notes),
    )


def _proven(req: _Request) -> tuple[int | None, tuple[tuple[float, float], ...], float | None]:
    """The greedy jumps ``x -> R(x)`` from the cold end: ``(fewest experiments, jumps,
    lower edge of a bin no experiment can cover)``."""
    reaches = []
    n = 0
    x = req.lo_c
    while x < req.hi_c:
        r = _reach(req, x)
        reaches.append((x, r))
        if r <= x:
            return None, tuple(reaches), x
        n += 1
        x = r
    return n, tuple(reaches), None


def proven_minimum(
    lo_c: float,
    hi_c: float,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    spec_settings: Mapping[str, Any] | None = None,
    approx_margin_c: float = 10.0,
) -> tuple[int | None, tuple[tuple[float, float], ...]]:
    """Only the proven part of :func:`split_range` (no planning, seconds): the fewest
    experiments any split of ``[lo_c, hi_c]`` needs and the greedy's jumps ``(x, R(x))``;
    ``None`` when some bin cannot be covered at all."""
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    req = _Request(
        float(lo_c), float(hi_c), params, limits, dict(spec_settings or {}), approx_margin_c
    )
    check_request(req.spec(req.lo_c, req.hi_c), limits)
    n, reaches, _ = _proven(req)
    return n, reaches
