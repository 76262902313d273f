"""``schedsyn plan --working LO HI --approx LO HI``: plan one experiment, write its files.

Writes to ``--out`` (default ``out/plan``): ``steps.csv`` (the step table to type in),
``plan.json`` (model, settings, coverage, solver status and time), ``program.png``,
``phase.png`` and ``coverage.png``. With several ``--chamber-min-c`` / ``--chamber-max-c``
values it answers "what chamber do I need?": one plan per (floor, ceiling), the table in
``chamber.csv``, and the files of the least demanding chamber that reaches full coverage
(or of the best one when none does).

--chamber NAME takes the chamber's rates, floor, ceiling and step limit from a preset
(schedsyn chambers lists them); the options given beside it override it. With --advise,
a plan that is not complete is followed by a search for the least change of one knob
(duration, chamber floor, ceiling, rates, levels) that makes it complete, each verified
by a complete plan: printed, in advice.csv, in plan.json ('advice'), and each verifying
plan in advice/<knob>/.

steps.csv starts with the plan's metadata (experiment, regions, model, limits, robust
box, end_soak_min: how long the device needs at the end to settle), so that
schedsyn simulate, compare and sweep read the region and model from it. --end-soak
appends that hold to the table (it must fit in the time limit).

Exit codes: 0 the plan is complete (every bin covered by the independent check of the
exported table, every limit met); 1 a plan was made but is incomplete; 2 bad input or
nothing could be planned (the message names the best coverage reachable); 3 an
environment fault (an output cannot be written, a worker process died).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from ..errors import InfeasiblePlanError, ParameterError
from ..params import Limits, ThermalParams, unit_slip_notes
from ..planner import OBJECTIVES, ExperimentSpec, Plan
from ..planner.ramps import NO_PROGRAMME_COVERS_BOX
from . import _common

#: ExperimentSpec's defaults (the CLI's are the same as a campaign file's)
_SPEC_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ExperimentSpec)}


def register(sub) -> None:
    p = sub.add_parser(
        "plan",
        help="plan one experiment (programme with full coverage)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--working",
        nargs=2,
        type=float,
        required=True,
        metavar=("LO_C", "HI_C"),
        help="working region, °C: every 1 °C bin gets the required levels",
    )
    p.add_argument(
        "--approx",
        nargs=2,
        type=float,
        default=None,
        metavar=("LO_C", "HI_C"),
        help="approximation region, °C (default: the working region widened by "
        "10 °C on each side, clipped to the device limits)",
    )
    p.add_argument("--name", default="plan", help="experiment name (default plan)")
    p.add_argument(
        "--levels", type=int, default=6, help="distinct gradient levels per bin (default 6)"
    )
    p.add_argument(
        "--delta-c-per-min",
        type=float,
        default=0.05,
        help="minimum gradient difference between levels, °C/min (default 0.05)",
    )
    p.add_argument(
        "--segment-min",
        type=float,
        default=_SPEC_DEFAULTS["segment_min"],
        help=f"decision segment length, whole min (default {_SPEC_DEFAULTS['segment_min']:g})",
    )
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="shortest",
        help="shortest programme, largest margin within the time limit, or informative: "
        "the shortest plan's sweeps run on to the time limit with every rate chosen for "
        "the drift fit's information",
    )
    p.add_argument(
        "--max-steps",
        type=int,
        default=None,
        help="most steps the exported table may have (default: the --chamber preset's, else 80)",
    )
    p.add_argument(
        "--effort-s",
        type=float,
        default=None,
        help="effort after which the search for other plans stops when the requested one "
        "cannot be met (fewer levels, sub-regions; default 45; 0 = no limit), in reference "
        "seconds of LP work (one is about half a CPU second of one core; counted in work, so "
        "the same request gives the same plan on any machine and under any load); the search "
        "for the requested plan runs to its end unless its proven bound says it is unlikely to fit "
        "and a plan with fewer levels is in hand",
    )
    p.add_argument(
        "--duration-max-min",
        type=float,
        default=None,
        help="time limit of the experiment, min (default 540)",
    )
    _common.add_model_options(p)
    p.add_argument(
        "--chamber",
        default=None,
        metavar="NAME",
        help="chamber preset: its rates, floor, ceiling and step limit (schedsyn chambers "
        "lists them); the options below override it",
    )
    add_rate_options(p)
    p.add_argument(
        "--chamber-min-c",
        type=float,
        nargs="+",
        default=None,
        metavar="C",
        help="chamber air floor, °C (default -70); several values: coverage vs "
        "floor in chamber.csv",
    )
    p.add_argument(
        "--chamber-max-c",
        type=float,
        nargs="+",
        default=None,
        metavar="C",
        help="chamber air ceiling, °C (default 80); several values: coverage vs "
        "ceiling in chamber.csv",
    )
    _common.add_device_options(p)
    p.add_argument(
        "--robust-tau-s",
        default=None,
        metavar="LO:HI",
        help="plan for every tau in LO..HI s (robust box), e.g. 2200:2600",
    )
    p.add_argument(
        "--robust-dt0-c",
        default=None,
        metavar="LO:HI",
        help="plan for every dT0 in LO..HI °C (robust box), e.g. 2:4",
    )
    p.add_argument(
        "--no-price",
        action="store_true",
        help="with a robust box: skip the nominal plan that prices robustness (price.csv)",
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL.json",
        help="plan with a linear augmented model file (from schedsyn diagnose); "
        "--tau-s/--dt0-c then override its base",
    )
    add_advise_options(p)
    add_end_soak_option(p)
    add_shorten_option(p)
    p.add_argument("--out", default=None, help="output directory (default out/plan)")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def add_rate_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--rate-min-c-per-min",
        type=float,
        default=None,
        help="fastest chamber cooling ramp, °C/min, < 0 (default: the preset's, else -1)",
    )
    p.add_argument(
        "--rate-max-c-per-min",
        type=float,
        default=None,
        help="fastest chamber heating ramp, °C/min, > 0 (default: the preset's, else 3)",
    )


def add_advise_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--advise",
        action="store_true",
        help="if the plan is not complete, search the least change of one knob (duration, "
        "chamber floor, ceiling, rates, levels) that makes it complete, each verified by a "
        "complete plan: printed, in advice.csv, in plan.json ('advice') and the verifying "
        "plans in advice/<knob>/",
    )
    p.add_argument(
        "--advise-knobs",
        nargs="+",
        default=None,
        choices=("duration", "floor", "ceiling", "rates", "levels"),
        metavar="KNOB",
        help="which knobs --advise searches: duration, floor, ceiling, rates, levels "
        "(default: all)",
    )
    p.add_argument(
        "--advise-budget-s",
        type=float,
        default=900.0,
        help="time budget of --advise, s (default 900; a plan under way is finished)",
    )


#: The files --advise may write, relative to the experiment's folder.
ADVICE_FILES = ("advice.csv",) + tuple(
    f"advice/{k}/{f}"
    for k in ("duration", "floor", "ceiling", "rates", "levels")
    for f in ("steps.csv", "plan.json", "program.png", "phase.png", "coverage.png")
)


def advise_plan(spec, params, limits, plan, args, progress, folder):
    """``--advise``: search what would make an incomplete request complete, write
    advice.csv and each verifying plan into ``folder``; returns ``(lines, advice dict)``."""
    from ..advise import KNOBS, AdviceSettings, advise
    from ..io import write_frame_atomic

    advice = advise(
        spec,
        params,
        limits,
        plan=plan,
        assume_incomplete=plan is None,
        settings=AdviceSettings(
            knobs=tuple(args.advise_knobs or KNOBS), time_budget_s=args.advise_budget_s
        ),
        backend=getattr(args, "backend", "local"),
        workers=getattr(args, "workers", None),
        progress=progress,
    )
    write_frame_atomic(folder / "advice.csv", advice.to_frame())
    lines = [f"what would make {spec.name} complete (one change at a time):"]
    for item in advice.items:
        lines.append(f"  {item.line}")
        if item.plan is not None:
            sub = folder / "advice" / item.knob
            sub.mkdir(parents=True, exist_ok=True)
            write_plan_outputs(item.plan, sub)
            changes = ", ".join(f"{k} = {v:g}" for k, v in item.changes.items())
            lines.append(f"    ({changes}; the plan is in advice/{item.knob}/)")
    return lines, advice.to_dict()


def advice_progress(args, spec):
    """A picklable progress callable for the advice's worker processes (None if quiet)."""
    if args.quiet:
        return None
    from functools import partial

    from ..campaign import _tagged

    return partial(_tagged, _common.progress_of(args), spec.name)


