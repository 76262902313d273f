"""scripts/bench_general.py and data/bench: the requests, the re-check, the headline figures.

The end-to-end test runs the script on two tiny requests (a subprocess: the script plans
in a process pool) and recomputes every row with other code (schedsyn's simulator and
coverage counter, the bound, its own counting); the rest are hand-built cases for the
re-check and the headline figures, where the expected answer is known by construction.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from schedsyn import Limits, ThermalParams, coverage_report, read_steps, simulate
from schedsyn.campaign import PAPER_REGIONS_C, CampaignConfig, load_campaign
from schedsyn.planner import ExperimentSpec, duration_lower_bound

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "bench_general.py"
BENCH = ROOT / "data" / "bench"


def _script():
    spec = importlib.util.spec_from_file_location("bench_general", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


bench = _script()


# ---------------------------------------------------------------------------------------
# the requests
# ---------------------------------------------------------------------------------------
def test_bench_requests_load_and_span_what_issue_12_asks():
    files = sorted(BENCH.glob("*.toml"))
    assert len(files) >= 30
    readme = (BENCH / "README.md").read_text(encoding="utf-8")
    regions, taus, dt0s, rates, levels, deltas, budgets, segments, steps = (set() for _ in range(9))
    for f in files:
        config = load_campaign(f)
        assert len(config.experiments) == 1, f
        e = config.experiments[0]
        assert e.name == f.stem, f
        assert f"`{f.stem}`" in readme, f"{f.stem} is missing from data/bench/README.md"
        regions.add((e.working_lo_c, e.working_hi_c, e.approx_lo_c, e.approx_hi_c))
        taus.add(config.params.tau_s)
        dt0s.add(config.params.dt0_c)
        rates.add((config.limits.rate_min_c_per_min, config.limits.rate_max_c_per_min))
        levels.add(e.levels_required)
        deltas.add(e.delta_c_per_min)
        budgets.add(config.limits.duration_max_min)
        segments.add(e.segment_min)
        steps.add(e.max_steps)
    # the paper's four and the issue's six requests are there
    for _, lo, hi, alo, ahi in PAPER_REGIONS_C:
        assert (lo, hi, alo, ahi) in regions
    for region in [(10, 40, 0, 50), (-20, 0, -30, 10), (-30, 0, -40, 10), (-30, -10, -40, 0)]:
        assert tuple(float(x) for x in region) in regions
    assert (40.0, 60.0, 30.0, 60.0) in regions and (-5.0, 35.0, -15.0, 45.0) in regions
    widths = {hi - lo for lo, hi, _, _ in regions}
    assert min(widths) <= 10 and max(widths) >= 40
    assert min(lo for lo, *_ in regions) <= -50 and max(hi for _, hi, *_ in regions) >= 60
    assert min(taus) <= 600 and max(taus) >= 3600
    assert min(dt0s) <= 0 and max(dt0s) >= 6
    assert (-0.5, 1.5) in rates and (-3.0, 3.0) in rates
    assert min(levels) <= 4 and max(levels) >= 8
    assert min(deltas) <= 0.05 and max(deltas) >= 0.1
    assert min(budgets) <= 240 and max(budgets) >= 720
    assert min(segments) <= 5 and max(segments) >= 15
    assert min(steps) < 80


def test_some_bench_requests_cannot_be_complete_by_the_bound():
    """Not built for the planner's comfort: some requests' bound exceeds their budget."""
    beyond = []
    for f in sorted(BENCH.glob("*.toml")):
        config = load_campaign(f)
        e = config.experiments[0]
        bound = duration_lower_bound(e, config.params, config.limits).lower_bound_min
        if bound > config.limits.duration_max_min:
            beyond.append(f.stem)
    assert 2 <= len(beyond) <= len(list(BENCH.glob("*.toml"))) // 4


def test_unknown_request_is_one_line_and_exit_2(tmp_path, capsys):
    code = bench.main(["--only", "no-such-request", "--out", str(tmp_path), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "no-such-request" in err[0] and "w2-slow-chamber-720" in err[0]


def test_a_request_with_two_experiments_is_refused(tmp_path, capsys):
    text = (BENCH / "w1.toml").read_text(encoding="utf-8")
    (tmp_path / "two.toml").write_text(
        text.replace('name = "w1"', 'name = "two"') + text.replace('name = "w1"', 'name = "b"')
    )
    code = bench.main(["--bench-dir", str(tmp_path), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "exactly one [[experiment]]" in err and "two.toml" in err


def test_a_planner_crash_is_a_row_with_its_traceback(tmp_path, monkeypatch):
    """A crash (a planner bug) does not stop the benchmark; an old table is not re-used."""

    def crash(*args, **kwargs):
        raise ZeroDivisionError("planted")

    monkeypatch.setattr(bench, "plan_experiment", crash)
    folder = tmp_path / "w1"
    folder.mkdir()
    (folder / "steps.csv").write_text("left from an earlier run\n")
    row = bench.plan_request(str(BENCH / "w1.toml"), str(tmp_path), None)
    assert row["status"] == "crashed" and row["steps_csv"] is None
    assert "ZeroDivisionError: planted" in row["error"] and row["solve_s"] >= 0
    assert "planted" in (folder / "traceback.txt").read_text()
    assert not (folder / "steps.csv").exists()
    config = load_campaign(BENCH / "w1.toml")
    out = bench.recheck(row, config, bench._check_tables_module())
    assert not out["complete"] and out["status"] == "crashed"
    head = bench.headline(pd.DataFrame([out], columns=list(bench.COLUMNS)))
    assert head["crashed"] == ["w1"]
    assert "CRASHED" in "\n".join(bench.headline_lines({**head, "paper": {}, "campaign": None}))


def test_an_infeasible_request_is_a_row_with_the_planners_message(tmp_path, monkeypatch):
    from schedsyn.errors import InfeasiblePlanError

    def refuse(spec, *args, **kwargs):
        raise InfeasiblePlanError(f"{spec.name}: nothing fits", best_coverage=0.25)

    monkeypatch.setattr(bench, "plan_experiment", refuse)
    row = bench.plan_request(str(BENCH / "w2-300.toml"), str(tmp_path), None)
    assert row["status"] == "infeasible" and row["planner_coverage"] == 0.25
    assert row["error"] == "w2-300: nothing fits"
    out = bench.recheck(row, load_campaign(BENCH / "w2-300.toml"), bench._check_tables_module())
    assert not out["complete"] and not out["bound_fits_budget"] and out["recheck_agrees"]


# ---------------------------------------------------------------------------------------
# the re-check, on hand-built step tables
# ---------------------------------------------------------------------------------------
def _table(tmp_path: Path, knots: list[tuple[float, float]]) -> Path:
    """A step table through (minute, chamber degC) knots, as the planner writes it."""
    t = np.array([k[0] for k in knots])
    tk = np.array([k[1] for k in knots])
    frame = pd.DataFrame(
        {
            "step": np.arange(1, len(knots)),
            "start_min": t[:-1],
            "duration_min": np.diff(t),
            "tk_start_c": tk[:-1],
            "tk_end_c": tk[1:],
            "rate_c_per_min": np.diff(tk) / np.diff(t),
        }
    )
    path = tmp_path / "steps.csv"
    frame.to_csv(path, index=False)
    return path


# one cooling and one heating crossing of [0, 10] degC: two levels in every bin
DOWN_UP = [(0, 20.0), (30, -10.0), (90, -10.0), (120, 20.0), (200, 20.0)]


def _planned(steps: Path, complete: bool, coverage: float, bound: float = 100.0) -> dict:
    return {
        "request": "r",
        "steps_csv": str(steps),
        "duration_lower_bound_min": bound,
        "status": "complete" if complete else "incomplete",
        "planner_complete": complete,
        "planner_coverage": coverage,
        "solve_s": 1.0,
        "note": "",
        "error": "",
    }


def _config(levels: int, **limits) -> CampaignConfig:
    return CampaignConfig(
        experiments=(ExperimentSpec("r", 0.0, 10.0, -10.0, 20.0, levels_required=levels),),
        limits=Limits(**limits),
    )


def _library_check(steps: Path, spec: ExperimentSpec, params: ThermalParams):
    """Coverage and device range by schedsyn's own simulator and counter."""
    traj = simulate(read_steps(steps), params, dt_min=0.05, t0_c=20.0)
    rep = coverage_report(
        traj.t_c, traj.g_c_per_min, spec.grid, spec.levels_required, spec.delta_c_per_min
    )
    return rep.coverage, float(traj.t_c.min()), float(traj.t_c.max())


