"""The report a quality engineer files after a run: planned vs measured, in one page.

A leaf like :mod:`schedsyn.sheet` (HTML and matplotlib only here). :func:`run_report`
compares a measured log with the step table that was run (:func:`schedsyn.compare.
compare_run`: Kalman-smoothed gradient, the plan simulated through the model, the same
coverage metric on both) and renders:

* the verdict: achieved vs planned coverage, the residual;
* phase portraits (measured over simulated), temperatures with the residual, gradients,
  and the per-bin levels planned vs achieved;
* the diagnosis (``schedsyn diagnose --out DIR``) and the drift fit, where given: their
  JSON summaries, tables and pictures;
* what produced it: package versions, every input file with its SHA-256, the command.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from .compare import RunComparison
from .errors import ParameterError
from .sheet import (
    Column,
    esc,
    facts_html,
    figure_html,
    figure_uri,
    page,
    provenance_html,
    table_html,
)

#: Largest CSV of a diagnosis/fit folder shown as a table (rows).
MAX_TABLE_ROWS = 60


@dataclass(frozen=True, slots=True)
class RunReport:
    """A rendered run report: the page, its machine-readable summary and the comparison."""

    html: str
    summary: dict[str, Any]
    comparison: RunComparison

    def to_frame(self) -> pd.DataFrame:
        """Per bin: planned and achieved passes and levels."""
        return self.comparison.coverage_frame()


def _fmt_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list | tuple):
        return ", ".join(_fmt_value(x) for x in v) if v else "–"
    if isinstance(v, dict):
        return "; ".join(f"{k}: {_fmt_value(x)}" for k, x in v.items()) if v else "–"
    return str(v)


def _folder_section(title: str, folder: Path, special: Mapping[str, Any] | None = None) -> str:
    """A diagnosis/fit folder: JSON summaries as facts, small CSVs as tables, PNGs."""
    if not folder.is_dir():
        raise ParameterError(f"{folder} is not a folder; give the --out folder of that command")
    parts = [
        f"<h2>{esc(title)}</h2>",
        f'<p class="sub">from <span class="mono">{esc(folder)}</span></p>',
    ]
    if special:
        parts.append(facts_html([(k, _fmt_value(v)) for k, v in special.items()]))
    files = sorted(folder.iterdir())
    for f in files:
        if f.suffix.lower() == ".json" and not (special and f.name == "diagnosis.json"):
            try:
                doc = json.loads(f.read_text(encoding="utf-8"))
            except (json.JSONDecodeError, UnicodeDecodeError):
                parts.append(f"<p>{esc(f.name)}: not valid JSON, not shown.</p>")
                continue
            if isinstance(doc, dict):
                parts.append(f"<h3>{esc(f.name)}</h3>")
                parts.append(facts_html([(k, _fmt_value(v)) for k, v in doc.items()]))
    for f in files:
        if f.suffix.lower() == ".csv":
            try:
                frame = pd.read_csv(f, comment="#")
            except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
                continue
            parts.append(f"<h3>{esc(f.name)}</h3>")
            if len(frame) > MAX_TABLE_ROWS:
                parts.append(
                    f"<p>{len(frame)} rows: the first {MAX_TABLE_ROWS} are shown; the file is "
                    "listed with its SHA-256 below.</p>"
                )
                frame = frame.head(MAX_TABLE_ROWS)
            from .sheet import column_header

            cols = [
                Column(c, column_header(str(c)), _cell_fmt, left=frame[c].dtype == object)
                for c in frame.columns
            ]
            parts.append(table_html(frame, cols))
    for f in files:
        if f.suffix.lower() == ".png":
            import base64

            uri = "data:image/png;base64," + base64.b64encode(f.read_bytes()).decode("ascii")
            parts.append(figure_html(uri, f.name, f.name))
    return "\n".join(parts)


def _cell_fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _diagnosis_facts(folder: Path) -> dict[str, Any] | None:
    path = folder / "diagnosis.json"
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ParameterError(f"{path}: not valid JSON") from None
    if not isinstance(d, dict):
        return None
    out: dict[str, Any] = {"effect found": d.get("effect", "–")}
    unc = d.get("uncertainty", {}) or {}
    for k, v in (d.get("parameters") or {}).items():
        u = unc.get(k)
        out[f"parameter {k}"] = f"{v:.4g}" + (f" ± {u:.2g}" if isinstance(u, int | float) else "")
    if "rms_before_c" in d and "rms_after_c" in d:
        out["RMS gap, °C"] = f"{d['rms_before_c']:.3f} → {d['rms_after_c']:.3f}"
    hold = d.get("holdout") or {}
    if "rms_before_c" in hold and "rms_after_c" in hold:
        part = " (the first part, fitted on the rest)" if hold.get("part") == "first" else ""
        out[f"held-out RMS gap{part}, °C"] = (
            f"{hold['rms_before_c']:.3f} → {hold['rms_after_c']:.3f}"
        )
    if d.get("ambiguous_with"):
        out["cannot be told apart from"] = d["ambiguous_with"]
    for i, w in enumerate(d.get("warnings") or [], start=1):
        out[f"warning {i}"] = w
    return out


def run_report(
    comparison: RunComparison,
    *,
    log_path: Path | str,
    steps_path: Path | str,
    diagnosis_dir: Path | str | None = None,
    fit_dir: Path | str | None = None,
    provenance: Mapping[str, Any] | None = None,
    title: str | None = None,
) -> RunReport:
    """Render the report of a finished run.

    Parameters
    ----------
    comparison : RunComparison
        From :func:`schedsyn.compare.compare_run` (log vs the step table that was run).
    log_path, steps_path : path
        The inputs (named on the page).
    diagnosis_dir, fit_dir : path, optional
        Output folders of ``schedsyn diagnose`` and of the drift fit.
    provenance : mapping, optional
        :func:`schedsyn.provenance.provenance` of the inputs.
    """
    from . import plots

    c = comparison
    p, r = c.planned_coverage, c.run_coverage
    region = (p.grid.lo_c, p.grid.hi_c)
    short = p.coverage - r.coverage
    facts = [
        ("log", f"{log_path} ({c.log.n_rows} rows, {c.log.time_min[-1]:.1f} min)"),
        ("step table", f"{steps_path} ({c.planned.duration_min:g} min)"),
        ("working region", f"{region[0]:g} .. {region[1]:g} °C"),
        (
            "model",
            f"tau {c.params.tau_s:g} s, dT0 {c.params.dt0_c:g} °C; simulated from "
            f"{c.t0_c:.2f} °C ({c.t0_source})",
        ),
        (
            "coverage planned",
            f"{p.coverage:.0%} (min {p.min_levels} levels; ≥ {p.levels_required} levels "
            f"{p.delta_c_per_min:g} °C/min apart)",
        ),
        ("coverage achieved", f"{r.coverage:.0%} (min {r.min_levels} levels)"),
        (
            "internal temperature, measured − simulated",
            f"RMS {c.rms_residual_c:.2f} °C, max {c.max_abs_residual_c:.2f} °C",
        ),
        ("gradient estimator", f"{c.estimate.method} (Kalman smoother)"),
    ]
    if r.complete:
        verdict = '<p class="good">The run covered the whole working region.</p>'
    elif short > 1e-12:
        verdict = (
            f'<div class="warn">The run covered {r.coverage:.0%} of the working region, '
            f"{short:.0%} less than planned ({p.coverage:.0%}); bins short: "
            f"{esc(', '.join(f'[{a:g}, {b:g})' for a, b, _ in r.short_bins()[:12]))}"
            f"{' ...' if len(r.short_bins()) > 12 else ''}</div>"
        )
    else:
        verdict = (
            f'<div class="warn">The run covered {r.coverage:.0%} of the working region '
            f"(as planned: {p.coverage:.0%}); it is not a complete calibration.</div>"
        )
    body = [verdict, *(f'<div class="warn">{esc(n)}</div>' for n in c.notes)]
    body += [facts_html(facts), "<h2>Planned vs measured</h2>"]
    body.append(
        figure_html(
            figure_uri(
                plots.phase_overlay_plot(
                    c.planned.t_c,
                    c.planned.g_c_per_min,
                    c.run_dense.t_c,
                    c.run_dense.g_c_per_min,
                    region=region,
                    title="phase portrait: measured over simulated",
                )
            ),
            "phase portrait, measured over simulated",
            "Internal temperature against its gradient: the plan simulated through the model "
            "(thin) and the run (Kalman-smoothed).",
        )
    )
    body.append(
        figure_html(
            figure_uri(
                plots.temperature_compare_plot(
                    c.log.time_min,
                    c.log.t_int_c,
                    c.simulated.t_c,
                    title="internal temperature: measured vs simulated",
                )
            ),
            "internal temperature, measured vs simulated, with the residual",
            "Right axis: measured minus simulated.",
        )
    )
    ax = plots.gradient_plot(c.estimate, title="gradient: estimated vs simulated")
    ax.plot(c.simulated.time_min, c.simulated.g_c_per_min, color="k", lw=0.6, label="simulated")
    ax.legend(loc="best")
    body.append(figure_html(figure_uri(ax), "gradient, estimated vs simulated"))
    body.append('<h2 class="page-break">Coverage: planned vs achieved</h2>')
    body.append(
        figure_html(
            figure_uri(plots.coverage_compare_plot(p, r)),
            "distinct levels per bin, planned and achieved",
        )
    )
    frame = c.coverage_frame()
    body.append(
        table_html(
            frame,
            [
                Column("bin_lo_c", "bin from, °C", "{:g}"),
                Column("bin_hi_c", "bin to, °C", "{:g}"),
                Column("planned_passes", "passes planned"),
                Column("run_passes", "passes run"),
                Column("planned_levels", "levels planned"),
                Column("run_levels", "levels run"),
                Column("run_covered", "covered by the run", lambda v: "yes" if v else "NO"),
            ],
            row_class=lambda row: "" if row["run_covered"] else "missing",
        )
    )
    if diagnosis_dir is not None:
        folder = Path(diagnosis_dir)
        body.append(
            _folder_section(
                "Diagnosis: which effect the model lacks", folder, _diagnosis_facts(folder)
            )
        )
    if fit_dir is not None:
        body.append(_folder_section("Drift fit", Path(fit_dir)))
    body.append("<h2>What produced this report</h2>")
    body.append(provenance_html(provenance))
    summary = {
        **c.summary_dict(),
        "steps": str(steps_path),
        "diagnosis_dir": None if diagnosis_dir is None else str(diagnosis_dir),
        "fit_dir": None if fit_dir is None else str(fit_dir),
        "provenance": dict(provenance or {}),
    }
    text = page(
        title or f"Run report: {Path(str(log_path)).name}",
        "\n".join(body),
        f"Measured run {log_path} against the programme {steps_path}",
    )
    return RunReport(text, summary, c)
