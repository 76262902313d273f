"""``schedsyn simulate STEPS.csv``: simulate a step table, report coverage, write plots."""

from __future__ import annotations

import argparse

from ..coverage import trajectory_coverage
from ..io import write_frame_atomic
from ..params import ThermalParams
from ..programme import read_steps
from ..simulate import simulate
from . import _common
from . import fit as fit_cli


def register(sub) -> None:
    p = sub.add_parser(
        "simulate", help="simulate a step table and report its coverage", description=__doc__
    )
    p.add_argument("steps", metavar="STEPS.csv", help="chamber step table")
    p.add_argument("--out", default=None, help="output directory (default out/simulate)")
    _common.add_model_options(p)
    _common.add_region_option(p)
    _common.add_limit_options(p)
    p.add_argument("--levels", type=int, default=6, help="required distinct gradient levels")
    p.add_argument(
        "--delta-c-per-min",
        type=float,
        default=0.05,
        help="minimum gradient difference between levels, °C/min",
    )
    p.add_argument("--dt-min", type=float, default=0.1, help="simulation step, min")
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL.json",
        help="augmented model file (from `schedsyn diagnose --out DIR`); "
        "--tau-s/--dt0-c then override its base",
    )
    fit_cli.add_simulate_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .. import plots

    params = _common.thermal_params(args)
    limits = _common.limits(args)
    programme = read_steps(args.steps, limits)
    if args.model is not None:  # an augmented model: exact if linear, else on a grid
        import dataclasses

        from ..models_io import load_model, simulate_effect

        spec = load_model(args.model)
        params = _common.thermal_params(args, ThermalParams(spec.tau_s, spec.dt0_c))
        spec = dataclasses.replace(spec, tau_s=params.tau_s, dt0_c=params.dt0_c)
        limits = spec.planner_limits(limits)
        traj = simulate_effect(programme, spec, dt_min=args.dt_min, t0_c=limits.t_init_c)
        print(
            f"model {args.model}: effect {spec.effect} "
            f"{dict(spec.parameters) if spec.parameters else ''}"
        )
    else:
        traj = simulate(programme, params, dt_min=args.dt_min, t0_c=limits.t_init_c)
    lo, hi = args.region
    report = trajectory_coverage(traj, lo, hi, args.levels, args.delta_c_per_min)
    out = _common.out_dir(args.out, "out/simulate")
    inputs = [args.steps]
    write_frame_atomic(out / "trajectory.csv", traj.to_frame(), inputs)
    write_frame_atomic(out / "coverage.csv", report.to_frame(), inputs)
    plots.save_figure(
        plots.programme_plot(traj, region=(lo, hi), title=f"programme {args.steps}"),
        out / "program.png",
        inputs,
    )
    plots.save_figure(
        plots.phase_plot(
            traj.t_c,
            traj.g_c_per_min,
            region=(lo, hi),
            title=f"phase portrait (tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C)",
        ),
        out / "phase.png",
        inputs,
    )
    plots.save_figure(plots.coverage_plot(report), out / "coverage.png", inputs)
    print(
        f"programme: {programme.n_segments} steps, {programme.total_min:.1f} min, "
        f"chamber {programme.boundary_temps_c.min():.1f} .. "
        f"{programme.boundary_temps_c.max():.1f} °C"
    )
    print(
        f"internal temperature: min {traj.t_c.min():.2f} °C, max {traj.t_c.max():.2f} °C "
        f"(tau {params.tau_s:g} s, dT0 {params.dt0_c:g} °C)"
    )
    for v in programme.violations(limits):
        print(f"warning: {v}")
    if traj.t_c.min() < limits.device_min_c or traj.t_c.max() > limits.device_max_c:
        print(
            f"warning: the internal temperature leaves the device limits "
            f"{limits.device_min_c:g} .. {limits.device_max_c:g} °C"
        )
    print(report.summary())
    extra = fit_cli.simulate_hook(args, programme, params, limits, traj, out, inputs)
    names = ["trajectory.csv", "coverage.csv", "program.png", "phase.png", "coverage.png"]
    print(f"wrote {out}/" + ", ".join(names + extra))
    return 0