def add_end_soak_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--end-soak",
        action="store_true",
        help="append a hold at the end temperature until the device is within the end "
        "tolerance (±0.5 °C) of where it settles; it must fit in the time limit",
    )


def add_shorten_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--shorten",
        action="store_true",
        help="give a complete plan to the timetable stage for a shorter one (rates and "
        "crossing times by sequential LP; the paper's regions come out 40-80 min shorter, "
        "at 1-2 min more planning each, and less robust to model error: see schedsyn sweep); "
        "objective shortest, one model, no robust box",
    )


#: The files one experiment's folder gets.
PLAN_FILES = ("steps.csv", "plan.json", "program.png", "phase.png", "coverage.png")


# ---------------------------------------------------------------------------------------
# outputs shared with `schedsyn campaign`
# ---------------------------------------------------------------------------------------
def write_plan_outputs(
    plan: Plan,
    out: Path,
    inputs=(),
    model=None,
    model_json: dict | None = None,
    extra_json: dict | None = None,
) -> list[Path]:
    """Write steps.csv (with the plan's metadata), plan.json, program.png, phase.png,
    coverage.png into ``out``; ``extra_json`` adds fields to plan.json (e.g. ``advice``).

    The phase portrait and the coverage plot show the same parameters, the plan's nominal
    ones (their titles say which); for a robust plan the coverage title also gives the
    worst point of the box.
    """
    from .. import plots
    from ..coverage import coverage_report
    from ..io import write_json_atomic
    from ..programme import StepTableMeta
    from ..simulate import simulate

    out = Path(out)
    spec = plan.spec
    region = (spec.working_lo_c, spec.working_hi_c)
    traj = simulate(plan.programme, plan.params, model=model, dt_min=0.1, t0_c=plan.limits.t_init_c)
    soak, _, _ = end_state(plan, model)
    recorded = plan.programme.meta
    meta = StepTableMeta.from_plan(
        plan,
        end_soak_min=soak,
        end_soak_included_min=recorded.end_soak_included_min if recorded else None,
        model_json=model_json,
        segment_min=recorded.segment_min if recorded else None,
    )
    written = [
        plan.programme.with_meta(meta).to_csv(out / "steps.csv", inputs),
        write_json_atomic(
            out / "plan.json",
            {
                **plan.to_json_dict(),
                "end_soak_min": soak,
                # the --model file the plan was made with; monitor and replan predict with it
                **({} if model_json is None else {"model": model_json}),
                **(extra_json or {}),
            },
            inputs,
        ),
    ]
    state = "complete" if plan.complete else f"NOT COMPLETE ({plan.status})"
    model_text = f"tau {plan.params.tau_s:g} s, dT0 {plan.params.dt0_c:g} °C"
    robust = len(plan.scenarios) > 1
    if robust:
        model_text = "nominal " + model_text
    written.append(
        plots.save_figure(
            plots.programme_plot(
                traj,
                region=region,
                limits=plan.limits,
                programme=plan.programme,
                title=f"{spec.name}: {plan.duration_min:g} min, {plan.steps} steps, {state} "
                f"({model_text})",
            ),
            out / "program.png",
            inputs,
        )
    )
    written.append(
        plots.save_figure(
            plots.phase_plot(
                traj.t_c,
                traj.g_c_per_min,
                region=region,
                title=f"{spec.name}: phase portrait ({model_text})",
            ),
            out / "phase.png",
            inputs,
        )
    )
    # coverage at the parameters of the phase portrait (for a robust plan plan.coverage is
    # the worst design scenario: said in the title, not drawn)
    shown = coverage_report(
        traj.t_c, traj.g_c_per_min, spec.grid, spec.levels_required, spec.delta_c_per_min
    )
    title = (
        f"{spec.name}: {'' if plan.complete else 'NOT COMPLETE, '}coverage {shown.coverage:.0%} "
        f"at {model_text} (Δ {spec.delta_c_per_min:g}), "
        f"{plan.coverage_0p1.coverage:.0%} at Δ 0.1 °C/min"
    )
    worst = (plan.box_check or {}).get("worst") if robust else None
    if worst:
        title += f"; worst point of the box {worst['coverage']:.0%}"
    written.append(
        plots.save_figure(plots.coverage_plot(shown, title=title), out / "coverage.png", inputs)
    )
    return written


