"""Stage 7: the plan and its independent check.

A :class:`Plan` is judged only on its exported step table (whole minutes, 0.1 degC, what
the operator types), re-simulated densely every 0.1 min by :func:`check_programme` and
scored by :mod:`schedsyn.coverage` -- never on the optimiser's variables. Where that count
is close to changing, the check also samples every 0.02 min and keeps the worse of the
two, so that a plan whose levels sit right at ``delta`` apart is not claimed complete on
the strength of one sampling (another checker, sampling otherwise, would count a level
fewer).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..coverage import CoverageReport, coverage_report, passes
from ..errors import ParameterError
from ..model import LinearThermalModel
from ..params import Limits, ThermalParams
from ..programme import Programme
from ..simulate import simulate
from .request import ExperimentSpec

#: Sampling of the independent check, min.
CHECK_DT_MIN = 0.1
#: The check's second, finer sampling, min: the worse count of the two is kept. Pass
#: means move by a few 1e-4 degC/min between samplings, enough to flip two levels planned
#: exactly ``delta`` apart (w1-slow-chamber-720: 0.0504 at 0.1 min, 0.0500 at 0.05 min).
FINE_CHECK_DT_MIN = 0.02
#: The fine sampling runs only where the coarse count is that close to changing: levels
#: within this much of ``delta`` apart, degC/min, or passes shorter than this many samples.
SAMPLING_TOL_C_PER_MIN = 0.002
SHORT_PASS_SAMPLES = 5
#: The level separation every plan also reports coverage at, degC/min.
REPORT_DELTA_C_PER_MIN = 0.1
#: Slack of the device-limit check, degC (floating point only).
DEVICE_TOL_C = 1e-6


@dataclass(frozen=True, slots=True)
class Plan:
    """A planned experiment, checked on its exported (rounded) step table.

    ``coverage`` and ``coverage_0p1`` come from an independent dense re-simulation of
    ``programme`` (what the operator types), never from the optimiser's variables; for a
    robust plan they are the worst of its design scenarios. ``lp`` holds what the LP
    solves did (:class:`~.lp.LpStats`): counts of optimal, inaccurate, infeasible and
    failed solves.
    """

    spec: ExperimentSpec
    params: ThermalParams
    limits: Limits
    programme: Programme
    coverage: CoverageReport
    coverage_0p1: CoverageReport
    complete: bool
    status: str
    solve_s: float
    margin_g_c_per_min: float
    margin_t_c: float
    lp: dict[str, Any]
    problem_size: dict
    scenarios: tuple[ThermalParams, ...]
    violations: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())
    t_min_c: float = float("nan")
    t_max_c: float = float("nan")
    box_check: dict | None = None
    #: a continuation: the minute from which the rest of the run was planned
    continued_from_min: float | None = None
    #: proven lower bound on the duration of any complete plan of the request, min
    #: (:mod:`.bound`; None where the proof does not apply: augmented models, continuations)
    duration_lower_bound_min: float | None = None
    #: robust plans: coverage at the nominal point (``params``); ``coverage`` is the worst
    #: of the design scenarios, ``box_check`` the dense check over the whole box
    coverage_nominal: CoverageReport | None = None
    #: robust plans: which fallback was planned ("inner half", "inner quarter", "nominal
    #: point") when no programme fitted the whole box; None when it did
    robust_fallback: str | None = None
    #: fewer levels than asked were planned because the target could not be met (graded
    #: partial plan): the level count every bin was planned for
    levels_planned: int | None = None
    #: ``objective = "informative"``: what the extra time bought (:mod:`.informative`):
    #: shortest plan's duration, price in minutes, information gain, D-efficiencies
    informative: dict | None = None

    @property
    def complete_plan_proven_impossible(self) -> bool | None:
        """The proven lower bound exceeds the budget (or is infinite): no complete plan
        exists. None where the proof does not apply."""
        if self.duration_lower_bound_min is None:
            return None
        return bool(self.duration_lower_bound_min > self.limits.duration_max_min)

    @property
    def gap_to_bound_min(self) -> float | None:
        """How much longer than the proven lower bound this plan is, min."""
        if self.duration_lower_bound_min is None:
            return None
        return self.duration_min - self.duration_lower_bound_min

    @property
    def duration_min(self) -> float:
        return self.programme.total_min

    @property
    def steps(self) -> int:
        return self.programme.n_segments

    @property
    def n_lp(self) -> int:
        """LP solves of this plan (search, fallbacks, polish)."""
        return int(self.lp["lp_solves"])

    def to_frame(self) -> pd.DataFrame:
        """The step table."""
        return self.programme.to_frame()

    def to_summary_dict(self) -> dict:
        return {
            "experiment": self.spec.name,
            "working_min_c": self.spec.working_lo_c,
            "working_max_c": self.spec.working_hi_c,
            "duration_min": self.duration_min,
            "steps": self.steps,
            "coverage": self.coverage.coverage,
            "min_levels": self.coverage.min_levels,
            "coverage_delta_0p1": self.coverage_0p1.coverage,
            "complete": self.complete,
            "margin_g_c_per_min": self.margin_g_c_per_min,
            "margin_t_c": self.margin_t_c,
            "solve_s": self.solve_s,
            "duration_lower_bound_min": self.duration_lower_bound_min,
            "gap_to_bound_min": self.gap_to_bound_min,
            # objective "informative": minutes over the shortest plan, information factor
            "informative_price_min": (self.informative or {}).get("price_min"),
            "information_factor": (self.informative or {}).get("information_factor"),
        }

    def to_json_dict(self) -> dict:
        return {
            "experiment": self.spec.name,
            "tau_s": self.params.tau_s,
            "dt0_c": self.params.dt0_c,
            "spec": self.spec.to_dict(),
            "limits": self.limits.to_dict(),
            "robust_scenarios": [p.to_dict() for p in self.scenarios]
            if len(self.scenarios) > 1
            else [],
            "status": self.status,
            "complete": self.complete,
            "coverage": self.coverage.coverage,
            "coverage_delta_0p1": self.coverage_0p1.coverage,
            "min_levels": self.coverage.min_levels,
            "short_bins": [list(b) for b in self.coverage.short_bins()],
            "duration_min": self.duration_min,
            "steps": self.steps,
            "device_min_c": self.t_min_c,
            "device_max_c": self.t_max_c,
            "margin_g_c_per_min": self.margin_g_c_per_min,
            "margin_t_c": self.margin_t_c,
            "solve_s": self.solve_s,
            "lp_solves": self.n_lp,
            "lp": self.lp,
            "problem_size": self.problem_size,
            "solver": "Clarabel (LP; HiGHS when Clarabel fails), whole-programme LPs via cvxpy",
            "violations": list(self.violations),
            "notes": list(self.notes),
            "robust_box_check": self.box_check,
            "continued_from_min": self.continued_from_min,
            # null where the proof does not apply; an infinite bound (some bin cannot be
            # crossed at all) is null too (JSON has no infinity): the next field tells
            "duration_lower_bound_min": self.duration_lower_bound_min,
            "gap_to_bound_min": self.gap_to_bound_min,
            "complete_plan_proven_impossible": self.complete_plan_proven_impossible,
            "coverage_nominal": (
                None if self.coverage_nominal is None else self.coverage_nominal.coverage
            ),
            "min_levels_nominal": (
                None if self.coverage_nominal is None else self.coverage_nominal.min_levels
            ),
            "coverage_worst_design_scenario": (
                self.coverage.coverage if len(self.scenarios) > 1 else None
            ),
            "robust_fallback": self.robust_fallback,
            "levels_planned": self.levels_planned,
            "informative": self.informative,
        }


def _sampling_sensitive(traj, grid, spec: ExperimentSpec, rep: CoverageReport) -> bool:
    """Whether another sampling could count fewer levels than ``rep``: a bin's count
    drops when its levels must be ``SAMPLING_TOL_C_PER_MIN`` further apart (pass means
    move by a few 1e-4 degC/min between samplings), or a pass in the region lasts fewer
    than ``SHORT_PASS_SAMPLES`` samples (a graze, whose mean depends on where the samples
    fall). The coverage at 0.1 degC/min (a report, not the claim) does not trigger it."""
    wider = coverage_report(
        traj.t_c,
        traj.g_c_per_min,
        grid,
        spec.levels_required,
        spec.delta_c_per_min + SAMPLING_TOL_C_PER_MIN,
    )
    if np.any(wider.levels < rep.levels):
        return True
    _, _, first, last = passes(traj.t_c, traj.g_c_per_min, grid)
    return bool(np.any(last - first + 1 < SHORT_PASS_SAMPLES))


def _worse(a: CoverageReport, b: CoverageReport) -> bool:
    """``a`` counts fewer: lower coverage, then fewer levels in the weakest bin, then in all."""
    return (a.coverage, a.min_levels, int(a.levels.sum())) < (
        b.coverage,
        b.min_levels,
        int(b.levels.sum()),
    )


def device_limit_problem(t_lo: float, t_hi: float, limits: Limits, where: str = "") -> str:
    """The violation line of a device reaching ``t_lo .. t_hi`` past its limits, with
    the excess and enough digits to see it: rounded to 0.01 °C, a device 0.0009 °C below
    4.7 °C read "reaches 4.70 .. 9.28 °C, outside its limits 4.7 .. 9.3 °C" (red team)."""
    over = [
        (ex, side)
        for ex, side in (
            (limits.device_min_c - t_lo, f"below the lower limit {limits.device_min_c:g} °C"),
            (t_hi - limits.device_max_c, f"above the upper limit {limits.device_max_c:g} °C"),
        )
        if ex > DEVICE_TOL_C
    ]
    smallest = min((ex for ex, _ in over), default=1.0)
    digits = min(6, max(2, 1 - math.floor(math.log10(smallest))))
    excess = "; ".join(f"{ex:.{digits}f} °C {side}" for ex, side in over)
    return (
        f"the device reaches {t_lo:.{digits}f} .. {t_hi:.{digits}f} °C{where}, outside its "
        f"limits {limits.device_min_c:g} .. {limits.device_max_c:g} °C ({excess})"
    )


def check_programme(
    programme: Programme,
    spec: ExperimentSpec,
    limits: Limits,
    scenarios: Sequence[ThermalParams],
    model: LinearThermalModel | None = None,
) -> tuple[CoverageReport, CoverageReport, list[str], float, float]:
    """Independent check of a step table: dense simulation for every scenario.

    Sampled every ``CHECK_DT_MIN`` (0.1 min) and, where that count is close to changing
    (:func:`_sampling_sensitive`), every ``FINE_CHECK_DT_MIN`` (0.02 min); the worse count
    of the two (and of the scenarios) is kept.

    Returns the worst-scenario coverage at ``delta`` and at 0.1 degC/min, every limit the
    programme breaks, and the device's min/max temperature. ``model`` replaces the
    first-order lag of a single scenario (an augmented model).
    """
    if not scenarios:
        raise ParameterError("check_programme needs at least one scenario")
    grid = spec.grid
    worst: CoverageReport | None = None
    worst01: CoverageReport | None = None
    problems = list(programme.violations(limits))
    t_lo, t_hi = np.inf, -np.inf
    for p in scenarios:
        for dt_min in (CHECK_DT_MIN, FINE_CHECK_DT_MIN):
            traj = simulate(
                programme,
                p,
                model=model if len(scenarios) == 1 else None,
                dt_min=dt_min,
                t0_c=limits.t_init_c,
            )
            rep = coverage_report(
                traj.t_c, traj.g_c_per_min, grid, spec.levels_required, spec.delta_c_per_min
            )
            rep01 = coverage_report(
                traj.t_c, traj.g_c_per_min, grid, spec.levels_required, REPORT_DELTA_C_PER_MIN
            )
            if worst is None or _worse(rep, worst):
                worst = rep
            if worst01 is None or _worse(rep01, worst01):
                worst01 = rep01
            t_lo, t_hi = min(t_lo, traj.t_c.min()), max(t_hi, traj.t_c.max())
            if not _sampling_sensitive(traj, grid, spec, rep):
                break  # the finer sampling could not count fewer: skip it (8x the cost)
    if t_lo < limits.device_min_c - DEVICE_TOL_C or t_hi > limits.device_max_c + DEVICE_TOL_C:
        where = (
            ""
            if len(scenarios) == 1
            else f" (over the {len(scenarios)} design scenarios of the robust box)"
        )
        problems.append(device_limit_problem(t_lo, t_hi, limits, where))
    assert worst is not None and worst01 is not None  # scenarios is not empty
    return worst, worst01, problems, float(t_lo), float(t_hi)


def step_limit_problems(
    programme: Programme, spec: ExperimentSpec, what: str = "the step table"
) -> list[str]:
    """What of ``max_steps`` and ``min_step_min`` the exported table (``what``) breaks."""
    problems = []
    if programme.n_segments > spec.max_steps:
        problems.append(
            f"{what} has {programme.n_segments} steps, more than max_steps = {spec.max_steps}"
        )
    short_steps = int(np.sum(programme.durations_min < spec.min_step_min - 1e-9))
    if short_steps:
        problems.append(
            f"{short_steps} step(s) of {what} are shorter than min_step_min = "
            f"{spec.min_step_min:g} min"
        )
    return problems
