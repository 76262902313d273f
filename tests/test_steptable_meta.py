"""Step tables carry their metadata; European CSV; the end soak (issue 13, items 1 and 7)."""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pandas as pd
import pytest

from schedsyn import Limits, ParameterError, Programme, StepTableError, ThermalParams, simulate
from schedsyn.csvdialect import CsvDialect, detect_csv_dialect
from schedsyn.programme import STEP_COLUMNS, StepTableMeta, read_step_meta, read_steps
from schedsyn.simulate import end_soak_min


def _plan_like(robust: bool = False):
    """A stand-in for a planner ``Plan``: the attributes ``StepTableMeta.from_plan`` reads."""
    spec = types.SimpleNamespace(
        name="W3",
        working_lo_c=0.0,
        working_hi_c=30.0,
        approx_lo_c=-10.0,
        approx_hi_c=40.0,
        levels_required=6,
        delta_c_per_min=0.05,
    )
    params = ThermalParams(2000.0, 2.5)
    scen = (params,)
    if robust:
        scen = (
            params,
            ThermalParams(1800.0, 2.0),
            ThermalParams(2200.0, 3.0),
            ThermalParams(2000.0, 2.0),
        )
    return types.SimpleNamespace(
        spec=spec, params=params, limits=Limits(chamber_min_c=-60.0), scenarios=scen
    )


PROG = Programme([30, 15, 60, 40], [-1.0, 0.0, 0.5, 0.25])


def test_metadata_round_trip_through_the_csv(tmp_path):
    meta = StepTableMeta.from_plan(_plan_like(robust=True), end_soak_min=123.0)
    path = PROG.with_meta(meta).to_csv(tmp_path / "steps.csv")
    text = path.read_text()
    head = text.splitlines()[:3]
    assert head[0].startswith("# schedsyn_version: ")
    assert "# experiment: W3" in head
    assert "# working_lo_c: 0.0" in text and "# robust_tau_hi_s: 2200.0" in text
    # the table after the comment lines is the usual one
    frame = pd.read_csv(path, comment="#")
    assert tuple(frame.columns[:6]) == STEP_COLUMNS
    back = read_steps(path)
    assert back.meta == meta
    np.testing.assert_allclose(back.durations_min, PROG.durations_min)
    np.testing.assert_allclose(back.rates_c_per_min, PROG.rates_c_per_min)
    assert back.meta.working_region_c == (0.0, 30.0)
    assert back.meta.params() == ThermalParams(2000.0, 2.5)
    assert back.meta.limits() == Limits(chamber_min_c=-60.0)
    assert back.meta.robust_box == ((1800.0, 2200.0), (2.0, 3.0))
    assert read_step_meta(path) == meta


def test_metadata_survives_merge_and_rounding():
    meta = StepTableMeta(experiment="x", working_lo_c=-10.0, working_hi_c=0.0)
    prog = Programme([10, 10, 7.4], [1.0, 1.0, -0.333], meta=meta)
    assert prog.merged().meta == meta
    assert prog.rounded(Limits()).meta == meta


def test_a_table_without_comment_lines_reads_as_no_metadata(tmp_path):
    meta = StepTableMeta.from_plan(_plan_like())
    path = PROG.with_meta(meta).to_csv(tmp_path / "steps.csv")
    stripped = tmp_path / "stripped.csv"
    lines = path.read_text().splitlines(keepends=True)
    stripped.write_text("".join(ln for ln in lines if not ln.startswith("#")))
    back = read_steps(stripped)
    assert back.meta is None
    np.testing.assert_allclose(back.durations_min, PROG.durations_min)
    free = tmp_path / "free.csv"
    free.write_text("# typed in by hand on Monday\n" + stripped.read_text())
    assert read_steps(free).meta is None


def test_spreadsheet_damage_to_the_comment_lines_is_tolerated(tmp_path):
    body = PROG.to_frame().to_csv(index=False)
    path = tmp_path / "saved.csv"
    path.write_text(
        '"# experiment: W1",,,,,,,\n# working_lo_c: -50,,,,,,,\n# working_hi_c: -30.0;;;\n'
        "# dt0_c: 3,5\n" + body
    )
    meta = read_steps(path).meta
    assert meta.experiment == "W1"
    assert meta.working_region_c == (-50.0, -30.0)
    assert meta.dt0_c == 3.5


