"""``schedsyn campaign [CONFIG.toml]``: plan every experiment of a campaign.

Without a config, the paper's campaign (``data/paper_campaign.toml``: W1..W4). Writes to
``--out`` (default ``out/campaign``), per experiment, ``<name>/steps.csv``,
``plan.json``, ``program.png``, ``phase.png``, ``coverage.png``, the operator sheet
``sheet.html`` and, with an ``[export]`` table, the controller programmes
``steps.<controller>.json|csv``; ``summary.csv`` (one row per experiment, next to the
paper-like baseline where the config names one) and ``index.html``.

Every step table starts with its experiment's metadata (region, model, limits, end
soak). The outputs of a run appear all at once at the end (they are written to a staging
folder beside DIR first), and DIR/schedsyn-run.json lists them; files of an earlier run
that this one does not rewrite are removed. Outputs that would overwrite an input are
refused before any planning.

With --end-soak each table ends with a hold until the device settles; an experiment
whose soak does not fit in the time limit is written without it and reported.

With --advise, for every experiment that is not complete (or cannot be planned), the
least change of one knob (duration, chamber floor, ceiling, rates, levels) that makes it
complete is searched and verified by a complete plan: printed, in <name>/advice.csv, in
<name>/plan.json ('advice') and the verifying plans in <name>/advice/<knob>/.

Exit codes: 0 every experiment is complete (independent check of its exported table);
1 at least one experiment is incomplete or infeasible, or its end soak does not fit (its
files, if any, are still written and the problem is printed); 2 bad input (config,
options); 3 an environment fault (an output cannot be written, a worker process died).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from ..errors import ParameterError
from . import _common
from .plan import (
    ADVICE_FILES,
    PLAN_FILES,
    add_advise_options,
    add_end_soak_option,
    add_shorten_option,
)


def register(sub) -> None:
    p = sub.add_parser(
        "campaign",
        help="plan a campaign of experiments (default: the paper's)",
        description=_common.plain(__doc__),
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
    add_advise_options(p)
    add_end_soak_option(p)
    add_shorten_option(p)
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def campaign_outputs(config, advise: bool = False) -> list[str]:
    """Every file a campaign writes, relative to its output folder."""
    from ..export import default_export_path

    per_experiment: list[str] = [*PLAN_FILES, "sheet.html"]
    if advise:
        per_experiment += ADVICE_FILES
    per_experiment += [str(default_export_path("steps.csv", e.controller)) for e in config.exports]
    return ["summary.csv", "index.html"] + [
        f"{e.name}/{f}" for e in config.experiments for f in per_experiment
    ]


def wrote_line(target, written: Sequence[str], exports: Sequence[str] = ()) -> str:
    """The closing "wrote ..." line: only what was written.

    An experiment that could not be planned gets no folder, so the line names the
    experiment folders written, and none when no experiment was planned (red team: the
    line promised ``<experiment>/steps.csv, plan.json ...`` after an infeasible one).
    """
    head = f"wrote {target}/summary.csv, index.html"
    if not written:
        return head + " (no experiment was planned: no step table written)"
    files = ", ".join(
        ["steps.csv", "plan.json", "program.png", "phase.png", "coverage.png", "sheet.html"]
        + list(exports)
    )
    if len(written) == 1:
        return f"{head} and {target}/{written[0]}/{files}"
    return f"{head} and {target}/<experiment>/{files} for {', '.join(written)}"


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..campaign import (
        check_shorten,
        default_campaign,
        load_campaign,
        plan_campaign,
        stderr_progress,
    )
    from ..export import default_export_path
    from ..io import write_frame_atomic
    from ..params import unit_slip_notes
    from ..planner import plan_experiment
    from .plan import (
        advice_progress,
        advise_plan,
        end_soak_lines,
        informative_with_room_for_soak,
        report_plan,
        with_end_soak,
        write_plan_outputs,
    )
    from .sheet import write_campaign_index, write_plan_deliverables

    config = default_campaign() if args.config is None else load_campaign(args.config)
    for note in unit_slip_notes(config.params, config.limits):
        _common.stderr(f"warning: {note}")
    if args.advise and (config.robust_tau_s is not None or config.robust_dt0_c is not None):
        raise ParameterError(
            "--advise searches with the nominal model: remove the [robust] table or drop --advise"
        )
    try:
        check_shorten(config)
        shorten_applies = True
    except ParameterError:
        if args.shorten:
            raise
        shorten_applies = False
    # a --shorten hint only where --shorten would be accepted and did not run
    hint_ok = shorten_applies and not (args.shorten or config.shorten)
    inputs = [args.config] if args.config else []
    inputs += [b for b in config.baseline_steps if b is not None]
    # checked before any planning: no output overwrites an input, the folder is writable
    out = _common.output_dir(
        args.out, "out/campaign", inputs, campaign_outputs(config, args.advise)
    )
    result = plan_campaign(
        config,
        progress=None if args.quiet else stderr_progress,
        backend=args.backend,
        workers=args.workers,
        shorten=args.shorten,
        end_soak=args.end_soak,
    )
    lines = []
    no_soak: list[str] = []
    links: dict[str, list[tuple[str, str]]] = {}
    lost: list[str] = []
    plans = list(result.plans)
    for i, (spec, plan, err) in enumerate(
        zip(config.experiments, result.plans, result.errors, strict=True)
    ):
        advice_json = None
        if (plan is None or not plan.complete) and args.advise:
            more, advice = advise_plan(
                spec,
                config.params,
                config.limits,
                plan,
                args,
                advice_progress(args, spec),
                out.folder(spec.name),
            )
            advice_json = {"advice": advice}
        else:
            more = []
        if plan is None:
            lines.append(f"*** {spec.name} COULD NOT BE PLANNED: {err}")
            lines += more
            continue
        if args.end_soak:
            if spec.objective == "informative":  # it runs to the limit: room for the soak
                plan = informative_with_room_for_soak(
                    plan,
                    lambda lim, spec=spec: plan_experiment(
                        spec,
                        config.params,
                        lim,
                        robust_tau_s=config.robust_tau_s,
                        robust_dt0_c=config.robust_dt0_c,
                        end_soak=True,
                    ),
                )
            try:
                plan = plans[i] = with_end_soak(plan)
            except ParameterError as exc:  # the others go on; this one is reported
                no_soak.append(spec.name)
                lines.append(f"*** {exc}; its table is written WITHOUT an end soak")
        folder = out.folder(spec.name)
        write_plan_outputs(plan, folder, extra_json=advice_json)
        lines += report_plan(plan, shorten_hint_ok=hint_ok)
        lines += end_soak_lines(plan)
        lines += more
        extra, links[spec.name], lost_one = write_plan_deliverables(
            plan, folder, config.exports, config.sheet, inputs
        )
        lines += extra
        if lost_one:
            lost.append(spec.name)
    if args.end_soak:
        import dataclasses

        result = dataclasses.replace(result, plans=tuple(plans))
    frame = result.summary_frame()
    write_frame_atomic(out.path("summary.csv"), frame)
    write_campaign_index(out.path("summary.csv").parent, frame, links, inputs)
    out.commit()
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        summary = frame.to_string(index=False, float_format=lambda x: f"{x:.4g}")
    n_bad = sum(not (p is not None and p.complete) for p in result.plans)
    soak_text = f"; no end soak fits in {', '.join(no_soak)}" if no_soak else ""
    _common.say(
        summary,
        *lines,
        f"campaign planned in {result.wall_s:.1f} s; "
        + (
            "every experiment is complete"
            if n_bad == 0
            else f"{n_bad} of {len(result.plans)} experiments are NOT complete"
        )
        + soak_text,
        wrote_line(
            out.target,
            [s.name for s, p in zip(config.experiments, plans, strict=True) if p is not None],
            [str(default_export_path("steps.csv", e.controller)) for e in config.exports],
        ),
    )
    if lost:
        print(
            f"*** the controller export of {', '.join(lost)} failed, covers LESS than its "
            "step table or breaks a limit the table meets (see above)"
        )
    return 0 if n_bad == 0 and not no_soak and not lost else 1
