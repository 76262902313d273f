"""Stage 9: :func:`plan_experiment` -- request in, checked :class:`~.check.Plan` out.

scenarios -> search (robust ladder) -> polish -> round for the operator -> check
    (nothing fits in time: cut the over-long structure, or plan sub-regions, and keep
    the option that covers most of the region)
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..coverage import CoverageReport
from ..errors import InfeasiblePlanError, ParameterError, SolverFailedError
from ..model import FirstOrderLag, LinearThermalModel
from ..params import Limits, ThermalParams
from ..programme import Programme
from .bands import BAND_SAFETY_C_PER_MIN, BAND_WIDTH_C_PER_MIN
from .bound import duration_lower_bound
from .check import Plan, check_programme, step_limit_problems
from .continuation import plan_continuation
from .explain import explain_shortfall
from .informative import L1_WEIGHT_LADDER, informative_rates
from .lp import Context, LpStats, lp_nonzeros_solved, require_solvable
from .physics import LIMIT_FRACTION
from .polish import honour_step_limits, merge_small_changes, polish, step_runs
from .ramps import EVALS_PER_LEVEL, box_spread_proof, ramp_search
from .request import Continuation, ExperimentSpec, check_request, check_start_excursion
from .robust import box_note, box_scenarios, held_note, search_robust, verify_robust
from .search import Search, Structure, split_note, subregions, synthesise, truncate

#: Rates closer than this are one step of the exported table, degC/min.
MERGE_TOL_C_PER_MIN = 1e-6
#: Re-polishes with tightened device limits after rounding pushed the device past one.
MAX_REPOLISH = 2
#: Extra tightening of the device limits per re-polish, degC, beyond the excess found.
REPOLISH_PAD_C = 0.05
#: Longest decision segment the planner uses, min (ExperimentSpec allows up to 30).
MAX_SEGMENT_MIN = 30
#: Segment lengths (multiples of the requested one) tried when merging steps cannot meet
#: max_steps.
COARSER_FACTORS = (2, 3, 5, 10)
#: Effort after which a plan's optional searches stop (the partial-coverage fallbacks,
#: the graded search for fewer levels; see :func:`plan_experiment`), in reference seconds
#: (:data:`LP_NONZEROS_PER_EFFORT_S`).
EFFORT_S = 45.0
#: The fewest LP solves the timetable stage gets under a small effort limit (its first
#: candidate's SLP takes 10-60).
MIN_TIMETABLE_LPS = 50
#: Effort is counted in LP work, not time: one reference second is this many
#: constraint-matrix nonzeros solved (:func:`.lp.lp_nonzeros_solved`). Measured on the
#: 2-core machine of 2026-11-25, one core: 345 000 per CPU second planning W1 for 8
#: levels (540-min LPs), 450 000 for [-10, 0] degC at 10 levels in 240 min. Probes that
#: the rate limits prove infeasible count as solved (:func:`.lp.bounds_prove_infeasible`),
#: so the cuts stayed where they were while the work got cheaper: 0.55-0.99 million per
#: CPU second since (W2, W4: ``scripts/bench_lp.py``).
LP_NONZEROS_PER_EFFORT_S = 400_000
#: Device excess (degC) below which rounding is not worth a re-polish.
EXCESS_TOL_C = 1e-6
#: A step that changes the setpoint by less than this is merged into a neighbour when the
#: plan stays as good (an operator types fewer, more meaningful steps), degC.
MIN_STEP_CHANGE_C = 0.5
#: What the refusal of a request that no programme covers any part of advises.
NO_PLAN_ADVICE = "Lengthen the duration, narrow the region or lower the level count."


@dataclass(slots=True)
class _Effort:
    """The effort limit of one :func:`plan_experiment` call: ``spent()`` says whether an
    optional search should stop -- the caller's ``stop``, or ``effort_s`` reference
    seconds of LP work (:data:`LP_NONZEROS_PER_EFFORT_S`) since ``work_tic`` once some
    answer is in hand (``answered``: a complete plan for fewer levels), so the limit never
    leaves the user with nothing -- and remembers that it said so, for the plan's notes.

    Work, not a clock: CPU time grows when another process shares the core (W4 plans in
    42 s alone and 70 s beside another plan on a 2-core machine), so a CPU-time limit cut
    the same search at different places under different loads, and the same request got
    different answers."""

    work_tic: int
    effort_s: float | None
    stop: Callable[[], bool] | None
    #: a search was stopped, by the effort limit (``hit_limit``) or the caller's ``stop``
    hit: bool = False
    hit_limit: bool = False
    answered: bool = False
    #: whether a search that finds no complete plan looks for sub-regions that fit (its
    #: partial plan, a last resort); the graded search's later counts do not
    #: (:func:`_fewer_levels`)
    partials: bool = True
    #: what the optional searches that the limit stops are
    what: str = "some fewer-level counts or sub-regions were not searched"
    #: the call's tables will end with a soak (plan_experiment's ``end_soak``): carried
    #: here so that every plan made on the way (fewer levels, sub-regions, longer
    #: segments) honours it too
    end_soak: bool = False

    def spent(self) -> bool:
        by_caller = self.stop is not None and self.stop()
        by_limit = (
            self.answered
            and self.effort_s is not None
            and lp_nonzeros_solved() - self.work_tic > self.effort_s * LP_NONZEROS_PER_EFFORT_S
        )
        self.hit_limit = self.hit_limit or by_limit
        self.hit = self.hit or by_caller or by_limit
        return by_caller or by_limit

    def note(self) -> str:
        """What stopped the optional searches, in the limit's own unit (red team: "stopped
        at its effort limit (effort_s = 45 s)" read as seconds after a 6-s plan: the limit
        counts LP work, and probes the bounds prove infeasible count as solved at no cost
        in time, so 45 reference seconds can pass in a few seconds of CPU)."""
        if not self.hit_limit:
            return "the search for other plans was stopped by the caller"
        assert self.effort_s is not None  # (hit_limit needs a limit)
        nonzeros = self.effort_s * LP_NONZEROS_PER_EFFORT_S
        return (
            f"the search for other plans stopped at its effort limit, effort_s = "
            f"{self.effort_s:g} reference seconds of LP work ({nonzeros / 1e6:.3g} million "
            "constraint-matrix nonzeros solved, counting the probes the bounds prove "
            "infeasible as solved: not wall or CPU time, which can be far less): "
            f"{self.what}; allow more with effort_s (CLI --effort-s, "
            "0 = no limit)"
        )


@dataclass(slots=True)
class _Candidate:
    """Rates of one programme the planner may return, with its margins and origin."""

    u: np.ndarray
    margin_g: float
    margin_t: float
    search: Search
    ctx: Context
    note: str = ""


def operator_programme(u: np.ndarray, spec: ExperimentSpec, limits: Limits) -> Programme:
    """What the operator types: equal rates merged, whole minutes, 0.1 degC."""
    raw = Programme(np.full(u.size, float(spec.segment_min)), u, limits.start_c)
    return raw.merged(rate_tol_c_per_min=MERGE_TOL_C_PER_MIN).rounded(limits)


def _device_excess(limits: Limits, t_lo: float, t_hi: float) -> float:
    return max(limits.device_min_c - t_lo, t_hi - limits.device_max_c)


def _cut_at_limit(search: Search, spec: ExperimentSpec, limits: Limits) -> Structure | None:
    """The search's over-long structure cut to end within the time limit (None: it had
    none, or no cut returns to the end temperature in time)."""
    if search.overrun is None:
        return None
    max_seg = int(limits.duration_max_min // spec.segment_min)
    return truncate(search.ctx, search.overrun, max_seg)


def _fallback(
    spec: ExperimentSpec,
    limits: Limits,
    params_list: list[ThermalParams],
    models: Sequence[LinearThermalModel],
    model: LinearThermalModel | None,
    search: Search,
    progress: Callable[[str], None] | None,
    stats: LpStats,
    effort: _Effort,
) -> _Candidate:
    """Nothing fits in time: the over-long structure cut at the limit, or the widest
    sub-regions that fit; whichever covers most of the region (by the dense check)."""
    options: list[_Candidate] = []
    structure = _cut_at_limit(search, spec, limits)
    if search.overrun is not None and structure is not None:
        options.append(
            _Candidate(
                structure.u,
                0.0,
                0.0,
                search,
                search.ctx,
                f"all {spec.levels_required} sweeps need "
                f"{search.overrun.n_seg * spec.segment_min:g} min, more than the limit "
                f"{limits.duration_max_min:g} min; the programme is cut at the limit",
            )
        )
    elif search.overrun is not None:
        search.reasons.append(
            "the over-long programme cannot be cut to return to the end temperature in time"
        )
    checked: dict[int, float] = {}

    def verified(option: _Candidate) -> float:
        key = id(option.u)
        if key not in checked:
            prog = operator_programme(option.u, spec, limits)
            checked[key] = check_programme(prog, spec, limits, params_list, model)[0].coverage
        return checked[key]

    def full_coverage_found() -> bool:
        return any(verified(o) >= 1.0 for o in options[-1:])

    for sub_spec, sub_search in subregions(
        spec,
        params_list,
        limits,
        models,
        progress,
        stats,
        stop=lambda: full_coverage_found() or effort.spent() or not effort.partials,
        deep=lambda: not options,  # nothing else covers any part of the region
    ):
        assert sub_search.best is not None  # subregions yields only what fits
        u_sub, mg, mt = polish(sub_search.ctx, sub_search.best[0])
        options.append(
            _Candidate(
                u_sub,
                mg,
                mt,
                sub_search,
                sub_search.ctx,
                f"sweeps designed for the sub-region [{sub_spec.working_lo_c:g}, "
                f"{sub_spec.working_hi_c:g}] °C (the full region did not fit in time)",
            )
        )
    if not options:
        require_solvable(stats, spec.name)
        reasons = "; ".join(list(dict.fromkeys(search.reasons))[:2])  # each once
        raise InfeasiblePlanError(
            f"{spec.name}: no programme covers any part of [{spec.working_lo_c:g}, "
            f"{spec.working_hi_c:g}] °C with {spec.levels_required} gradient levels "
            f"{spec.delta_c_per_min:g} °C/min apart within {limits.duration_max_min:g} min "
            f"({reasons}); best reachable coverage is 0%. {NO_PLAN_ADVICE}",
            best_coverage=0.0,
        )
    return max(options, key=verified)


def _shape_steps(
    spec: ExperimentSpec,
    limits: Limits,
    params_list: list[ThermalParams],
    model: LinearThermalModel | None,
    ctx: Context,
    structure: Structure,
    chosen: _Candidate,
    cov: CoverageReport,
):
    """Merge steps: to meet ``max_steps`` and ``min_step_min``, then steps that change the
    setpoint by less than ``MIN_STEP_CHANGE_C`` (for the operator). A merge is kept only
    when the rounded table, re-checked, covers at least as much, stays inside the device
    limits and meets the step limits. Returns the new table's check, or None (unchanged).
    """
    min_seg = max(1, math.ceil(spec.min_step_min / spec.segment_min - 1e-9))
    result = None

    def run(u: np.ndarray):
        prog = operator_programme(u, spec, limits)
        return prog, check_programme(prog, spec, limits, params_list, model)

    def accept(u: np.ndarray) -> bool:
        _, c = run(u)
        steps_ok = c[0].coverage >= cov.coverage and not [p for p in c[2] if "device" in p]
        return steps_ok and c[0].min_levels >= cov.min_levels

    programme, _ = run(chosen.u)
    too_many = programme.n_segments > spec.max_steps
    too_short = bool(np.any(programme.durations_min < spec.min_step_min - 1e-9))
    if too_many or too_short:
        res = honour_step_limits(ctx, structure, chosen.u, accept, spec.max_steps, min_seg)
        if res is not None:
            chosen.u, chosen.margin_g, chosen.margin_t = res
            result = run(chosen.u)
    res = merge_small_changes(ctx, structure, chosen.u, accept, MIN_STEP_CHANGE_C)
    if res is not None and len(step_runs(res[0])) <= len(step_runs(chosen.u)):
        chosen.u, chosen.margin_g, chosen.margin_t = res
        result = run(chosen.u)
    return result


def plan_experiment(
    spec: ExperimentSpec,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    model: LinearThermalModel | None = None,
    robust_tau_s: tuple[float, float] | None = None,
    robust_dt0_c: tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    require_complete: bool = False,
    continuation: Continuation | None = None,
    graded: bool = True,
    effort_s: float | None = EFFORT_S,
    stop: Callable[[], bool] | None = None,
    timetable: bool = True,
    shorten: bool = False,
    end_soak: bool = False,
) -> Plan:
    """Synthesise a chamber programme for ``spec`` (see :mod:`schedsyn.planner`).

    Parameters
    ----------
    spec : ExperimentSpec
    params : ThermalParams
        Nominal model parameters (default tau 2400 s, dT0 3 degC).
    limits : Limits
        Chamber, device and duration limits.
    model : LinearThermalModel, optional
        A linear device model to plan with instead of the first-order lag of ``params``
        (e.g. an augmented model from ``schedsyn diagnose``); ``params`` then only shapes
        the gradient bands.
    robust_tau_s, robust_dt0_c : (lo, hi), optional
        Plan one programme for every (tau, dT0) in the box (see :mod:`.robust`).
    progress : callable(str), optional
        Receives short progress messages.
    require_complete : bool
        Raise :class:`InfeasiblePlanError` instead of returning an incomplete plan.
    continuation : Continuation, optional
        Plan only the rest of a run in progress: its executed steps stay, the levels
        measured so far count (see :mod:`.continuation`). The plan's programme is the
        whole run; its coverage joins the measured passes and the new ones.
    graded : bool
        When the target cannot be met, also plan for fewer levels and return whichever
        plan gives the weakest bins the most levels, then the most complete bins (see
        :func:`_graded`).
    effort_s : float or None, reference s
        Effort after which the optional searches stop once a complete plan for fewer
        levels is in hand: the sub-region fallbacks and the graded search for further
        level counts (a note says when it stopped one). Counted in LP work, not time
        (one reference second is :data:`LP_NONZEROS_PER_EFFORT_S` constraint-matrix
        nonzeros solved, about half a CPU second of one core of a 2026 CI machine), so the
        same request gives the same answer on any machine and under any load, only
        sooner or later. The search for the requested plan itself runs to its end,
        unless its proven bound times ``GUESS_BOUND_RATIO`` exceeds the budget (no
        complete plan known was that close to its bound) and a graded plan for fewer
        levels is already in hand. With a plan in hand, a limit below :data:`EFFORT_S`
        also scales the timetable stage's LP budget down (at least
        :data:`MIN_TIMETABLE_LPS`). None: no limit.
    stop : callable() -> bool, optional
        Asked before each candidate structure of every search, the requested plan's too:
        True stops the search with what it has (cancellation by the caller).
    timetable : bool
        When the band search ends without a complete plan (and the proven bound fits the
        budget), try the timetable stage (:mod:`.timetable`: rates and bin-boundary
        crossing times by sequential LP, at most ``timetable.MAX_LPS`` LP solves) and
        return its plan if it is complete. One model, no robust box, no continuation,
        objective ``shortest``. Default True.
    shorten : bool
        Also give a *complete* plan of the band search to the timetable stage (same
        conditions) and return the shorter of the two: the stage searches rates and
        crossing times directly and found the paper's regions 40-80 min shorter, at
        1-2 min of LP solves each (up to ``timetable.MAX_LPS``). Default False; with a
        robust box, a continuation, another objective or ``timetable=False`` it is a
        :class:`ParameterError`.
    end_soak : bool
        The table will end with a soak until the device settles (``--end-soak``). An
        ``informative`` plan then ends settled (within ``end_tol_c``) wherever the
        programme can, and never farther from settled than the shortest plan run on with
        holds does (otherwise it may spend its last minutes in a region far from the end
        temperature, and the soak would not fit). Every plan made on the way (graded,
        fewer levels, longer segments) does the same. Default False.

    Returns
    -------
    Plan
        Always checked by dense re-simulation of the rounded step table. When the target
        cannot be met, the plan covers the largest part of the region it can and
        ``notes`` say which bins fall short and which limit binds.

    Raises
    ------
    ParameterError
        A request no programme can meet by construction (see :func:`check_request`).
    InfeasiblePlanError
        Nothing at all can be planned (or, with ``require_complete``, not all of it).
    SolverFailedError
        The LP solvers failed numerically and proved nothing infeasible.
    """
    if effort_s is not None and not (math.isfinite(effort_s) and effort_s > 0):
        raise ParameterError(
            f"effort_s must be a positive number of seconds or None (no limit), got {effort_s!r}"
        )
    _check_nominal_in_box(ThermalParams() if params is None else params, robust_tau_s, robust_dt0_c)
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    tic = time.perf_counter()
    single = continuation is None and robust_tau_s is None and robust_dt0_c is None
    if shorten and not (single and spec.objective == "shortest" and timetable):
        raise ParameterError(
            f"{spec.name}: shorten applies to objective 'shortest' planned for one model "
            f"(got objective {spec.objective!r}"
            + (", a robust box" if robust_tau_s is not None or robust_dt0_c is not None else "")
            + (", a continuation" if continuation is not None else "")
            + (", timetable=False" if not timetable else "")
            + "); drop --shorten or plan the shortest objective without a robust box"
        )
    try_timetable = timetable and single and spec.objective == "shortest"
    try:
        plan = _plan(
            spec,
            params,
            limits,
            model=model,
            robust_tau_s=robust_tau_s,
            robust_dt0_c=robust_dt0_c,
            progress=progress,
            require_complete=require_complete,
            continuation=continuation,
            graded=graded,
            effort=_Effort(lp_nonzeros_solved(), effort_s, stop, end_soak=end_soak),
            search_stop=stop,
        )
    except InfeasiblePlanError as err:
        if not try_timetable or (stop is not None and stop()):
            raise
        best = err.best_plan if isinstance(err.best_plan, Plan) else None
        found = _timetable_plan(spec, params, limits, model, progress, best, tic)
        if found is None:
            raise
        return found
    if not try_timetable or (stop is not None and stop()):
        return plan
    if plan.complete:
        if not shorten:
            return plan
        shorter = _timetable_plan(
            spec, params, limits, model, progress, plan, tic, shorten=True, effort_s=effort_s
        )
        if shorter is None or shorter.duration_min >= plan.duration_min:
            return _timed(plan, tic)
        return shorter
    # (the stage's own time counts: a red team's incomplete plan said "solved in 49 s"
    # after 315 s, most of it in the stage)
    found = _timetable_plan(spec, params, limits, model, progress, plan, tic, effort_s=effort_s)
    return found or _timed(plan, tic)


def _timed(plan: Plan, tic: float) -> Plan:
    """``plan`` with the whole call's solve time (``tic``: when the call began)."""
    return dataclasses.replace(plan, solve_s=time.perf_counter() - tic)


