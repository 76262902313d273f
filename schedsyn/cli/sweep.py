"""``schedsyn sweep STEPS.csv``: coverage of a plan over a tau x dT0 grid (or re-plan there).

Writes ``DIR/sweep.csv`` (one row per grid point) and ``DIR/sweep.png`` (heatmaps with
the nominal point marked) and prints a summary. Runs in parallel on the local cores by
default, or on a Dask cluster with ``--dask tcp://HOST:PORT``. The working region, the
nominal point and the coverage requirement are the step table's (its metadata) unless
given; a table that records no working region needs --region. The default grid is around
the nominal point and takes in the robust box the table records. An augmented model
(--model, else the one the step table records) is swept over its base tau and dT0 with its
effect held at its fitted strength.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, SchedsynError
from ..io import write_frame_atomic
from ..params import Limits, ThermalParams, unit_slip_notes
from ..programme import read_step_meta, read_steps
from ..sweep import (
    DEFAULT_DT0_SPREAD_C,
    DEFAULT_TAU_SPREAD,
    TAU_PARAMETERS,
    default_grid,
    parse_grid,
    sweep_fixed,
    sweep_replan,
)
from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "sweep",
        help="coverage of a plan over a grid of tau and dT0 (or re-plan at every grid point)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "steps",
        metavar="STEPS.csv",
        nargs="?",
        default=None,
        help="chamber step table (not needed with --replan)",
    )
    _common.add_region_option(
        p,
        help_text="working region LO HI, °C (default: the one the step table records; "
        "needed with --replan)",
    )
    p.add_argument(
        "--approx",
        nargs=2,
        type=float,
        default=None,
        metavar=("LO_C", "HI_C"),
        help="approximation region for --replan, °C (default: 10 °C beyond the "
        "working region, within the device limits)",
    )
    p.add_argument(
        "--tau-s",
        default=None,
        metavar="START:STOP:N",
        help="grid of time constants, s (default: 13 values from 0.75 to 1.25 x the "
        "nominal tau, widened to the step table's robust box; 1800:3000:13 around 2400 s)",
    )
    p.add_argument(
        "--dt0-c",
        default=None,
        metavar="START:STOP:N",
        help="grid of self-heating offsets, °C (default: 13 values within 3 °C of the "
        "nominal dT0, widened to the step table's robust box; 0:6:13 around 3 °C); attach "
        "a negative start with '=', e.g. --dt0-c=-2:4:7",
    )
    p.add_argument("--out", default=None, help="output directory (default out/sweep)")
    p.add_argument(
        "--levels",
        type=int,
        default=None,
        help="required distinct gradient levels (default: the step table's, else 6)",
    )
    p.add_argument(
        "--deltas-c-per-min",
        "--delta-c-per-min",
        dest="deltas_c_per_min",
        type=float,
        nargs="+",
        default=None,
        metavar="DELTA",
        help="gradient separations of distinct levels, °C/min; the first is the headline "
        "coverage (default: the step table's delta, else 0.05, then 0.1)",
    )
    p.add_argument("--dt-min", type=float, default=0.1, help="simulation step, min")
    p.add_argument(
        "--nominal-tau-s",
        type=float,
        default=None,
        help="nominal time constant marked on the heatmap, s (default: the step "
        "table's, else 2400)",
    )
    p.add_argument(
        "--nominal-dt0-c",
        type=float,
        default=None,
        help="nominal offset marked on the heatmap, °C (default: the step table's, else 3.0)",
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL.json",
        help="augmented model file (from schedsyn diagnose --out DIR): its effect is held "
        "while the grid varies its tau and dT0, and its base is the nominal point (default: "
        "the model the step table records, else the first-order lag)",
    )
    p.add_argument(
        "--replan",
        action="store_true",
        help="re-plan at every grid point (needs the planner) instead of sweeping a fixed plan",
    )
    p.add_argument(
        "--dask",
        default=None,
        metavar="ADDR",
        help="run on the Dask scheduler at ADDR, e.g. tcp://HOST:PORT",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="local worker processes (default: all cores; 1 = in this process)",
    )
    _common.add_quiet_option(p)
    p.add_argument("--no-progress", dest="quiet", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=run)


@dataclass(frozen=True, slots=True)
class PlanAtPoint:
    """Picklable ``plan_fn`` for :func:`~schedsyn.sweep.sweep_replan`: plan with given params.

    Calls ``schedsyn.planner.plan_experiment(ExperimentSpec(...), params, limits)``; the
    planner is imported lazily so that the fixed-plan sweep works without it.
    """

    region: tuple[float, float]
    approx: tuple[float, float]
    levels_required: int
    delta_c_per_min: float
    limits: Limits
    #: a linear augmented model (``schedsyn.effects.ModelSpec``), its effect held at every
    #: point; None: the first-order lag
    model: Any = None

    def __call__(self, params: ThermalParams):
        from ..planner import plan_experiment

        spec = replan_spec(self.region, self.approx, self.levels_required, self.delta_c_per_min)
        if self.model is None or self.model.effect == "none":
            return plan_experiment(spec, params, self.limits)
        model = dataclasses.replace(self.model, tau_s=params.tau_s, dt0_c=params.dt0_c)
        return plan_experiment(
            spec, params, model.planner_limits(self.limits), model=model.linear_model()
        )


def replan_spec(
    region: tuple[float, float],
    approx: tuple[float, float],
    levels_required: int,
    delta_c_per_min: float,
):
    """The planner's request at every grid point of ``--replan`` (an ``ExperimentSpec``,
    which validates the regions, levels and delta as ``schedsyn plan``'s does)."""
    from ..planner import ExperimentSpec

    return ExperimentSpec(
        "sweep",
        region[0],
        region[1],
        approx[0],
        approx[1],
        levels_required=levels_required,
        delta_c_per_min=delta_c_per_min,
    )


