"""Stage 9: :func:`plan_experiment` -- request in, checked :class:`~.check.Plan` out.

scenarios -> search (robust ladder) -> polish -> round for the operator -> check
    (nothing fits in time: cut the over-long structure, or plan sub-regions, and keep
    the option that covers most of the region)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InfeasiblePlanError, ParameterError
from ..model import FirstOrderLag, LinearThermalModel
from ..params import Limits, ThermalParams
from ..programme import Programme
from .bound import duration_lower_bound
from .check import Plan, check_programme
from .continuation import plan_continuation
from .explain import explain_shortfall
from .lp import Context, LpStats, require_solvable
from .polish import polish
from .request import Continuation, ExperimentSpec, check_request
from .robust import box_note, box_scenarios, search_robust, verify_robust
from .search import Search, subregions, synthesise, truncate

#: Rates closer than this are one step of the exported table, degC/min.
MERGE_TOL_C_PER_MIN = 1e-6
#: Re-polishes with tightened device limits after rounding pushed the device past one.
MAX_REPOLISH = 2
#: Extra tightening of the device limits per re-polish, degC, beyond the excess found.
REPOLISH_PAD_C = 0.05
#: Device excess (degC) below which rounding is not worth a re-polish.
EXCESS_TOL_C = 1e-6


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


def _fallback(
    spec: ExperimentSpec,
    limits: Limits,
    params_list: list[ThermalParams],
    models: Sequence[LinearThermalModel],
    model: LinearThermalModel | None,
    search: Search,
    progress: Callable[[str], None] | None,
    stats: LpStats,
) -> _Candidate:
    """Nothing fits in time: the over-long structure cut at the limit, or the widest
    sub-regions that fit; whichever covers most of the region (by the dense check)."""
    max_seg = int(limits.duration_max_min // spec.segment_min)
    options: list[_Candidate] = []
    if search.overrun is not None:
        structure = truncate(search.ctx, search.overrun, max_seg)
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
        spec, params_list, limits, models, progress, stats, stop=full_coverage_found
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
        raise InfeasiblePlanError(
            f"{spec.name}: no programme covers any part of [{spec.working_lo_c:g}, "
            f"{spec.working_hi_c:g}] °C with {spec.levels_required} gradient levels "
            f"{spec.delta_c_per_min:g} °C/min apart within {limits.duration_max_min:g} min "
            f"({'; '.join(search.reasons[:2])}); best reachable coverage is 0%. "
            "Lengthen the duration, narrow the region or lower the level count.",
            best_coverage=0.0,
        )
    return max(options, key=verified)


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
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    tic = time.perf_counter()
    check_request(spec, limits)
    robust = robust_tau_s is not None or robust_dt0_c is not None
    if robust and model is not None:
        raise ParameterError(
            "robust planning uses the first-order model of each scenario; "
            "give either a model or a robust box, not both"
        )
    stats = LpStats()
    notes: list[str] = []
    if continuation is not None:
        if robust:
            raise ParameterError("a continuation is planned with one model, not a robust box")
        return _plan_continued(spec, params, limits, model, continuation, progress, stats, tic)
    if robust:
        params_list = box_scenarios(params, robust_tau_s, robust_dt0_c)
        search, notes = search_robust(
            spec, params, limits, robust_tau_s, robust_dt0_c, progress, stats
        )
    else:
        params_list = [params]
        search = synthesise(
            spec, params_list, limits, [model or FirstOrderLag(params)], progress, stats
        )
    models = [model if model is not None else FirstOrderLag(p) for p in params_list]

    if search.best is not None:
        u, margin_g, margin_t = polish(search.ctx, search.best[0])
        chosen = _Candidate(u, margin_g, margin_t, search, search.ctx)
    else:
        notes += explain_shortfall(spec, params, limits)
        chosen = _fallback(spec, limits, params_list, models, model, search, progress, stats)
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
        chosen.margin_g, chosen.margin_t, ctx = mg2, mt2, tight
    if programme.n_segments > spec.max_steps:
        problems.append(
            f"the step table has {programme.n_segments} steps, more than "
            f"max_steps = {spec.max_steps}"
        )
    complete = cov.complete and not problems
    if not cov.complete:
        short = cov.short_bins()
        notes.append(
            f"{len(short)} of {spec.grid.n_bins} bins have fewer than {spec.levels_required} "
            f"distinct levels: " + ", ".join(f"[{a:g},{b:g}) {n}" for a, b, n in short[:10])
        )
        notes += [n for n in explain_shortfall(spec, params, limits) if n not in notes]
    box_check = None
    if robust:
        box_check = verify_robust(programme, spec, params, robust_tau_s, robust_dt0_c, limits)
        if not box_check["holds"]:
            complete = False
            notes.append(box_note(box_check))
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
            notes.append(
                f"no complete plan exists within {limits.duration_max_min:g} min: any plan "
                f"whose sweeps cross the whole region needs at least {bound:.0f} min "
                "(proven lower bound)"
            )
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
    )
    if require_complete and not complete:
        raise InfeasiblePlanError(
            f"{spec.name}: the target cannot be met: {'; '.join(notes + problems)}; best "
            f"reachable coverage is {cov.coverage:.0%}",
            best_coverage=cov.coverage,
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
    programme, mg, mt, search, notes, check = plan_continuation(
        spec, params, limits, model, continuation, progress, stats
    )
    cov, cov01, problems, t_lo, t_hi = check
    if programme.n_segments > spec.max_steps:
        problems.append(
            f"the step table has {programme.n_segments} steps, more than "
            f"max_steps = {spec.max_steps}"
        )
    complete = cov.complete and not problems
    if not cov.complete:
        short = cov.short_bins()
        notes.append(
            f"{len(short)} of {spec.grid.n_bins} bins have fewer than {spec.levels_required} "
            f"distinct levels (measured and planned): "
            + ", ".join(f"[{a:g},{b:g}) {n}" for a, b, n in short[:10])
        )
    status = "complete" if complete else ("incomplete" if not problems else "limits violated")
    return Plan(
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
    )