@pytest.mark.parametrize(
    ("lines", "words"),
    [
        ("# tau_s: fast\n", ["line 1", "tau_s", "not a number"]),
        ("# tau_s: 2400\n# tau_s: 2000\n", ["line 2", "tau_s", "twice", "line 1"]),
        ("# levels_required: 5.5\n", ["levels_required", "whole number"]),
        ("# dt0_c: nan\n", ["dt0_c", "finite"]),
    ],
)
def test_bad_metadata_is_an_error_naming_the_line(tmp_path, lines, words):
    path = tmp_path / "bad.csv"
    path.write_text(lines + PROG.to_frame().to_csv(index=False))
    with pytest.raises(StepTableError) as info:
        read_steps(path)
    for w in words:
        assert w in str(info.value)


def test_the_recorded_limits_validate_the_table_when_none_are_given(tmp_path):
    cold = Programme([95, 95], [-1.0, 1.0])  # down to -75 degC and back
    plain = cold.to_csv(tmp_path / "plain.csv")
    with pytest.raises(StepTableError, match="chamber limits"):
        read_steps(plain)
    meta = StepTableMeta(chamber_min_c=-80.0)
    tagged = cold.with_meta(meta).to_csv(tmp_path / "tagged.csv")
    assert read_steps(tagged).meta.chamber_min_c == -80.0
    with pytest.raises(StepTableError, match="chamber limits"):  # explicit limits win
        read_steps(tagged, Limits())


# ---------------------------------------------------------------------------------------
# European CSV
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("head", "expected"),
    [
        ("step,start_min,tk_c\n1,0,20.5\n2,10,-3.25\n", (",", ".")),
        ("step;start_min;tk_c\n1;0;20,5\n2;10;-3,25\n", (";", ",")),
        ("step;start_min;tk_c\n1;0;20.5\n2;10;-3.25\n", (";", ".")),
        ("step\tstart_min\ttk_c\n1\t0\t20,5\n", ("\t", ",")),
        ("# tau_s: 2400,0\n\nstep;start_min\n1;0,5\n2;1", (";", ",")),
        ('a,b\n"1,5",2\n', (",", ".")),
        ("only_one_column\n1\n2\n", (",", ".")),
        ("sep=;\nstep;start_min\n1;0,5\n", (";", ",")),
        ('"sep=,"\nstep,start_min\n1,0.5\n', (",", ".")),
        ("", (",", ".")),
    ],
)
def test_detect_csv_dialect(head, expected):
    d = detect_csv_dialect(head)
    assert isinstance(d, CsvDialect) and tuple(d) == expected


@pytest.mark.parametrize(("sep", "decimal"), [(";", ","), ("\t", ","), (";", ".")])
def test_european_step_tables_are_read(tmp_path, sep, decimal):
    prog = Programme([30, 15, 60], [-1.0, 0.0, 0.5])
    frame = prog.to_frame()
    path = tmp_path / "euro.csv"
    with open(path, "w", encoding="utf-8-sig") as fh:  # with the BOM a spreadsheet writes
        fh.write("# working_lo_c: -5,0\n")
        frame.to_csv(fh, sep=sep, decimal=decimal, index=False)
    if decimal == ",":
        assert "-1,0" in path.read_text(encoding="utf-8-sig")
    back = read_steps(path)
    np.testing.assert_allclose(back.durations_min, prog.durations_min)
    np.testing.assert_allclose(back.rates_c_per_min, prog.rates_c_per_min)
    assert back.meta.working_lo_c == -5.0


def test_an_unknown_format_is_named_in_the_error(tmp_path):
    path = tmp_path / "pipes.csv"
    path.write_text(PROG.to_frame().to_csv(sep="|", index=False))
    with pytest.raises(StepTableError) as info:
        read_steps(path)
    msg = str(info.value)
    assert "missing column" in msg and "comma-separated" in msg and "step|start_min" in msg


# ---------------------------------------------------------------------------------------
# the model of the metadata, the end soak
# ---------------------------------------------------------------------------------------
def test_simulate_uses_the_model_of_the_metadata(tmp_path):
    meta = StepTableMeta(tau_s=2000.0, dt0_c=1.0, t_init_c=18.0)
    path = PROG.with_meta(meta).to_csv(tmp_path / "steps.csv")
    prog = read_steps(path)
    got = simulate(prog)
    want = simulate(PROG, ThermalParams(2000.0, 1.0), t0_c=18.0)
    np.testing.assert_allclose(got.t_c, want.t_c, atol=1e-12)
    default = simulate(PROG)
    assert np.max(np.abs(default.t_c - got.t_c)) > 0.5
    # explicit parameters still win
    np.testing.assert_allclose(simulate(prog, ThermalParams()).t_c[1:], default.t_c[1:], atol=2.1)


