"""The measured-log reader: contracts, clear errors, NaN/gap reports, synthetic logs."""

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from independent import chamber_knots, ode_trajectories

from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.logs import MeasuredLog, log_from_frame, read_log
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate
from schedsyn.synth import synth_log

DATA = Path(__file__).resolve().parents[1] / "data"


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


def test_a_time_column_in_minutes_is_told_how_to_convert(tmp_path):
    """Red team: a log with time_min got only 'missing required column(s) time_s'."""
    path = tmp_path / "minutes.csv"
    path.write_text("time_min,t_int_c\n0,20\n1,20.1\n2,20.2\n")
    with pytest.raises(
        LogFormatError,
        match=r"time_min looks like the time in other units "
        r"than seconds: rename it time_s and multiply it by 60$",
    ):
        read_log(path)


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
    # the real range -50..+60 degC is accepted (over 3 h: a rate a device can follow)
    log_from_frame(_frame(dt=600.0).assign(t_int_c=np.linspace(-52.0, 62.0, 20)))


def _fahrenheit(c):
    return c * 1.8 + 32.0


def test_fahrenheit_inside_the_plausible_range_is_caught():
    """The sample run (W1, -51..20 degC) in Fahrenheit reads -60..68: plausible as degC,
    but the device would move 1.8x as far as its chamber drives it (or 1/1.8 with the
    chamber in F)."""
    f = pd.read_csv(DATA / "sample_run_exp1.csv")
    log_from_frame(f)  # in degC: read
    with pytest.raises(LogFormatError, match=r"t_int_c looks like Fahrenheit.*1\.80:1"):
        log_from_frame(f.assign(t_int_c=_fahrenheit(f["t_int_c"])))
    with pytest.raises(LogFormatError, match=r"tk_set_c looks like Fahrenheit.*0\.56:1"):
        log_from_frame(f.assign(tk_set_c=_fahrenheit(f["tk_set_c"])))
    with pytest.raises(LogFormatError, match=r"tk_air_c looks like Fahrenheit"):
        log_from_frame(f.drop(columns="tk_set_c").assign(tk_air_c=_fahrenheit(f["tk_air_c"])))


def test_a_device_column_swapped_with_its_chamber_is_refused():
    """Red team: with t_int_c and tk_set_c swapped the gradient of the setpoint was
    estimated, silently. A device lags its chamber; swapped, the 'chamber' lags the
    'device' (the sample run: 99.6 % against 25 %). The log as it is: read."""
    f = pd.read_csv(DATA / "sample_run_exp1.csv")
    log_from_frame(f)
    swapped = f.rename(columns={"t_int_c": "tk_set_c", "tk_set_c": "t_int_c"})
    with pytest.raises(LogFormatError, match="t_int_c and tk_set_c look swapped"):
        log_from_frame(swapped)
    air = f.drop(columns="tk_set_c").rename(columns={"t_int_c": "tk_air_c", "tk_air_c": "t_int_c"})
    with pytest.raises(LogFormatError, match="t_int_c and tk_air_c look swapped"):
        log_from_frame(air)


def test_a_log_wholly_in_fahrenheit_is_told_by_its_room_temperature_ends():
    """Red team: every temperature column in F (the slopes all 1:1, so the slope checks
    cannot see it) was estimated, diagnosed (dT0 5.4 "degC") and fitted without a word.
    A run starts and ends at room temperature: 68 F reads as 68 degC. Warned, with the
    chamber's start and end (its device lags it at the end) or, without a chamber column,
    the device's start; the same log in degC and a device starting at 20 degC: no note."""
    f = pd.read_csv(DATA / "sample_run_exp1.csv")
    assert not any("room temperature" in w for w in log_from_frame(f).report.warnings)
    cols = [c for c in ("t_int_c", "tk_set_c", "tk_air_c") if c in f]
    all_f = f.assign(**{c: _fahrenheit(f[c]) for c in cols})
    (w,) = [w for w in log_from_frame(all_f).report.warnings if "room temperature" in w]
    assert w.startswith("tk_set_c starts at 63.") and "(F - 32) * 5 / 9" in w, w
    device_only = all_f[["time_s", "t_int_c"]]
    (w,) = [w for w in log_from_frame(device_only).report.warnings if "room temperature" in w]
    assert w.startswith("t_int_c starts at 68.0 °C") and "(20.0 °C)" in w, w
    assert not any(
        "room temperature" in w for w in log_from_frame(f[["time_s", "t_int_c"]]).report.warnings
    )