def _timetable_plan(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    model: LinearThermalModel | None,
    progress: Callable[[str], None] | None,
    band_plan: Plan | None,
    tic: float,
    shorten: bool = False,
    effort_s: float | None = None,
) -> Plan | None:
    """The timetable stage's plan for a request the band search did not complete, checked
    like every plan (dense re-simulation of the rounded table, limits, step limits), or
    None. ``band_plan``: the band search's best (its notes about the search are replaced
    by what the timetable did). ``shorten``: ``band_plan`` is complete and the stage looks
    for a shorter one (the shortest of its candidates within its LP budget, not the
    first). ``effort_s``: with a plan in hand, an effort limit below :data:`EFFORT_S`
    scales the stage's LP budget down with it (red team: ``--effort-s 15`` left the stage
    its full 500 LPs, 110 s after the graded answer); None, or nothing in hand, the whole
    budget."""
    from .timetable import MAX_LPS, SAFETY_C_PER_MIN, timetable_search

    max_lps = MAX_LPS
    if band_plan is not None and effort_s is not None:
        max_lps = max(MIN_TIMETABLE_LPS, round(MAX_LPS * min(1.0, effort_s / EFFORT_S)))

    if progress:
        why = (
            f"complete in {band_plan.duration_min:g} min from the band search; the timetable "
            "stage looks for a shorter plan"
            if shorten and band_plan is not None
            else "no complete plan from the band search: the timetable stage"
        )
        progress(f"{spec.name}: {why}")
    found = timetable_search(
        spec,
        params,
        limits,
        model=model,
        max_lps=max_lps,
        first_found=not shorten,
        progress=progress,
    )
    if found is None:
        if progress:
            progress(f"{spec.name}: the timetable stage found no complete plan either")
        return None
    programme = found.programme
    cov, cov01, problems, t_lo, t_hi = check_programme(programme, spec, limits, [params], model)
    problems = [*problems, *step_limit_problems(programme, spec)]
    if not cov.complete or problems:  # cannot happen: the stage checks its tables so
        return None
    bound = None
    if model is None:
        bound = duration_lower_bound(spec, params, limits).lower_bound_min
    before = (
        ""
        if band_plan is None
        else f" (the band search's best: {band_plan.coverage.coverage:.0%}, min "
        f"{band_plan.coverage.min_levels} levels, {band_plan.duration_min:g} min)"
    )
    if shorten and band_plan is not None:
        before = (
            f", {band_plan.duration_min - programme.total_min:g} min shorter than the band "
            f"search's complete plan ({band_plan.duration_min:g} min)"
        )
    note = (
        f"planned by the timetable stage{before}: {found.order} sweeps (C cooling, H "
        f"heating, digit the rank, 1 the slowest), rates and bin-boundary crossing times "
        f"by sequential LP ({found.n_lp} LPs); worst bin's level separation "
        f"{found.min_separation_c_per_min:.3f} °C/min"
    )
    if found.safety_c_per_min < SAFETY_C_PER_MIN:
        note += (
            f" (a near miss, searched again with {found.safety_c_per_min:g} °C/min above "
            f"delta instead of {SAFETY_C_PER_MIN:g})"
        )
    plan = _stage_plan(
        spec,
        params,
        limits,
        programme,
        (cov, cov01, t_lo, t_hi),
        found.min_separation_c_per_min,
        tic,
        lp={
            **(band_plan.lp if band_plan is not None else LpStats().to_dict()),
            "timetable_lps": found.n_lp,
            "timetable_order": found.order,
        },
        problem_size=band_plan.problem_size if band_plan is not None else {},
        scenarios=(params,),
        notes=(note,),
        duration_lower_bound_min=bound,
    )
    if progress:
        progress(f"{spec.name}: timetable stage: complete in {plan.duration_min:g} min")
    return with_table_meta(plan)