def end_state(plan: Plan, model=None) -> tuple[float, float, float]:
    """``(end_soak_min, device temperature at the end, settled temperature)`` of a plan's
    exported programme at its nominal parameters (see :func:`schedsyn.simulate.end_soak_min`)."""
    from ..simulate import end_soak_min, simulate

    prog, lim = plan.programme, plan.limits
    soak = end_soak_min(prog, plan.params, model=model, tol_c=lim.end_tol_c, t0_c=lim.t_init_c)
    t_end, settled = simulate(
        prog, plan.params, model=model, t0_c=lim.t_init_c, times_min=np.array([prog.total_min, 1e6])
    ).t_c
    return soak, float(t_end), float(settled)


def end_soak_lines(plan: Plan, model=None) -> list[str]:
    """The end of the programme in words: device temperature, the soak it needs."""
    soak, t_end, settled = end_state(plan, model)
    return ["  " + _common.end_soak_text(plan.programme, t_end, soak, settled, plan.limits)]


#: Re-plans an informative plan gets to leave room for its end soak (--end-soak).
SOAK_ROOM_TRIES = 3


def informative_with_room_for_soak(plan: Plan, replan, model=None) -> Plan:
    """An ``informative`` plan runs on to the time limit, so its end soak never fits:
    it is planned again with the limit shortened by the soak it needs (``replan(limits)``,
    up to :data:`SOAK_ROOM_TRIES` times, as the soak depends on where the plan ends).
    The plan returned carries the request's own limits; when no room is found, the
    first plan (``with_end_soak`` then says the soak does not fit)."""
    limits = plan.limits
    candidate = plan
    for _ in range(SOAK_ROOM_TRIES):
        soak, _, _ = end_state(candidate, model)
        over = candidate.programme.total_min + soak - limits.duration_max_min
        if over <= 1e-9:
            return dataclasses.replace(candidate, limits=limits)
        shorter = math.floor(candidate.limits.duration_max_min - over)
        if shorter < 1:
            break
        try:
            candidate = replan(dataclasses.replace(limits, duration_max_min=float(shorter)))
        except (InfeasiblePlanError, ParameterError):
            # nothing can be planned within the shorter limit: the soak does not fit, and
            # with_end_soak says so for the request's own limit (not the shorter one's
            # error: "no complete plan exists within 111 min" when 240 were asked)
            break
        if not candidate.complete:
            break
    return plan


