"""Operator sheets, the campaign index and run reports.

The band is checked against scipy's ODE solver on a finer (tau, dT0) grid than the one
the sheet samples; pages are rendered in a real headless browser (Debian's chromium;
skipped with a reason where none is installed): the screenshot must not be blank and
the rendered DOM must hold every step and every checkpoint.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import re
import shutil
import subprocess
import sys
import tempfile
from datetime import datetime
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from schedsyn.checkpoints import (
    SheetSettings,
    ToleranceBox,
    checkpoints,
    clock,
    parse_start,
)
from schedsyn.cli import main
from schedsyn.errors import ParameterError
from schedsyn.export import CoverageCheck, ExportSettings, export_programme, read_step_table
from schedsyn.grid import BinGrid
from schedsyn.params import ThermalParams
from schedsyn.sheet import build_sheet, campaign_index, column_header

BASELINE = Path("data/baseline_exp1_steps.csv")
LOG = Path("data/sample_run_exp1.csv")
W1 = BinGrid(-50.0, -30.0)


def run_cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


# ---------------------------------------------------------------------------------------
# a real headless browser
# ---------------------------------------------------------------------------------------
def _browser() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if Path("/usr/bin/chromium").is_file() else None


BROWSER = _browser()
needs_browser = pytest.mark.skipif(
    BROWSER is None,
    reason="no headless browser: install Debian's chromium (apt-get install -y chromium)",
)
slow = pytest.mark.slow


def browse(page: Path, *args: str, window: str = "1200,2400") -> subprocess.CompletedProcess:
    """Run chromium headless on a local page with a fresh profile (no network use)."""
    assert BROWSER is not None
    with tempfile.TemporaryDirectory() as profile:
        cmd = [
            BROWSER,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            f"--window-size={window}",
            *args,
            page.resolve().as_uri(),
        ]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=False)


def screenshot_stats(png: Path) -> dict:
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3].astype(float)
    gray = img.mean(axis=2)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return {
        "ink": float(np.mean(gray < 0.9)),
        "std": float(gray.std()),
        "red": int(np.sum((r > 0.75) & (g < 0.45) & (b < 0.45))),
        "blue": int(np.sum((b > 0.6) & (r < 0.3))),
    }


def table_rows_after(dom: str, heading: str) -> int:
    """Body rows of the first table after the ``<h2>`` with ``heading``."""
    i = dom.index(heading)
    table = dom[dom.index("<table", i) : dom.index("</table>", i)]
    body = table[table.index("<tbody>") :]
    return body.count("<tr")


# ---------------------------------------------------------------------------------------
# the band and the checkpoints
# ---------------------------------------------------------------------------------------
def ode_temperatures(prog, taus_s, dt0s_c, times_min: np.ndarray) -> np.ndarray:
    """Device temperature for many (tau, dT0) at once: one vector ODE, scipy's solver."""
    edges = np.concatenate(([0.0], np.cumsum(prog.durations_min)))
    temps = prog.boundary_temps_c
    tau = np.asarray(taus_s, dtype=float) / 60.0
    d0 = np.asarray(dt0s_c, dtype=float)
    sol = solve_ivp(
        lambda x, y: (np.interp(x, edges, temps) + d0 - y) / tau,
        (0.0, float(edges[-1])),
        np.full(tau.size, 20.0),
        t_eval=times_min,
        max_step=0.2,
        rtol=1e-9,
        atol=1e-9,
    )
    return sol.y


def test_band_is_the_range_of_the_device_temperature_over_the_box():
    prog = read_step_table(BASELINE).programme
    params = ThermalParams(2400.0, 3.0)
    box = ToleranceBox.around(params, 0.15, 2.0)
    cp = checkpoints(prog, params, box, interval_min=30.0)
    assert (box.tau_lo_s, box.tau_hi_s, box.dt0_lo_c, box.dt0_hi_c) == (2040.0, 2760.0, 1.0, 5.0)
    t = cp.check_min
    nominal = ode_temperatures(prog, [2400.0], [3.0], t)[0]
    assert np.max(np.abs(cp.check_t_c - nominal)) < 1e-4
    # independent: a finer grid, with interior dT0 values too
    taus, dt0s = np.meshgrid(np.linspace(2040.0, 2760.0, 25), np.linspace(1.0, 5.0, 5))
    runs = ode_temperatures(prog, taus.ravel(), dt0s.ravel(), t)
    lo, hi = runs.min(axis=0), runs.max(axis=0)
    # the sheet samples a subset (9 taus x the dT0 ends), so its band lies inside, and
    # within a small sampling error of, the fine one
    assert np.all(cp.check_low_c >= lo - 1e-4) and np.all(cp.check_high_c <= hi + 1e-4)
    assert np.max(np.abs(cp.check_low_c - lo)) < 0.05
    assert np.max(np.abs(cp.check_high_c - hi)) < 0.05
    assert np.all(cp.check_low_c <= cp.check_t_c + 1e-9)
    assert np.all(cp.check_t_c <= cp.check_high_c + 1e-9)
    # wide enough to matter after the start: a 1 degC dT0 error shows after an hour
    assert cp.band_width_at(0.0) == pytest.approx(0.0, abs=1e-9)
    assert cp.band_width_at(60.0) > 1.0