def _ramp_plan(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    robust_tau_s: tuple[float, float] | None,
    robust_dt0_c: tuple[float, float] | None,
    box_check: dict | None,
    stats: LpStats,
    progress: Callable[[str], None] | None,
    tic: float,
    max_evals: int,
) -> Plan | None:
    """The ramp rung's plan for a robust box (:mod:`.ramps`), checked like every robust
    plan (dense re-simulation of the rounded table at the design scenarios, limits, step
    limits, the dense box check), or None. ``box_check``: the dense check of the band
    search's programme for the whole box, which does not hold on it (None: the band search
    found no programme for the whole box)."""
    band = (
        "the band search found no programme for the whole robust box"
        if box_check is None
        else "the band search's programme for the robust box does not hold on all of it "
        f"(worst point {box_check['worst']['coverage']:.0%})"
    )
    if progress:
        progress(f"{spec.name}: {band}; searching ramp programmes")
    found = ramp_search(
        spec, params, limits, robust_tau_s, robust_dt0_c, progress, max_evals=max_evals
    )
    if found is None:
        if progress:
            progress(f"{spec.name}: the ramp search found no programme for the whole box")
        return None
    programme = found.programme
    scenarios = box_scenarios(params, robust_tau_s, robust_dt0_c)
    cov, cov01, problems, t_lo, t_hi = check_programme(programme, spec, limits, scenarios)
    problems = [*problems, *step_limit_problems(programme, spec)]
    if not cov.complete or problems or not found.box_check["holds"]:
        return None  # cannot happen: the rung checks its tables so
    note = (
        f"planned by the ramp rung: {band}; a programme of {found.legs} constant-rate legs "
        f"turning beyond the region, searched on {len(found.screened)} scenarios of the "
        f"box, holds at all {found.box_check['grid_points']} points of the box's grid "
        f"(dense check; {found.evals} evaluations)"
    )
    bound = max(duration_lower_bound(spec, p, limits).lower_bound_min for p in scenarios)
    return _stage_plan(
        spec,
        params,
        limits,
        programme,
        (cov, cov01, t_lo, t_hi),
        found.min_separation_c_per_min,
        tic,
        lp={**stats.to_dict(), "ramp_evals": found.evals},
        problem_size={},
        scenarios=tuple(scenarios),
        notes=(note,),
        duration_lower_bound_min=bound,
        box_check=found.box_check,
        coverage_nominal=check_programme(programme, spec, limits, [params])[0],
    )


def _stage_plan(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    programme: Programme,
    checked: tuple[CoverageReport, CoverageReport, float, float],
    min_separation_c_per_min: float,
    tic: float,
    **fields,
) -> Plan:
    """The complete plan of a stage that searches tables directly (the timetable stage,
    the ramp rung): ``programme`` checked complete within every limit (``checked``:
    :func:`~.check.check_programme`'s coverage at delta and at 0.1 degC/min and the
    device's range), its worst level separation, and the stage's own ``fields``."""
    cov, cov01, t_lo, t_hi = checked
    return Plan(
        spec=spec,
        params=params,
        limits=limits,
        programme=programme,
        coverage=cov,
        coverage_0p1=cov01,
        complete=True,
        status="complete",
        solve_s=time.perf_counter() - tic,
        margin_g_c_per_min=min_separation_c_per_min - spec.delta_c_per_min,
        margin_t_c=float("nan"),
        violations=(),
        t_min_c=t_lo,
        t_max_c=t_hi,
        **fields,
    )