def check_replan_request(
    region: tuple[float, float],
    approx: tuple[float, float],
    levels_required: int,
    delta_c_per_min: float,
    limits: Limits,
) -> None:
    """Refuse, before any planning, a re-plan request no grid point can plan: the checks
    ``schedsyn plan`` makes (the request's own, then the planner's
    :func:`~schedsyn.planner.check_request`). Without them every row was "failed"."""
    from ..planner import check_request

    check_request(replan_spec(region, approx, levels_required, delta_c_per_min), limits)


def default_approx(region: tuple[float, float], limits: Limits) -> tuple[float, float]:
    """The paper's approximation region: 10 degC beyond the working region on each side,
    but not past the device limits (W1 = [-50, -30] gives [-52, -20], as in experiment 1)."""
    from ..design import DesignSpace

    return DesignSpace.default_approx(region[0], region[1], limits)


#: The second gradient separation sweep reports by default, °C/min (the planner's report
#: delta, ``schedsyn.planner.check.REPORT_DELTA_C_PER_MIN``; not imported: the fixed-plan
#: sweep works without the planner).
SECOND_DELTA_C_PER_MIN = 0.1


def _coverage_requirement(args: argparse.Namespace, meta) -> tuple[int, list[float], str]:
    """``(levels_required, deltas_c_per_min, line saying them and where they come from)``.

    The options, else what the step table records (the coverage its plan was made for),
    else 6 levels 0.05 °C/min apart; by default the second delta is 0.1 °C/min.
    """
    given = args.deltas_c_per_min
    (levels, levels_src), (delta, delta_src) = _common.coverage_sources(
        args.levels, given[0] if given else None, meta
    )
    if given:
        deltas = [float(d) for d in given]
    else:
        deltas = [delta] + ([SECOND_DELTA_C_PER_MIN] if delta != SECOND_DELTA_C_PER_MIN else [])
    if levels_src == delta_src:
        src = levels_src
    else:
        src = f"levels {levels_src}, delta {delta_src}"
    if src == "default" and args.steps is not None:
        src = "default; the step table records none"
    return (
        levels,
        deltas,
        f"coverage requirement: >= {levels} levels {deltas[0]:g} °C/min apart ({src})",
    )