def test_recheck_agrees_with_the_library_on_a_hand_built_table(tmp_path):
    steps = _table(tmp_path, DOWN_UP)
    config = _config(2)
    row = bench.recheck(_planned(steps, True, 1.0), config, bench._check_tables_module())
    coverage, t_lo, t_hi = _library_check(steps, config.experiments[0], config.params)
    assert coverage == 1.0
    assert row["coverage"] == 1.0 and row["min_levels"] == 2
    assert row["complete"] and row["recheck_agrees"] and row["recheck_problems"] == ""
    assert row["duration_min"] == 200.0 and row["steps"] == 4
    assert row["gap_to_bound_min"] == pytest.approx(100.0)
    # the device lags the chamber (well inside its -10 .. 20 degC excursion) and both
    # simulations put it at the same place
    assert -10.0 < row["device_min_c"] < 0.0
    assert row["device_min_c"] == pytest.approx(t_lo, abs=1e-3)
    assert row["device_max_c"] == pytest.approx(t_hi, abs=1e-3)


def test_recheck_does_not_take_the_planners_word(tmp_path):
    """A planner claiming a complete plan is contradicted when the table covers less."""
    steps = _table(tmp_path, DOWN_UP)
    config = _config(3)  # two crossings cannot give three levels
    row = bench.recheck(_planned(steps, True, 1.0), config, bench._check_tables_module())
    assert row["coverage"] == 0.0 and row["min_levels"] == 2
    assert not row["complete"] and not row["recheck_agrees"]
    frame = pd.DataFrame([row], columns=list(bench.COLUMNS))
    assert bench.headline(frame)["recheck_disagrees"] == ["r"]


