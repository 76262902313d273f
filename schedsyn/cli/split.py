"""``schedsyn split --range LO HI``: the fewest experiments that cover a temperature range.

Proposes consecutive working regions (whole degrees, no gap) with their approximation
regions (10 °C wider on each side, but not beyond the ends of the range, as in the
paper), each as wide as a complete plan within the time limit allows, each verified by a
complete plan. The proven lower bound on the duration says how many experiments any
split needs at least; when the split found has that many it is the fewest possible.

The model, chamber and settings come from the options, else from CONFIG.toml (a campaign
file: its [model], [chamber], [limits] and [settings]; its experiments are ignored), else
the defaults; --chamber NAME takes a chamber preset (schedsyn chambers lists them).

Writes to --out (default out/split): <name>/steps.csv, plan.json, program.png, phase.png,
coverage.png per experiment, split.csv (one row per experiment), summary.csv (as a
campaign's: scripts/check_tables.py re-checks the folder) and campaign.toml, a campaign
file that plans the same experiments again (schedsyn campaign campaign.toml).

Exit codes: 0 the range is covered, every plan complete; 1 it is not (the experiments
found so far are written, and why it stopped); 2 bad input; 3 an environment fault.
"""

from __future__ import annotations

import argparse

from ..planner import OBJECTIVES
from . import _common
from .plan import PLAN_FILES, add_rate_options


def register(sub) -> None:
    p = sub.add_parser(
        "split",
        help="the fewest experiments that cover a temperature range (each verified)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--range",
        nargs=2,
        type=float,
        required=True,
        metavar=("LO_C", "HI_C"),
        help="the range to cover, °C, whole degrees apart (e.g. -50 60)",
    )
    p.add_argument(
        "config",
        nargs="?",
        default=None,
        metavar="CONFIG.toml",
        help="campaign file whose model, chamber, limits and settings to use",
    )
    p.add_argument("--chamber", default=None, metavar="NAME", help="chamber preset")
    add_rate_options(p)
    p.add_argument("--chamber-min-c", type=float, default=None, help="chamber air floor, °C")
    p.add_argument("--chamber-max-c", type=float, default=None, help="chamber air ceiling, °C")
    p.add_argument(
        "--duration-max-min",
        type=float,
        default=None,
        help="time limit of each experiment, min (default 540)",
    )
    p.add_argument("--levels", type=int, default=None, help="distinct levels per bin (6)")
    p.add_argument(
        "--delta-c-per-min", type=float, default=None, help="level separation, °C/min (0.05)"
    )
    p.add_argument("--segment-min", type=float, default=None, help="segment length, min (5)")
    p.add_argument("--objective", choices=OBJECTIVES, default=None, help="planner objective")
    p.add_argument("--max-steps", type=int, default=None, help="most steps per table (80)")
    _common.add_model_options(p)
    p.add_argument(
        "--approx-margin-c",
        type=float,
        default=10.0,
        help="approximation region beyond the working region on each side, °C (default 10)",
    )
    p.add_argument(
        "--max-experiments",
        type=int,
        default=None,
        help='stop once this many experiments do not cover the range ("do N do?")',
    )
    p.add_argument(
        "--max-plans", type=int, default=60, help="most plans over the search (default 60)"
    )
    p.add_argument(
        "--budget-s",
        type=float,
        default=7200.0,
        help="time budget, s (default 7200; plans under way are finished)",
    )
    p.add_argument("--name-prefix", default="S", help="experiments are named S1, S2, ...")
    p.add_argument(
        "--backend",
        default="local",
        help="'local' (widths planned in parallel on the cores, default), 'serial' or a "
        "Dask scheduler address",
    )
    p.add_argument("--workers", type=int, default=None, help="widths planned per round")
    p.add_argument("--out", default=None, help="output directory (default out/split)")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def _request(args):
    """``(params, limits, settings)``: options over the config over the defaults."""
    from ..chambers import limits_with_preset
    from ..params import Limits, ThermalParams
    from ..split import SETTING_KEYS

    params, limits = ThermalParams(), Limits()
    settings: dict = {}
    if args.config is not None:
        from ..campaign import load_campaign

        cfg = load_campaign(args.config)
        params, limits = cfg.params, cfg.limits
        first = cfg.experiments[0].to_dict()
        settings = {k: first[k] for k in SETTING_KEYS}
    params = _common.thermal_params(args, params)
    if args.chamber is not None:
        from ..chambers import chamber_preset

        settings["max_steps"] = chamber_preset(args.chamber).max_steps
    limits = limits_with_preset(
        args.chamber,
        limits,
        rate_min_c_per_min=args.rate_min_c_per_min,
        rate_max_c_per_min=args.rate_max_c_per_min,
        chamber_min_c=args.chamber_min_c,
        chamber_max_c=args.chamber_max_c,
        duration_max_min=args.duration_max_min,
    )
    for key, value in (
        ("levels_required", args.levels),
        ("delta_c_per_min", args.delta_c_per_min),
        ("segment_min", args.segment_min),
        ("objective", args.objective),
        ("max_steps", args.max_steps),
    ):
        if value is not None:
            settings[key] = value
    return params, limits, settings


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..io import write_frame_atomic, write_text_atomic
    from ..split import SplitSettings, split_range
    from .plan import write_plan_outputs

    params, limits, spec_settings = _request(args)
    settings = SplitSettings(
        approx_margin_c=args.approx_margin_c,
        max_experiments=args.max_experiments,
        max_plans=args.max_plans,
        time_budget_s=args.budget_s,
        name_prefix=args.name_prefix,
    )
    inputs = [args.config] if args.config else []
    # the experiment folders are known only at the end: check the fixed names now
    out = _common.output_dir(
        args.out, "out/split", inputs, ["split.csv", "summary.csv", "campaign.toml"]
    )
    progress = None if args.quiet else _common.progress_of(args)
    result = split_range(
        args.range[0],
        args.range[1],
        params,
        limits,
        spec_settings,
        settings=settings,
        backend=args.backend,
        workers=args.workers,
        progress=progress,
    )
    for e in result.experiments:
        write_plan_outputs(e.plan, out.folder(e.spec.name), inputs)
    write_frame_atomic(out.path("split.csv"), result.to_frame())
    # as a campaign's summary.csv: scripts/check_tables.py re-checks the folder
    summary = pd.DataFrame([e.plan.to_summary_dict() for e in result.experiments])
    write_frame_atomic(out.path("summary.csv"), summary)
    write_text_atomic(out.path("campaign.toml"), result.campaign_toml())
    out.commit()
    names = ", ".join(e.spec.name for e in result.experiments) or "none"
    _common.say(
        *result.lines(),
        f"split searched in {result.wall_s:.0f} s ({result.plans} plans)",
        f"wrote {out.target}/split.csv, summary.csv, campaign.toml and the experiments' folders "
        f"({names}: {', '.join(PLAN_FILES)})",
    )
    return 0 if result.covered else 1
