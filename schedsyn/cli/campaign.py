"""``schedsyn campaign [CONFIG.toml]``: plan every experiment of a campaign.

Without a config, the paper's campaign (``data/paper_campaign.toml``: W1..W4). Writes to
``--out`` (default ``out/campaign``), per experiment, ``<name>/steps.csv``,
``plan.json``, ``program.png``, ``phase.png``, ``coverage.png``, the operator sheet
``sheet.html`` and, with an ``[export]`` table, the controller programmes
``steps.<controller>.json|csv``; ``summary.csv`` (one row per experiment, next to the
paper-like baseline where the config names one) and ``index.html``.

Exit codes: 0 every experiment is complete (independent check of its exported table);
1 at least one experiment is incomplete or infeasible (its files, if any, are still
written and the problem is printed); 2 bad input (config, options).
"""

from __future__ import annotations

import argparse

from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "campaign",
        help="plan a campaign of experiments (default: the paper's)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "config",
        nargs="?",
        default=None,
        metavar="CONFIG.toml",
        help="campaign file (default: the paper's four experiments)",
    )
    p.add_argument("--out", default=None, help="output directory (default out/campaign)")
    p.add_argument(
        "--backend",
        default="local",
        help="'local' (process pool over the cores, default), 'serial' or a Dask "
        "scheduler address tcp://HOST:PORT",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes of the local pool (default: the number of cores)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..campaign import default_campaign, load_campaign, plan_campaign, stderr_progress
    from ..export import default_export_path
    from ..io import write_frame_atomic
    from .plan import report_plan, write_plan_outputs
    from .sheet import write_campaign_index, write_plan_deliverables

    config = default_campaign() if args.config is None else load_campaign(args.config)
    out = _common.out_dir(args.out, "out/campaign")
    inputs = [args.config] if args.config else []
    inputs += [b for b in config.baseline_steps if b is not None]
    result = plan_campaign(
        config,
        progress=None if args.quiet else stderr_progress,
        backend=args.backend,
        workers=args.workers,
    )
    lines = []
    links, lost = {}, []
    for spec, plan, err in zip(config.experiments, result.plans, result.errors, strict=True):
        if plan is None:
            lines.append(f"*** {spec.name} COULD NOT BE PLANNED: {err}")
            continue
        write_plan_outputs(plan, out / spec.name, inputs)
        lines += report_plan(plan)
        extra, links[spec.name], lost_one = write_plan_deliverables(
            plan, out / spec.name, config.exports, config.sheet, inputs
        )
        lines += extra
        if lost_one:
            lost.append(spec.name)
    frame = result.summary_frame()
    write_frame_atomic(out / "summary.csv", frame, inputs)
    write_campaign_index(out, frame, links, inputs)
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(frame.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    print("\n".join(lines))
    n_bad = sum(not (p is not None and p.complete) for p in result.plans)
    print(
        f"campaign planned in {result.wall_s:.1f} s; "
        + (
            "every experiment is complete"
            if n_bad == 0
            else f"{n_bad} of {len(result.plans)} experiments are NOT complete"
        )
    )
    if lost:
        print(
            f"*** the controller export of {', '.join(lost)} failed or covers LESS than its "
            "step table (see above)"
        )
    print(
        f"wrote {out}/summary.csv, index.html and {out}/<experiment>/steps.csv, plan.json, "
        "program.png, phase.png, coverage.png, sheet.html"
        + "".join(f", {default_export_path('steps.csv', e.controller)}" for e in config.exports)
    )
    return 0 if n_bad == 0 and not lost else 1