def test_checkpoints_every_interval_with_wall_clock_times():
    prog = read_step_table(BASELINE).programme  # 496 min
    cp = checkpoints(prog, interval_min=30.0, start=parse_start("2026-11-24 23:30"))
    frame = cp.to_frame()
    assert frame["elapsed_min"].tolist() == [30.0 * k for k in range(17)] + [496.0]
    assert frame["clock"].iloc[0] == "23:30"
    assert frame["clock"].iloc[1] == "Wed 25 Nov 00:00"  # past midnight: the date shows
    assert frame["chamber_setpoint_c"].iloc[1] == pytest.approx(20.0 - 30.0)  # -1 degC/min
    steps = cp.steps_frame()
    assert steps["clock_start"].iloc[1] == "Wed 25 Nov 00:57"  # 87 min after 23:30
    assert clock(None, 125.0) == "T+2:05"
    assert cp.end == datetime(2026, 11, 25, 7, 46)


def test_sheet_settings_and_start_times_are_validated():
    assert parse_start("2026-11-24T08:00") == datetime(2026, 11, 24, 8, 0)
    for bad in ("24.11.2026 08:00", "2026-13-01 08:00", "tomorrow"):
        with pytest.raises(ParameterError, match="write it like '2026-11-24 08:00'"):
            parse_start(bad)
    with pytest.raises(ParameterError, match="interval_min"):
        SheetSettings(interval_min=0)
    with pytest.raises(ParameterError, match="tau_rel"):
        SheetSettings(band_tau_rel=1.5)
    robust = SheetSettings().box(ThermalParams(), ((2200.0, 2600.0), (2.0, 4.0)))
    assert (robust.tau_lo_s, robust.dt0_hi_c) == (2200.0, 4.0) and "robust" in robust.source


def test_index_headers_carry_units():
    assert column_header("duration_min") == "duration, min"
    assert column_header("rate_c_per_min") == "rate, °C/min"
    assert column_header("coverage_delta_0p1") == "coverage at Δ 0.1, %"
    assert column_header("drift_dph") == "drift, °/h"
    assert column_header("d_efficiency") == "D-efficiency"


# ---------------------------------------------------------------------------------------
# rendering in a browser
# ---------------------------------------------------------------------------------------
def _sheet(tmp_path, controller="espec-p300", max_steps=5):
    table = read_step_table(BASELINE)
    check = CoverageCheck(W1)
    ex = export_programme(
        table.programme, ExportSettings(controller, max_steps=max_steps), check=check
    )
    text, cp = build_sheet(
        table.programme,
        experiment="exp 1 <baseline>",
        check=check,
        settings=SheetSettings(start=parse_start("2026-11-24 08:00")),
        export=ex,
        source=str(BASELINE),
    )
    path = tmp_path / "sheet.html"
    path.write_text(text, encoding="utf-8")
    return path, text, cp, ex


def test_sheet_is_self_contained_and_complete(tmp_path):
    path, text, cp, ex = _sheet(tmp_path)
    # self-contained: no external resource, images as data URIs, style inline
    assert not re.search(r"""(src|href)=["']?(https?:|//)""", text)
    assert text.count('src="data:image/png;base64,') == 2
    assert "@media print" in text and "@page" in text
    assert "exp 1 &lt;baseline&gt;" in text  # escaped
    # the export's programme numbers and notes are on it
    assert "ESPEC P-300: programme(s) 1, 2, 3" in text
    assert "chained (end mode RUN" in text
    for unit in ("chamber setpoint, °C", "device band, °C", "rate, °C/min", "duration, min"):
        assert unit in text


