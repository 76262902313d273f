"""Operator sheets and campaign index pages: self-contained HTML for the chamber operator.

A leaf like :mod:`schedsyn.plots`: the core never imports it; matplotlib is imported
inside the functions. Pages carry their pictures as PNG data URIs and their style
inline (``templates/page.css``), so one file can be mailed, opened offline and printed
to PDF from a browser (print CSS: A4, repeated table headers, no rows cut in half).

* :func:`operator_sheet` - one experiment: the facts, what to do before the start, the
  programme with the device's tolerance band (:mod:`schedsyn.checkpoints`),
  checkpoints every 30 min with blank cells for the readings, the step table with
  wall-clock times (and the controller's programme/step numbers when exported).
* :func:`campaign_index` - the campaign's summary table with links to each sheet.

Plot functions follow :mod:`schedsyn.plots`: ``ax=None``, one thing drawn, the axes
returned.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .checkpoints import Checkpoints, SheetSettings, checkpoints, clock, hmm
from .coverage import CoverageReport
from .errors import ParameterError
from .params import Limits, ThermalParams
from .programme import Programme

# ---------------------------------------------------------------------------------------
# HTML building blocks (shared with schedsyn.report)
# ---------------------------------------------------------------------------------------


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def css() -> str:
    """The page style (package data ``schedsyn/templates/page.css``)."""
    return (resources.files("schedsyn") / "templates" / "page.css").read_text(encoding="utf-8")


def page(title: str, body: str, subtitle: str = "") -> str:
    """A complete HTML document with the style inlined."""
    sub = f'<p class="sub">{esc(subtitle)}</p>' if subtitle else ""
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{esc(title)}</title>\n<style>\n{css()}</style>\n</head>\n<body>\n"
        f"<h1>{esc(title)}</h1>\n{sub}\n{body}\n</body>\n</html>\n"
    )


@dataclass(frozen=True, slots=True)
class Column:
    """One column of :func:`table_html`: data key, header text (with its unit), format."""

    key: str
    header: str
    fmt: str | Callable[[Any], str] = "{}"
    left: bool = False


def _cell(value: Any, fmt: str | Callable[[Any], str]) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if callable(fmt):
        return fmt(value)
    try:
        return fmt.format(value)
    except (ValueError, TypeError):
        return str(value)


def table_html(
    frame: pd.DataFrame,
    columns: Sequence[Column],
    *,
    cls: str = "data",
    row_class: Callable[[pd.Series], str] | None = None,
    blank: Sequence[str] = (),
    raw: Sequence[str] = (),
) -> str:
    """A table of ``frame`` rows; ``blank`` adds empty columns (to fill in by hand) and
    ``raw`` names columns whose formatted values are HTML already."""
    head = "".join(
        f'<th class="{"l" if c.left else ""}">{esc(c.header)}</th>' for c in columns
    ) + "".join(f"<th>{esc(b)}</th>" for b in blank)
    rows = []
    for _, r in frame.iterrows():
        klass = row_class(r) if row_class is not None else ""
        cells = []
        for c in columns:
            text = _cell(r[c.key], c.fmt)
            cells.append(
                f'<td class="{"l" if c.left else ""}">{text if c.key in raw else esc(text)}</td>'
            )
        cells += ['<td class="blank"></td>' for _ in blank]
        rows.append(f'<tr class="{klass}">{"".join(cells)}</tr>')
    return (
        f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )


def facts_html(facts: Sequence[tuple[str, str]]) -> str:
    """A two-column table of (label, value) pairs; values are escaped."""
    rows = "".join(f"<tr><td>{esc(k)}</td><td>{esc(v)}</td></tr>" for k, v in facts)
    return f'<table class="facts"><tbody>{rows}</tbody></table>'


def figure_uri(ax_or_fig, dpi: int = 130) -> str:
    """PNG of the figure holding ``ax_or_fig`` as a ``data:`` URI; closes the figure."""
    import matplotlib.pyplot as plt

    fig = ax_or_fig.figure if hasattr(ax_or_fig, "figure") else ax_or_fig
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def figure_html(uri: str, alt: str, caption: str = "") -> str:
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return f'<figure><img src="{uri}" alt="{esc(alt)}">{cap}</figure>'


def provenance_html(prov: Mapping[str, Any] | None) -> str:
    """Footer: versions, inputs with SHA-256, command and time."""
    if not prov:
        return ""
    vers = ", ".join(f"{k} {v}" for k, v in prov.get("versions", {}).items())
    rows = "".join(
        f'<tr><td class="l">{esc(i["role"])}</td><td class="l mono">{esc(i["path"])}</td>'
        f'<td>{i["bytes"]}</td><td class="l mono">{esc(i["sha256"])}</td></tr>'
        for i in prov.get("inputs", [])
    )
    inputs = (
        '<table class="data"><thead><tr><th class="l">input</th><th class="l">file</th>'
        '<th>size, bytes</th><th class="l">SHA-256</th></tr></thead>'
        f"<tbody>{rows}</tbody></table>"
        if rows
        else ""
    )
    cmd = prov.get("command", "")
    return (
        "<footer>"
        f"<div>Generated {esc(prov.get('generated_utc', ''))}"
        + (f' by <span class="mono">{esc(cmd)}</span>' if cmd else "")
        + f"</div><div>Versions: {esc(vers)}</div>{inputs}</footer>"
    )


def _axes(ax, figsize):
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig.add_subplot()


# ---------------------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------------------
def band_plot(
    cp: Checkpoints,
    ax=None,
    region: tuple[float, float] | None = None,
    until_min: float | None = None,
    title: str | None = None,
):
    """Chamber setpoint, expected device temperature and its band against time.

    Checkpoints are marked on the expected device curve; with a start time the top axis
    gives the clock. ``until_min`` shows only the first minutes (e.g. the first two
    hours, where a wrong start shows).
    """
    ax = _axes(ax, (9.0, 4.4))
    t = cp.time_min
    keep = np.ones(t.size, bool) if until_min is None else t <= until_min + 1e-9
    if region is not None:
        ax.axhspan(
            region[0], region[1], color="tab:green", alpha=0.10, lw=0, label="working region"
        )
    ax.fill_between(
        t[keep],
        cp.t_low_c[keep],
        cp.t_high_c[keep],
        color="tab:red",
        alpha=0.22,
        lw=0,
        label=f"device band ({cp.box.describe().split(' (')[0]})",
    )
    ax.plot(t[keep], cp.tk_c[keep], color="tab:blue", lw=1.4, label="chamber setpoint")
    ax.plot(
        t[keep],
        cp.t_c[keep],
        color="tab:red",
        lw=1.4,
        label=f"device expected (tau {cp.params.tau_s:g} s, dT0 {cp.params.dt0_c:g} °C)",
    )
    ck = cp.check_min <= (until_min if until_min is not None else np.inf) + 1e-9
    ax.plot(
        cp.check_min[ck],
        cp.check_t_c[ck],
        ls="none",
        marker="o",
        ms=4,
        color="k",
        label=f"checkpoints (every {_interval(cp):g} min)",
    )
    end = float(t[keep][-1])
    ax.set_xlim(0.0, end)
    step = 60.0 if end > 180 else 15.0
    ax.set_xticks(np.arange(0.0, end + 1e-9, step))
    ax.set_xlabel("elapsed time, min")
    ax.set_ylabel("temperature, °C")
    ax.grid(True, alpha=0.3)
    if cp.start is not None:
        top = ax.secondary_xaxis("top")
        first = (60 - cp.start.minute) % 60 if step == 60.0 else (15 - cp.start.minute % 15) % 15
        ticks = np.arange(float(first), end + 1e-9, step)
        top.set_xticks(ticks, labels=[clock(cp.start, m) for m in ticks])
        top.set_xlabel("clock time")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False, fontsize=9)
    if title:
        ax.set_title(title)
    return ax


def _interval(cp: Checkpoints) -> float:
    return float(cp.check_min[1] - cp.check_min[0]) if cp.check_min.size > 1 else 0.0


# ---------------------------------------------------------------------------------------
# the operator sheet
# ---------------------------------------------------------------------------------------
def _f1(x: float) -> str:
    return f"{x:.1f}"


def _rate(x: float) -> str:
    return f"{x:+.3f}" if abs(x) > 1e-12 else "0"


def operator_sheet(
    cp: Checkpoints,
    *,
    experiment: str,
    region: tuple[float, float] | None = None,
    coverage: CoverageReport | None = None,
    source_coverage: CoverageReport | None = None,
    export: Any = None,
    source: str = "",
    provenance: Mapping[str, Any] | None = None,
    warnings: Sequence[str] = (),
) -> str:
    """The operator sheet of one experiment (an HTML document).

    Parameters
    ----------
    cp : Checkpoints
        Checkpoints of the programme the chamber will run (the export's read-back
        programme when there is one).
    experiment : str
        Name shown in the title.
    region : (lo, hi), optional
        Working region, degC.
    coverage : CoverageReport, optional
        Coverage of the programme that runs (re-simulated).
    source_coverage : CoverageReport, optional
        Coverage of the step table before export (shown when it differs).
    export : ControllerExport, optional
        The controller export: programme/step numbers in the step table, its notes.
    source : str
        The step table's file name.
    provenance : mapping, optional
        :func:`schedsyn.provenance.provenance` of the inputs.
    warnings : sequence of str
        Shown in a box under the facts (what the table was planned for and is not:
        :func:`schedsyn.export.planned_for_notes`).
    """
    prog = cp.programme
    total = prog.total_min
    facts: list[tuple[str, str]] = [("experiment", experiment)]
    if region is not None:
        facts.append(("working region", f"{region[0]:g} .. {region[1]:g} °C"))
    when = (
        f"{cp.start:%Y-%m-%d %H:%M} → {clock(cp.start, total)}"
        if cp.start is not None
        else "not set (times are elapsed from the start, T+h:mm)"
    )
    facts += [
        ("start → end", when),
        ("duration", f"{total:g} min ({hmm(total)} h:mm), {prog.n_segments} steps"),
        (
            "chamber",
            f"{prog.boundary_temps_c.min():.1f} .. {prog.boundary_temps_c.max():.1f} °C, "
            f"rates {prog.rates_c_per_min.min():+.2f} .. {prog.rates_c_per_min.max():+.2f} °C/min",
        ),
        ("model", f"tau {cp.params.tau_s:g} s, dT0 {cp.params.dt0_c:g} °C"),
        ("device band", cp.box.describe()),
    ]
    if export is not None:
        facts.append(
            (
                "controller",
                f"{export.spec.title}: programme(s) {', '.join(str(n) for n in export.numbers)}",
            )
        )
    if coverage is not None:
        txt = (
            f"{coverage.coverage:.0%} of the bins have ≥ {coverage.levels_required} levels "
            f"{coverage.delta_c_per_min:g} °C/min apart (min {coverage.min_levels})"
        )
        if source_coverage is not None and (
            source_coverage.coverage != coverage.coverage
            or source_coverage.min_levels != coverage.min_levels
        ):
            txt += f"; the step table before export: {source_coverage.coverage:.0%}"
        facts.append(("planned coverage", txt))
    if source:
        facts.append(("step table", source))

    body = [facts_html(facts)]
    body += [f'<div class="warn">{esc(w)}</div>' for w in warnings]
    if coverage is not None and not coverage.complete:
        body.append(
            f'<div class="warn">This programme covers only {coverage.coverage:.0%} of the '
            "working region: it is not a complete calibration.</div>"
        )
    body.append('<h2>Before the start</h2><ol class="todo">')
    todo = []
    if export is not None:
        todo.append(
            f"Load the {esc(export.spec.title)} programme(s) "
            f"{esc(', '.join(str(n) for n in export.numbers))} from the export file and "
            "compare a few steps with the table below."
        )
    else:
        todo.append("Type the programme in from the step table below and check it twice.")
    todo += [
        f"Soak the device with the chamber at {prog.start_c:g} °C. The plan assumes its "
        f"internal temperature is {cp.t_c[0]:g} °C when the programme starts (a device "
        "that heats itself reads more once running: the first checkpoints then read high "
        "by that difference, which fades within about three time constants).",
        "Start the data logger (time, internal temperature, chamber setpoint and air "
        "temperature) at the same moment as the programme.",
        "At every checkpoint write down the device temperature. Outside the band: check "
        "the programme step and the chamber display, the sensor and its cable, the door; "
        "note the time. Two readings outside the band in a row: stop and call the engineer.",
    ]
    body.append("".join(f"<li>{t}</li>" for t in todo) + "</ol>")
    notes = list(export.notes) if export is not None else []
    if notes:
        body.append('<ul class="notes">' + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>")

    body.append("<h2>Programme and device band</h2>")
    body.append(
        figure_html(
            figure_uri(band_plot(cp, region=region)),
            "chamber setpoint, expected device temperature and band against time",
            "Blue: what the chamber is told to do. Red: what the device's internal "
            "temperature should do, with its band (the range over the model box). "
            "Dots: the checkpoints of the table below.",
        )
    )
    first = min(total, 120.0)
    body.append(
        figure_html(
            figure_uri(band_plot(cp, region=None, until_min=first)),
            "the first two hours",
            f"The first {first:g} min: a wrong programme, a chamber that does not follow "
            "or a sensor fault shows here.",
        )
    )

    body.append("<h2>Checkpoints</h2>")
    w30 = cp.band_width_at(min(30.0, total))
    w60 = cp.band_width_at(min(60.0, total))
    body.append(
        f"<p>One checkpoint every {_interval(cp):g} min. Band width after 30 min: "
        f"{w30:.1f} °C, after 60 min: {w60:.1f} °C. "
        "Rows of the first hour are shaded. The band covers the model's uncertainty "
        "only: allow for your sensor's accuracy on top.</p>"
    )
    frame = cp.to_frame()
    frame["band"] = [
        f"{lo:.1f}\u00a0..\u00a0{hi:.1f}"  # no line break inside a band
        for lo, hi in zip(frame["device_low_c"], frame["device_high_c"], strict=True)
    ]
    body.append(
        table_html(
            frame,
            [
                Column("checkpoint", "#"),
                Column("clock", "clock" if cp.start is not None else "time"),
                Column("elapsed_hmm", "elapsed, h:mm"),
                Column("chamber_setpoint_c", "chamber setpoint, °C", _f1),
                Column("device_expected_c", "device expected, °C", _f1),
                Column("band", "device band, °C"),
                Column("gradient_expected_c_per_min", "device gradient, °C/min", "{:+.2f}"),
            ],
            row_class=lambda r: "early" if r["elapsed_min"] <= 60.0 + 1e-9 else "",
            blank=("device read, °C", "chamber read, °C", "initials"),
        )
    )

    body.append('<h2 class="page-break">Step table</h2>')
    steps = cp.steps_frame()
    cols = [Column("step", "step")]
    if export is not None:
        exp = export.to_frame()
        if len(exp) == len(steps):
            steps["programme"] = exp["programme"].to_numpy()
            steps["programme_step"] = exp["programme_step"].to_numpy()
            cols += [
                Column("programme", f"{export.spec.title} programme"),
                Column("programme_step", "programme step"),
            ]
    steps["type"] = np.where(np.abs(steps["rate_c_per_min"]) < 1e-12, "hold", "ramp")
    cols += [
        Column("clock_start", "start" if cp.start is not None else "start, T+h:mm"),
        Column("clock_end", "end" if cp.start is not None else "end, T+h:mm"),
        Column("duration_min", "duration, min", "{:g}"),
        Column("duration_hhmm", "duration, h:mm"),
        Column("tk_start_c", "chamber from, °C", _f1),
        Column("tk_end_c", "chamber to, °C", _f1),
        Column("rate_c_per_min", "rate, °C/min", _rate),
        Column("type", "type", left=True),
    ]
    body.append(table_html(steps, cols))
    body.append(provenance_html(provenance))
    subtitle = "Operator sheet: chamber programme, checkpoints and step table"
    return page(f"{experiment}: operator sheet", "\n".join(body), subtitle)


def build_sheet(
    programme: Programme,
    *,
    experiment: str,
    check: Any = None,
    settings: SheetSettings | None = None,
    robust: tuple[tuple[float, float], tuple[float, float]] | None = None,
    export: Any = None,
    limits: Limits | None = None,
    source: str = "",
    provenance: Mapping[str, Any] | None = None,
    warnings: Sequence[str] = (),
) -> tuple[str, Checkpoints]:
    """Checkpoints and the operator sheet of a programme.

    Parameters
    ----------
    programme : Programme
        The step table.
    experiment : str
    check : CoverageCheck, optional
        Region and model (the band is centred on its model; default
        :class:`ThermalParams`).
    settings : SheetSettings, optional
        Start time, checkpoint interval, band box.
    robust : ((tau_lo, tau_hi), (dt0_lo, dt0_hi)), optional
        The plan's robust box: the band uses it instead of the default box.
    export : ControllerExport, optional
        When given, the sheet shows the exported programme (what the controller runs).
    limits : Limits, optional
        ``t_init_c`` gives the device's start temperature.
    warnings : sequence of str
        Boxes on the sheet (:func:`operator_sheet`).
    """
    settings = SheetSettings() if settings is None else settings
    limits = Limits() if limits is None else limits
    params = check.params if check is not None else ThermalParams()
    runs = export.exported if export is not None else programme
    cp = checkpoints(
        runs,
        params,
        settings.box(params, robust),
        interval_min=settings.interval_min,
        start=settings.start,
        t0_c=limits.t_init_c,
    )
    coverage = check.report(runs) if check is not None else None
    src_cov = check.report(programme) if (check is not None and export is not None) else None
    region = (check.grid.lo_c, check.grid.hi_c) if check is not None else None
    text = operator_sheet(
        cp,
        experiment=experiment,
        region=region,
        coverage=coverage,
        source_coverage=src_cov,
        export=export,
        source=source,
        provenance=provenance,
        warnings=warnings,
    )
    return text, cp


# ---------------------------------------------------------------------------------------
# the campaign index
# ---------------------------------------------------------------------------------------
_UNITS = (
    ("_c_per_min", "°C/min"),
    ("_dph", "°/h"),
    ("_min", "min"),
    ("_s", "s"),
    ("_c", "°C"),
)


def column_header(name: str) -> str:
    """``duration_min`` -> ``duration, min``; ``coverage`` -> ``coverage, %``;
    ``d_efficiency`` -> ``D-efficiency``."""
    m = re.fullmatch(r"([daigDAIG])_efficiency", name)
    if m:
        return f"{m.group(1).upper()}-efficiency"
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ')}, {unit}"
    if name.startswith("coverage") or name.endswith("coverage") or "_coverage" in name:
        return f"{name.replace('_', ' ').replace('delta 0p1', 'at Δ 0.1')}, %"
    return name.replace("_", " ")


def _column_format(name: str, values: pd.Series) -> str | Callable[[Any], str]:
    if "coverage" in name:
        return lambda v: f"{100 * float(v):.0f}"
    if pd.api.types.is_bool_dtype(values):
        return lambda v: "yes" if bool(v) else "no"
    if pd.api.types.is_float_dtype(values):
        return "{:.4g}"
    return "{}"


#: Summary columns that measure informativeness (D-/I-efficiency ...): shown up front.
_INFORMATIVE = re.compile(r"effic|informat|(^|_)[daig]_?eff", re.IGNORECASE)
_MAIN = (
    ("duration_min", "duration, min", "{:g}"),
    ("steps", "steps", "{:g}"),
    ("coverage", "coverage, %", None),
    ("min_levels", "min levels", "{:g}"),
    ("coverage_delta_0p1", "coverage at Δ 0.1 °C/min, %", None),
    ("status", "status", "{}"),
)


def campaign_index(
    summary: pd.DataFrame,
    links: Mapping[str, Sequence[tuple[str, str]]],
    *,
    title: str = "Calibration campaign",
    notes: Sequence[str] = (),
    provenance: Mapping[str, Any] | None = None,
) -> str:
    """Index page of a campaign.

    A main table (region, duration, steps, coverage, levels, status, any
    informativeness column such as a D- or I-efficiency, links to each experiment's
    sheet and files) and, below, every column of the summary transposed (one row per
    column, units from the column names), so that columns added later show too.
    ``links`` maps an experiment name to ``(label, relative href)`` pairs.
    """
    if "experiment" not in summary.columns:
        raise ParameterError("the campaign summary needs an 'experiment' column")
    frame = summary.copy()
    frame["files"] = [
        " · ".join(f'<a href="{esc(h)}">{esc(lbl)}</a>' for lbl, h in links.get(str(e), ()))
        for e in frame["experiment"]
    ]
    cols = [Column("experiment", "experiment", left=True)]
    if {"working_min_c", "working_max_c"} <= set(frame.columns):
        frame["region"] = [
            f"{a:g} .. {b:g}"
            for a, b in zip(frame["working_min_c"], frame["working_max_c"], strict=True)
        ]
        cols.append(Column("region", "working region, °C"))
    for key, header, fmt in _MAIN:
        if key in frame.columns:
            cols.append(
                Column(key, header, fmt or _column_format(key, frame[key]), left=key == "status")
            )
    for key in summary.columns:
        if _INFORMATIVE.search(str(key)):
            cols.append(Column(key, column_header(str(key)), _column_format(key, frame[key])))
    cols.append(Column("files", "files", left=True))
    n_bad = int((~summary["complete"].astype(bool)).sum()) if "complete" in summary else 0
    verdict = (
        '<p class="good">Every experiment is complete.</p>'
        if n_bad == 0
        else f'<div class="warn">{n_bad} of {len(summary)} experiments are NOT complete.</div>'
    )
    body = [verdict, table_html(frame, cols, raw=("files",))]
    if notes:
        body.append('<ul class="notes">' + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>")
    # every column, transposed: one row per summary column, one column per experiment
    names = [str(e) for e in summary["experiment"]]
    rows = []
    for key in summary.columns:
        if key == "experiment":
            continue
        col_fmt = _column_format(key, summary[key])
        rows.append([column_header(str(key))] + [_cell(v, col_fmt) for v in summary[key]])
    detail = pd.DataFrame(rows, columns=["column", *names])
    body.append("<h2>Every figure of the summary</h2>")
    body.append(
        table_html(
            detail,
            [Column("column", "summary column", left=True)] + [Column(n, n) for n in names],
        )
    )
    body.append(provenance_html(provenance))
    return page(title, "\n".join(body), "Summary of the planned experiments")


def write_page(path: Path | str, text: str, inputs: Sequence[Path | str] = ()) -> Path:
    """Write an HTML page atomically (never over an input)."""
    from .io import write_text_atomic

    return write_text_atomic(path, text, inputs)
