"""``schedsyn simulate STEPS.csv``: simulate a step table, report its coverage and end, write
trajectory.csv, coverage.csv and the plots.

The working region, the model (tau, dT0, an augmented model), the coverage requirement and
the limits are those the step table records in its metadata (a table written by
``schedsyn plan`` or ``campaign``); options override them. A table without a recorded
working region needs --region: the region is never guessed.
"""

from __future__ import annotations

import argparse

import numpy as np

from ..coverage import trajectory_coverage
from ..io import write_frame_atomic
from ..params import ThermalParams
from ..programme import read_step_meta, read_steps
from ..simulate import end_soak_min, simulate
from . import _common
from . import fit as fit_cli

NAMES = ("trajectory.csv", "coverage.csv", "program.png", "phase.png", "coverage.png")


def register(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate a step table and report its coverage",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("steps", metavar="STEPS.csv", help="chamber step table")
    p.add_argument("--out", default=None, help="output directory (default out/simulate)")
    _common.add_model_options(p, default_from="the step table's")
    _common.add_region_option(p)
    _common.add_limit_options(p)
    _common.add_coverage_options(p)
    p.add_argument("--dt-min", type=float, default=None, help="simulation step, min (default 0.1)")
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL.json",
        help="augmented model file (from schedsyn diagnose --out DIR); --tau-s/--dt0-c "
        "then override its base (default: the model the step table records)",
    )
    fit_cli.add_simulate_options(p)
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from .. import plots
    from ..models_io import simulate_effect

    meta = read_step_meta(args.steps)
    limits = _common.limits(args, meta.limits() if meta is not None else None)
    programme = read_steps(args.steps, limits)
    lo, hi = _common.region_from_table(args, programme.meta, args.steps)
    levels, delta = _common.coverage_settings(args, programme.meta)
    params, source = _common.model_from_table(args, programme.meta)
    dt_min = 0.1 if args.dt_min is None else args.dt_min
    out = _common.output_dir(args.out, "out/simulate", [args.steps, args.model], NAMES)
    spec, spec_from = _common.augmented_model(args.model, programme.meta, args.steps)
    lines = [
        f"programme: {programme.n_segments} steps, {programme.total_min:.1f} min, "
        f"chamber {programme.boundary_temps_c.min():.1f} .. "
        f"{programme.boundary_temps_c.max():.1f} °C"
    ]
    if programme.meta is not None:  # what the table was planned for and is not
        from ..export import planned_for_notes

        recorded = {
            k: str(v)
            for k in ("status", "max_steps", "min_step_min")
            if (v := getattr(programme.meta, k)) is not None
        }
        lines += [f"*** {n} ***" for n in planned_for_notes(recorded, programme, str(args.steps))]
    model = None
    if spec is not None:  # an augmented model: exact if linear, else on a grid
        base = ThermalParams(spec.tau_s, spec.dt0_c)
        params = _common.thermal_params(args, base)
        source = f"from {spec_from}"
        spec = dataclasses.replace(spec, tau_s=params.tau_s, dt0_c=params.dt0_c)
        limits = spec.planner_limits(limits)
        traj = simulate_effect(programme, spec, dt_min=dt_min, t0_c=limits.t_init_c)
        model = spec.linear_model() if spec.is_linear else None
        effect = f"{spec.effect} {dict(spec.parameters) if spec.parameters else ''}".strip()
        lines.append(
            f"model ({source}): effect {effect}, tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C"
        )
    else:
        traj = simulate(programme, params, dt_min=dt_min, t0_c=limits.t_init_c)
        lines.append(f"model: tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C ({source})")
    region_src = "given" if args.region is not None else "from the step table"
    lines.append(f"working region: [{lo:g}, {hi:g}] °C ({region_src})")
    tau_box, dt0_box = programme.meta.robust_box if programme.meta is not None else (None, None)
    if tau_box is not None or dt0_box is not None:
        box = " x ".join(
            t
            for t in (
                f"tau {tau_box[0]:g} .. {tau_box[1]:g} s" if tau_box else "",
                f"dT0 {dt0_box[0]:g} .. {dt0_box[1]:g} °C" if dt0_box else "",
            )
            if t
        )
        lines.append(
            f"the table was planned for the robust box {box}; this is its nominal point "
            "(schedsyn sweep checks the box)"
        )
    report = trajectory_coverage(traj, lo, hi, levels, delta)
    soak = end_soak_min(
        programme, params, model=model, tol_c=limits.end_tol_c, t0_c=limits.t_init_c
    )
    settled = float(
        simulate(
            programme, params, model=model, t0_c=limits.t_init_c, times_min=np.array([1e6])
        ).t_c[0]
    )

    write_frame_atomic(out.path("trajectory.csv"), traj.to_frame())
    write_frame_atomic(out.path("coverage.csv"), report.to_frame())
    experiment = meta.experiment if meta is not None else None
    name = f"{args.steps}" + (f" ({experiment})" if experiment else "")
    plots.save_figure(
        plots.programme_plot(
            traj,
            region=(lo, hi),
            limits=limits,
            programme=programme,
            title=f"programme {name}",
        ),
        out.path("program.png"),
    )
    plots.save_figure(
        plots.phase_plot(
            traj.t_c,
            traj.g_c_per_min,
            region=(lo, hi),
            title=f"phase portrait (tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C)",
        ),
        out.path("phase.png"),
    )
    plots.save_figure(plots.coverage_plot(report), out.path("coverage.png"))
    extra, fit_lines = fit_cli.simulate_hook(
        args, programme, params, limits, traj, (lo, hi), out, [args.steps]
    )
    out.commit()

    lines.append(f"internal temperature: min {traj.t_c.min():.2f} °C, max {traj.t_c.max():.2f} °C")
    lines.append(_common.end_soak_text(programme, float(traj.t_c[-1]), soak, settled, limits))
    lines += [f"warning: {v}" for v in programme.violations(limits)]
    if traj.t_c.min() < limits.device_min_c or traj.t_c.max() > limits.device_max_c:
        lines.append(
            f"warning: the internal temperature leaves the device limits "
            f"{limits.device_min_c:g} .. {limits.device_max_c:g} °C"
        )
    lines.append(report.summary())
    lines += fit_lines
    lines.append(f"wrote {out.target}/" + ", ".join([*NAMES, *extra]))
    _common.say(*lines)
    return 0
