"""Campaign config (TOML), plan_campaign/`schedsyn campaign` outputs, chamber_requirement.

The planner is slow: only small cases are planned (a 10 degC region with 2 levels), each
once per module. The small campaign must be complete, and that claim is checked with
separate code: the exported step table integrated by scipy and its levels counted plainly
(tests/independent.py), not with schedsyn's simulator or coverage metric.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import re

import numpy as np
import pandas as pd
import pytest
from independent import chamber_knots, ode_trajectories, table_check

from schedsyn.campaign import (
    PAPER_BASELINE_EXP1,
    PAPER_CAMPAIGN_TOML,
    SUMMARY_COLUMNS,
    CampaignConfig,
    chamber_requirement,
    default_campaign,
    load_campaign,
)
from schedsyn.cli import main
from schedsyn.coverage import trajectory_coverage
from schedsyn.errors import ParameterError
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate

# cvxpy warns when Clarabel reports an inaccurate LP solution inside the planner's search;
# the plan is still checked independently (here and by the planner), so it is not an error
pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")

SMALL_TOML = """
[model]
tau_s = 2400
dt0_c = 3.0

[limits]
chamber_min_c = -70

[settings]
levels_required = 2
segment_min = 5

[[experiment]]
name = "S"
working_lo_c = -10
working_hi_c = 0
approx_lo_c = -20
approx_hi_c = 10
baseline_steps = "{baseline}"
"""


# ---------------------------------------------------------------------------------------
# config
# ---------------------------------------------------------------------------------------
def test_paper_campaign_file_is_the_default_campaign():
    cfg = load_campaign(PAPER_CAMPAIGN_TOML)
    assert cfg == default_campaign()
    assert [e.name for e in cfg.experiments] == ["W1", "W2", "W3", "W4"]
    w1 = cfg.experiments[0]
    assert (w1.working_lo_c, w1.working_hi_c, w1.approx_lo_c, w1.approx_hi_c) == (
        -50,
        -30,
        -52,
        -20,
    )
    assert cfg.baseline_for(0) == PAPER_BASELINE_EXP1 and cfg.baseline_for(3) is None


def test_settings_apply_to_every_experiment_and_can_be_overridden(tmp_path):
    text = """