def test_recheck_counts_a_broken_limit_as_incomplete(tmp_path):
    """Full coverage but a chamber below its floor: not complete."""
    steps = _table(tmp_path, DOWN_UP)
    row = bench.recheck(
        _planned(steps, False, 1.0), _config(2, chamber_min_c=-5.0), bench._check_tables_module()
    )
    assert row["coverage"] == 1.0 and not row["complete"] and row["recheck_agrees"]
    assert "floor -5" in row["recheck_problems"]


LIMITS = Limits()
SPEC = ExperimentSpec("r", 0.0, 10.0, -10.0, 20.0, max_steps=10)
GOOD = {
    "duration_min": 540.0,
    "steps": 10,
    "rate_min": -1.0,
    "rate_max": 3.0,
    "chamber_min_c": -70.04,
    "chamber_max_c": 80.0,
    "device_min_c": -52.001,
    "device_max_c": 62.0,
    "chamber_start_c": 20.0,
    "chamber_end_c": 20.5,
}


def test_limit_problems_none_at_the_limits():
    assert bench.limit_problems(GOOD, SPEC, LIMITS) == []


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("duration_min", 541.0, "541 > 540 min"),
        ("steps", 11, "11 steps > max_steps 10"),
        ("rate_min", -1.01, "< -1 °C/min"),
        ("rate_max", 3.01, "> 3 °C/min"),
        ("chamber_min_c", -70.1, "< floor -70"),
        ("chamber_max_c", 80.1, "> ceiling 80"),
        ("device_min_c", -52.01, "device -52.010"),
        ("device_max_c", 62.01, "device 62.010"),
        ("chamber_start_c", 20.1, "starts at 20.1"),
        ("chamber_end_c", 19.4, "ends at 19.4"),
    ],
)
def test_limit_problems_each_limit(key, value, words):
    problems = bench.limit_problems({**GOOD, key: value}, SPEC, LIMITS)
    assert len(problems) == 1 and words in problems[0]


# ---------------------------------------------------------------------------------------
# the headline figures, on hand-built tables
# ---------------------------------------------------------------------------------------
def _row(name, complete, duration, bound, budget=540.0, agrees=True, status=None):
    return {
        "request": name,
        "complete": complete,
        "duration_min": duration,
        "duration_lower_bound_min": bound,
        "gap_to_bound_min": duration - bound,
        "bound_fits_budget": bound <= budget,
        "recheck_agrees": agrees,
        "status": status or ("complete" if complete else "incomplete"),
    }


def test_headline_share_counts_only_requests_whose_bound_fits():
    frame = pd.DataFrame(
        [
            _row("a", True, 500, 400),
            _row("b", True, 480, 300),
            _row("c", False, 540, 350),
            _row("d", False, math.nan, 600),  # bound beyond the budget: not counted
            _row("e", False, math.nan, math.inf, status="infeasible"),
        ]
    )
    head = bench.headline(frame)
    assert head["bound_fits_budget"] == 3 and head["complete_where_bound_fits"] == 2
    assert head["complete_share_where_bound_fits"] == pytest.approx(2 / 3)
    assert not head["meets_share_target"]
    assert head["incomplete_where_bound_fits"] == ["c"]
    assert head["median_gap_complete_min"] == pytest.approx(140.0)
    assert head["below_bound"] == [] and head["crashed"] == []