@slow
@needs_browser
def test_sheet_renders_in_a_headless_browser(tmp_path):
    path, text, cp, ex = _sheet(tmp_path)
    png = tmp_path / "sheet.png"
    res = browse(path, f"--screenshot={png}", window="1200,2600")
    assert png.is_file() and png.stat().st_size > 20_000, res.stderr[-2000:]
    stats = screenshot_stats(png)
    # not blank: text, tables and the plots' red band and blue chamber curve are drawn
    assert stats["ink"] > 0.03 and stats["std"] > 0.08, stats
    assert stats["red"] > 500 and stats["blue"] > 500, stats
    dom = browse(path, "--dump-dom").stdout
    assert table_rows_after(dom, "Step table</h2>") == ex.exported.n_segments == 12
    assert table_rows_after(dom, "Checkpoints</h2>") == cp.check_min.size == 18
    pdf = tmp_path / "sheet.pdf"
    browse(path, f"--print-to-pdf={pdf}", "--no-pdf-header-footer")
    data = pdf.read_bytes()
    assert data[:5] == b"%PDF-" and len(re.findall(rb"/Type\s*/Page[^s]", data)) >= 2


def test_cli_sheet_from_a_plan_folder_uses_plan_json(tmp_path):
    plan_dir = tmp_path / "W1"
    plan_dir.mkdir()
    (plan_dir / "steps.csv").write_bytes(BASELINE.read_bytes())
    plan = {
        "experiment": "W1",
        "tau_s": 2500.0,
        "dt0_c": 2.5,
        "spec": {"name": "W1", "working_lo_c": -50.0, "working_hi_c": -30.0,
                 "levels_required": 6, "delta_c_per_min": 0.05},
        "limits": {"chamber_min_c": -70.0, "t_init_c": 20.0},
        "robust_scenarios": [{"tau_s": 2300.0, "dt0_c": 2.0}, {"tau_s": 2700.0, "dt0_c": 3.0}],
    }  # fmt: skip
    (plan_dir / "plan.json").write_text(json.dumps(plan))
    rc, out, err = run_cli(["sheet", str(plan_dir), "--start", "2026-11-24 08:00"])
    assert rc == 0, err
    text = (plan_dir / "sheet.html").read_text(encoding="utf-8")
    assert "tau 2300–2700 s × dT0 2–3 °C (the plan&#x27;s robust box)" in text
    assert "tau 2500 s, dT0 2.5 °C" in text
    assert "-50 .. -30 °C" in text
    sha = hashlib.sha256(BASELINE.read_bytes()).hexdigest()
    assert sha in text
    # bad input: one line, exit 2
    rc, _, err = run_cli(["sheet", str(plan_dir), "--start", "24/11/2026"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "2026-11-24 08:00" in err
    rc, _, err = run_cli(["sheet", str(BASELINE)])
    assert rc == 2 and "give --region LO HI" in err


# ---------------------------------------------------------------------------------------
# the campaign: exports, sheets and the index
# ---------------------------------------------------------------------------------------
CAMPAIGN = """
[settings]
levels_required = 2
segment_min = 5

[export]
controller = ["espec-p300", "watlow-f4t", "binder-mb"]
max_steps = 6

[sheet]
start = "2026-11-24 08:00"
interval_min = 20

[[experiment]]
name = "S"
working_lo_c = -10
working_hi_c = 0
approx_lo_c = -20
approx_hi_c = 10
"""


@pytest.fixture(scope="module")
def small_campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("campaign")
    cfg = d / "small.toml"
    cfg.write_text(CAMPAIGN)
    out = d / "out"
    rc, text, err = run_cli(["campaign", str(cfg), "--out", str(out), "--quiet"])
    return out, rc, text, err


@slow
@pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")
def test_campaign_writes_exports_sheets_and_an_index(small_campaign):
    out, rc, text, err = small_campaign
    summary = pd.read_csv(out / "summary.csv")
    assert rc == (0 if bool(summary["complete"].iloc[0]) else 1), err
    steps = read_step_table(out / "S" / "steps.csv").programme
    from schedsyn.export import read_export

    for ctl, suffix in (("espec-p300", "json"), ("watlow-f4t", "json"), ("binder-mb", "csv")):
        back = read_export(out / "S" / f"steps.{ctl}.{suffix}")
        assert back.programme.total_min == pytest.approx(steps.total_min)
        if ctl == "binder-mb" and len(back.parts) > 1:
            # each part but the last ends a second early for its 1-s end segment
            t = np.arange(0.0, steps.total_min, 0.05)
            gap = np.abs(back.programme.chamber_at(t) - steps.chamber_at(t))
            assert np.max(gap) <= 3.0 / 60.0 + 1e-9
            continue
        assert np.allclose(back.programme.boundary_temps_c, steps.boundary_temps_c)
        assert np.allclose(back.programme.durations_min, steps.durations_min)
    assert "coverage of [-10, 0] °C re-simulated" in text
    sheet = (out / "S" / "sheet.html").read_text(encoding="utf-8")
    assert "every 20 min" in sheet and "08:00" in sheet
    assert "staging" not in sheet  # the sheet names its table as it lies beside it
    index = (out / "index.html").read_text(encoding="utf-8")
    assert "staging" not in index
    for href in re.findall(r'href="([^"]+)"', index):
        assert (out / href).is_file(), href


@slow
@needs_browser
@pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")
def test_campaign_index_renders_with_one_row_per_experiment(small_campaign):
    out, *_ = small_campaign
    dom = browse(out / "index.html", "--dump-dom").stdout
    assert table_rows_after(dom, "<h1>") == 1
    assert ">sheet</a>" in dom


def test_campaign_export_and_sheet_tables_are_validated(tmp_path):
    from schedsyn.campaign import load_campaign

    base = CAMPAIGN.replace("max_steps = 6", 'max_steps = 6\nend_mode = "OFF"')
    cfg = tmp_path / "c.toml"
    cfg.write_text(base.replace('["espec-p300", "watlow-f4t", "binder-mb"]', '"espec-p300"'))
    conf = load_campaign(cfg)
    assert [e.controller for e in conf.exports] == ["espec-p300"]
    assert conf.exports[0].end_mode == "OFF" and conf.sheet.interval_min == 20.0
    cases = [
        (CAMPAIGN.replace("max_steps = 6", "max_step = 6"), r"\[export\]: unknown key"),
        (CAMPAIGN.replace('"binder-mb"]', '"binder"]'), r"\[export\].*controller 'binder'"),
        (CAMPAIGN.replace('"2026-11-24 08:00"', '"8 am"'), r"\[sheet\].*2026-11-24 08:00"),
        (CAMPAIGN.replace("interval_min = 20", "interval_min = -5"), r"\[sheet\].*interval_min"),
    ]
    for text, words in cases:
        cfg.write_text(text)
        with pytest.raises(ParameterError, match=words):
            load_campaign(cfg)
    # a TOML date-time works as a start too
    cfg.write_text(CAMPAIGN.replace('"2026-11-24 08:00"', "2026-11-24T08:00:00"))
    assert load_campaign(cfg).sheet.start == datetime(2026, 11, 24, 8, 0)


def test_index_shows_informativeness_columns_and_every_column():
    frame = pd.DataFrame(
        {
            "experiment": ["W1", "W2"],
            "working_min_c": [-50.0, -30.0],
            "working_max_c": [-30.0, 0.0],
            "coverage": [1.0, 0.9],
            "complete": [True, False],
            "d_efficiency": [0.81, 0.62],
            "new_figure_s": [1.5, 2.5],
        }
    )
    text = campaign_index(frame, {"W1": [("sheet", "W1/sheet.html")]})
    assert "1 of 2 experiments are NOT complete" in text
    assert "D-efficiency" in text and "0.81" in text
    assert "new figure, s" in text  # a column added later still shows, with its unit
    assert '<a href="W1/sheet.html">sheet</a>' in text


# ---------------------------------------------------------------------------------------
# the run report
# ---------------------------------------------------------------------------------------
def test_report_names_versions_inputs_and_verdict(tmp_path):
    diag = tmp_path / "diag"
    diag.mkdir()
    (diag / "diagnosis.json").write_text(
        json.dumps(
            {
                "effect": "chamber_lag",
                "parameters": {"tau_air_s": 312.5},
                "uncertainty": {"tau_air_s": 4.2},
                "rms_before_c": 0.91,
                "rms_after_c": 0.12,
                "holdout": {"part": "first", "rms_before_c": 0.95, "rms_after_c": 0.15},
                "ambiguous_with": ["second_time_constant"],
                "warnings": ["no air channel"],
            }
        )
    )
    fit = tmp_path / "fit"
    fit.mkdir()
    (fit / "fit.json").write_text(json.dumps({"model": "cubic in (T, g)", "rms_dph": 0.0123}))
    (fit / "coefficients.csv").write_text("term,value_dph\n1,0.5\nT,0.01\n")
    out = tmp_path / "rep"
    rc, text, err = run_cli(
        ["report", str(LOG), str(BASELINE), "--region", "-50", "-30",
         "--diagnosis", str(diag), "--fit", str(fit), "--out", str(out)]
    )  # fmt: skip
    assert rc == 0, err
    page = (out / "report.html").read_text(encoding="utf-8")
    for path in (LOG, BASELINE, diag / "diagnosis.json", fit / "fit.json"):
        assert hashlib.sha256(path.read_bytes()).hexdigest() in page, path
    for pkg in ("numpy", "scipy", "pandas", "cvxpy"):
        assert f"{pkg} {metadata.version(pkg)}" in page
    summary = json.loads((out / "report.json").read_text())
    cov = pd.read_csv(out / "coverage.csv")
    assert summary["run_coverage"] == pytest.approx(cov["run_covered"].mean())
    assert summary["planned_coverage"] == pytest.approx(cov["planned_covered"].mean())
    assert summary["run_coverage"] < summary["planned_coverage"]  # the sample run falls short
    assert f"The run covered {summary['run_coverage']:.0%}" in page
    assert "chamber_lag" in page and "312.5 ± 4.2" in page and "0.910 → 0.120" in page
    assert "held-out RMS gap (the first part, fitted on the rest), °C" in page
    assert "cubic in (T, g)" in page and "value, °/h" in page  # value_dph: unit from the name
    assert "coefficients.csv" in page
    assert not re.search(r"""(src|href)=["']?(https?:|//)""", page)
    rc, _, err = run_cli(
        ["report", str(LOG), str(BASELINE), "--region", "-50", "-30", "--fit", str(tmp_path / "x")]
    )
    assert rc == 2 and "--fit" in err and "not a folder" in err


@slow
@needs_browser
def test_report_renders_every_bin(tmp_path):
    out = tmp_path / "rep"
    rc, _, err = run_cli(
        ["report", str(LOG), str(BASELINE), "--region", "-50", "-30", "--out", str(out)]
    )
    assert rc == 0, err
    png = tmp_path / "r.png"
    browse(out / "report.html", f"--screenshot={png}", window="1200,3000")
    stats = screenshot_stats(png)
    assert stats["ink"] > 0.03 and stats["red"] > 500, stats
    dom = browse(out / "report.html", "--dump-dom").stdout
    assert table_rows_after(dom, "Coverage: planned vs achieved</h2>") == 20


# ---------------------------------------------------------------------------------------
# layering
# ---------------------------------------------------------------------------------------
def test_core_modules_do_not_load_matplotlib():
    code = (
        "import sys, schedsyn, schedsyn.export, schedsyn.checkpoints, schedsyn.provenance, "
        "schedsyn.controllers; assert 'matplotlib' not in sys.modules, 'matplotlib loaded'"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stderr


def test_a_failing_export_does_not_stop_the_sheet(tmp_path):
    from types import SimpleNamespace

    from schedsyn.cli.sheet import write_plan_deliverables
    from schedsyn.params import Limits
    from schedsyn.planner import ExperimentSpec

    table = read_step_table(BASELINE)
    (tmp_path / "steps.csv").write_bytes(BASELINE.read_bytes())
    plan = SimpleNamespace(
        spec=ExperimentSpec("E1", -50.0, -30.0, -52.0, -20.0),
        params=ThermalParams(),
        limits=Limits(),
        programme=table.programme,
        scenarios=(ThermalParams(),),
    )
    too_small = ExportSettings("espec-p300", max_steps=1, programmes=2)
    lines, links, problem = write_plan_deliverables(
        plan, tmp_path, (too_small, ExportSettings("csv")), None
    )
    assert problem and any("espec-p300 export of E1 FAILED" in ln for ln in lines)
    assert (tmp_path / "sheet.html").is_file()
    assert links == [("sheet", "sheet.html"), ("plan", "plan.json"), ("csv", "steps.typed.csv")]
    assert not (tmp_path / "steps.espec-p300.json").exists()
    assert read_step_table(tmp_path / "steps.typed.csv").programme.n_segments == 12