def with_end_soak(plan: Plan, model=None) -> Plan:
    """The plan with a hold appended at its end temperature until the device settles
    (``--end-soak``), re-checked: coverage, limits and completeness of the new table.

    Raises :class:`ParameterError` when the soak does not fit in the time limit.
    """
    from ..planner import check_programme

    soak, _, _ = end_state(plan, model)
    if soak <= 0:
        return plan
    from ..programme import StepTableMeta

    base = plan.programme
    try:  # the metadata records the soak the table includes (end_soak_included_min)
        prog = base.with_meta(base.meta or StepTableMeta()).with_end_soak(soak, plan.limits)
    except ParameterError as exc:
        hint = (
            "; or try --objective informative with --end-soak (objective = "
            '"informative" in a campaign\'s [settings]): it plans the run to end settled '
            "within the limit where it can (red team: 399 of 400 min where this plan's "
            "soak did not fit)"
            if plan.spec.objective != "informative"
            else ""
        )
        raise ParameterError(f"{plan.spec.name}: --end-soak: {exc}{hint}") from None
    # the soak runs after the planned sweeps, so the device passes bins again: check anew
    scenarios = tuple(plan.scenarios) or (plan.params,)
    cov, cov01, problems, t_lo, t_hi = check_programme(
        prog, plan.spec, plan.limits, scenarios, model=model
    )
    box_check = plan.box_check
    complete = plan.complete and cov.complete and not problems
    notes = (*plan.notes, f"an end soak of {soak:g} min was appended (--end-soak)")
    if len(scenarios) > 1 and box_check is not None:
        box_check = _box_check(prog, plan, scenarios)
        complete = complete and bool(box_check["holds"])
    return dataclasses.replace(
        plan,
        programme=prog,
        coverage=cov,
        coverage_0p1=cov01,
        complete=complete,
        status=(  # a broken limit dominates "incomplete"
            plan.status
            if complete
            else "limits violated"
            if problems
            else (plan.status if not plan.complete else "incomplete")
        ),
        violations=tuple(problems),
        notes=notes,
        t_min_c=t_lo,
        t_max_c=t_hi,
        box_check=box_check,
    )