@pytest.mark.parametrize(
    "tau_s, tau2_s, in_f",
    [
        (1200.0, 0.0, "refused"),
        (2400.0, 300.0, "refused"),
        (2400.0, 900.0, "refused or warned"),
        (6000.0, 0.0, "warned"),
    ],
)
def test_devices_in_celsius_are_not_taken_for_fahrenheit(tau_s, tau2_s, in_f):
    """A device unlike the model (another tau, a second thermal mass) still follows its
    chamber 1:1: no Fahrenheit error or warning (simulated apart, by tests/independent.py).
    Read in F, it is refused where the Fahrenheit fit leaves at most 0.1 of the 1:1 fit's
    squared residual, else warned up to 0.3 (tau 6000 s lies between the fit's taus: 0.18;
    a second time constant of 900 s: 0.097). A one-pole fit alone had refused two-pole
    devices in degC (red team: 0.18-0.23)."""
    knots_t, knots_tk = chamber_knots(DATA / "baseline_exp1_steps.csv")
    t_min, temp, _ = ode_trajectories(knots_t, knots_tk, tau_s, 3.0, dt_min=0.5, tau2_s=tau2_s)
    rng = np.random.default_rng(7)
    f = pd.DataFrame(
        {
            "time_s": 60.0 * t_min,
            "t_int_c": temp[0] + rng.normal(0.0, 0.02, t_min.size),
            "tk_set_c": np.interp(t_min, knots_t, knots_tk),
        }
    )
    log = log_from_frame(f)
    assert log.n_rows == t_min.size
    assert not any("Fahrenheit" in w for w in log.report.warnings), log.report.warnings
    try:
        warned = log_from_frame(f.assign(t_int_c=_fahrenheit(f["t_int_c"]))).report.warnings
        outcome = "warned" if any("t_int_c looks like Fahrenheit" in w for w in warned) else ""
    except LogFormatError as err:
        assert "t_int_c looks like Fahrenheit" in str(err)
        outcome = "refused"
    assert outcome and outcome in in_f, (outcome, in_f)


def test_a_two_pole_device_on_a_wide_swing_is_read_as_celsius():
    """Verification red team: six logs of two-pole devices on W3/W4 plans (the chamber
    swinging -31..62 degC) were refused as Fahrenheit by the one-pole fit (shares
    0.18-0.23). A second time constant of 500 s on W3's plan: one pole 0.30, with a second
    pole in the fit 4000+: read, with no warning."""
    knots_t, knots_tk = chamber_knots(Path(__file__).parent / "data/plans/w3_steps.csv")
    t_min, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=0.5, tau2_s=500.0)
    f = pd.DataFrame(
        {
            "time_s": 60.0 * t_min,
            "t_int_c": temp[0] + np.random.default_rng(7).normal(0.0, 0.02, t_min.size),
            "tk_set_c": np.interp(t_min, knots_t, knots_tk),
        }
    )
    assert not any("Fahrenheit" in w for w in log_from_frame(f).report.warnings)


def test_a_chamber_that_hardly_moves_tells_nothing_about_units():
    """Below 10 degC of chamber movement the slope is not identified: no check."""
    f = _frame(n=200, dt=30.0, tk_set_c=np.linspace(20.0, 25.0, 200))
    log_from_frame(f.assign(t_int_c=_fahrenheit(f["tk_set_c"])))


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
    # a signal the steps sample many times per wiggle, as a real log samples a device (a
    # 10-min period at 100 s steps can look like glitch readings to the reader's check)
    temp = 20.0 + np.sin(t / 1000.0)
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