[model]
tau_s = 2000
[limits]
chamber_min_c = -60
duration_max_min = 480
[settings]
levels_required = 4
objective = "margin"
[robust]
dt0_c = [2, 4]
[[experiment]]
name = "a"
working_lo_c = 0
working_hi_c = 10
approx_lo_c = -5
approx_hi_c = 15
[[experiment]]
name = "b"
working_lo_c = 10
working_hi_c = 20
approx_lo_c = 5
approx_hi_c = 25
levels_required = 3
segment_min = 10
"""
    path = tmp_path / "c.toml"
    path.write_text(text)
    cfg = load_campaign(path)
    assert cfg.params == ThermalParams(tau_s=2000.0, dt0_c=3.0)
    assert cfg.limits == Limits(chamber_min_c=-60.0, duration_max_min=480.0)
    assert cfg.robust_dt0_c == (2.0, 4.0) and cfg.robust_tau_s is None
    a, b = cfg.experiments
    assert a == ExperimentSpec("a", 0, 10, -5, 15, levels_required=4, objective="margin")
    assert b == ExperimentSpec(
        "b", 10, 20, 5, 25, levels_required=3, objective="margin", segment_min=10
    )
    assert cfg.baseline_steps == ()


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda t: t.replace("[model]", "[model]\ntau = 3"), ["[model]", "unknown", "tau"]),
        (lambda t: t.replace("tau_s = 2400", 'tau_s = "fast"'), ["[model]", "tau_s", "number"]),
        (
            lambda t: t.replace("levels_required = 2", "levels_required = 2.5"),
            ["[settings]", "levels_required", "whole"],
        ),
        (lambda t: t.replace("working_hi_c = 0\n", ""), ["S", "missing", "working_hi_c"]),
        (lambda t: t.replace('name = "S"', "name = 7"), ["name", "string"]),
        (
            lambda t: t.replace("approx_hi_c = 10", "approx_hi_c = -5"),
            ["S", "approximation region"],
        ),
        (
            lambda t: t.replace("chamber_min_c = -70", "chamber_min_c = true"),
            ["[limits]", "chamber_min_c", "number"],
        ),
        (lambda t: t.replace("[settings]", "[setting]"), ["unknown", "setting"]),
        (lambda t: t.replace("baseline_exp1", "no_such"), ["baseline_steps", "does not exist"]),
        (
            lambda t: (
                t + '\n[[experiment]]\nname = "S"\nworking_lo_c = 0\nworking_hi_c = 1\n'
                "approx_lo_c = 0\napprox_hi_c = 1\n"
            ),
            ["distinct", "S"],
        ),
        (lambda t: t.replace("dt0_c = 3.0", "dt0_c = 3.0 ="), ["not valid TOML"]),
        (lambda t: t.split("[[experiment]]")[0], ["no experiment"]),
    ],
)
def test_config_errors_name_the_file_and_key(tmp_path, edit, words):
    path = tmp_path / "bad.toml"
    path.write_text(edit(SMALL_TOML.format(baseline=PAPER_BASELINE_EXP1.as_posix())))
    with pytest.raises(ParameterError) as info:
        load_campaign(path)
    msg = str(info.value)
    assert str(path) in msg
    for w in words:
        assert w in msg, msg


def test_config_validates_in_python_too():
    spec = ExperimentSpec("x", 0, 10, -5, 15)
    with pytest.raises(ParameterError, match="at least one"):
        CampaignConfig(())
    with pytest.raises(ParameterError, match="folder"):
        CampaignConfig((dataclasses.replace(spec, name="a/b"),))
    with pytest.raises(ParameterError, match="lo <= hi"):
        CampaignConfig((spec,), robust_tau_s=(2600.0, 2200.0))
    with pytest.raises(ParameterError, match="one entry per experiment"):
        CampaignConfig((spec,), baseline_steps=(None, None))
    with pytest.raises(ParameterError, match="does not exist"):
        load_campaign("/nonexistent/campaign.toml")


# ---------------------------------------------------------------------------------------
# `schedsyn campaign` on a small campaign (planned once)
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small_campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("campaign")
    cfg = d / "small.toml"
    cfg.write_text(SMALL_TOML.format(baseline=PAPER_BASELINE_EXP1.as_posix()))
    out = d / "out"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):  # progress lines (one experiment: in-process)
        rc = main(["campaign", str(cfg), "--out", str(out)])
    return cfg, out, rc, err.getvalue()


def test_campaign_writes_every_output(small_campaign):
    _, out, rc, _ = small_campaign
    summary = pd.read_csv(out / "summary.csv")
    assert tuple(summary.columns) == SUMMARY_COLUMNS
    assert summary["experiment"].tolist() == ["S"]
    for name in ("steps.csv", "plan.json", "program.png", "phase.png", "coverage.png"):
        assert (out / "S" / name).stat().st_size > 0, name
    row = summary.iloc[0]
    # this small request is easily met: complete, exit code 0 (1 means incomplete)
    assert rc == 0 and bool(row["complete"]) and row["status"] == "complete"
    assert row["coverage"] == 1.0 and row["min_levels"] >= 2
    plan = json.loads((out / "S" / "plan.json").read_text())
    assert plan["tau_s"] == 2400.0 and plan["dt0_c"] == 3.0
    assert plan["complete"] is True and plan["violations"] == []
    assert plan["coverage"] == pytest.approx(row["coverage"])
    assert plan["spec"]["levels_required"] == 2
    assert math.isfinite(plan["solve_s"]) and plan["solve_s"] > 0


def test_campaign_reports_progress_with_experiment_and_solver_time(small_campaign):
    *_, err = small_campaign
    # stderr is not a terminal here: plain lines, each with a timestamp
    stamp = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d ")
    assert all(stamp.match(ln) for ln in err.splitlines()), err
    lines = [stamp.sub("", ln) for ln in err.splitlines()]
    lines = [ln for ln in lines if ln.startswith("S [")]
    assert lines, err
    times = [float(re.match(r"S \[\s*([0-9.]+) s\]", ln).group(1)) for ln in lines]
    assert times == sorted(times) and times[-1] > 0
    assert "done:" in lines[-1]


def test_exported_table_gives_the_reported_coverage(small_campaign):
    """Independent check of steps.csv: scipy's ODE solver and plain counting give every
    bin at least 2 distinct levels, the summary's figures, and every limit met."""
    _, out, _, _ = small_campaign
    row = pd.read_csv(out / "summary.csv").iloc[0]
    limits = Limits()
    steps = out / "S" / "steps.csv"
    ind = table_check(steps, (-10.0, 0.0), 2)
    assert ind["coverage"] == 1.0 and ind["min_levels"] >= 2, ind["levels"]
    assert ind["min_levels"] == row["min_levels"]
    assert table_check(steps, (-10.0, 0.0), 2, delta=0.1)["coverage"] == pytest.approx(
        row["coverage_delta_0p1"]
    )
    assert ind["duration_min"] == pytest.approx(row["duration_min"])
    # every limit: rates, chamber range, 20 degC at both ends, time limit, device range
    assert limits.rate_min_c_per_min - 1e-9 <= ind["rates_c_per_min"].min()
    assert ind["rates_c_per_min"].max() <= limits.rate_max_c_per_min + 1e-9
    assert ind["chamber_start_c"] == 20.0 and abs(ind["chamber_end_c"] - 20.0) <= 0.5
    assert ind["duration_min"] <= limits.duration_max_min
    assert limits.device_min_c <= ind["device_min_c"] <= ind["device_max_c"] <= 62.0
    # the table reads back (validation) with whole minutes and 0.1 degC, as typed
    prog = read_steps(steps, limits)
    assert prog.n_segments == row["steps"] and prog.violations(limits) == []
    assert np.allclose(prog.durations_min, np.round(prog.durations_min))
    assert np.allclose(prog.boundary_temps_c * 10, np.round(prog.boundary_temps_c * 10))


