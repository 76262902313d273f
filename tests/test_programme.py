"""Step tables: export, read back, validation errors that name the row."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schedsyn import Limits, Programme, StepTableError, read_steps, simulate
from schedsyn.programme import STEP_COLUMNS


def test_round_trip_is_identity(tmp_path):
    prog = Programme([30, 15, 60], [-1.0, 0.0, 0.5])
    path = prog.to_csv(tmp_path / "s.csv")
    frame = pd.read_csv(path)
    assert tuple(frame.columns[:6]) == STEP_COLUMNS
    # the file holds the programme's own boundary temperatures (written to 0.001 degC)
    tk = prog.boundary_temps_c
    np.testing.assert_allclose(frame["tk_start_c"], tk[:-1], rtol=0, atol=5e-4 + 1e-12)
    np.testing.assert_allclose(frame["tk_end_c"], tk[1:], rtol=0, atol=5e-4 + 1e-12)
    assert frame["segment_type"].tolist() == ["RAMP", "HOLD", "RAMP"]
    assert frame["duration_hhmm"].tolist() == ["00:30", "00:15", "01:00"]
    back = read_steps(path)
    np.testing.assert_allclose(back.durations_min, prog.durations_min)
    np.testing.assert_allclose(back.rates_c_per_min, prog.rates_c_per_min)


#: Typing a temperature to 0.1 degC moves it by at most half a step.
HALF_STEP_C = 0.05


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(1, 120), st.floats(-1.0, 3.0)), min_size=1, max_size=12),
    st.floats(-40.0, 60.0),
)
def test_rounded_programme_is_typable_and_within_half_a_step(segs, start_c):
    """Whole-minute segments: rounding moves no boundary temperature by more than 0.05 degC.

    Why this bound holds even at the rate limits: with whole-minute durations the limits
    -1 and +3 degC/min change the temperature by whole degrees, so the nearest 0.1 degC
    value of every boundary is always reachable from the rounded previous one (rounding
    commutes with adding a multiple of 0.1). Between boundaries both paths are linear, so
    the whole chamber path is within 0.05 degC too.
    """
    prog = Programme([d for d, _ in segs], [r for _, r in segs], start_c)
    lim = Limits(chamber_min_c=-1000, chamber_max_c=1000, duration_max_min=5000, start_c=start_c)
    r = prog.rounded(lim)
    assert np.allclose(r.durations_min, np.round(r.durations_min))
    tk = r.boundary_temps_c
    assert np.allclose(tk * 10, np.round(tk * 10), atol=1e-6)
    assert np.all(r.rates_c_per_min <= 3.0 + 1e-9) and np.all(r.rates_c_per_min >= -1.0 - 1e-9)
    assert np.all(np.abs(np.diff(r.rates_c_per_min)) > 1e-9)  # merged
    assert r.total_min == pytest.approx(prog.total_min)
    # every original boundary (time and temperature), and a dense path between them
    edges = np.concatenate(([0.0], np.cumsum(prog.durations_min)))
    gap = np.abs(r.chamber_at(edges) - prog.boundary_temps_c)
    assert gap.max() <= HALF_STEP_C + 1e-9, (gap.max(), np.argmax(gap))
    t = np.linspace(0, prog.total_min, 1000)
    assert np.max(np.abs(r.chamber_at(t) - prog.chamber_at(t))) <= HALF_STEP_C + 1e-9


@pytest.mark.parametrize("start_c", [20.0, -17.26, 33.349999])
def test_rounding_is_to_the_nearest_tenth(start_c):
    """Hand-made boundaries whose nearest tenths are known: no bias in either direction."""
    d = [10.0, 10.0, 10.0, 10.0]
    wanted_changes = [-3.04, 2.96, -0.55 + 1e-6, 7.4449]
    prog = Programme(d, np.array(wanted_changes) / 10.0, start_c)
    r = prog.rounded(Limits(chamber_min_c=-100, start_c=start_c))
    exact = prog.boundary_temps_c
    expected = np.floor(exact * 10 + 0.5) / 10  # nearest tenth (no boundary is a tie)
    np.testing.assert_allclose(r.chamber_at(np.cumsum([0.0, *d])), expected, atol=1e-9)


def test_merge_keeps_path():
    prog = Programme([10, 5, 5, 10], [1.0, 1.0, 1.0, 0.0])
    m = prog.merged()
    assert m.n_segments == 2
    t = np.linspace(0, 30, 61)
    np.testing.assert_allclose(
        simulate(m, times_min=t).t_c, simulate(prog, times_min=t).t_c, atol=1e-10
    )


def _table(tmp_path, edit):
    prog = Programme([30, 30, 50], [-1.0, 0.0, 0.6])
    frame = prog.to_frame()
    edit(frame)
    path = tmp_path / "bad.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda f: f.__delitem__("tk_end_c"), "missing column.*tk_end_c"),
        (lambda f: f.__setitem__("tk_start_c", [20, -5, -10]), "step 2.*continue"),
        (lambda f: f.__setitem__("rate_c_per_min", [-1, 0, 0.9]), "step 3.*rate_c_per_min"),
        (lambda f: f.__setitem__("duration_min", [30, 0, 50]), "step 2.*duration_min"),
        (lambda f: f.__setitem__("tk_start_c", [25, -10, -10]), "starts at 25"),
        (lambda f: f.__setitem__("step", [1, 3, 2]), "row 2.*step"),
        (lambda f: f.__setitem__("duration_min", ["30", "abc", "50"]), "row 2.*duration_min"),
        # a NaN was shown as "np.float64(nan)" (red team, export)
        (
            lambda f: f.__setitem__("tk_end_c", [-10, float("nan"), 20]),
            r"row 2, column tk_end_c: an empty cell or NaN is not a number$",
        ),
    ],
)
def test_bad_tables_name_row_and_problem(tmp_path, edit, match):
    with pytest.raises(StepTableError, match=match):
        read_steps(_table(tmp_path, edit))


def test_rate_over_limit_is_refused(tmp_path):
    path = Programme([10], [4.0]).to_csv(tmp_path / "fast.csv")
    with pytest.raises(StepTableError, match="step 1.*outside the chamber limits"):
        read_steps(path)


def test_too_long_is_refused(tmp_path):
    path = Programme([300, 300], [0.0, 0.0]).to_csv(tmp_path / "long.csv")
    with pytest.raises(StepTableError, match="600 min.*540"):
        read_steps(path)


def test_not_a_csv(tmp_path):
    p = tmp_path / "x.csv"
    p.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(StepTableError):
        read_steps(p)
    with pytest.raises(StepTableError, match="does not exist"):
        read_steps(tmp_path / "missing.csv")


def test_violations_report_end_temperature_and_device():
    prog = Programme([10.0], [1.0])
    v = prog.violations(Limits())
    assert any("ends at 30.00" in s for s in v)


def test_duration_hhmm_is_the_duration_in_whole_minutes():
    """An off-grid duration of 59.7 min was shown as "00:60" and 119.5 min as "01:60"
    (red team, export): the operator column must read as h:mm with minutes 0..59."""
    d = np.array([59.7, 119.5, 30.2, 0.4, 61.49])
    prog = Programme(d, np.zeros(d.size), 20.0)
    for shown, minutes in zip(prog.to_frame()["duration_hhmm"], d, strict=True):
        hours, mins = (int(x) for x in shown.split(":"))
        assert 0 <= mins <= 59
        assert abs(60 * hours + mins - minutes) <= 0.5


@pytest.mark.parametrize(
    "column, value, match",
    [
        ("duration_hhmm", "00:40", r"step 2: duration_hhmm 00:40 is 40 min but duration_min is 30"),
        ("duration_hhmm", "09:99", r"step 2: duration_hhmm '09:99' is not h:mm"),
        ("segment_type", "HOLD", r"step 1: segment_type HOLD but the temperature changes"),
    ],
)
def test_operator_columns_that_disagree_with_the_numbers_are_refused(
    tmp_path, column, value, match
):
    """A hand edit of duration_min without duration_hhmm (or the reverse) was read
    silently from duration_min while the operator types h:mm (red team, export): the
    two would run different programmes."""
    prog = Programme([40.0, 30.0, 40.0], [-1.0, 0.0, 1.0])
    frame = prog.to_frame()
    # independent of schedsyn: the table as written agrees with itself
    for hhmm, d in zip(frame["duration_hhmm"], frame["duration_min"], strict=True):
        h, m = (int(x) for x in hhmm.split(":"))
        assert 60 * h + m == d
    row = 0 if column == "segment_type" else 1
    frame[column] = frame[column].astype(object)
    frame.loc[row, column] = value
    path = tmp_path / "edited.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(StepTableError, match=match):
        read_steps(path)
    # the whole minute shown for an off-grid duration, an h:mm:ss cell and a blank cell pass
    frame = prog.to_frame()
    frame["duration_hhmm"] = ["0:40:00", "", "00:40"]
    frame.to_csv(path, index=False)
    assert read_steps(path).total_min == pytest.approx(110.0)


def test_ending_at_steers_the_last_ramp_onto_the_end_temperature():
    """A plan may end within end_tol_c of 20 degC (fuzzing: a timetable table ending at
    20.1); ending_at moves the last ramp's end onto 20, the holds after it with it, and
    leaves everything before that ramp as it was (compared on the chamber's path)."""
    limits = Limits(rate_min_c_per_min=-3.0)
    # 20 -> 0 -> 22 -> 20.1 then a 30-min hold
    prog = Programme(np.array([20.0, 11.0, 1.0, 30.0]), np.array([-1.0, 2.0, -1.9, 0.0]))
    assert prog.end_c == pytest.approx(20.1)
    out = prog.ending_at(20.0, limits)
    assert out.end_c == pytest.approx(20.0, abs=1e-12)
    assert out.total_min == prog.total_min
    before = np.linspace(0.0, 31.0, 63)  # up to the start of the last ramp
    np.testing.assert_allclose(out.chamber_at(before), prog.chamber_at(before), atol=1e-12)
    assert out.chamber_at(np.array([32.0]))[0] == pytest.approx(20.0)  # the ramp, steered
    np.testing.assert_allclose(out.chamber_at(np.linspace(32.0, 62.0, 31)), 20.0)  # the hold
    assert not out.violations(limits)
    # already at 20: the very same programme
    assert out.ending_at(20.0, limits) is out
    # a steered ramp that would break the rate limit (22 -> 20 in 1 min under a
    # -1.95 degC/min limit): a 1-min ramp 20.1 -> 20 appended after the hold instead, if
    # the duration limit has room; a hold-only programme likewise
    slow = Limits(rate_min_c_per_min=-1.95, duration_max_min=63.0)
    out = prog.ending_at(20.0, slow)
    assert out.total_min == prog.total_min + 1 and out.end_c == pytest.approx(20.0, abs=1e-12)
    np.testing.assert_allclose(
        out.chamber_at(np.linspace(0.0, 62.0, 125)),
        prog.chamber_at(np.linspace(0.0, 62.0, 125)),
        atol=1e-12,
    )
    assert not out.violations(slow)
    full = Limits(rate_min_c_per_min=-1.95, duration_max_min=62.0)
    assert prog.ending_at(20.0, full) is prog  # no room: left as it was
    hold_only = Programme(np.array([10.0]), np.array([0.0]), 20.3)
    out = hold_only.ending_at(20.0, limits)
    assert out.end_c == pytest.approx(20.0) and out.total_min == 11.0