#: The ramp rung (robust boxes) runs when ``effort_s`` is at least this share of
#: :data:`EFFORT_S` (its budget scales with the share).
RAMP_MIN_EFFORT_SHARE = 0.05

#: A device time constant below this is not a gyro in a chamber: the robust box was
#: likely given in minutes (the refusal says so).
TAU_MINUTES_HINT_S = 120.0


def _check_nominal_in_box(
    params: ThermalParams,
    tau_s: tuple[float, float] | None,
    dt0_c: tuple[float, float] | None,
) -> None:
    """Refuse a robust box that does not hold the nominal device: the box is the
    uncertainty about that device, and a plan for a box beside it was called complete
    while it covered nothing at the nominal model (tau given in minutes: 40:45)."""
    for name, rng, value, unit, option in (
        ("tau", tau_s, params.tau_s, "s", "--robust-tau-s / [robust] tau_s"),
        ("dT0", dt0_c, params.dt0_c, "°C", "--robust-dt0-c / [robust] dt0_c"),
    ):
        if rng is None:
            continue
        lo, hi = float(rng[0]), float(rng[1])
        for end in (lo, hi):  # each end is a device: its own limits, named by the option
            try:
                dataclasses.replace(params, **{"tau_s" if name == "tau" else "dt0_c": end})
            except ParameterError as exc:
                raise ParameterError(f"the robust box {option} {lo:g}..{hi:g}: {exc}") from None
        if lo == hi:  # (a zero-width box held, the plan priced robustness for one point)
            raise ParameterError(
                f"the robust box {option} {lo:g}..{hi:g} {unit} has no width: give LO < HI "
                f"(the range the device's {name} may take), or leave it out to plan for "
                f"{name} exactly its nominal value"
            )
        if lo - 1e-9 <= value <= hi + 1e-9:
            continue
        hint = ""
        if name == "tau" and 0.0 < hi < TAU_MINUTES_HINT_S:
            hint = f" (tau is in seconds: {lo:g}..{hi:g} min would be {60 * lo:g}:{60 * hi:g})"
        raise ParameterError(
            f"the robust box {option} {lo:g}..{hi:g} {unit} does not contain the nominal "
            f"{name} {value:g} {unit}{hint}; give a box around the device you plan for, or "
            f"set the nominal inside it (--{'tau-s' if name == 'tau' else 'dt0-c'} or [model] "
            f"{'tau_s' if name == 'tau' else 'dt0_c'})"
        )


def _no_complete_plan(bound_min: float, limits: Limits) -> str:
    """The note of a request its proven bound rules out (an infinite bound: a bin no
    sweep can cross, for any budget)."""
    needs = (
        "some bin cannot be crossed at all"
        if not math.isfinite(bound_min)
        else "any plan whose sweeps cross the whole region needs at least "
        f"{bound_min:.0f} min (proven lower bound)"
    )
    return f"no complete plan exists within {limits.duration_max_min:g} min: {needs}"