# -- chunked reading ---------------------------------------------------------------------
def _messy_frame(n=200, seed=0):
    """A log with NaN runs, a gap, irregular steps, an extra text column."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(5.0, 15.0, n))
    t[n * 3 // 5 :] += 600.0
    f = pd.DataFrame(
        {
            "time_s": np.round(t, 3),
            "t_int_c": np.round(20.0 + np.sin(t / 300.0), 4),
            "tk_set_c": np.round(25.0 - t / 100.0, 3),
            "note": [f"n{i}" for i in range(n)],
        }
    )
    f.loc[[i for i in (3, 4, 5, 63, 64, 199) if i < n], "t_int_c"] = np.nan
    return f


@pytest.mark.parametrize("chunk_rows", [1, 7, 64, 10_000])
def test_chunked_read_equals_the_whole_frame(tmp_path, chunk_rows):
    f = _messy_frame()
    path = tmp_path / "log.csv"
    f.to_csv(path, index=False)
    whole = log_from_frame(f, source=str(path))
    seen = []
    log = read_log(path, chunk_rows=chunk_rows, progress=lambda *a: seen.append(a))
    for name in ("time_s", "t_int_c", "tk_set_c"):
        np.testing.assert_array_equal(getattr(log, name), getattr(whole, name))
    assert log.report == whole.report
    pd.testing.assert_frame_equal(log.extra, whole.extra)
    # progress: bytes read, non-decreasing, ending at the file size
    size = path.stat().st_size
    assert seen and all(s == "reading" and tot == size for s, _, tot in seen)
    done = [d for _, d, _ in seen]
    assert done == sorted(done) and done[-1] == size
    lean = read_log(path, chunk_rows=chunk_rows, keep_extra=False)
    assert lean.extra.shape == (len(f), 0)
    np.testing.assert_array_equal(lean.t_int_c, whole.t_int_c)


@pytest.mark.parametrize(
    ("row", "value", "pattern"),
    [
        # row is 0-based; the chunk boundary is at row 50 (chunk_rows = 50)
        (50, "dup", r"row 51 \(line 52\), column time_s: time 490 s duplicates"),
        (
            50,
            "back",
            r"row 51 \(line 52\), column time_s: time 400 s is earlier than the "
            r"previous row's 490 s",
        ),
        (120, "text", r"row 121 \(line 122\), column t_int_c: 'x1' is not a finite number"),
        (130, "hot", r"row 131 \(line 132\), column t_int_c: 500 is not a plausible"),
        (170, "no time", r"row 171 \(line 172\), column time_s: the time is missing"),
    ],
)
def test_errors_name_the_row_in_the_whole_file(tmp_path, row, value, pattern):
    n = 200
    t = 10.0 * np.arange(n)
    temp = np.full(n, 20.0).astype(object)
    times = t.astype(object)
    if value == "dup":
        times[row] = t[row - 1]
    elif value == "back":
        times[row] = 400.0
    elif value == "text":
        temp[row] = "x1"
    elif value == "hot":
        temp[row] = 500.0
    else:
        times[row] = ""
    path = tmp_path / "bad.csv"
    pd.DataFrame({"time_s": times, "t_int_c": temp}).to_csv(path, index=False)
    with pytest.raises(LogFormatError, match=pattern):
        read_log(path, chunk_rows=50)
    # the same message as the one-shot reader
    with pytest.raises(LogFormatError, match=pattern):
        read_log(path, chunk_rows=10_000)


def test_kelvin_spread_over_chunks_is_still_kelvin(tmp_path):
    path = tmp_path / "k.csv"
    t = np.arange(100.0)
    pd.DataFrame({"time_s": t, "t_int_c": 250.0 + t}).to_csv(path, index=False)
    with pytest.raises(LogFormatError, match=r"t_int_c: every value lies in 250 \.\. 349.*kelvin"):
        read_log(path, chunk_rows=10)


def test_european_spreadsheet_log_is_read(tmp_path):
    f = _messy_frame(n=40)
    ref = tmp_path / "ref.csv"
    f.to_csv(ref, index=False)
    euro = tmp_path / "euro.csv"
    f.to_csv(euro, index=False, sep=";", decimal=",", encoding="utf-8-sig")
    assert ";" in euro.read_text(encoding="utf-8-sig").splitlines()[1]
    a, b = read_log(ref), read_log(euro, chunk_rows=9)
    for name in ("time_s", "t_int_c", "tk_set_c"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert list(b.extra.columns) == ["note"]
    tab = tmp_path / "tab.csv"
    f.to_csv(tab, index=False, sep="\t")
    np.testing.assert_array_equal(read_log(tab).t_int_c, a.t_int_c)


def test_decimal_commas_in_a_comma_file_are_named(tmp_path):
    path = tmp_path / "c.csv"
    path.write_text("time_s,t_int_c\n0,20,5\n10,20,75\n20,21,0\n")
    with pytest.raises(LogFormatError, match=r"c\.csv: .*decimal commas in a comma-separated"):
        read_log(path)
    quoted = tmp_path / "q.csv"
    quoted.write_text('time_s,t_int_c\n0,"20,5"\n10,"20,75"\n')
    with pytest.raises(LogFormatError, match=r"row 1 .*'20,5'.*decimal comma"):
        read_log(quoted)


def test_ragged_line_deep_in_the_file_is_named(tmp_path):
    path = tmp_path / "r.csv"
    lines = ["time_s,t_int_c"] + [f"{10 * i},20.0" for i in range(300)]
    lines[250] = "2490,20.0,7"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogFormatError, match=r"r\.csv: not a readable CSV log.*line 251"):
        read_log(path, chunk_rows=64)


def test_thin_log_keeps_every_kth_row():
    from schedsyn.logs import thin_log

    f = _messy_frame(n=200)
    log = log_from_frame(f)
    same, k = thin_log(log, 500)
    assert k == 1 and same is log
    thin, k = thin_log(log, 60)
    assert k == 4 and thin.n_rows == 50
    np.testing.assert_array_equal(thin.time_s, log.time_s[::4])
    np.testing.assert_array_equal(thin.t_int_c, log.t_int_c[::4], strict=False)
    np.testing.assert_array_equal(thin.tk_set_c, log.tk_set_c[::4])
    assert thin.nan_counts["t_int_c"] == int(np.isnan(log.t_int_c[::4]).sum())
    assert list(thin.extra["note"]) == list(f["note"][::4])
    with pytest.raises(ParameterError, match="max_rows"):
        thin_log(log, 2)


def test_collector_grows_past_a_low_row_estimate():
    """The reader preallocates from a line count; if that is ever low it grows."""
    from schedsyn.logs import _Collector

    f = _messy_frame(n=100)
    col = _Collector(f.columns, "x", keep_extra=False, expected_rows=3)
    for lo in range(0, 100, 30):
        col.add(f.iloc[lo : lo + 30])
    log = col.finish()
    np.testing.assert_array_equal(log.time_s, f["time_s"].to_numpy())
    np.testing.assert_array_equal(log.t_int_c, f["t_int_c"].to_numpy())
    assert log.report == log_from_frame(f).report


@pytest.mark.parametrize(("scale", "refused"), [(0.1, True), (0.15, True), (0.3, False),
                                              (2.7, False)])  # fmt: skip
def test_a_device_column_on_another_scale_is_refused_or_warned(scale, refused):
    """Red team: t_int_c divided by 10 (tenths of a degree read as degrees, or the
    reverse) was estimated without a word: it stays plausible in degC, but the device
    would move a tenth as far as its chamber drives it. The free-slope fit names the
    factor: refused beyond 0.2-5 (no device is coupled so), a warning beyond 0.4-2.5 (a
    device leaking heat through its fixture can follow its chamber partly); the log as it
    is reads without either."""
    f = pd.read_csv(DATA / "sample_run_exp1.csv")
    assert not any("as far as" in w for w in log_from_frame(f).report.warnings)
    centre = float(f["t_int_c"].mean())  # scaled about the run's middle: stays plausible
    scaled = f.assign(t_int_c=centre + scale * (f["t_int_c"] - centre))
    if refused:
        with pytest.raises(LogFormatError, match=r"t_int_c moves [\d.]+x as far as tk_set_c") as e:
            log_from_frame(scaled)
        text = str(e.value)
    else:
        (text,) = [w for w in log_from_frame(scaled).report.warnings if "as far as" in w]
    moved = float(re.search(r"moves ([\d.]+)x", text).group(1))
    assert moved == pytest.approx(scale, rel=0.1)