def test_headline_flags_a_complete_plan_below_its_bound():
    frame = pd.DataFrame(
        [_row("ok", True, 400, 399.5), _row("bad", True, 390, 400), _row("x", False, 300, 400)]
    )
    head = bench.headline(frame)
    assert head["below_bound"] == ["bad"]
    lines = "\n".join(bench.headline_lines({**head, "paper": {}, "campaign": None}))
    assert "*** VALIDITY" in lines and "bad" in lines


def test_headline_flags_crashes_and_disagreements():
    frame = pd.DataFrame(
        [
            _row("a", True, 500, 400, agrees=False),
            _row("b", False, math.nan, 300, status="crashed"),
        ]
    )
    head = bench.headline(frame)
    assert head["recheck_disagrees"] == ["a"] and head["crashed"] == ["b"]
    assert head["complete_share_where_bound_fits"] == pytest.approx(0.5)


# ---------------------------------------------------------------------------------------
# end to end on two tiny requests
# ---------------------------------------------------------------------------------------
TINY = """[limits]
duration_max_min = {budget}

[settings]
levels_required = 2

[[experiment]]
name = "{name}"
working_lo_c = 10.0
working_hi_c = 14.0
approx_lo_c = 0.0
approx_hi_c = 24.0
"""


@pytest.mark.slow
def test_script_end_to_end_agrees_with_a_separate_recheck(tmp_path):
    requests = tmp_path / "bench"
    requests.mkdir()
    # 4 degC, two levels: plannable in 4 h; in 30 min the bound (about 50 min) says no
    (requests / "tiny-240.toml").write_text(TINY.format(budget=240.0, name="tiny-240"))
    (requests / "tiny-30.toml").write_text(TINY.format(budget=30.0, name="tiny-30"))
    out = tmp_path / "out"
    proc = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            "--bench-dir",
            str(requests),
            "--out",
            str(out),
            "--campaign-runs",
            "0",
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    frame = pd.read_csv(out / "bench_general.csv")
    assert list(frame.columns) == list(bench.COLUMNS)
    assert sorted(frame["request"]) == ["tiny-240", "tiny-30"]
    head = json.loads((out / "headline.json").read_text())
    fits = 0
    done = 0
    for _, row in frame.iterrows():
        config = load_campaign(requests / f"{row['request']}.toml")
        spec, params, limits = config.experiments[0], config.params, config.limits
        bound = duration_lower_bound(spec, params, limits).lower_bound_min
        assert row["duration_lower_bound_min"] == pytest.approx(bound)
        assert bool(row["bound_fits_budget"]) == (bound <= limits.duration_max_min)
        fits += bound <= limits.duration_max_min
        steps = out / "requests" / row["request"] / "steps.csv"
        if not steps.exists():
            assert not row["complete"] and math.isnan(row["coverage"])
            continue
        # recomputed by the library's simulator and counter (not check_tables' code)
        prog = read_steps(steps)
        traj = simulate(prog, params, dt_min=0.05, t0_c=limits.t_init_c)
        rep = coverage_report(
            traj.t_c, traj.g_c_per_min, spec.grid, spec.levels_required, spec.delta_c_per_min
        )
        assert row["coverage"] == pytest.approx(rep.coverage)
        assert row["min_levels"] == rep.min_levels
        assert row["duration_min"] == pytest.approx(prog.total_min)
        assert row["steps"] == prog.n_segments
        assert row["device_min_c"] == pytest.approx(traj.t_c.min(), abs=1e-3)
        assert row["device_max_c"] == pytest.approx(traj.t_c.max(), abs=1e-3)
        ok = (
            rep.coverage == 1.0
            and prog.n_segments <= spec.max_steps
            and prog.total_min <= limits.duration_max_min
            and not prog.violations(limits)
        )
        assert bool(row["complete"]) == ok
        plan = json.loads((out / "requests" / row["request"] / "plan.json").read_text())
        assert bool(row["planner_complete"]) == plan["complete"]
        assert bool(row["recheck_agrees"])
        if ok:
            assert row["duration_min"] >= bound
        done += ok and bound <= limits.duration_max_min
    tiny30 = frame.set_index("request").loc["tiny-30"]
    assert not tiny30["bound_fits_budget"] and not tiny30["complete"]
    assert head["bound_fits_budget"] == fits == 1
    assert head["complete_where_bound_fits"] == done
    assert head["complete_share_where_bound_fits"] == pytest.approx(done / fits)
    md = (out / "bench_general.md").read_text(encoding="utf-8")
    assert "`tiny-240`" in md and "`tiny-30`" in md and "not in this run" in md