def _plan(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    *,
    model: LinearThermalModel | None,
    robust_tau_s: tuple[float, float] | None,
    robust_dt0_c: tuple[float, float] | None,
    progress: Callable[[str], None] | None,
    require_complete: bool,
    continuation: Continuation | None,
    graded: bool,
    effort: _Effort,
    search_stop: Callable[[], bool] | None,
) -> Plan:
    """:func:`plan_experiment` within one effort limit, shared by the plans it makes on
    the way (fewer levels, longer segments); ``search_stop`` ends the search for the
    requested plan itself."""
    tic = time.perf_counter()
    check_request(spec, limits, check_start=continuation is None)
    robust = robust_tau_s is not None or robust_dt0_c is not None
    if continuation is None and model is None:  # (a given model's start is its own)
        check_start_excursion(
            box_scenarios(params, robust_tau_s, robust_dt0_c) if robust else (params,),
            limits,
            spec.name,
        )
    if robust and model is not None:
        raise ParameterError(
            "robust planning uses the first-order model of each scenario; "
            "give either a model or a robust box, not both"
        )
    if spec.min_step_min > spec.segment_min:  # plan with steps at least that long
        seg = min(MAX_SEGMENT_MIN, math.ceil(spec.min_step_min - 1e-9))
        if seg > spec.segment_min:
            inner = _plan(
                dataclasses.replace(spec, segment_min=seg),
                params,
                limits,
                model=model,
                robust_tau_s=robust_tau_s,
                robust_dt0_c=robust_dt0_c,
                progress=progress,
                require_complete=False,
                continuation=continuation,
                graded=graded,
                effort=effort,
                search_stop=search_stop,
            )
            note = (
                f"planned with {seg:g}-min segments so that no step is shorter than "
                f"min_step_min = {spec.min_step_min:g} min"
            )
            return _respec(inner, spec, note, require_complete)
    # graded plans: for the first-order model's nominal plans, unless a complete one is
    # required (a graded plan is not what was asked for)
    graded_ok = graded and model is None and not robust and not require_complete
    found: _Fewer | None = None
    searched_fewer = False
    proven_note = None
    partials: list[Plan] = []  # the graded search's plans that are not complete
    if graded_ok and continuation is None:
        # proven impossible: the search for these levels (and its fallbacks) cannot succeed,
        # and a graded plan for fewer levels beats any partial one (its weakest bin has more)
        proven = duration_lower_bound(spec, params, limits).lower_bound_min
        if proven > limits.duration_max_min:
            proven_note = _no_complete_plan(proven, limits)
            note = f"{proven_note}; {spec.levels_required} levels were not searched"
            if progress:
                progress(f"{spec.name}: {note}")
            found = _fewer_levels(spec, params, limits, progress, effort, partials=partials)
            searched_fewer = True
            fewer = _graded(None, spec, params, limits, (note,), found, effort)
            if fewer is None and math.isinf(proven):  # some bin cannot be reached at all
                fewer = _plan_reachable_part(spec, params, limits, progress, effort, proven_note)
            if fewer is not None:
                return with_table_meta(_finished(fewer, tic, effort))
        elif proven * GUESS_BOUND_RATIO > limits.duration_max_min:
            # possible but unlikely (no complete plan found so far was this close to its
            # bound): the graded answer first, then the requested levels while effort lasts
            found = _fewer_levels(spec, params, limits, progress, effort, partials=partials)
            searched_fewer = True
            if found is not None:
                search_stop = effort.spent
    stats = LpStats()
    notes: list[str] = []
    fallback: str | None = None
    if continuation is not None:
        if robust:
            raise ParameterError("a continuation is planned with one model, not a robust box")
        return _plan_continued(spec, params, limits, model, continuation, progress, stats, tic)
    if robust:
        params_list = box_scenarios(params, robust_tau_s, robust_dt0_c)

        def holds_on_box(found: Search) -> bool:
            """The dense box check of the programme ``found`` gives: its structure polished
            or, when it overran, cut at the limit (as :func:`_fallback` cuts it)."""
            if found.best is not None:
                u, _, _ = polish(found.ctx, found.best[0])
            elif (cut := _cut_at_limit(found, spec, limits)) is not None:
                u = cut.u
            else:
                return False
            programme = operator_programme(u, spec, limits)
            return bool(
                verify_robust(programme, spec, params, robust_tau_s, robust_dt0_c, limits)["holds"]
            )

        inner_tic: list[int] = []

        def inner_stop(phrase: str) -> bool:
            """Asked once the nominal plan is in hand: the later searches are optional,
            and get ``effort_s`` of work of their own (from the first time this is
            asked); ``phrase`` says what stopping now leaves out, for the effort note."""
            if not inner_tic:
                inner_tic.append(lp_nonzeros_solved())
                effort.work_tic, effort.answered = inner_tic[0], True
            effort.what = phrase
            return effort.spent()

        # a box no programme covers (proof): the ramp rung would search in vain
        spread = box_spread_proof(spec, params, limits, robust_tau_s, robust_dt0_c)
        ramp_tried: list[Plan | None] = [] if spread is None else [None]

        def ramp_rung(box_check: dict | None = None) -> bool:
            """The ramp rung (once): True when it planned the whole box. An optional
            search: its budget of evaluations (a count, not a clock) scales with
            ``effort_s`` against its default, and an effort limit under
            :data:`RAMP_MIN_EFFORT_SHARE` of it, or already spent, skips it."""
            if ramp_tried:
                return ramp_tried[0] is not None
            share = 1.0 if effort.effort_s is None else min(1.0, effort.effort_s / EFFORT_S)
            phrase = "the ramp rung (ramp-and-hold programmes for the whole box) was not searched"
            if share < RAMP_MIN_EFFORT_SHARE:
                effort.hit = effort.hit_limit = True  # (the note says so)
                effort.what = phrase
            if share < RAMP_MIN_EFFORT_SHARE or inner_stop(phrase):
                ramp_tried.append(None)
                return False
            budget = round(share * EVALS_PER_LEVEL * spec.levels_required)
            ramp_tried.append(
                _ramp_plan(
                    spec,
                    params,
                    limits,
                    robust_tau_s,
                    robust_dt0_c,
                    box_check,
                    stats,
                    progress,
                    tic,
                    budget,
                )
            )
            return ramp_tried[0] is not None

        search, notes, fallback = search_robust(
            spec,
            params,
            limits,
            robust_tau_s,
            robust_dt0_c,
            progress,
            stats,
            holds_on_box,
            stop=inner_stop,
            whole_box=ramp_rung,
            proven_impossible=spread is not None,
        )
        if ramp_tried and ramp_tried[0] is not None:
            return with_table_meta(_timed(ramp_tried[0], tic))
    else:
        params_list = [params]
        search = synthesise(
            spec,
            params_list,
            limits,
            [model or FirstOrderLag(params)],
            progress,
            stats,
            stop=search_stop,
        )
    models = [model if model is not None else FirstOrderLag(p) for p in params_list]

    if search.best is not None:
        u, margin_g, margin_t = polish(search.ctx, search.best[0])
        chosen = _Candidate(u, margin_g, margin_t, search, search.ctx)
        if search.split is not None:
            notes.append(split_note(*search.split))
    else:
        notes += explain_shortfall(spec, params, limits)
        if graded_ok and not searched_fewer:  # first: the effort limit cuts sub-regions
            found = _fewer_levels(spec, params, limits, progress, effort, partials=partials)
            searched_fewer = True
        try:
            chosen = _fallback(
                spec, limits, params_list, models, model, search, progress, stats, effort
            )
        except InfeasiblePlanError as err:
            # nothing at all with these levels: fewer levels, if some count fits
            fewer = _graded(None, spec, params, limits, tuple(notes), found, effort)
            if fewer is None:  # no count complete: the best part of the region, if any
                why = [n for n in (proven_note, *notes) if n]
                fewer = _best_partial(partials, spec, params, limits, tuple(why))
            if fewer is None:
                # say why: the proven bound and the limit that binds, not only the search's
                # reasons (a bin the chamber cannot reach read as "lengthen the duration")
                why = [n for n in (proven_note, *notes) if n]
                if not why:
                    raise
                # the cause first (the bound, the binding limit), then what the search saw
                saw = str(err).removeprefix(f"{spec.name}: ")
                if any("unreachable" in w for w in why):  # not a matter of time or levels
                    saw = saw.replace(f" {NO_PLAN_ADVICE}", "")
                raise InfeasiblePlanError(
                    f"{spec.name}: {'; '.join(why)}. The search: {saw}",
                    best_coverage=err.best_coverage,
                ) from err
            return with_table_meta(_finished(fewer, tic, effort))
        notes.append(chosen.note)

    programme = operator_programme(chosen.u, spec, limits)
    cov, cov01, problems, t_lo, t_hi = check_programme(programme, spec, limits, params_list, model)
    # rounding to whole minutes and 0.1 degC can push the device a hair past a limit the
    # LP met at its samples: polish again with the limits tightened by that much
    best = chosen.search.best
    ctx = chosen.ctx
    for _ in range(MAX_REPOLISH):
        excess = _device_excess(limits, t_lo, t_hi)
        if excess <= EXCESS_TOL_C or best is None:
            break
        tight = ctx.tightened(ctx.device_margin_c + excess + REPOLISH_PAD_C)
        u2, mg2, mt2 = polish(tight, best[0])
        prog2 = operator_programme(u2, spec, limits)
        check2 = check_programme(prog2, spec, limits, params_list, model)
        if check2[0].coverage < cov.coverage or _device_excess(limits, *check2[3:]) >= excess:
            break
        programme, (cov, cov01, problems, t_lo, t_hi) = prog2, check2
        chosen.u, chosen.margin_g, chosen.margin_t, ctx = u2, mg2, mt2, tight
    if best is not None:  # fewer, longer steps: within the limits, and no trivial ones
        checked = _shape_steps(spec, limits, params_list, model, ctx, best[0], chosen, cov)
        if checked is not None:
            programme, (cov, cov01, problems, t_lo, t_hi) = checked
    problems += step_limit_problems(programme, spec)
    complete = cov.complete and not problems
    if not cov.complete:
        short = cov.short_bins()
        notes.append(
            f"{len(short)} of {spec.grid.n_bins} bins have fewer than {spec.levels_required} "
            f"distinct levels: " + ", ".join(f"[{a:g},{b:g}) {n}" for a, b, n in short[:10])
        )
        notes += [n for n in explain_shortfall(spec, params, limits) if n not in notes]
    box_check = None
    cov_nominal = None
    if robust:
        cov_nominal = check_programme(programme, spec, limits, [params])[0]
        box_check = verify_robust(programme, spec, params, robust_tau_s, robust_dt0_c, limits)
        if not box_check["holds"] and not ramp_tried and ramp_rung(box_check):
            ramp = ramp_tried[0]
            assert ramp is not None  # (ramp_rung said so)
            return with_table_meta(_timed(ramp, tic))
        if not box_check["holds"]:
            complete = False
            notes.append(box_note(box_check))
            if spread is not None:
                notes.append(spread)
        elif fallback is not None:
            # the search for the whole box failed, yet the fallback's programme holds on it
            notes = [n for n in notes if not n.startswith("FALLBACK")]
            notes.append(held_note(fallback, box_check))
        # a box over one parameter leaves the other at its nominal value: say so, so
        # that a user who meant both (and forgot one option) is not left to guess
        for rng, name, value, option in (
            (robust_tau_s, "tau", f"{params.tau_s:g} s", "--robust-tau-s / robust_tau_s"),
            (robust_dt0_c, "dT0", f"{params.dt0_c:g} degC", "--robust-dt0-c / robust_dt0_c"),
        ):
            if rng is None:
                notes.append(
                    f"robust box over one parameter only: {name} is taken as exactly its "
                    f"nominal {value} (give {option} LO:HI to plan for its uncertainty too)"
                )
    if stats.failed:
        notes.append(
            f"{stats.failed} of {stats.solves} LP solves failed numerically in both solvers "
            "(counted apart from infeasible ones; see plan.json 'lp')"
        )
    status = "complete" if complete else ("incomplete" if not problems else "limits violated")
    bound = None
    if model is None:  # the proof is for the first-order lag; a robust plan meets every scenario
        bound = max(duration_lower_bound(spec, p, limits).lower_bound_min for p in params_list)
        if bound > limits.duration_max_min:
            notes.append(_no_complete_plan(bound, limits))
    plan = Plan(
        spec=spec,
        params=params,
        limits=limits,
        programme=programme,
        coverage=cov,
        coverage_0p1=cov01,
        complete=complete,
        status=status,
        solve_s=time.perf_counter() - tic,
        margin_g_c_per_min=chosen.margin_g,
        margin_t_c=chosen.margin_t,
        lp=stats.to_dict(),
        problem_size=ctx.size,
        scenarios=tuple(params_list),
        violations=tuple(problems),
        notes=tuple(notes),
        t_min_c=t_lo,
        t_max_c=t_hi,
        box_check=box_check,
        duration_lower_bound_min=bound,
        coverage_nominal=cov_nominal,
        robust_fallback=fallback,
    )
    if spec.objective == "informative":
        structure = best[0] if best is not None else None
        plan = _make_informative(
            plan, model, ctx, structure, chosen, progress, end_soak=effort.end_soak
        )
    if (
        programme.n_segments > spec.max_steps
        and cov.complete
        and graded
        and not robust
        and continuation is None
    ):  # merging steps was not enough: coarser control has fewer steps
        coarser = _coarser(spec, params, limits, model, progress, effort)
        if coarser is not None:
            plan = coarser
            complete = True
    if not complete and graded_ok:
        if not searched_fewer:
            found = _fewer_levels(spec, params, limits, progress, effort, plan.coverage.min_levels)
        # the notes about the request (why it cannot be met), not about the replaced plan
        about_request = explain_shortfall(spec, params, limits)
        about_request += [n for n in plan.notes if n.startswith("no complete plan exists")]
        plan = _graded(plan, spec, params, limits, tuple(about_request), found, effort) or plan
    plan = with_table_meta(_finished(plan, tic, effort))
    if require_complete and not complete:
        raise InfeasiblePlanError(
            f"{spec.name}: no complete plan was found: {'; '.join(notes + problems)}; best "
            f"reachable coverage is {cov.coverage:.0%}",
            best_coverage=cov.coverage,
            best_plan=plan,
        )
    return plan