def test_baseline_sits_next_to_the_plan(small_campaign):
    _, out, _, _ = small_campaign
    row = pd.read_csv(out / "summary.csv").iloc[0]
    prog = read_steps(PAPER_BASELINE_EXP1)
    traj = simulate(prog, ThermalParams(), t0_c=20.0)
    rep = trajectory_coverage(traj, -10, 0, levels_required=2, delta_c_per_min=0.05)
    assert row["baseline"] == PAPER_BASELINE_EXP1.name
    assert row["baseline_coverage"] == pytest.approx(rep.coverage)
    assert row["baseline_min_levels"] == rep.min_levels
    assert row["baseline_duration_min"] == pytest.approx(prog.total_min)
    assert row["baseline_steps"] == prog.n_segments


def test_campaign_bad_config_is_one_line_exit_2(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(
        "[model]\ntau_s = -1\n[[experiment]]\nname='x'\nworking_lo_c=0\n"
        "working_hi_c=1\napprox_lo_c=0\napprox_hi_c=1\n"
    )
    assert main(["campaign", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "tau_s" in err and str(path) in err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------
# what chamber do I need?
# ---------------------------------------------------------------------------------------
def test_chamber_requirement_coverage_grows_as_the_floor_is_lowered():
    # near -50 degC the floor binds: g_cool <= (Tk_min + dT0 - T)/tau; at -52 degC the
    # device cannot even go below -49 degC, at -70 degC cooling at 0.425 degC/min is possible
    spec = ExperimentSpec("cold", -50, -47, -52, -40, levels_required=2)
    frame = chamber_requirement(spec, floors_c=[-52.0, -70.0])
    assert frame["chamber_min_c"].tolist() == [-52.0, -70.0]
    assert (frame["chamber_max_c"] == Limits().chamber_max_c).all()
    cov = frame["coverage"].to_numpy()
    assert np.all(np.isfinite(cov)) and np.all((cov >= 0) & (cov <= 1))
    assert cov[1] >= cov[0]
    assert cov[0] < 1.0 and not frame["complete"].iloc[0]  # the -52 floor cannot reach -50
    assert frame["complete"].iloc[1] and cov[1] == 1.0  # -70 degC is floor enough


def test_campaign_end_soak_leaves_room_in_an_informative_plan(tmp_path):
    """objective = "informative" runs each plan on to the time limit, so --end-soak never
    fitted and every table was written without its soak; now the plan ends no farther
    from settled than its shortest plan run on, and within the tolerance where it can
    (plan_campaign's end_soak), as `plan --end-soak` does: a region far from 20 degC, where
    the informative plan would otherwise end far out and its soak not fit."""
    cfg = tmp_path / "inf.toml"
    cfg.write_text(
        '[settings]\nobjective = "informative"\n\n[limits]\nduration_max_min = 240.0\n\n'
        '[[experiment]]\nname = "small"\nworking_lo_c = 0.0\nworking_hi_c = 6.0\n'
        "approx_lo_c = -4.0\napprox_hi_c = 10.0\nlevels_required = 3\n"
    )
    out = tmp_path / "out"
    with contextlib.redirect_stdout(io.StringIO()) as said:
        rc = main(["campaign", str(cfg), "--end-soak", "--out", str(out), "--quiet"])
    assert rc == 0, said.getvalue()
    assert "WITHOUT an end soak" not in said.getvalue()
    steps = read_steps(out / "small" / "steps.csv")
    assert steps.total_min <= 240.0 + 1e-9
    plan = json.loads((out / "small" / "plan.json").read_text())
    assert plan["complete"] and plan["informative"]["price_min"] > 60.0, plan["notes"]
    # scipy's trajectory of the table as written: complete, and settled (20 + dT0) at its end
    assert table_check(out / "small" / "steps.csv", (0.0, 6.0), 3)["coverage"] == 1.0
    knots_t, knots_tk = chamber_knots(out / "small" / "steps.csv")
    _, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=1.0)
    assert abs(temp[0][-1] - 23.0) <= 0.5 + 1e-3
