"""schedsyn sheet STEPS.csv|PLAN_DIR: the operator sheet of one experiment (HTML).

One self-contained page (pictures embedded, printable to PDF from a browser): the
programme with the device's tolerance band, checkpoints every 30 min with the chamber
and device temperatures the operator should see (the band: min/max of the simulated
device temperature over tau ±15 % × dT0 ±2 °C, or over the plan's robust box), and the
step table with wall-clock times from --start.

PLAN_DIR is a folder written by schedsyn plan or schedsyn campaign (its
steps.csv and plan.json give the region, the model and the robust box); for a
step table they come from its # key: value lines or from the options. With
--controller the sheet shows the exported programme (what the controller runs) with
its programme and step numbers.

Writes --out (default PLAN_DIR/sheet.html, or STEM.sheet.html beside the
table). Exit codes: 0 written; 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..errors import ParameterError, SchedsynError
from ..export import CONTROLLER_KEYS
from . import _common
from .export import add_check_options, check_for, export_name


def register(sub) -> None:
    p = sub.add_parser(
        "sheet",
        help="write the operator sheet of an experiment (HTML, printable)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", metavar="STEPS.csv|PLAN_DIR", help="step table or plan folder")
    p.add_argument(
        "--start", default=None, help="wall-clock start, e.g. '2026-11-24 08:00' (default: none)"
    )
    p.add_argument("--out", default=None, help="output HTML file")
    add_sheet_options(p)
    add_check_options(p)
    p.add_argument(
        "--controller",
        default=None,
        choices=CONTROLLER_KEYS,
        help="show the programme exported for this controller (numbers, rounding)",
    )
    p.add_argument("--first-programme", type=int, default=1, help="first programme number")
    p.add_argument("--max-steps", type=int, default=None, help="steps one programme holds")
    _common.add_quiet_option(p)
    p.set_defaults(func=run)


def add_sheet_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--interval-min", type=float, default=30.0, help="minutes between checkpoints (30)"
    )
    p.add_argument(
        "--band-tau-rel",
        type=float,
        default=0.15,
        help="band: relative tau half-range without a robust box (0.15 = ±15 %%)",
    )
    p.add_argument(
        "--band-dt0-c",
        type=float,
        default=2.0,
        help="band: dT0 half-range without a robust box, °C (2)",
    )


def sheet_settings(args: argparse.Namespace, start: str | None):
    from ..checkpoints import SheetSettings, parse_start

    return SheetSettings(
        start=None if start is None else parse_start(start),
        interval_min=args.interval_min,
        band_tau_rel=args.band_tau_rel,
        band_dt0_c=args.band_dt0_c,
    )


def plan_json_meta(plan: dict[str, Any]) -> dict[str, str]:
    """``# key: value``-style metadata from a ``plan.json`` (spec, model, limits, box)."""
    meta: dict[str, str] = {}
    spec = plan.get("spec", {}) if isinstance(plan.get("spec"), dict) else {}
    for k in ("working_lo_c", "working_hi_c", "levels_required", "delta_c_per_min"):
        if k in spec:
            meta[k] = str(spec[k])
    if "name" in spec:
        meta["experiment"] = str(spec["name"])
    elif "experiment" in plan:
        meta["experiment"] = str(plan["experiment"])
    for k in ("tau_s", "dt0_c"):
        if k in plan:
            meta[k] = str(plan[k])
    if isinstance(plan.get("limits"), dict):
        meta.update({k: str(v) for k, v in plan["limits"].items()})
    scen = plan.get("robust_scenarios") or []
    if len(scen) > 1:
        taus = [float(s["tau_s"]) for s in scen]
        dt0s = [float(s["dt0_c"]) for s in scen]
        meta["robust_tau_s"] = f"{min(taus)}:{max(taus)}"
        meta["robust_dt0_c"] = f"{min(dt0s)}:{max(dt0s)}"
    return meta