def _plan_continued(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    model: LinearThermalModel | None,
    continuation: Continuation,
    progress: Callable[[str], None] | None,
    stats: LpStats,
    tic: float,
) -> Plan:
    """:func:`plan_experiment` for the rest of a run (see :mod:`.continuation`)."""
    continuation.check_grid(spec)
    if continuation.at_min >= limits.duration_max_min:
        raise ParameterError(
            f"{spec.name}: the run has lasted {continuation.at_min:g} min, the limit is "
            f"{limits.duration_max_min:g} min: nothing is left to plan"
        )
    model = model if model is not None else FirstOrderLag(params)
    programme, mg, mt, search, notes, check, spoilt = plan_continuation(
        spec, params, limits, model, continuation, progress, stats
    )
    segment_used = spec.segment_min
    if spoilt:  # merging steps was not enough: coarser control has fewer steps
        for factor in COARSER_FACTORS:
            seg = spec.segment_min * factor
            if seg > MAX_SEGMENT_MIN:
                break
            if progress:
                progress(
                    f"a rest that covers more breaks max_steps = {spec.max_steps} or "
                    f"min_step_min: trying {seg:g}-min segments"
                )
            try:
                alt = plan_continuation(
                    dataclasses.replace(spec, segment_min=seg),
                    params,
                    limits,
                    model,
                    continuation,
                    progress,
                    stats,
                )
            except InfeasiblePlanError:
                continue
            a_check = alt[5]
            if a_check[2] or (
                not check[2]
                and (a_check[0].coverage, a_check[0].min_levels)
                <= (check[0].coverage, check[0].min_levels)
            ):
                continue  # a rest that can be run, covering more (or the first that can)
            programme, mg, mt, search, notes, check = alt[:6]
            segment_used = seg
            notes = [
                *notes,
                f"planned with {seg:g}-min segments: with {spec.segment_min:g}-min ones the "
                "rest that covered most broke the step limits (max_steps / min_step_min)",
            ]
            if check[0].complete:
                break
    cov, cov01, problems, t_lo, t_hi = check  # step limits: on the new steps (the check)
    complete = cov.complete and not problems
    if not cov.complete:
        short = cov.short_bins()
        notes.append(
            f"{len(short)} of {spec.grid.n_bins} bins have fewer than {spec.levels_required} "
            f"distinct levels (measured and planned): "
            + ", ".join(f"[{a:g},{b:g}) {n}" for a, b, n in short[:10])
        )
    status = "complete" if complete else ("incomplete" if not problems else "limits violated")
    return with_table_meta(
        Plan(
            spec=spec,
            params=params,
            limits=limits,
            programme=programme,
            coverage=cov,
            coverage_0p1=cov01,
            complete=complete,
            status=status,
            solve_s=time.perf_counter() - tic,
            margin_g_c_per_min=mg,
            margin_t_c=mt,
            lp=stats.to_dict(),
            problem_size=search.ctx.size if search is not None else {},
            scenarios=(params,),
            violations=tuple(problems),
            notes=tuple(notes),
            t_min_c=t_lo,
            t_max_c=t_hi,
            continued_from_min=continuation.at_min,
        ),
        segment_min=segment_used,
    )


def _make_informative(
    plan: Plan,
    model: LinearThermalModel | None,
    ctx: Context,
    structure: Structure | None,
    chosen: _Candidate,
    progress: Callable[[str], None] | None,
    end_soak: bool = False,
) -> Plan:
    """``objective = "informative"``: the complete shortest ``plan`` run on to the budget
    with every rate chosen for the drift fit (:mod:`.informative`), when the result checks
    complete and within every limit; otherwise ``plan`` with a note saying why not.
    ``end_soak``: the device ends settled where it can (:func:`informative_rates`'s
    ``end_settled``)."""
    from ..design import plan_design, plan_space

    tic = time.perf_counter()
    spec, limits = plan.spec, plan.limits

    def keep(why: str) -> Plan:
        return dataclasses.replace(plan, notes=(*plan.notes, f"informative: {why}"))

    if not plan.complete or structure is None:
        return keep("only a complete plan is made more informative; this one is not")
    if len(plan.scenarios) > 1:
        return keep("not applied to robust plans (the information is a single model's)")
    r = ctx.responses
    n_ext = min(r.durations.size, r.max_segments(limits.duration_max_min))
    space = plan_space(plan)
    problems: list[str] = []
    res = None
    for l1_weight in L1_WEIGHT_LADDER:  # heavier rate-change prices give fewer steps
        # at least 80 % of the margins the shortest plan keeps (its rates meet them in full)
        res = informative_rates(
            ctx, structure, chosen.u, space, n_ext, progress=progress,
            margins=(0.8 * chosen.margin_g, 0.8 * chosen.margin_t), l1_weight=l1_weight,
            end_settled=(
                (_settled_c(limits, plan.params, model), limits.end_tol_c)
                if end_soak else None
            ),
        )  # fmt: skip
        if res is None:
            return keep("no change of the rates raised the information; the shortest stands")
        programme = operator_programme(res.u, spec, limits)
        cov, cov01, problems, t_lo, t_hi = check_programme(
            programme, spec, limits, [plan.params], model
        )
        problems += step_limit_problems(programme, spec)
        if programme.n_segments <= spec.max_steps:
            break
    if res is None or not cov.complete or problems:
        why = "; ".join(problems) or f"coverage {cov.coverage:.1%} after rounding"
        return keep(f"the informative programme failed its check ({why}); the shortest stands")
    before = plan_design(plan)
    candidate = dataclasses.replace(
        plan, programme=programme, coverage=cov, coverage_0p1=cov01, t_min_c=t_lo, t_max_c=t_hi
    )
    after = plan_design(candidate)
    p = len(before.terms)
    # DesignReport.log_det is per sample (M = X'X/n): the total information adds p log n
    info_factor = math.exp(
        (
            after.log_det
            + p * math.log(max(after.n_in_region, 1))
            - before.log_det
            - p * math.log(max(before.n_in_region, 1))
        )
        / p
    )
    if not info_factor > 1.0:
        return keep("the longer programme was not more informative; the shortest plan stands")
    info = {
        "shortest_duration_min": plan.duration_min,
        "price_min": programme.total_min - plan.duration_min,
        "information_factor": info_factor,
        "d_efficiency_pct_shortest": before.d_efficiency_pct,
        "d_efficiency_pct": after.d_efficiency_pct,
        "i_efficiency_pct_shortest": before.i_efficiency_pct,
        "i_efficiency_pct": after.i_efficiency_pct,
        "slp_iterations": res.iterations,
    }
    note = (
        f"informative: {programme.total_min - plan.duration_min:.0f} min longer than the "
        f"shortest complete plan for {spec.levels_required} levels per bin "
        f"({plan.duration_min:.0f} min) for {info_factor:.2f}x its "
        f"information (D-efficiency {before.d_efficiency_pct:.1f} -> "
        f"{after.d_efficiency_pct:.1f} %, I-efficiency {before.i_efficiency_pct:.0f} -> "
        f"{after.i_efficiency_pct:.0f} %)"
    )
    return dataclasses.replace(
        candidate,
        notes=(*plan.notes, note),
        informative=info,
        solve_s=plan.solve_s + time.perf_counter() - tic,
    )


def with_table_meta(plan: Plan, segment_min: float | None = None) -> Plan:
    """The plan with its step table carrying what it was planned for (region, model,
    limits, box): ``schedsyn.simulate(plan.programme)`` and readers of the written table
    then use the plan's own parameters. ``segment_min``: the segments the rates were
    chosen on, when not ``plan.spec``'s (coarser, to meet the step limits); by default
    what the table already records, else ``plan.spec``'s."""
    from ..programme import StepTableMeta

    if segment_min is None and plan.programme.meta is not None:
        segment_min = plan.programme.meta.segment_min
    meta = StepTableMeta.from_plan(plan, segment_min=segment_min)
    return dataclasses.replace(plan, programme=plan.programme.with_meta(meta))