def unit_slip_warnings(
    args: argparse.Namespace,
    taus: np.ndarray,
    dt0s: np.ndarray,
    nominal: ThermalParams,
    limits: Limits,
) -> list[str]:
    """``plan``'s warnings for figures that look like a unit slip (``unit_slip_notes``: a
    tau in minutes, a dT0 beyond 20 °C, a rate in °C/h) for the grids' ends and the
    nominal point, each said once and where it comes from."""
    checks = []  # a default grid is around the nominal point: said once, for the point
    if args.tau_s is not None:
        checks += [
            (f"--tau-s {args.tau_s}", ThermalParams(tau_s=float(tau), dt0_c=0.0))
            for tau in dict.fromkeys((taus[0], taus[-1]))
        ]
    if args.dt0_c is not None:
        checks += [
            (f"--dt0-c {args.dt0_c}", ThermalParams(dt0_c=float(dt0)))
            for dt0 in dict.fromkeys((dt0s[0], dt0s[-1]))
        ]
    checks.append(("nominal point", nominal))
    said: dict[str, str] = {}
    for where, params in checks:
        for note in unit_slip_notes(params, limits):
            if note.startswith(("tau_s", "dt0_c")):
                said.setdefault(f"{where}: {note}", "")
            else:  # the limits' own (the table's rates): the same at every point
                said.setdefault(note, "")
    return list(said)