def _box_check(programme, plan: Plan, scenarios) -> dict:
    """The robust box check of a modified programme (the planner's own check)."""
    from ..planner.robust import verify_robust

    taus = [p.tau_s for p in scenarios]
    dt0s = [p.dt0_c for p in scenarios]
    return verify_robust(
        programme,
        plan.spec,
        plan.params,
        (min(taus), max(taus)),
        (min(dt0s), max(dt0s)),
        plan.limits,
    )


#: A complete shortest plan this far above its proven bound (share of the bound, and at
#: least SHORTEN_HINT_MIN min) gets the hint to try --shorten. The paper's four regions
#: plan 32-39 % above their bounds (README's benchmark table) and get none; a red team's
#: request (3 levels, 30-min segments) planned 330 min against a bound of 112 with the
#: band search, and 181 min when the timetable stage planned it.
SHORTEN_HINT_SHARE = 0.5
SHORTEN_HINT_MIN = 30.0


def shorten_hint(plan: Plan) -> str | None:
    """The hint to plan again with ``--shorten``, for a complete plan of the shortest
    objective, one model and no continuation, far above its proven bound (not counting an
    end soak appended to it) and planned by the band search alone; else None. (The caller
    leaves it out where ``--shorten`` ran or cannot apply, :func:`report_plan`.)"""
    bound = plan.duration_lower_bound_min
    if (
        not plan.complete
        or plan.spec.objective != "shortest"
        or len(plan.scenarios) > 1
        or plan.continued_from_min is not None
        or bound is None
        or not math.isfinite(bound)
        or any(n.startswith("planned by the timetable stage") for n in plan.notes)
    ):
        return None
    meta = plan.programme.meta
    soak = (meta.end_soak_included_min if meta is not None else None) or 0.0
    gap = plan.duration_min - soak - bound
    if gap < max(SHORTEN_HINT_SHARE * bound, SHORTEN_HINT_MIN):
        return None
    return (
        f"{gap:.0f} min above the bound: the timetable stage may find a shorter plan "
        "(plan again with --shorten; a minute or two more planning, less robust to model "
        "error)"
    )


def report_plan(plan: Plan, shorten_hint_ok: bool = True) -> list[str]:
    """Lines describing a plan; an incomplete plan says so loudly, with its short bins.
    ``shorten_hint_ok``: the request could be planned again with ``--shorten`` and was not
    (else no :func:`shorten_hint`)."""
    s = plan.spec
    lines = [
        f"{s.name}: [{s.working_lo_c:g}, {s.working_hi_c:g}] °C, "
        f"{plan.duration_min:g} min, {plan.steps} steps, status {plan.status}, "
        f"solved in {plan.solve_s:.1f} s",
        "  " + plan.coverage.summary(),
        f"  coverage at Δ 0.1 °C/min: {plan.coverage_0p1.coverage:.1%}",
    ]
    if plan.duration_lower_bound_min is not None:
        bound = plan.duration_lower_bound_min
        lines.append(
            f"  proven lower bound on any complete plan: {bound:.0f} min "
            + (
                f"(this plan {plan.gap_to_bound_min:+.0f} min)"
                if plan.complete
                else f"(this plan, not complete, {plan.duration_min:g} min)"
            )
            if math.isfinite(bound)
            else "  proven: no complete plan exists (some bin cannot be crossed at all)"
        )
        hint = shorten_hint(plan) if shorten_hint_ok else None
        if hint:
            lines.append(f"  hint: {hint}")
    if plan.coverage_nominal is not None:
        p = plan.params
        lines.append(
            f"  robust: coverage {plan.coverage_nominal.coverage:.1%} at the nominal tau "
            f"{p.tau_s:g} s, dT0 {p.dt0_c:g} °C; {plan.coverage.coverage:.1%} at the worst "
            "design scenario of the box"
            + (f"; planned for the {plan.robust_fallback}" if plan.robust_fallback else "")
        )
    if not plan.complete:
        lines.insert(
            0,
            f"*** {s.name} IS NOT COMPLETE ({plan.status}): do not run it as a "
            "full calibration ***",
        )
        lines += [f"  violation: {v}" for v in plan.violations]
    lines += [f"  note: {n}" for n in plan.notes]
    return lines


