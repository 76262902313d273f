"""The measured-log reader: contracts, clear errors, NaN/gap reports, synthetic logs."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.logs import MeasuredLog, log_from_frame, read_log
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate
from schedsyn.synth import synth_log


def _frame(n=20, dt=10.0, **extra):
    t = dt * np.arange(n)
    cols = {"time_s": t, "t_int_c": 20.0 + 0.01 * t}
    cols.update(extra)
    return pd.DataFrame(cols)


def test_round_trip_through_csv_keeps_everything(tmp_path):
    f = _frame(tk_set_c=np.linspace(20, 10, 20), note=["a"] * 20, g_true_c_per_min=0.6)
    f.loc[3, "t_int_c"] = np.nan
    path = tmp_path / "log.csv"
    f.to_csv(path, index=False)
    log = read_log(path)
    assert isinstance(log, MeasuredLog)
    assert log.source == str(path)
    assert log.tk_air_c is None and log.drift_dph is None
    np.testing.assert_array_equal(log.time_s, f["time_s"].to_numpy())
    np.testing.assert_array_equal(log.time_min, f["time_s"].to_numpy() / 60.0)
    assert np.isnan(log.t_int_c[3]) and log.n_rows == 20  # kept, not dropped
    assert list(log.extra.columns) == ["note", "g_true_c_per_min"]
    back = log.to_frame()
    assert list(back.columns) == ["time_s", "t_int_c", "tk_set_c", "note", "g_true_c_per_min"]
    pd.testing.assert_frame_equal(back, f[back.columns], check_dtype=False)


def test_nan_and_gap_report():
    f = _frame(n=30)
    t = f["time_s"].to_numpy().copy()
    t[20:] += 100.0  # a 110 s step among 10 s steps
    f["time_s"] = t
    f.loc[[5, 6, 7, 12], "t_int_c"] = np.nan
    log = log_from_frame(f, source="mem")
    assert log.nan_counts == {"t_int_c": 4}
    assert log.report.nan_spans_s == ((50.0, 70.0, 3), (120.0, 120.0, 1))
    assert log.gaps == ((190.0, 300.0),)
    assert log.report.median_step_s == 10.0
    text = log.report.summary()
    assert "4 of 30 rows are NaN" in text and "190 .. 300 s" in text
    assert not log.report.clean
    assert log_from_frame(_frame()).report.clean


def test_missing_column_names_file_and_column(tmp_path):
    path = tmp_path / "bad.csv"
    pd.DataFrame({"time_s": [0, 1, 2], "T1": [1, 2, 3]}).to_csv(path, index=False)
    with pytest.raises(LogFormatError, match=r"bad\.csv.*missing required column.*t_int_c"):
        read_log(path)
    with pytest.raises(LogFormatError, match="does not exist"):
        read_log(tmp_path / "none.csv")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(LogFormatError, match="not a readable CSV"):
        read_log(empty)


def test_non_numeric_value_names_row_and_column():
    f = _frame().astype({"t_int_c": object})
    f.loc[7, "t_int_c"] = "21,5"
    with pytest.raises(LogFormatError, match=r"row 8 \(line 9\), column t_int_c: '21,5'"):
        log_from_frame(f, source="x.csv")
    g = _frame(drift_dph=np.zeros(20))
    g.loc[2, "drift_dph"] = np.inf
    with pytest.raises(LogFormatError, match="row 3.*drift_dph"):
        log_from_frame(g)
    # blanks are readings that are missing, not errors
    h = _frame().astype({"t_int_c": object})
    h.loc[4, "t_int_c"] = ""
    assert np.isnan(log_from_frame(h).t_int_c[4])


@pytest.mark.parametrize(
    ("times", "pattern"),
    [
        ([0, 10, 20, 20, 30, 40], r"row 4 .*duplicates"),
        ([0, 10, 20, 15, 30, 40], r"row 4 .*earlier than the previous row's 20 s"),
        ([0, 10, np.nan, 30, 40, 50], r"row 3 .*time is missing"),
    ],
)
def test_time_must_increase(times, pattern):
    f = pd.DataFrame({"time_s": times, "t_int_c": np.full(len(times), 20.0)})
    with pytest.raises(LogFormatError, match=pattern):
        log_from_frame(f)


def test_kelvin_and_fahrenheit_are_caught():
    f = _frame()
    with pytest.raises(LogFormatError, match="t_int_c.*kelvin.*273.15"):
        log_from_frame(f.assign(t_int_c=f["t_int_c"] + 273.15))
    with pytest.raises(LogFormatError, match="tk_air_c.*kelvin"):
        log_from_frame(f.assign(tk_air_c=np.full(20, 250.0)))
    # 60 degC in Fahrenheit is 140 F: plausible; a hot run reads 160 F = 71 degC
    hot = f.assign(t_int_c=np.linspace(68.0, 160.0, 20))
    with pytest.raises(LogFormatError, match=r"row 18 .*150.316 is not a plausible.*Fahrenheit"):
        log_from_frame(hot)
    # the real range -50..+60 degC is accepted
    log_from_frame(f.assign(t_int_c=np.linspace(-52.0, 62.0, 20)))


def test_too_short_log():
    with pytest.raises(LogFormatError, match="4 finite reading"):
        log_from_frame(_frame(n=4))
    f = _frame(n=10)
    f.loc[2:8, "t_int_c"] = np.nan
    with pytest.raises(LogFormatError, match="3 finite reading"):
        log_from_frame(f)


@settings(max_examples=30, deadline=None)
@given(
    steps=st.lists(st.floats(0.5, 100.0), min_size=5, max_size=40),
    nan_at=st.sets(st.integers(0, 39), max_size=5),
)
def test_csv_round_trip_property(tmp_path_factory, steps, nan_at):
    t = np.cumsum(steps)
    temp = 20.0 + np.sin(t / 100.0)
    nan_idx = [i for i in nan_at if i < t.size]
    temp[nan_idx] = np.nan
    if np.isfinite(temp).sum() < 5:
        return
    path = tmp_path_factory.mktemp("rt") / "log.csv"
    pd.DataFrame({"time_s": t, "t_int_c": temp}).to_csv(path, index=False)
    log = read_log(path)
    np.testing.assert_allclose(log.time_s, t, rtol=1e-15)
    np.testing.assert_allclose(log.t_int_c, temp, rtol=1e-15)
    assert log.nan_counts["t_int_c"] == len(nan_idx)
    assert sum(n for *_, n in log.report.nan_spans_s) == len(nan_idx)


def test_synth_log_matches_simulation_within_noise():
    prog = read_steps("data/baseline_exp1_steps.csv")
    df = synth_log(prog, sample_s=10.0, noise_c=0.02, quant_c=0.01, seed=3)
    assert list(df.columns) == [
        "time_s",
        "t_int_c",
        "tk_set_c",
        "tk_air_c",
        "t_true_c",
        "g_true_c_per_min",
    ]
    assert df["time_s"].iloc[-1] == prog.total_min * 60.0
    # quantised to 0.01 degC
    q = df["t_int_c"].to_numpy() / 0.01
    np.testing.assert_allclose(q, np.round(q), atol=1e-6)
    # truth is the dense simulation at the same times; noise has the requested size
    traj = simulate(prog, dt_min=1 / 6)
    np.testing.assert_allclose(df["t_true_c"], traj.t_c, atol=1e-9)
    np.testing.assert_allclose(df["g_true_c_per_min"], traj.g_c_per_min, atol=1e-9)
    resid = df["t_int_c"] - df["t_true_c"]
    assert 0.018 < resid.std() < 0.022 and abs(resid.mean()) < 0.003
    # the reader accepts it and keeps the truth columns as extras
    log = log_from_frame(df)
    assert list(log.extra.columns) == ["t_true_c", "g_true_c_per_min"]
    # same seed, same log; another seed, another noise
    pd.testing.assert_frame_equal(df, synth_log(prog, seed=3))
    assert not np.array_equal(df["t_int_c"], synth_log(prog, seed=4)["t_int_c"])
    with pytest.raises(ParameterError, match="sample_s"):
        synth_log(prog, sample_s=0.0)