def sweep_grid(
    args: argparse.Namespace, nominal: ThermalParams, meta
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``(tau_s_values, dt0_c_values, lines)``: the grids given, else the default grid
    around the nominal point that takes in the step table's robust box
    (:func:`~schedsyn.sweep.default_grid`); ``lines`` say how a default grid was made,
    or what of the nominal point and the robust box a given grid leaves out."""
    tau_box, dt0_box = meta.robust_box if meta is not None else (None, None)
    default_taus, default_dt0s = default_grid(nominal, tau_box, dt0_box)
    taus = default_taus if args.tau_s is None else parse_grid(args.tau_s, "--tau-s", "s")
    dt0s = default_dt0s if args.dt0_c is None else parse_grid(args.dt0_c, "--dt0-c", "°C")
    box = " x ".join(
        part
        for part in (
            f"tau {tau_box[0]:g} .. {tau_box[1]:g} s" if tau_box else "",
            f"dT0 {dt0_box[0]:g} .. {dt0_box[1]:g} °C" if dt0_box else "",
        )
        if part
    )
    lines = []
    defaults = [
        text
        for given, text in (
            (
                args.tau_s,
                f"tau {taus[0]:g} .. {taus[-1]:g} s (the nominal ±{DEFAULT_TAU_SPREAD:.0%})",
            ),
            (
                args.dt0_c,
                f"dT0 {dt0s[0]:g} .. {dt0s[-1]:g} °C (the nominal ±{DEFAULT_DT0_SPREAD_C:g} °C)",
            ),
        )
        if given is None
    ]
    if defaults:
        lines.append(
            f"grid (default): {', '.join(defaults)}"
            + (f", taking in the step table's robust box {box}" if box else "")
            + "; --tau-s and --dt0-c set it"
        )

    def within(values: np.ndarray, lo: float, hi: float) -> bool:
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        return bool(values[0] <= lo + tol and hi - tol <= values[-1])

    left_out = []
    if box and not (
        (tau_box is None or within(taus, *tau_box)) and (dt0_box is None or within(dt0s, *dt0_box))
    ):
        left_out.append(f"the step table's robust box {box}")
    if not (within(taus, nominal.tau_s, nominal.tau_s) and within(dt0s, *(nominal.dt0_c,) * 2)):
        left_out.append(f"the nominal point (tau {nominal.tau_s:g} s, dT0 {nominal.dt0_c:g} °C)")
    if left_out:
        lines.append(
            f"note: the grid (tau {taus[0]:g} .. {taus[-1]:g} s x dT0 {dt0s[0]:g} .. "
            f"{dt0s[-1]:g} °C) leaves out {' and '.join(left_out)}; leave --tau-s and "
            "--dt0-c out for a grid that takes them in"
        )
    return taus, dt0s, lines


def _planner_available() -> bool:
    try:
        return importlib.util.find_spec("schedsyn.planner") is not None
    except (ImportError, ValueError):
        return False


def _backend(args: argparse.Namespace):
    if args.workers is not None and args.workers < 1:
        raise ParameterError(f"--workers must be >= 1, got {args.workers}")
    return args.dask if args.dask else "local"


def run(args: argparse.Namespace) -> int:
    from .. import plots

    meta = read_step_meta(args.steps) if args.steps is not None else None
    augmented, augmented_from = _common.augmented_model(args.model, meta, args.steps)
    nominal, nominal_src = _common.model_from_table(
        args, meta, ("nominal_tau_s", "nominal_dt0_c"), table=args.steps is not None
    )
    if args.model is not None and augmented is not None:  # the model file's base
        nominal = ThermalParams(
            augmented.tau_s if args.nominal_tau_s is None else args.nominal_tau_s,
            augmented.dt0_c if args.nominal_dt0_c is None else args.nominal_dt0_c,
        )
        both = args.nominal_tau_s is not None and args.nominal_dt0_c is not None
        nominal_src = "given" if both else f"from {args.model}"
    taus, dt0s, grid_lines = sweep_grid(args, nominal, meta)
    limits = (meta.limits() if meta is not None else None) or Limits()
    for note in unit_slip_warnings(args, taus, dt0s, nominal, limits):
        _common.stderr(f"warning: {note}")
    if args.steps is None and not args.replan:
        raise ParameterError("give the step table STEPS.csv to sweep (or --replan to re-plan)")
    if args.replan and not _planner_available():
        raise SchedsynError(
            "re-planning needs the planner (schedsyn.planner), which this "
            "installation lacks; run the sweep without --replan"
        )
    if args.steps is None and args.region is None:
        raise ParameterError("re-planning needs the working region: give --region LO HI (°C)")
    lo, hi = _common.region_from_table(args, meta, args.steps)
    levels, deltas, requirement = _coverage_requirement(args, meta)
    approx: tuple[float, float] | None = None
    if args.replan:
        approx = (
            (float(args.approx[0]), float(args.approx[1]))
            if args.approx
            else default_approx((lo, hi), limits)
        )
        check_replan_request((lo, hi), approx, levels, deltas[0], limits)
        if augmented is not None and not augmented.is_linear:
            raise ParameterError(
                f"model ({augmented_from}): the effect {augmented.effect!r} is not linear; "
                "--replan needs a linear model (sweep the fixed plan through it instead: "
                "leave out --replan)"
            )
    model_line = [] if augmented is None else [_model_line(augmented, augmented_from)]
    backend = _backend(args)
    progress = _common.progress_of(args)
    inputs = [x for x in (args.steps, args.model) if x]
    out = _common.output_dir(args.out, "out/sweep", inputs, ("sweep.csv", "sweep.png"))
    marker = (nominal.tau_s, nominal.dt0_c)

    if approx is not None:
        plan_fn = PlanAtPoint((lo, hi), approx, levels, deltas[0], limits, augmented)
        replanned = sweep_replan(
            plan_fn, taus, dt0s, backend=backend, workers=args.workers, progress=progress
        )
        frame = replanned.to_frame()
        write_frame_atomic(out.path("sweep.csv"), frame)
        numeric = [
            c for c in frame.columns if c not in ("tau_s", "dt0_c") and frame[c].dtype.kind in "if"
        ]
        wanted = ("duration_min", "coverage", "margin_g_c_per_min")
        preferred = [c for c in wanted if c in numeric] or numeric[:2]
        if preferred:
            ok = frame[frame["status"] == "ok"]
            panels = [(ok, c, f"re-planned: {c}") for c in preferred]
            plots.save_figure(plots.sweep_panels(panels, nominal=marker)[0], out.path("sweep.png"))
        out.commit()
        _common.say(
            requirement,
            *model_line,
            *grid_lines,
            replanned.summary(),
            f"wrote {out.target}/sweep.csv" + (", sweep.png" if preferred else ""),
        )
        return 0

    programme = read_steps(args.steps, limits)
    kw = dict(
        levels_required=levels,
        deltas_c_per_min=deltas,
        dt_min=args.dt_min,
        t0_c=limits.t_init_c,
        model=augmented,
    )
    result = sweep_fixed(
        programme,
        (lo, hi),
        taus,
        dt0s,
        backend=backend,
        workers=args.workers,
        progress=progress,
        **kw,
    )
    at_nominal = sweep_fixed(programme, (lo, hi), [nominal.tau_s], [nominal.dt0_c], **kw)
    frame = result.to_frame()
    excess = result.device_excess_c(limits.device_min_c, limits.device_max_c)
    frame["device_excess_c"] = excess.ravel()
    write_frame_atomic(out.path("sweep.csv"), frame)
    d0 = result.deltas_c_per_min[0]
    panels = [
        (frame, "coverage", f"coverage (≥ {result.levels_required} levels, Δ {d0:g} °C/min)"),
        (frame, "min_levels", f"fewest distinct levels of any bin (Δ {d0:g} °C/min)"),
    ]
    plots.save_figure(
        plots.sweep_panels(
            panels, nominal=marker, suptitle=f"{args.steps}: working region [{lo:g}, {hi:g}] °C"
        )[0],
        out.path("sweep.png"),
    )
    out.commit()
    region_src = "given" if args.region is not None else "from the step table"
    lines = [
        f"programme: {programme.n_segments} steps, {programme.total_min:.1f} min; working "
        f"region [{lo:g}, {hi:g}] °C ({region_src})",
        requirement,
        f"at the nominal point (tau {nominal.tau_s:g} s, dT0 {nominal.dt0_c:g} °C): coverage "
        f"{at_nominal.coverage_grid[0, 0]:.1%}, min {at_nominal.min_levels_grid[0, 0]} "
        f"levels (nominal point: {nominal_src})",
        *model_line,
        *grid_lines,
        result.summary(),
    ]
    box = result.covered_box()
    if box is not None:
        (t0, t1), (c0, c1) = box["tau_s_range"], box["dt0_c_range"]
        lines.append(
            f"largest fully covered box: tau {t0:g} .. {t1:g} s x dT0 {c0:g} .. {c1:g} °C "
            f"({box['n_points']} grid points)"
        )
    lines.append(_device_line(result, excess, limits))
    for j, d in enumerate(result.deltas_c_per_min[1:], start=1):
        cov = result.coverage[:, :, j]
        lines.append(
            f"at delta {d:g} °C/min: coverage {cov.min():.1%} .. {cov.max():.1%}, min "
            f"levels {result.min_levels[:, :, j].min()} .. {result.min_levels[:, :, j].max()}"
        )
    lines.append(f"wrote {out.target}/sweep.csv, sweep.png")
    _common.say(*lines)
    return 0


def _model_line(model, source: str) -> str:
    """What the sweep holds of an augmented model, and what it varies."""
    line = (
        f"model (from {source}): effect {model.effect} "
        + ", ".join(f"{k} {v:g}" for k, v in model.parameters.items())
        + f", held while the grid varies its tau and dT0 (its own: tau {model.tau_s:g} s, "
        f"dT0 {model.dt0_c:g} °C)"
    )
    scaled = TAU_PARAMETERS.get(model.effect, ())
    if scaled:
        line += (
            f"; {' and '.join(scaled)} are scaled with each point's tau (times tau / "
            f"{model.tau_s:g} s)"
        )
    return line


#: past the device limits by more than this counts (the planner's own tolerance is
#: finer; this keeps rounding of the step table's 0.1 degC from being reported)
DEVICE_EXCESS_TOL_C = 0.05


def _device_line(result, excess: np.ndarray, limits: Limits) -> str:
    """One line on the device limits over the grid: held everywhere, or where not."""
    lo, hi = limits.device_min_c, limits.device_max_c
    bad = excess > DEVICE_EXCESS_TOL_C
    if not bad.any():
        return (
            f"device limits [{lo:g}, {hi:g}] °C (device_min_c, device_max_c): held at every "
            "grid point"
        )
    i, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
    t_lo, t_hi = result.t_min_c[i, j], result.t_max_c[i, j]
    past = f"{t_hi:.1f} °C > {hi:g}" if t_hi - hi >= lo - t_lo else f"{t_lo:.1f} °C < {lo:g}"
    return (
        f"WARNING: the device goes past its limits [{lo:g}, {hi:g}] °C at {int(bad.sum())} "
        f"of {bad.size} grid points (device_excess_c in sweep.csv); worst at tau "
        f"{result.tau_s_values[i]:g} s, dT0 {result.dt0_c_values[j]:g} °C: {past} "
        f"(by {excess[i, j]:.1f} °C)"
    )