@dataclass(frozen=True, slots=True)
class _Fewer:
    """What the graded search found: a complete plan for ``levels`` per bin (the most it
    found), and the counts it searched."""

    levels: int
    plan: Plan
    searched: tuple[int, ...]


def _fewer_levels(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    progress: Callable[[str], None] | None,
    effort: _Effort,
    floor: int = 0,
    partials: list[Plan] | None = None,
) -> _Fewer | None:
    """The most levels per bin below ``levels_required`` (and above ``floor``) that a
    complete plan reaches, with that plan; None when no count gives one. The plans of
    the counts searched that are not complete (sub-regions, cut at the limit) are
    appended to ``partials``: the last resort when nothing else can be planned.

    The effort is bounded: each count is planned complete or not at all (no truncated
    or partial plans; sub-regions only while ``effort`` lasts), counts whose proven
    bound exceeds the budget are never planned, and the counts are searched from a
    first guess (:func:`_first_guess`) up while plans are complete and down while they
    are not, so a request whose target is far out of reach costs two or three searches,
    not one per count below ``L``.
    Completeness is taken as monotone in the count (fewer levels, more time to spare):
    the search stops at the first count where it changes. The first guess is always
    searched; the others only while ``effort`` is not spent (a count whose search was
    stopped counts as not found). Sub-regions (for ``partials``) are searched for the
    first guess and the fewest levels only: on the way down they cost as much as the
    count's own search again and are dropped as soon as a lower count completes (a
    red-team request spent 90 s of its 245 s walk from 5 down to 3 levels on them).
    """
    fits = [
        k
        for k in range(max(2, floor + 1), spec.levels_required)
        if duration_lower_bound(
            dataclasses.replace(spec, levels_required=k), params, limits
        ).lower_bound_min
        <= limits.duration_max_min
    ]
    if not fits:
        return None
    tried: dict[int, Plan | None] = {}

    def attempt(levels: int, first: bool = False) -> Plan | None:
        if levels in tried:
            return tried[levels]
        if not first and effort.spent():
            return None  # (not searched; the effort note says so)
        if progress:
            progress(
                f"no complete plan found with {spec.levels_required} levels per bin: "
                f"planning {levels} instead"
            )
        # partial plans (sub-regions) from the first guess and the fewest levels only
        effort.partials = first or levels == fits[0]
        try:
            alt = _plan_nominal(  # complete or nothing (a partial plan kept: a last resort)
                dataclasses.replace(spec, levels_required=levels),
                params,
                limits,
                progress,
                effort,
                graded=False,
                search_stop=effort.stop if first else effort.spent,
            )
        except InfeasiblePlanError as err:
            alt = None
            if isinstance(err.best_plan, Plan) and partials is not None:
                partials.append(err.best_plan)
        except SolverFailedError:
            alt = None  # (numerical failures prove nothing; that count is skipped)
        finally:
            effort.partials = True
        tried[levels] = alt if alt is not None and alt.complete else None
        effort.answered = effort.answered or tried[levels] is not None
        return tried[levels]

    k = _first_guess(spec, params, limits, fits)
    if attempt(k, first=True) is not None:  # up while complete
        while k + 1 in fits and attempt(k + 1) is not None:
            k += 1
    else:  # down until complete
        while k - 1 in fits and attempt(k - 1) is None:
            k -= 1
        k -= 1
    found = tried.get(k)
    return None if found is None else _Fewer(k, found, tuple(sorted(tried)))


def _graded(
    plan: Plan | None,
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    notes: tuple[str, ...],
    fewer: _Fewer | None,
    effort: _Effort | None = None,
) -> Plan | None:
    """The better of ``plan`` (the best found with the requested ``L`` levels; None:
    nothing at all) and the graded search's complete plan for fewer levels: the one
    that gives the weakest bin more levels, then more bins at ``L`` (counted by the
    independent check at ``L``); a plan that breaks a limit loses to one that does not.
    """
    if fewer is None:
        return plan
    cov, cov01, problems, _, _ = check_programme(fewer.plan.programme, spec, limits, [params])
    violations = tuple(dict.fromkeys((*fewer.plan.violations, *problems)))
    if plan is not None and (
        not plan.violations,
        plan.coverage.min_levels,
        plan.coverage.coverage,
    ) >= (
        True,
        cov.min_levels,
        cov.coverage,
    ):
        return plan
    searched = ", ".join(str(n) for n in fewer.searched)
    bound_min = duration_lower_bound(spec, params, limits).lower_bound_min
    if bound_min > limits.duration_max_min:
        proof = (
            f"proven: no complete plan with {spec.levels_required} levels fits, the duration "
            + (
                "bound is infinite"
                if math.isinf(bound_min)
                else f"bound {bound_min:.0f} min exceeds the budget"
            )
        )
    else:
        # red team: "the most the search fits in 540 min" read as a proof, and a
        # request a simple generator covered with 6 levels in 449 min was sent to a
        # faster chamber or 4 levels
        # a longer search only where the effort limit cut one (with --effort-s 0, or a
        # search that ran to its end, more effort changes nothing)
        more = (
            "a longer search (--effort-s; this one stopped at its effort limit) or --advise "
            "may find more"
            if effort is not None and effort.hit_limit
            else "--advise may find more"
        )
        proof = (
            f"not proven: the duration bound, {bound_min:.0f} min, does not exclude "
            f"{spec.levels_required} levels; {more}"
        )
    return dataclasses.replace(
        fewer.plan,
        spec=spec,
        coverage=cov,
        coverage_0p1=cov01,
        complete=False,
        status="limits violated" if violations else "incomplete",  # a broken limit dominates
        violations=violations,
        levels_planned=fewer.levels,
        notes=(
            *notes,
            f"GRADED: no complete plan with {spec.levels_required} levels per bin "
            f"was found; this one plans {fewer.levels} in every bin (the most the search "
            f"found within {limits.duration_max_min:g} min; levels searched: {searched}; "
            f"{proof}): weakest bin {cov.min_levels} levels, {cov.coverage:.0%} of the bins "
            f"at {spec.levels_required}",
            # what the fewer-level plan's own objective did (it is the plan returned)
            *(n for n in fewer.plan.notes if n.startswith("informative:")),
        ),
        duration_lower_bound_min=bound_min,
    )


def _plan_nominal(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    progress: Callable[[str], None] | None,
    effort: _Effort,
    *,
    graded: bool,
    search_stop: Callable[[], bool] | None = None,
) -> Plan:
    """:func:`_plan` for a variant of the request with the first-order model and no box:
    graded (the best plan, complete or not) or complete-or-nothing (``graded=False``:
    :class:`InfeasiblePlanError` with the plan that fell short as ``best_plan``)."""
    return _plan(
        spec,
        params,
        limits,
        model=None,
        robust_tau_s=None,
        robust_dt0_c=None,
        progress=progress,
        require_complete=not graded,
        continuation=None,
        graded=graded,
        effort=effort,
        search_stop=search_stop or effort.stop,
    )


def _plan_reachable_part(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    progress: Callable[[str], None] | None,
    effort: _Effort,
    proven_note: str,
) -> Plan | None:
    """Some bin cannot be reached at all (the chamber floor or ceiling, with dT0, stops
    the device short of it): the plan of the part of the region that can be
    (:func:`reachable_part`; graded when the levels do not fit), reported for the whole
    region with the notes that name the limit that would do; None when no part can be
    planned."""
    part = reachable_part(spec, params, limits)
    if part is None or not math.isfinite(
        duration_lower_bound(part, params, limits).lower_bound_min
    ):
        return None
    if progress:
        progress(
            f"{spec.name}: planning the part the chamber can reach, "
            f"[{part.working_lo_c:g}, {part.working_hi_c:g}] °C"
        )
    try:
        plan = _plan_nominal(part, params, limits, progress, effort, graded=True)
    except (InfeasiblePlanError, SolverFailedError):
        return None
    levels = plan.levels_planned or part.levels_required
    share = float(np.mean(plan.coverage.levels >= levels))  # (a graded plan counts at L)
    return _reported_for(
        plan,
        spec,
        params,
        limits,
        (proven_note, *explain_shortfall(spec, params, limits)),
        f"PARTIAL: the chamber cannot bring the device through every bin; this plan is "
        f"for the part it can, [{part.working_lo_c:g}, {part.working_hi_c:g}] °C, with "
        f"{levels} levels in {share:.0%} of its bins (the other bins get "
        "what its sweeps give them",
    )