def load_source(source: str):
    """``(table, steps_path, plan_json_path or None)`` of a step table or a plan folder;
    a plan folder's ``plan.json`` fills metadata the table does not carry."""
    from ..export import StepTable, limits_from_meta, read_step_table

    path = Path(source)
    plan_path = None
    if path.is_dir():
        steps = path / "steps.csv"
        if not steps.is_file():
            raise ParameterError(f"{path} has no steps.csv; give a step table or a plan folder")
        plan_path = path / "plan.json"
        path = steps
    table = read_step_table(path)
    if plan_path is not None and plan_path.is_file():
        try:
            plan = json.loads(plan_path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ParameterError(f"{plan_path}: not valid JSON ({exc})") from None
        meta = {**plan_json_meta(plan if isinstance(plan, dict) else {}), **table.meta}
        table = StepTable(
            table.path, table.programme, meta, table.sha256, limits_from_meta(meta, table.limits)
        )
    else:
        plan_path = None
    return table, path, plan_path


def run(args: argparse.Namespace) -> int:
    from ..export import (
        ExportSettings,
        export_programme,
        planned_for_notes,
        robust_box_from_meta,
    )
    from ..provenance import provenance
    from ..sheet import build_sheet, write_page

    table, steps_path, plan_path = load_source(args.source)
    check = check_for(args, table)
    settings = sheet_settings(args, args.start)
    name = export_name(table)
    export = None
    if args.controller is not None:
        export = export_programme(
            table.programme,
            ExportSettings(
                args.controller,
                first_programme=args.first_programme,
                max_steps=args.max_steps,
                name=name,
            ),
            limits=table.limits,
            check=check,
        )
    robust = robust_box_from_meta(table.meta, str(steps_path))
    if robust is not None and any(math.isnan(v) for pair in robust for v in pair):
        robust = None
    warnings = planned_for_notes(table.meta, table.programme, str(steps_path))
    text, cp = build_sheet(
        table.programme,
        experiment=table.meta.get("experiment", name),
        check=check,
        settings=settings,
        robust=robust,
        export=export,
        limits=table.limits,
        source=str(steps_path),
        provenance=provenance({"step table": steps_path, "plan": plan_path}),
        warnings=warnings,
    )
    if args.out is not None:
        out = Path(args.out)
    elif Path(args.source).is_dir():
        out = Path(args.source) / "sheet.html"
    else:
        out = steps_path.with_name(f"{steps_path.stem}.sheet.html")
    if out.is_dir():
        raise ParameterError(f"--out {out} is a directory; give a file name")
    write_page(out, text, [steps_path] + ([plan_path] if plan_path else []))
    print(
        f"{name}: {cp.check_min.size} checkpoints every {settings.interval_min:g} min, "
        f"band {cp.box.describe()}"
    )
    for w in warnings:
        print(f"*** {w} ***")
    print(f"wrote {out}")
    return 0


# ---------------------------------------------------------------------------------------
# used by `schedsyn campaign` (and `schedsyn plan` if the lead wires it)
# ---------------------------------------------------------------------------------------
def write_plan_deliverables(plan, out: Path, exports=(), sheet=None, inputs=()):
    """Controller exports and the operator sheet of a plan, into ``out`` (its folder).

    Returns ``(lines to print, links [(label, file name)], problem)`` where ``problem``
    is true when an export covers less than the table or could not be made (e.g. more
    programmes than the controller stores): the line says which.
    """
    import dataclasses

    from ..export import CoverageCheck, default_export_path, export_programme, write_export
    from ..provenance import provenance
    from ..sheet import build_sheet, write_page

    out = Path(out)
    spec = plan.spec
    steps_path = out / "steps.csv"
    check = CoverageCheck(
        spec.grid, plan.params, spec.levels_required, spec.delta_c_per_min, plan.limits.t_init_c
    )
    lines: list[str] = []
    links: list[tuple[str, str]] = [("sheet", "sheet.html"), ("plan", "plan.json")]
    lost = False
    done = []
    for settings in exports:
        settings = dataclasses.replace(settings, name=_safe_name(spec.name))
        try:
            ex = export_programme(
                plan.programme,
                settings,
                limits=plan.limits,
                check=check,
                header={"experiment": spec.name, "source": "steps.csv"},
            )
        except SchedsynError as exc:  # the other exports, the sheet and the index go on
            lines.append(f"  *** {settings.controller} export of {spec.name} FAILED: {exc}")
            lost = True
            continue
        path = write_export(default_export_path(steps_path, settings.controller), ex, inputs)
        lines += [f"  {ln}" for ln in ex.summary()]
        links.append((settings.controller, path.name))
        lost = lost or not ex.faithful
        done.append(ex)
    robust = None
    if len(plan.scenarios) > 1:
        taus = [p.tau_s for p in plan.scenarios]
        dt0s = [p.dt0_c for p in plan.scenarios]
        robust = ((min(taus), max(taus)), (min(dt0s), max(dt0s)))
    text, _ = build_sheet(
        plan.programme,
        experiment=spec.name,
        check=check,
        settings=sheet,
        robust=robust,
        export=done[0] if done else None,
        limits=plan.limits,
        # the sheet lies beside its table: name it as such (``out`` may be a staging
        # folder that is renamed once everything is written)
        source=steps_path.name,
        provenance=_beside(provenance({"step table": steps_path})),
    )
    write_page(out / "sheet.html", text, inputs)
    return lines, links, lost


def _beside(prov: dict) -> dict:
    """Provenance whose input paths are file names (files in the sheet's own folder)."""
    for entry in prov.get("inputs", []):
        entry["path"] = Path(entry["path"]).name
    return prov


def _safe_name(name: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_\-]", "_", name)[:64] or "schedsyn"


def write_campaign_index(out: Path, summary, links, inputs=(), notes=()) -> Path:
    """``index.html``: the summary table with links to every experiment's files."""
    from ..provenance import provenance
    from ..sheet import campaign_index, write_page

    text = campaign_index(
        summary,
        {k: [(lbl, f"{k}/{h}") for lbl, h in v] for k, v in links.items()},
        notes=notes,
        provenance=_beside(provenance({"summary": Path(out) / "summary.csv"})),
    )
    return write_page(Path(out) / "index.html", text, inputs)