def design_lines(plan: Plan) -> list[str]:
    """How informative the plan is for the drift fit (:mod:`schedsyn.design`)."""
    from ..design import plan_design

    try:
        return ["  " + plan_design(plan).summary()]
    except ParameterError as exc:
        return [f"  drift-fit design: not computed ({exc})"]


# ---------------------------------------------------------------------------------------
def _robust(text: str | None, name: str):
    if text is None:
        return None
    from ..sweep import parse_range

    return parse_range(text, name)


def _model(args, params: ThermalParams, limits: Limits):
    """``(params, limits, linear model or None, model file dict or None)`` from ``--model``."""
    if args.model is None:
        return params, limits, None, None
    from ..models_io import load_model

    spec = load_model(args.model)
    params = _common.thermal_params(args, ThermalParams(spec.tau_s, spec.dt0_c))
    spec = dataclasses.replace(spec, tau_s=params.tau_s, dt0_c=params.dt0_c)
    if not spec.is_linear:
        raise ParameterError(
            f"model file {args.model}: the effect {spec.effect!r} is not linear; the planner "
            "needs a linear model (plan with the base model and check the plan with "
            "schedsyn simulate --model)"
        )
    return params, spec.planner_limits(limits), spec.linear_model(), spec.to_json_dict()


def build_spec(args, limits: Limits) -> ExperimentSpec:
    lo, hi = args.working
    from ..design import DesignSpace

    approx = args.approx if args.approx is not None else DesignSpace.default_approx(lo, hi, limits)
    alo, ahi = approx
    for name, v in (("--working", lo), ("--working", hi), ("--approx", alo), ("--approx", ahi)):
        if not math.isfinite(v):
            raise ParameterError(f"{name} values must be finite numbers, got {v}")
    return ExperimentSpec(
        name=args.name,
        working_lo_c=lo,
        working_hi_c=hi,
        approx_lo_c=alo,
        approx_hi_c=ahi,
        levels_required=args.levels,
        delta_c_per_min=args.delta_c_per_min,
        segment_min=args.segment_min,
        objective=args.objective,
        max_steps=_max_steps(args),
    )


def _effort_s(args) -> float | None:
    """``--effort-s``: None (no limit) for 0, the planner's default when not given."""
    from ..planner.core import EFFORT_S

    if args.effort_s is None:
        return EFFORT_S
    if not args.effort_s >= 0:
        raise ParameterError(f"--effort-s must be >= 0 s (0 = no limit), got {args.effort_s:g}")
    return None if args.effort_s == 0 else args.effort_s


def _max_steps(args) -> int:
    """``--max-steps``, else the ``--chamber`` preset's step limit, else 80."""
    if args.max_steps is not None:
        return args.max_steps
    if getattr(args, "chamber", None):
        from ..chambers import chamber_preset

        return chamber_preset(args.chamber).max_steps
    return 80


def _pick(pairs, results):
    """The least demanding chamber with a complete plan, else the best coverage."""
    from ..planner import Plan

    done = [(i, r) for i, r in enumerate(results) if isinstance(r, Plan)]
    if not done:
        return None
    complete = [(i, r) for i, r in done if r.complete]
    if complete:  # highest floor, then lowest ceiling
        return min(complete, key=lambda ir: (-pairs[ir[0]][0], pairs[ir[0]][1]))[1]
    return max(done, key=lambda ir: (ir[1].coverage.coverage, ir[1].coverage.min_levels))[1]