@pytest.mark.parametrize(("tau_s", "dt0_c"), [(2400.0, 3.0), (1500.0, 0.0), (3000.0, -2.0)])
def test_end_soak_matches_the_first_order_solution(tau_s, dt0_c):
    # after the end the chamber holds Tk_end: T(t) = S + (T_end - S) exp(-t/tau),
    # S = Tk_end + dT0, so |T - S| <= tol from t* = tau ln(|T_end - S| / tol) on
    params = ThermalParams(tau_s, dt0_c)
    prog = Programme([70, 20, 70], [-1.0, 0.0, 1.0])
    t_end = simulate(prog, params, times_min=[prog.total_min]).t_c[0]
    settled = prog.end_c + dt0_c
    t_star = params.tau_min * math.log(abs(t_end - settled) / 0.5)
    soak = end_soak_min(prog, params, tol_c=0.5)
    assert soak == float(int(soak))  # whole minutes
    assert math.ceil(t_star) <= soak <= math.ceil(t_star + 0.05)
    # and a device that ends settled needs none
    settled_prog = Programme([600], [0.0])
    assert end_soak_min(settled_prog, ThermalParams(2400.0, 3.0), tol_c=0.5) == 0.0


def test_end_soak_of_a_two_pole_model_by_dense_simulation():
    """A linear model with a second time constant: checked on its own dense response."""
    from schedsyn.effects import ModelSpec

    model = ModelSpec(
        tau_s=2400.0, dt0_c=3.0, effect="second_time_constant", parameters={"tau2_s": 900.0}
    ).linear_model()
    prog = Programme([60, 60], [-1.0, 1.0])
    soak = end_soak_min(prog, model=model, tol_c=0.5)
    after = prog.total_min + np.arange(0.0, 2000.0, 0.01)
    temp = simulate(prog, model=model, times_min=after).t_c
    settled = prog.end_c + 3.0
    outside = np.flatnonzero(np.abs(temp - settled) > 0.5)
    t_last_outside = after[outside[-1]] - prog.total_min
    assert t_last_outside < soak <= math.ceil(t_last_outside + 0.06)


def test_with_end_soak_appends_a_hold_and_respects_the_duration_limit():
    meta = StepTableMeta(experiment="x")
    prog = Programme([60, 60], [-1.0, 1.0], meta=meta)
    soaked = prog.with_end_soak(30.4, Limits())
    assert soaked.n_segments == 3 and soaked.durations_min[-1] == 31.0
    assert soaked.rates_c_per_min[-1] == 0.0 and soaked.end_c == prog.end_c
    assert soaked.meta.end_soak_included_min == 31.0
    again = soaked.with_end_soak(9, Limits())  # a final hold is lengthened
    assert again.n_segments == 3 and again.durations_min[-1] == 40.0
    assert prog.with_end_soak(0.0) is prog
    with pytest.raises(ParameterError) as info:
        prog.with_end_soak(500.0, Limits())
    msg = str(info.value)
    assert "500 min" in msg and "620 min" in msg and "540 min by 80 min" in msg


def test_meta_fields_are_validated():
    with pytest.raises(ParameterError, match="tau_s must be a number"):
        StepTableMeta(tau_s="2400")
    with pytest.raises(ParameterError, match="one line"):
        StepTableMeta(experiment="a\nb")
    m = StepTableMeta(levels_required=6.0)
    assert m.levels_required == 6 and isinstance(m.levels_required, int)
    assert dataclasses.replace(m, tau_s=2000).tau_s == 2000.0


def test_a_separator_hint_line_is_honoured_and_skipped(tmp_path):
    prog = Programme([30, 15, 60], [-1.0, 0.0, 0.5])
    path = tmp_path / "hint.csv"
    path.write_text("sep=;\n" + prog.to_frame().to_csv(sep=";", decimal=",", index=False))
    back = read_steps(path)
    np.testing.assert_allclose(back.rates_c_per_min, prog.rates_c_per_min)
