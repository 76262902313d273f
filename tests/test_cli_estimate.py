"""`schedsyn estimate` and `schedsyn compare`, in-process, plus the run-vs-plan API."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from schedsyn.cli import main
from schedsyn.compare import compare_run, resample_run
from schedsyn.coverage import coverage_report
from schedsyn.grid import BinGrid
from schedsyn.logs import log_from_frame, read_log
from schedsyn.params import ThermalParams
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate
from schedsyn.synth import synth_log

STEPS = "data/baseline_exp1_steps.csv"
SAMPLE = "data/sample_run_exp1.csv"


@pytest.fixture(scope="module")
def clean_log_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("logs") / "run.csv"
    synth_log(read_steps(STEPS), seed=8).to_csv(path, index=False)
    return path


def test_estimate_writes_gradient_csv(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["estimate", SAMPLE, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    # the NaN/gap report of the sample log is printed
    assert "12 of 2918 rows are NaN" in text and "gap in sampling 19200 .. 19800 s" in text
    assert "fitted by ML: q, r" in text
    grad = pd.read_csv(out / "gradient.csv")
    assert list(grad.columns[:4]) == ["time_s", "t_est_c", "g_est_c_per_min", "g_std_c_per_min"]
    log = read_log(SAMPLE)
    assert len(grad) == log.n_rows  # one row per log row, NaN rows included
    np.testing.assert_array_equal(grad["time_s"], log.time_s)
    assert grad["g_est_c_per_min"].notna().all()
    truth = log.extra["g_true_c_per_min"].to_numpy()
    assert np.sqrt(np.mean((grad["g_est_c_per_min"] - truth) ** 2)) < 0.01
    for name in ("phase.png", "gradient.png"):
        assert (out / name).stat().st_size > 0


def test_estimate_user_noise_and_model_method(tmp_path, capsys, clean_log_path):
    out = tmp_path / "o"
    rc = main(
        [
            "estimate",
            str(clean_log_path),
            "--out",
            str(out),
            "--q",
            "1e-3",
            "--r",
            "4e-4",
            "--method",
            "model",
            "--tau-s",
            "2400",
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "model Kalman smoother: q = 0.001 " in text and "fitted by ML: none" in text
    assert len(pd.read_csv(out / "gradient.csv")) == len(pd.read_csv(clean_log_path))


def test_estimate_bad_logs_are_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"time_s": [0, 10, 10, 20, 30, 40], "t_int_c": [20.0] * 6}).to_csv(
        bad, index=False
    )
    assert main(["estimate", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.csv" in err and "duplicates" in err
    kelvin = tmp_path / "k.csv"
    pd.DataFrame({"time_s": np.arange(10.0), "t_int_c": np.full(10, 293.0)}).to_csv(
        kelvin, index=False
    )
    assert main(["estimate", str(kelvin)]) == 2
    assert "kelvin" in capsys.readouterr().err
    no_tk = tmp_path / "n.csv"
    pd.DataFrame({"time_s": np.arange(10.0), "t_int_c": np.full(10, 20.0)}).to_csv(
        no_tk, index=False
    )
    assert main(["estimate", str(no_tk), "--method", "model", "--out", str(tmp_path)]) == 2
    assert "tk_set_c" in capsys.readouterr().err
    assert main(["estimate", str(no_tk), "--q", "-1", "--out", str(tmp_path)]) == 2


def test_compare_writes_outputs_and_reports_coverage(tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["compare", SAMPLE, STEPS, "--out", str(out), "--region", "-50", "-30"]) == 0
    text = capsys.readouterr().out
    assert "planned: coverage of [-50, -30]" in text and "run:     coverage of" in text
    assert "measured - simulated T: RMS" in text
    for name in (
        "gradient.csv",
        "compare.csv",
        "coverage.csv",
        "summary.json",
        "phase_compare.png",
        "temperature_compare.png",
        "coverage_compare.png",
        "compare.png",
    ):
        assert (out / name).stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    cov = pd.read_csv(out / "coverage.csv")
    assert len(cov) == 20
    assert summary["planned_coverage"] == pytest.approx(cov["planned_covered"].mean())
    assert summary["run_coverage"] == pytest.approx(cov["run_covered"].mean())
    # the sample device is slower than planned (tau 2700 s): the residual is degrees, not noise
    assert 0.5 < summary["rms_residual_c"] < 5.0


def test_compare_refuses_to_overwrite_inputs(tmp_path, capsys, clean_log_path):
    import shutil

    log = tmp_path / "compare.csv"
    shutil.copy(clean_log_path, log)
    before = log.read_bytes()
    assert main(["compare", str(log), STEPS, "--region", "-50", "-30", "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert log.read_bytes() == before


def test_compare_of_a_faithful_run_reproduces_the_plan(clean_log_path):
    """Right model, clean chamber: the run's coverage matches the plan's, residual ~ noise."""
    log = read_log(clean_log_path)
    programme = read_steps(STEPS)
    grid = BinGrid(-50.0, -30.0)
    cmp = compare_run(log, programme, grid=grid)
    assert cmp.rms_residual_c < 0.03  # sensor noise 0.02 + quantisation
    # levels 0.05 degC/min apart: an estimate within ~0.01 degC/min flips at most a
    # borderline level per bin (a passing bin of the plan may miss by one, or vice versa)
    diff = cmp.run_coverage.levels - cmp.planned_coverage.levels
    assert np.all(np.abs(diff) <= 1) and np.mean(diff == 0) >= 0.75
    assert abs(cmp.run_coverage.coverage - cmp.planned_coverage.coverage) <= 0.15
    frame = cmp.to_frame()
    assert len(frame) == log.n_rows
    np.testing.assert_allclose(frame["residual_c"], frame["t_meas_c"] - frame["t_sim_c"])
    # a wrong model shows up as a large residual, and the phase trajectories separate
    off = compare_run(log, programme, ThermalParams(tau_s=3000.0), grid=grid)
    assert off.rms_residual_c > 20 * cmp.rms_residual_c


def test_resample_run_breaks_at_gaps():
    t = np.concatenate((np.arange(0, 600, 10.0), np.arange(1200, 1800, 10.0)))
    temp = 20 - 0.01 * t
    log = log_from_frame(pd.DataFrame({"time_s": t, "t_int_c": temp}))
    from schedsyn.estimate import estimate_gradient

    est = estimate_gradient(log, q=1e-6, r=1e-4)
    dense = resample_run(log, est, dt_min=0.1)
    inside = (dense.time_min > 590.0 / 60.0) & (dense.time_min < 20.0)  # rows 590 s, 1200 s
    assert inside.any() and np.isnan(dense.t_c[inside]).all()
    assert np.isfinite(dense.t_c[~inside]).all()
    # a gap never counts as a pass: coverage equals that of the two halves separately
    grid = BinGrid(5.0, 15.0)
    rep = coverage_report(dense.t_c, dense.g_c_per_min, grid, levels_required=1)
    assert np.all(rep.pass_counts[4:9] == 0)  # 9..14 degC lie inside the gap
    assert np.all(rep.pass_counts[[0, 1, 2, 9]] == 1)


@pytest.mark.parametrize("kind", ["blank", "rows missing"])
def test_resample_run_breaks_at_blank_readings_as_at_gaps(kind):
    """Red team: an hour of blank t_int_c inside the region was counted as measured
    passes (the smoother's guess), 40 % where the device reached 25 %; with the rows
    missing instead, 0 %. Both are now the same: no pass where nothing was read."""
    t = np.concatenate((np.arange(0, 600, 10.0), np.arange(600, 1200, 10.0),
                        np.arange(1200, 1800, 10.0)))  # fmt: skip
    temp = 20 - 0.01 * t
    middle = (t >= 600) & (t < 1200)
    if kind == "blank":
        frame = pd.DataFrame({"time_s": t, "t_int_c": np.where(middle, np.nan, temp)})
    else:
        frame = pd.DataFrame({"time_s": t[~middle], "t_int_c": temp[~middle]})
    log = log_from_frame(frame)
    from schedsyn.estimate import estimate_gradient

    dense = resample_run(log, estimate_gradient(log, q=1e-6, r=1e-4), dt_min=0.1)
    rep = coverage_report(dense.t_c, dense.g_c_per_min, BinGrid(5.0, 15.0), levels_required=1)
    assert np.all(rep.pass_counts[4:9] == 0)  # 9..14 degC: no reading there
    assert np.all(rep.pass_counts[[0, 1, 2, 9]] == 1)
    if kind != "blank":
        return
    # two blank rows are bridged, as a sampling step of 3 median steps is (no gap)
    log = log_from_frame(frame.assign(t_int_c=np.where((t >= 300) & (t < 320), np.nan, temp)))
    dense = resample_run(log, estimate_gradient(log, q=1e-6, r=1e-4), dt_min=0.1)
    assert np.isfinite(dense.t_c).all()


def test_compare_with_the_model_based_estimator(clean_log_path, tmp_path, capsys):
    log = read_log(clean_log_path)
    programme = read_steps(STEPS)
    grid = BinGrid(-50.0, -30.0)
    air = compare_run(log, programme, grid=grid, method="model", chamber="tk_air_c")
    assert air.estimate.method == "model"
    truth = log.extra["g_true_c_per_min"].to_numpy()
    assert np.sqrt(np.mean((air.estimate.g_est_c_per_min - truth) ** 2)) < 0.01
    from schedsyn.errors import ParameterError

    with pytest.raises(ParameterError, match="method"):
        compare_run(log, programme, grid=grid, method="kalman")
    rc = main(
        [
            "compare",
            str(clean_log_path),
            STEPS,
            "--method",
            "model",
            "--chamber",
            "tk_air_c",
            "--region",
            "-50",
            "-30",
            "--out",
            str(tmp_path / "m"),
        ]
    )
    assert rc == 0 and "model Kalman smoother" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("epoch", r"starts at time_s = 1\.7e\+09 s, after the step table's programme has end"),
        ("shift", r"the logged setpoint tk_set_c = .* even allowing it to lag"),
        ("other", r"the logged setpoint tk_set_c = .* differs from the step table's programme"),
    ],
)
def test_compare_refuses_a_log_that_is_not_a_run_of_the_step_table(
    clean_log_path, tmp_path, capsys, change, message
):
    """Red team: Unix-epoch times, a log shifted by 30 min and a run of another programme
    were compared without a word (residual RMS 52 °C; "planned 100 %, run 25 %")."""
    frame = pd.read_csv(clean_log_path)
    if change == "epoch":
        frame["time_s"] += 1.7e9
    elif change == "shift":
        frame["time_s"] += 1800.0
    else:
        frame["tk_set_c"] = frame["tk_set_c"][::-1].to_numpy()
    path = tmp_path / "log.csv"
    frame.to_csv(path, index=False)
    out = tmp_path / "out"
    rc = main(["compare", str(path), STEPS, "--region", "-50", "-30", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress lines
    assert rc == 2 and err.startswith("schedsyn compare: error:") and re.search(message, err), err
    assert not out.exists()


def test_compare_takes_a_run_of_the_step_table_logged_late_rounded_or_begun_late(
    clean_log_path, tmp_path, capsys
):
    """The refusals above spare the table's own run: its setpoint logged to 1 °C and 20 s
    late, or 60 s late, and a log that begins 12 min into the programme (verification:
    refused, with the advice to shift its times, which would have misaligned it)."""
    path = tmp_path / "log.csv"
    out = tmp_path / "out"
    clean = pd.read_csv(clean_log_path)
    for late_s, rounded, start_min in ((20.0, True, 0.0), (60.0, False, 0.0), (0.0, False, 12)):
        ok = clean.copy()
        ok["tk_set_c"] = np.interp(ok["time_s"] - late_s, ok["time_s"], ok["tk_set_c"])
        if rounded:
            ok["tk_set_c"] = np.round(ok["tk_set_c"])
        ok = ok[ok["time_s"] >= 60.0 * start_min]
        ok.to_csv(path, index=False)
        args = ["compare", str(path), STEPS, "--region", "-50", "-30", "--out", str(out)]
        assert main(args) in (0, 1), capsys.readouterr().err


def test_the_runs_coverage_range_holds_the_devices_coverage():
    """Red team: a 120-s log read 35 % where the device did 25 % (two bins flipped by
    gradient errors of 1-2 sigma against the 0.05 °C/min level separation). The range
    with the separation widened and narrowed by the estimate's 2 sigma holds the device's
    own coverage (counted from the noise-free truth); its margin shrinks with denser rows."""
    programme = read_steps(STEPS)
    grid = BinGrid(-50.0, -30.0)
    truth = simulate(programme, dt_min=0.1)
    true = coverage_report(truth.t_c, truth.g_c_per_min, grid).coverage
    margins = {}
    for sample_s in (10.0, 120.0):
        for seed in range(3):
            frame = synth_log(programme, sample_s=sample_s, seed=seed)
            log = log_from_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]))
            cmp = compare_run(log, programme, grid=grid)
            low, high = cmp.run_coverage_low, cmp.run_coverage_high
            assert low is not None and high is not None
            assert low.coverage <= true <= high.coverage, (sample_s, seed, low, true, high)
            assert low.coverage <= cmp.run_coverage.coverage <= high.coverage
            margins.setdefault(sample_s, []).append(cmp.level_margin_c_per_min)
    assert 0 < max(margins[10.0]) < min(margins[120.0])
    assert "borderline bin(s)" in cmp.summary()
    assert cmp.summary_dict()["run_coverage_low"] == low.coverage


@pytest.mark.parametrize("change", ["shift", "other"])
def test_compare_without_a_chamber_column_warns_of_a_device_that_is_no_run_of_the_table(
    clean_log_path, tmp_path, capsys, change
):
    """Red team: without tk_set_c nothing was checked: a log of another programme (RMS
    residual 24 °C) and one shifted by 30 min (11.6 °C) were compared without a word. Now
    the device's readings are fitted as a first-order lag of the programme (tau, dT0,
    start free) and a misfit beyond 3 °C is said loudly, in the summary and
    summary.json (a warning: a genuine run with a strong effect misfits as much, and
    showing that is what compare is for). The sample run (tau 2700 s, dT0 2 °C against
    the plan's 2400 s, 3 °C: 1.7 °C RMS at the plan's values) gets no such note."""
    import json

    frame = pd.read_csv(clean_log_path)[["time_s", "t_int_c"]]
    if change == "shift":
        frame["time_s"] += 1800.0
    else:
        other = synth_log(read_steps("tests/data/plans/w2_steps.csv"), seed=3)
        frame = other[["time_s", "t_int_c"]]
    path = tmp_path / "log.csv"
    frame.to_csv(path, index=False)
    out = tmp_path / "out"
    rc = main(["compare", str(path), STEPS, "--region", "-50", "-30", "--out", str(out)])
    said = capsys.readouterr().out
    assert rc in (0, 1)
    note = [ln for ln in said.splitlines() if ln.startswith("*** ")]
    assert len(note) == 1 and "does not follow the step table" in note[0], said
    assert "add the chamber setpoint as tk_set_c" in note[0]
    notes = json.loads((out / "summary.json").read_text())["notes"]
    assert len(notes) == 1 and "°C RMS" in notes[0]
    sample = pd.read_csv(SAMPLE)[["time_s", "t_int_c"]]
    sample.to_csv(path, index=False)
    out2 = tmp_path / "out2"
    args = ["compare", str(path), STEPS, "--region", "-50", "-30", "--out", str(out2)]
    assert main(args) in (0, 1), capsys.readouterr().err
    assert "does not follow" not in capsys.readouterr().out
    assert json.loads((out2 / "summary.json").read_text())["notes"] == []


def test_a_run_that_starts_away_from_the_plans_start_is_noted_and_can_be_simulated_from_it(
    tmp_path, capsys
):
    """A device 6 °C warmer than the plan assumed at the start (20 °C): compare says so
    and, with --t0-c log, simulates the run from the log's own start (report too); that
    simulation matches scipy's ODE solution from the same start (tests/independent.py),
    the residual shrinks, the planned coverage stays the plan's. A given start is named as
    given, a log that begins before the programme is read at time 0, and a log that begins
    later, or a --t0-c that is no temperature, is refused."""
    from independent import chamber_knots, ode_trajectories

    from schedsyn.compare import log_start_c

    frame = synth_log(read_steps(STEPS), seed=2, t0_c=26.0)
    path = tmp_path / "warm.csv"
    frame.drop(columns=["t_true_c", "g_true_c_per_min"]).to_csv(path, index=False)
    base = ["compare", str(path), STEPS, "--region", "-50", "-30"]
    assert main([*base, "--out", str(tmp_path / "plan")]) in (0, 1)
    said = capsys.readouterr().out
    (note,) = [ln for ln in said.splitlines() if ln.startswith("*** the log starts at")]
    assert "the log starts at 26.0" in note and "--t0-c log" in note
    at_plan = json.loads((tmp_path / "plan" / "summary.json").read_text())
    assert at_plan["t0_c"] == 20.0 and len(at_plan["notes"]) == 1
    assert main([*base, "--t0-c", "log", "--out", str(tmp_path / "log")]) in (0, 1)
    said = capsys.readouterr().out
    assert "*** the log starts" not in said and "(the log's own start)" in said
    at_log = json.loads((tmp_path / "log" / "summary.json").read_text())
    assert at_log["t0_c"] == pytest.approx(26.0, abs=0.05) and at_log["notes"] == []
    assert at_log["rms_residual_c"] < 0.5 * at_plan["rms_residual_c"]
    # the plan's promise is the plan's, from its own start, whichever start the run has
    assert at_log["planned_coverage"] == at_plan["planned_coverage"]
    # report takes the same option: its summary as compare's
    rep = ["report", str(path), STEPS, "--region", "-50", "-30", "--quiet"]
    assert main([*rep, "--t0-c", "log", "--out", str(tmp_path / "rep")]) == 0
    capsys.readouterr()
    filed = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert filed["t0_c"] == at_log["t0_c"] and filed["notes"] == []
    rows = pd.read_csv(tmp_path / "log" / "compare.csv")
    knots_t, knots_tk = chamber_knots(STEPS)
    _, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, t0_c=at_log["t0_c"], dt_min=1 / 6)
    n = min(len(rows), temp.shape[1])
    np.testing.assert_allclose(rows["t_sim_c"].to_numpy()[:n], temp[0, :n], atol=2e-3)
    # a given start is named as given; a log that begins 30 min before the programme (the
    # device held at 26 degC) has its start at time 0, not 30 min of drift before it
    assert main([*base, "--t0-c", "22", "--out", str(tmp_path / "given")]) in (0, 1)
    said = capsys.readouterr().out
    assert "the simulation at 22 °C (given by --t0-c)" in said
    logged = frame.drop(columns=["t_true_c", "g_true_c_per_min"])
    before = logged.iloc[:180].copy()
    before["time_s"] = np.arange(-1800.0, 0.0, 10.0)
    before["t_int_c"] = 26.0 + 0.02 * np.random.default_rng(4).standard_normal(180)
    pd.concat([before, logged]).to_csv(path, index=False)
    assert log_start_c(read_log(path)) == pytest.approx(26.0, abs=0.05)
    # refused: a start the log does not hold, and a word for a temperature
    late = frame[frame["time_s"] >= 720.0].drop(columns=["t_true_c", "g_true_c_per_min"])
    late.to_csv(path, index=False)
    assert main([*base, "--t0-c", "log", "--out", str(tmp_path / "late")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "give it as a number (--t0-c T)" in err[0], err
    assert main([*base, "--t0-c", "warm", "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--t0-c must be a temperature in °C or 'log'" in err[0], err
    assert not (tmp_path / "late").exists() and not (tmp_path / "bad").exists()


@pytest.mark.parametrize(
    ("options", "named"),
    [
        (["--tau-s", "1200"], "--tau-s is for the model-based estimator"),
        (["--dt0-c", "2", "--tau-s", "900"], "--tau-s and --dt0-c are for the model-based"),
        (["--chamber", "tk_air_c"], "--chamber tk_air_c is for the model-based"),
        (["--method", "model", "--order", "2"], "--order 2 is the kinematic"),
        (["--method", "model", "--sensor-tau-s", "60"], "--sensor-tau-s is for the kinematic"),
        (["--sensor-tau-s", "1e6"], "a temperature sensor's own lag is 0 .. 3600 s"),
    ],
)
def test_estimate_refuses_options_its_estimator_would_ignore(
    tmp_path, capsys, clean_log_path, options, named
):
    """Red team: --tau-s and --dt0-c with the kinematic default, --order with --method
    model, and a sensor lag of 1e6 s were accepted and dropped without a word."""
    out = tmp_path / "o"
    assert main(["estimate", str(clean_log_path), "--out", str(out), *options]) == 2
    err = capsys.readouterr().err
    assert named in err and err.count("\n") == 1, err
    assert not out.exists()