def run(args: argparse.Namespace) -> int:
    from ..campaign import chamber_frame, chamber_plans
    from ..chambers import limits_with_preset
    from ..errors import InfeasiblePlanError
    from ..io import write_frame_atomic
    from ..planner import plan_experiment

    base = limits_with_preset(
        args.chamber,
        Limits(),
        duration_max_min=args.duration_max_min,
        rate_min_c_per_min=args.rate_min_c_per_min,
        rate_max_c_per_min=args.rate_max_c_per_min,
    )
    floors = args.chamber_min_c or [base.chamber_min_c]
    ceilings = args.chamber_max_c or [base.chamber_max_c]
    limits = dataclasses.replace(
        _common.device_limits(args, base), chamber_min_c=floors[0], chamber_max_c=ceilings[0]
    )
    params, limits, model, model_json = _model(args, _common.thermal_params(args), limits)
    for note in unit_slip_notes(params, limits):
        _common.stderr(f"warning: {note}")
    spec = build_spec(args, limits)
    robust_tau = _robust(args.robust_tau_s, "--robust-tau-s")
    robust_dt0 = _robust(args.robust_dt0_c, "--robust-dt0-c")
    several = not (len(floors) == 1 and len(ceilings) == 1)
    if several and model is not None:
        raise ParameterError(
            "--model with several chamber floors/ceilings is not "
            "supported; give one --chamber-min-c/--chamber-max-c"
        )
    if args.shorten and several:
        raise ParameterError(
            "--shorten plans one chamber: give one --chamber-min-c and one --chamber-max-c, "
            "or drop --shorten"
        )
    if args.advise and (model is not None or robust_tau is not None or robust_dt0 is not None):
        raise ParameterError(
            "--advise searches with the nominal first-order model: drop --model and "
            "--robust-tau-s/--robust-dt0-c, or drop --advise"
        )
    inputs = [args.model] if args.model else []
    names = list(PLAN_FILES)
    if args.advise:
        names += ADVICE_FILES
    if several:
        names.append("chamber.csv")
    if robust_tau is not None or robust_dt0 is not None:
        names.append("price.csv")
    # checked before any planning: outputs are not inputs, the folder can be written
    out = _common.output_dir(args.out, "out/plan", inputs, names)
    reporter = _common.progress_of(args)
    progress = None
    if not args.quiet:
        import time

        tic = time.perf_counter()

        def progress(message: str) -> None:  # experiment, solver time so far, message
            reporter(f"{spec.name} [{time.perf_counter() - tic:6.1f} s] {message}")

    lines: list[str] = []
    if not several:

        def plan_within(lim: Limits) -> Plan:
            return plan_experiment(
                spec,
                params,
                lim,
                model=model,
                robust_tau_s=robust_tau,
                robust_dt0_c=robust_dt0,
                progress=progress,
                effort_s=_effort_s(args),
                shorten=args.shorten,
                end_soak=args.end_soak,
            )

        try:
            plan = plan_within(limits)
            if args.end_soak and spec.objective == "informative":
                plan = informative_with_room_for_soak(plan, plan_within, model)
        except InfeasiblePlanError:
            if args.advise:  # nothing planned: still say what would make it plannable
                said, _ = advise_plan(
                    spec, params, limits, None, args, advice_progress(args, spec), out.folder(".")
                )
                out.commit()
                _common.say(*said, f"wrote {out.target}/advice.csv")
            raise
    else:
        pairs, results = chamber_plans(
            spec,
            floors,
            ceilings,
            params,
            limits,
            robust_tau_s=robust_tau,
            robust_dt0_c=robust_dt0,
            # runs in worker processes: a picklable callable
            progress=None if args.quiet else reporter,
        )
        frame = chamber_frame(pairs, results)
        write_frame_atomic(out.path("chamber.csv"), frame)
        lines += [
            "coverage vs chamber floor/ceiling:",
            frame.drop(columns=["notes"]).to_string(index=False),
        ]
        plan = _pick(pairs, results)
        if plan is None:
            out.commit()  # the table says what each chamber reaches
            _common.say(*lines, f"wrote {out.target}/chamber.csv")
            best = max(r.best_coverage for r in results if not isinstance(r, Plan))
            raise InfeasiblePlanError(
                f"no chamber in the list can plan {spec.name}; best reachable coverage is "
                f"{best:.0%} ({results[0]})",
                best_coverage=best,
            )
        lines.append(
            f"files below are for the chamber {plan.limits.chamber_min_c:g} .. "
            f"{plan.limits.chamber_max_c:g} °C"
        )
    advice_lines: list[str] = []
    advice_json = None
    if not plan.complete:
        if args.advise:
            advice_lines, advice = advise_plan(
                spec, params, plan.limits, plan, args, advice_progress(args, spec), out.folder(".")
            )
            advice_json = {"advice": advice}
        elif (
            plan.coverage.complete
            and plan.violations
            and all("max_steps" in v or "min_step_min" in v for v in plan.violations)
        ):  # only the step limits are broken: --advise's knobs would not help
            advice_lines = [
                f"  every bin is covered but the table breaks its step limits "
                f"({plan.programme.n_segments} steps, max_steps {spec.max_steps}; the planner "
                "also tried longer segments): raise --max-steps (or lower min_step_min in a "
                "campaign file) to what the controller takes, or split the region "
                "(schedsyn split)"
            ]
        elif any(n.startswith(NO_PROGRAMME_COVERS_BOX) for n in plan.notes):
            advice_lines = [  # proven: more time or effort would not help
                "  no programme covers the whole robust box (the note above proves it): "
                "narrow the box (--robust-dt0-c) or widen the device limit (--device-min-c / "
                "--device-max-c) as the note says; more time or search effort would not help"
            ]
        elif robust_tau is not None or robust_dt0 is not None:
            # --advise searches with the nominal model and refuses a box: say what helps
            advice_lines = [
                "  the plan does not hold on the whole robust box: plan.json's "
                "robust_box_check names the part it covers; narrow the box "
                "(--robust-tau-s/--robust-dt0-c) to what the device's uncertainty needs, "
                "allow more time (--duration-max-min) or search effort (--effort-s, 0 = no "
                "limit); --advise searches the nominal model only (run it without the box "
                "to see what the nominal plan needs)"
            ]
        elif model is not None:
            advice_lines = [
                "  --advise searches the nominal first-order model only: run it without "
                "--model to see what the nominal plan needs, or allow more time "
                "(--duration-max-min) or search effort (--effort-s, 0 = no limit)"
            ]
        else:
            advice_lines = [
                "  run again with --advise to search what would make it complete "
                "(duration, chamber floor, ceiling, rates or levels; each verified by a plan)"
            ]
    if args.end_soak:
        plan = with_end_soak(plan, model)
    write_plan_outputs(
        plan, out.folder("."), model=model, model_json=model_json, extra_json=advice_json
    )
    lines += report_plan(plan, shorten_hint_ok=not (args.shorten or several))
    lines += design_lines(plan)
    lines += end_soak_lines(plan, model)
    lines += advice_lines
    _common.say(*lines)  # the plan's report now; the price may take as long again
    lines = []
    wrote = ["steps.csv", "plan.json", "program.png", "phase.png", "coverage.png"]
    if advice_json is not None:
        wrote.append("advice.csv")
    if several:
        wrote.append("chamber.csv")
    if (robust_tau is not None or robust_dt0 is not None) and not args.no_price:
        from ..planner import robustness_price

        if progress is not None:
            progress("planning the nominal point for the price of robustness")
        try:
            nominal = plan_experiment(spec, params, plan.limits, progress=progress)
        except InfeasiblePlanError as exc:  # the robust plan's files are written anyway
            lines.append(
                f"price of robustness not computed: the nominal point cannot be planned ({exc})"
            )
        else:
            price = robustness_price(nominal, plan, robust_tau, robust_dt0)
            write_frame_atomic(out.path("price.csv"), price)
            lines += [
                "price of robustness (both plans checked on the same grid over the box):",
                price.to_string(index=False),
            ]
            wrote.append("price.csv")
    out.commit()
    lines.append(f"wrote {out.target}/" + ", ".join(wrote))
    _common.say(*lines)
    return 0 if plan.complete else 1
