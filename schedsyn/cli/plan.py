"""``schedsyn plan --working LO HI --approx LO HI``: plan one experiment, write its files.

Writes to ``--out`` (default ``out/plan``): ``steps.csv`` (the step table to type in),
``plan.json`` (model, settings, coverage, solver status and time), ``program.png``,
``phase.png`` and ``coverage.png``. With several ``--chamber-min-c`` / ``--chamber-max-c``
values it answers "what chamber do I need?": one plan per (floor, ceiling), the table in
``chamber.csv``, and the files of the least demanding chamber that reaches full coverage
(or of the best one when none does).

Exit codes: 0 the plan is complete (every bin covered by the independent check of the
exported table, every limit met); 1 a plan was made but is incomplete; 2 bad input or
nothing could be planned (the message names the best coverage reachable).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

from ..errors import ParameterError
from ..params import Limits, ThermalParams
from ..planner import OBJECTIVES, ExperimentSpec, Plan
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "plan",
        help="plan one experiment (programme with full coverage)",
        description=__doc__,
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
        default=5.0,
        help="decision segment length, whole min (default 5)",
    )
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default="shortest",
        help="shortest programme, or largest margin within the time limit",
    )
    p.add_argument(
        "--max-steps",
        type=int,
        default=80,
        help="most steps the exported table may have (default 80)",
    )
    p.add_argument(
        "--duration-max-min",
        type=float,
        default=None,
        help="time limit of the experiment, min (default 540)",
    )
    _common.add_model_options(p)
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
        help="plan with a linear augmented model file (from `schedsyn diagnose`); "
        "--tau-s/--dt0-c then override its base",
    )
    p.add_argument("--out", default=None, help="output directory (default out/plan)")
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    p.set_defaults(func=run)


# ---------------------------------------------------------------------------------------
# outputs shared with `schedsyn campaign`
# ---------------------------------------------------------------------------------------
def write_plan_outputs(plan: Plan, out: Path, inputs=(), model=None, model_spec=None) -> list[Path]:
    """Write steps.csv, plan.json, program.png, phase.png, coverage.png into ``out``.

    ``model_spec`` (a :class:`~schedsyn.effects.ModelSpec`, the ``--model`` file) is
    recorded in plan.json as ``model``, where ``schedsyn monitor``/``replan`` read it.
    """
    from .. import plots
    from ..io import write_json_atomic
    from ..simulate import simulate

    out = Path(out)
    spec = plan.spec
    region = (spec.working_lo_c, spec.working_hi_c)
    written = [
        plan.programme.to_csv(out / "steps.csv", inputs),
        write_json_atomic(
            out / "plan.json",
            plan.to_json_dict()
            | ({} if model_spec is None else {"model": model_spec.to_json_dict()}),
            inputs,
        ),
    ]
    traj = simulate(plan.programme, plan.params, model=model, dt_min=0.1, t0_c=plan.limits.t_init_c)
    state = "complete" if plan.complete else f"NOT COMPLETE ({plan.status})"
    written.append(
        plots.save_figure(
            plots.programme_plot(
                traj,
                region=region,
                title=f"{spec.name}: {plan.duration_min:g} min, {plan.steps} steps, {state}",
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
                title=f"{spec.name}: phase portrait (tau {plan.params.tau_s:g} s, "
                f"dT0 {plan.params.dt0_c:g} °C)",
            ),
            out / "phase.png",
            inputs,
        )
    )
    written.append(
        plots.save_figure(
            plots.coverage_plot(
                plan.coverage,
                title=f"{spec.name}: {'' if plan.complete else 'NOT COMPLETE, '}"
                f"coverage {plan.coverage.coverage:.0%} "
                f"(Δ {spec.delta_c_per_min:g}), "
                f"{plan.coverage_0p1.coverage:.0%} at Δ 0.1 °C/min",
            ),
            out / "coverage.png",
            inputs,
        )
    )
    return written


def report_plan(plan: Plan) -> list[str]:
    """Lines describing a plan; an incomplete plan says so loudly, with its short bins."""
    s = plan.spec
    lines = [
        f"{s.name}: [{s.working_lo_c:g}, {s.working_hi_c:g}] °C, "
        f"{plan.duration_min:g} min, {plan.steps} steps, status {plan.status}, "
        f"solved in {plan.solve_s:.1f} s",
        "  " + plan.coverage.summary(),
        f"  coverage at Δ 0.1 °C/min: {plan.coverage_0p1.coverage:.1%}",
    ]
    if not plan.complete:
        lines.insert(
            0,
            f"*** {s.name} IS NOT COMPLETE ({plan.status}): do not run it as a "
            "full calibration ***",
        )
        lines += [f"  violation: {v}" for v in plan.violations]
        lines += [f"  note: {n}" for n in plan.notes]
    return lines


# ---------------------------------------------------------------------------------------
def _default_approx(lo: float, hi: float, limits: Limits) -> tuple[float, float]:
    # the paper's rule: 10 degC wider on each side, but not beyond the device limits
    return max(lo - 10.0, limits.device_min_c), min(hi + 10.0, limits.device_max_c)


def _robust(text: str | None, name: str):
    if text is None:
        return None
    from ..sweep import parse_range

    return parse_range(text, name)


def _model(args, params: ThermalParams, limits: Limits):
    """``(params, limits, linear model, model spec)`` from ``--model`` (Nones without)."""
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
            "`schedsyn simulate --model`)"
        )
    return params, spec.planner_limits(limits), spec.linear_model(), spec


def build_spec(args, limits: Limits) -> ExperimentSpec:
    lo, hi = args.working
    alo, ahi = args.approx if args.approx is not None else _default_approx(lo, hi, limits)
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
        max_steps=args.max_steps,
    )


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
    from ..campaign import chamber_frame, chamber_plans, stderr_progress
    from ..errors import InfeasiblePlanError
    from ..io import write_frame_atomic
    from ..planner import plan_experiment

    base = Limits()
    if args.duration_max_min is not None:
        base = dataclasses.replace(base, duration_max_min=args.duration_max_min)
    floors = args.chamber_min_c or [base.chamber_min_c]
    ceilings = args.chamber_max_c or [base.chamber_max_c]
    limits = dataclasses.replace(base, chamber_min_c=floors[0], chamber_max_c=ceilings[0])
    params, limits, model, model_spec = _model(args, _common.thermal_params(args), limits)
    spec = build_spec(args, limits)
    robust_tau = _robust(args.robust_tau_s, "--robust-tau-s")
    robust_dt0 = _robust(args.robust_dt0_c, "--robust-dt0-c")
    out = _common.out_dir(args.out, "out/plan")
    progress = None
    if not args.quiet:
        import time

        tic = time.perf_counter()

        def progress(message: str) -> None:  # experiment, solver time so far, message
            stderr_progress(f"{spec.name} [{time.perf_counter() - tic:6.1f} s] {message}")

    inputs = [args.model] if args.model else []

    if len(floors) == 1 and len(ceilings) == 1:
        plan = plan_experiment(
            spec,
            params,
            limits,
            model=model,
            robust_tau_s=robust_tau,
            robust_dt0_c=robust_dt0,
            progress=progress,
        )
    else:
        if model is not None:
            raise ParameterError(
                "--model with several chamber floors/ceilings is not "
                "supported; give one --chamber-min-c/--chamber-max-c"
            )
        pairs, results = chamber_plans(
            spec,
            floors,
            ceilings,
            params,
            limits,
            robust_tau_s=robust_tau,
            robust_dt0_c=robust_dt0,
            # runs in worker processes: a picklable callable
            progress=None if args.quiet else stderr_progress,
        )
        frame = chamber_frame(pairs, results)
        write_frame_atomic(out / "chamber.csv", frame, inputs)
        print("coverage vs chamber floor/ceiling:")
        print(frame.drop(columns=["notes"]).to_string(index=False))
        print(f"wrote {out}/chamber.csv")
        plan = _pick(pairs, results)
        if plan is None:
            best = max(r.best_coverage for r in results if not isinstance(r, Plan))
            raise InfeasiblePlanError(
                f"no chamber in the list can plan {spec.name}; best reachable coverage is "
                f"{best:.0%} ({results[0]})",
                best_coverage=best,
            )
        print(
            f"files below are for the chamber {plan.limits.chamber_min_c:g} .. "
            f"{plan.limits.chamber_max_c:g} °C"
        )
    write_plan_outputs(plan, out, inputs, model=model, model_spec=model_spec)
    print("\n".join(report_plan(plan)))
    print(f"wrote {out}/steps.csv, plan.json, program.png, phase.png, coverage.png")
    if (robust_tau is not None or robust_dt0 is not None) and not args.no_price:
        from ..planner import robustness_price

        if progress is not None:
            progress("planning the nominal point for the price of robustness")
        try:
            nominal = plan_experiment(spec, params, plan.limits, progress=progress)
        except InfeasiblePlanError as exc:  # the robust plan's files are written already
            print(f"price of robustness not computed: the nominal point cannot be planned ({exc})")
        else:
            price = robustness_price(nominal, plan, robust_tau, robust_dt0)
            write_frame_atomic(out / "price.csv", price, inputs)
            print("price of robustness (both plans checked on the same grid over the box):")
            print(price.to_string(index=False))
            print(f"wrote {out}/price.csv")
    return 0 if plan.complete else 1