def _best_partial(
    partials: Sequence[Plan],
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    notes: tuple[str, ...],
) -> Plan | None:
    """The last resort when no level count gives a complete plan and nothing at all
    fits with the requested levels: the best of the graded search's partial plans (a
    sub-region, or cut at the limit, with fewer levels), so that the user gets the part
    of the region that can be calibrated, with every reason the rest cannot. Ranked by
    keeping every limit, then the most levels in the weakest bin, then the most bins at
    the plan's own level count, then that count. None when there is none."""
    if not partials:
        return None

    def rank(p: Plan) -> tuple:
        cov = p.coverage
        return (not p.violations, cov.min_levels, cov.coverage, p.spec.levels_required)

    best = max(partials, key=rank)
    k = best.spec.levels_required
    lo, hi = best.spec.working_lo_c, best.spec.working_hi_c
    part = "" if (lo, hi) == (spec.working_lo_c, spec.working_hi_c) else f" of [{lo:g}, {hi:g}] °C"
    if best.violations:
        # it may give every bin k levels, but not within the limits (red team: "no plan
        # gives every bin even 2 levels ...; this one gives 2 levels to 100% of the bins")
        head = (
            f"PARTIAL: the search found no plan within the limits that gives every bin even "
            f"{k} levels within {limits.duration_max_min:g} min (not a proof); the best found "
            f"gives {k} levels to "
            f"{best.coverage.coverage:.0%} of the bins{part} but BREAKS A LIMIT (see the "
            "violations; the part of the region that fits"
        )
    else:
        head = (
            f"PARTIAL: the search found no plan that gives every bin even {k} levels "
            f"within {limits.duration_max_min:g} min (not a proof: a programme of another "
            f"shape may); this one gives {k} levels to "
            f"{best.coverage.coverage:.0%} of the bins{part} (the part of the region that fits"
        )
    return _reported_for(best, spec, params, limits, notes, head)


def _reported_for(
    part: Plan,
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    notes: tuple[str, ...],
    head: str,
) -> Plan:
    """``part`` (a plan of part of ``spec``'s region, or with fewer levels) reported
    for ``spec``: coverage re-counted over the whole region at the requested levels,
    never complete; ``head`` (an open parenthesis, closed here with the weakest bin and
    the share at the requested levels) after ``notes``, then ``part``'s own notes."""
    cov, cov01, problems, _, _ = check_programme(part.programme, spec, limits, [params])
    violations = tuple(dict.fromkeys((*part.violations, *problems)))
    own = part.notes
    lo, hi = part.spec.working_lo_c, part.spec.working_hi_c
    if (lo, hi) != (spec.working_lo_c, spec.working_hi_c):
        # the part's graded note counts its own bins, not the region's: say so
        own = tuple(
            f"in the part planned, [{lo:g}, {hi:g}] °C: {n}" if n.startswith("GRADED:") else n
            for n in own
        )
    return dataclasses.replace(
        part,
        spec=spec,
        coverage=cov,
        coverage_0p1=cov01,
        complete=False,
        status="limits violated" if violations else "incomplete",  # a broken limit dominates
        violations=violations,
        levels_planned=part.levels_planned or part.spec.levels_required,
        notes=(
            *notes,
            f"{head}; weakest bin {cov.min_levels} levels, {cov.coverage:.0%} of the bins "
            f"at {spec.levels_required})",
            *own,
        ),
        duration_lower_bound_min=duration_lower_bound(spec, params, limits).lower_bound_min,
    )


#: How far past the edge margin a region's edge must lie from the temperature the chamber
#: floor or ceiling drives the device towards (limit + dT0), degC, to count as reachable
#: in reasonable time: the exponential approach takes ``tau ln(gap / 1 degC)`` for the
#: last stretch (the shortfall note's advice assumes the same degree). At least as far as
#: one gradient band of that direction needs: ``tau (delta/2 + safety + width)`` over
#: ``LIMIT_FRACTION``.
REACH_HEADROOM_C = 1.0


def reachable_part(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits
) -> ExperimentSpec | None:
    """The widest part of the working region, in whole bins, that the chamber floor and
    ceiling let the device pass by the edge margin with :data:`REACH_HEADROOM_C` to spare,
    and fast enough for one gradient band; None when that is the whole region or not a
    single bin."""
    w = spec.grid.bin_c
    one_band_c_per_min = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN + BAND_WIDTH_C_PER_MIN
    room = spec.edge_margin_c + max(
        REACH_HEADROOM_C, params.tau_min * one_band_c_per_min / LIMIT_FRACTION
    )
    lo_need = limits.chamber_min_c + params.dt0_c + room
    hi_need = limits.chamber_max_c + params.dt0_c - room
    lo = spec.working_lo_c + max(0, math.ceil((lo_need - spec.working_lo_c) / w - 1e-9)) * w
    hi = spec.working_hi_c - max(0, math.ceil((spec.working_hi_c - hi_need) / w - 1e-9)) * w
    if hi - lo < w - 1e-9 or (lo, hi) == (spec.working_lo_c, spec.working_hi_c):
        return None
    return dataclasses.replace(spec, working_lo_c=float(lo), working_hi_c=float(hi))


#: Complete plans take at least this multiple of their proven lower bound (the bound
#: relaxes turning and level separation): 1.25-2.1 over the benchmark's complete plans,
#: 1.4 typically. The graded search's first guess is the most levels whose bound times
#: this fits the budget.
GUESS_BOUND_RATIO = 1.3


def _first_guess(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, fits: list[int]
) -> int:
    """The level count the graded search plans first: the most of ``fits`` whose proven
    bound, scaled by :data:`GUESS_BOUND_RATIO`, fits the budget (else the fewest)."""
    for k in sorted(fits, reverse=True):
        bound = duration_lower_bound(dataclasses.replace(spec, levels_required=k), params, limits)
        if bound.lower_bound_min * GUESS_BOUND_RATIO <= limits.duration_max_min:
            return k
    return min(fits)


def _finished(plan: Plan, tic: float, effort: _Effort) -> Plan:
    """``plan`` with the whole call's solve time and, when the effort limit stopped a
    search, the note that says so."""
    notes = plan.notes
    if effort.hit and effort.note() not in notes:
        notes = (*notes, effort.note())
    return dataclasses.replace(plan, solve_s=time.perf_counter() - tic, notes=notes)


def _respec(plan: Plan, spec: ExperimentSpec, note: str, require_complete: bool) -> Plan:
    """A plan made for a variant of ``spec`` (other segments), reported for ``spec``."""
    out = dataclasses.replace(plan, spec=spec, notes=(*plan.notes, note))
    if require_complete and not out.complete:
        raise InfeasiblePlanError(
            f"{spec.name}: no complete plan was found: {'; '.join(out.notes)}",
            best_coverage=out.coverage.coverage,
            best_plan=out,
        )
    meta = plan.programme.meta
    inner = meta.segment_min if meta is not None else None  # went coarser again inside
    return with_table_meta(out, segment_min=inner or plan.spec.segment_min)


def _coarser(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    model: LinearThermalModel | None,
    progress: Callable[[str], None] | None,
    effort: _Effort,
) -> Plan | None:
    """A complete plan within ``max_steps`` with longer segments, or None. (Not cut by
    the effort limit: it is how a complete plan meets its step limit.)"""
    for factor in COARSER_FACTORS:
        seg = spec.segment_min * factor
        if seg > MAX_SEGMENT_MIN:
            break
        if progress:
            progress(f"more than max_steps = {spec.max_steps} steps: trying {seg:g}-min segments")
        try:
            alt = _plan(
                dataclasses.replace(spec, segment_min=seg),
                params,
                limits,
                model=model,
                robust_tau_s=None,
                robust_dt0_c=None,
                progress=progress,
                require_complete=False,
                continuation=None,
                graded=False,
                effort=effort,
                search_stop=effort.stop,
            )
        except InfeasiblePlanError:
            continue
        if alt.complete:
            note = (
                f"planned with {seg:g}-min segments: with {spec.segment_min:g}-min ones the "
                f"table had more than max_steps = {spec.max_steps} steps"
            )
            return _respec(alt, spec, note, False)
    return None


def _settled_c(limits: Limits, params: ThermalParams, model: LinearThermalModel | None) -> float:
    """Where the device settles with the chamber held at ``limits.end_c``, degC (the first-
    order lag: ``end_c + dT0``; any linear model: its exact response long after a hold)."""
    if model is None:
        return limits.end_c + params.dt0_c
    from ..programme import Programme
    from ..simulate import simulate

    hold = Programme(np.array([1.0]), np.array([0.0]), start_c=limits.end_c)
    return float(simulate(hold, model=model, times_min=np.array([1e6])).t_c[0])
