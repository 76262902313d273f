"""Sensitivity sweeps: grid parsing, agreement with direct simulation, backends, CLI."""

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from schedsyn import (
    BinGrid,
    InfeasiblePlanError,
    ParameterError,
    ThermalParams,
    coverage_report,
    read_steps,
    simulate,
)
from schedsyn.cli import main
from schedsyn.sweep import (
    SweepResult,
    parse_grid,
    parse_range,
    run_map,
    sweep_fixed,
    sweep_replan,
    verify_box,
)

STEPS = "data/baseline_exp1_steps.csv"
REGION = (-50.0, -30.0)


@pytest.fixture(scope="module")
def programme():
    return read_steps(STEPS)


@pytest.fixture(scope="module")
def full_grid(programme):
    """The issue's 13 x 13 grid, serial (also the reference for the monotone checks)."""
    return sweep_fixed(programme, REGION, parse_grid("1800:3000:13"), parse_grid("0:6:13"))


# -- grid strings --------------------------------------------------------------------------
def test_parse_grid_values():
    np.testing.assert_array_equal(parse_grid("1800:3000:13"), np.linspace(1800, 3000, 13))
    assert parse_grid("1800:3000:13")[6] == 2400.0
    assert parse_grid("0:6:13")[6] == 3.0
    np.testing.assert_array_equal(parse_grid(" 2400 "), [2400.0])
    np.testing.assert_array_equal(parse_grid("-1.5:1.5:3"), [-1.5, 0.0, 1.5])
    np.testing.assert_array_equal(parse_grid("5:5:1"), [5.0])
    assert parse_range("2000:2800") == (2000.0, 2800.0)


@pytest.mark.parametrize(
    "spec, words",
    [
        ("1800:3000", "2 ':'-separated parts"),
        ("1800:3000:13:1", "4 ':'-separated parts"),
        ("a:3000:13", "START 'a'"),
        ("1800:x:13", "STOP 'x'"),
        ("1800:3000:2.5", "whole number"),
        ("1800:3000:0", ">= 1"),
        ("3000:1800:5", "START must be < STOP"),
        ("1800:3000:1", "START = STOP"),
        ("nan:3000:5", "finite"),
        ("", "is not a number"),
    ],
)
def test_parse_grid_errors_name_the_option(spec, words):
    with pytest.raises(ParameterError, match="--tau-s") as info:
        parse_grid(spec, "--tau-s", "s")
    assert words in str(info.value)
    assert "\n" not in str(info.value)


def test_parse_range_errors():
    for bad in ("2000", "2800:2000", "a:1"):
        with pytest.raises(ParameterError, match="--robust-tau-s"):
            parse_range(bad, "--robust-tau-s")


# -- physics: each grid point equals a direct simulation + the one coverage metric ---------
def _direct(programme, tau_s, dt0_c, delta):
    traj = simulate(programme, ThermalParams(tau_s=tau_s, dt0_c=dt0_c))
    rep = coverage_report(traj.t_c, traj.g_c_per_min, BinGrid(*REGION), 6, delta)
    return rep, traj


def test_sweep_equals_direct_simulation(programme, full_grid):
    frame = full_grid.to_frame().set_index(["tau_s", "dt0_c"])
    # the nominal point and the corners of the grid, at both gradient separations
    for tau, dt0 in [(2400.0, 3.0), (1800.0, 0.0), (3000.0, 6.0), (1800.0, 6.0), (2700.0, 1.5)]:
        row = frame.loc[(tau, dt0)]
        for delta, suffix in [(0.05, "0p05"), (0.1, "0p1")]:
            rep, traj = _direct(programme, tau, dt0, delta)
            assert row[f"coverage_delta_{suffix}"] == rep.coverage
            assert row[f"min_levels_delta_{suffix}"] == rep.min_levels
        rep, traj = _direct(programme, tau, dt0, 0.05)
        assert row["coverage"] == rep.coverage and row["min_levels"] == rep.min_levels
        assert row["t_min_c"] == traj.t_c.min() and row["t_max_c"] == traj.t_c.max()


def test_frame_layout(full_grid):
    frame = full_grid.to_frame()
    assert list(frame.columns[:4]) == ["tau_s", "dt0_c", "coverage", "min_levels"]
    for c in (
        "coverage_delta_0p05",
        "min_levels_delta_0p05",
        "coverage_delta_0p1",
        "min_levels_delta_0p1",
    ):
        assert c in frame.columns
    assert len(frame) == 169
    assert frame[["tau_s", "dt0_c"]].drop_duplicates().shape[0] == 169
    # tau outer, dT0 inner
    assert frame["tau_s"].iloc[:13].nunique() == 1 and frame["dt0_c"].iloc[:13].nunique() == 13
    np.testing.assert_array_equal(frame["coverage"], frame["coverage_delta_0p05"])


def test_monotone_in_delta_and_levels(programme, full_grid):
    cov, lev = full_grid.coverage, full_grid.min_levels
    # a wider separation can only merge levels: fewer distinct levels, lower coverage
    assert np.all(cov[:, :, 1] <= cov[:, :, 0])
    assert np.all(lev[:, :, 1] <= lev[:, :, 0])
    assert np.any(cov[:, :, 1] < cov[:, :, 0])  # the check can fail: it bites somewhere
    # demanding more levels can only lower coverage
    harder = sweep_fixed(
        programme,
        REGION,
        full_grid.tau_s_values[::4],
        full_grid.dt0_c_values[::4],
        levels_required=7,
    )
    assert np.all(harder.coverage_grid <= full_grid.coverage_grid[::4, ::4])


def test_summary_numbers(full_grid):
    w = full_grid.worst()
    assert w["coverage"] == full_grid.coverage_grid.min()
    mask = full_grid.covered_mask(0.5)
    assert mask.mean() == np.mean(full_grid.coverage_grid >= 0.5)
    assert full_grid.holds(0.0) and not full_grid.holds(1.0)
    assert f"worst at tau {w['tau_s']:g} s" in full_grid.summary()


def test_verify_box_density_and_ends(programme):
    res = verify_box(programme, REGION, (2000.0, 2800.0), (0.0, 6.0))
    assert res.shape == (9, 7)
    assert res.tau_s_values[0] == 2000.0 and res.tau_s_values[-1] == 2800.0
    assert res.dt0_c_values[0] == 0.0 and res.dt0_c_values[-1] == 6.0
    ref = sweep_fixed(programme, REGION, np.linspace(2000, 2800, 9), np.linspace(0, 6, 7))
    np.testing.assert_array_equal(res.coverage, ref.coverage)
    with pytest.raises(ParameterError, match="at least 9 points"):
        verify_box(programme, REGION, (2000.0, 2800.0), (0.0, 6.0), n_tau=5)
    with pytest.raises(ParameterError, match="lo <= hi"):
        verify_box(programme, REGION, (2800.0, 2000.0), (0.0, 6.0))
    one = verify_box(programme, REGION, (2400.0, 2400.0), (3.0, 3.0))
    assert one.shape == (1, 1)


def test_bad_sweep_inputs(programme):
    with pytest.raises(ParameterError, match="tau_s"):
        sweep_fixed(programme, REGION, [-10.0, 100.0], [3.0])
    with pytest.raises(ParameterError, match="strictly increasing"):
        sweep_fixed(programme, REGION, [2400.0, 2000.0], [3.0])
    with pytest.raises(ParameterError, match="delta"):
        sweep_fixed(programme, REGION, [2400.0], [3.0], deltas_c_per_min=(0.05, 0.0))
    with pytest.raises(ParameterError, match="backend"):
        run_map(abs, [1, 2], backend="cluster")
    with pytest.raises(ParameterError, match="workers"):
        run_map(abs, [1, 2], backend="local", workers=0)


# -- backends --------------------------------------------------------------------------------
def fake_plan(params):
    """A cheap stand-in planner (module level, so it pickles): infeasible for slow devices."""
    if params.tau_s > 2600:
        raise InfeasiblePlanError(f"tau {params.tau_s:g} s too slow", best_coverage=0.8)
    return _FakePlan(params.tau_s, params.dt0_c)


class _FakePlan:
    def __init__(self, tau_s, dt0_c):
        self.tau_s, self.dt0_c = tau_s, dt0_c

    def to_summary_dict(self):
        return {
            "duration_min": 300.0 + self.tau_s / 10.0 + self.dt0_c,
            "coverage_margin": 0.01 * self.dt0_c,
            "tau_s": -1.0,
        }


def _all_backends(programme, backend, workers=None):
    fixed = sweep_fixed(
        programme,
        REGION,
        [1800.0, 2400.0, 3000.0],
        [0.0, 3.0, 6.0],
        backend=backend,
        workers=workers,
    ).to_frame()
    replan = sweep_replan(
        fake_plan, [2000.0, 2400.0, 2800.0], [0.0, 3.0], backend=backend, workers=workers
    ).to_frame()
    mapped = run_map(np.sqrt, [1.0, 4.0, 9.0, 16.0], backend, workers=workers, progress=False)
    return fixed, replan, mapped


def test_replan_machinery_serial():
    res = sweep_replan(fake_plan, [2000.0, 2400.0, 2800.0], [0.0, 3.0])
    frame = res.to_frame()
    assert list(frame.columns[:4]) == ["tau_s", "dt0_c", "status", "message"]
    assert len(frame) == 6 and res.n_ok == 4
    bad = frame[frame["tau_s"] == 2800.0]
    assert (bad["status"] == "infeasible").all() and (bad["best_coverage"] == 0.8).all()
    ok = frame[frame["status"] == "ok"]
    np.testing.assert_allclose(ok["duration_min"], 300.0 + ok["tau_s"] / 10 + ok["dt0_c"])
    assert (frame["tau_s"] > 0).all()  # the grid point wins over a summary's own tau_s
    assert "4 plans found, 2 infeasible" in res.summary()


def test_backends_agree(programme):
    ref = _all_backends(programme, "serial")
    local = _all_backends(programme, "local", workers=2)
    pd.testing.assert_frame_equal(ref[0], local[0], check_exact=True)
    pd.testing.assert_frame_equal(ref[1], local[1], check_exact=True)
    assert ref[2] == local[2] == [1.0, 2.0, 3.0, 4.0]


@pytest.fixture(scope="module")
def dask_address():
    """A 2-worker Dask cluster on 127.0.0.1 (threads, real TCP), for this module only."""
    distributed = pytest.importorskip("distributed")
    import dask

    # a loaded machine (CI shares its cores) can take longer than dask's default 30 s to
    # start even an in-process cluster; the test is about results, not start-up speed
    timeouts = {
        "distributed.comm.timeouts.connect": "180s",
        "distributed.comm.timeouts.tcp": "180s",
    }
    with (
        dask.config.set(timeouts),
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=False,
            protocol="tcp://",
            host="127.0.0.1",
            dashboard_address=":0",  # any free port: None means the default 8787 here
        ) as cluster,
    ):
        yield cluster.scheduler_address


def test_dask_backend_agrees(programme, dask_address):
    assert dask_address.startswith("tcp://127.0.0.1:")
    ref = _all_backends(programme, "serial")
    got = _all_backends(programme, dask_address)
    pd.testing.assert_frame_equal(ref[0], got[0], check_exact=True)
    pd.testing.assert_frame_equal(ref[1], got[1], check_exact=True)
    assert got[2] == ref[2]


def test_import_stays_light():
    code = (
        "import sys, schedsyn.sweep; "
        "print(sorted(m for m in ('matplotlib', 'distributed', 'tqdm') if m in sys.modules))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "[]"


# -- command line ----------------------------------------------------------------------------
def test_cli_writes_table_and_heatmap(tmp_path, capsys, programme):
    out = tmp_path / "sw"
    rc = main(
        [
            "sweep",
            STEPS,
            "--region",
            "-50",
            "-30",
            "--tau-s",
            "2000:2800:3",
            "--dt0-c",
            "0:6:4",
            "--out",
            str(out),
            "--workers",
            "2",
            "--no-progress",
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "at the nominal point (tau 2400 s, dT0 3 °C): coverage 55.0%" in text
    assert "full coverage on" in text and "worst at" in text
    frame = pd.read_csv(out / "sweep.csv")
    assert len(frame) == 12
    assert list(frame.columns[:4]) == ["tau_s", "dt0_c", "coverage", "min_levels"]
    assert {"coverage_delta_0p05", "coverage_delta_0p1", "min_levels_delta_0p1"} <= set(
        frame.columns
    )
    api = sweep_fixed(programme, REGION, [2000.0, 2400.0, 2800.0], [0.0, 2.0, 4.0, 6.0])
    np.testing.assert_array_equal(frame["coverage"], api.to_frame()["coverage"])
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    "option, value, words",
    [
        ("--tau-s", "1800:3000", "--tau-s"),
        ("--tau-s", "1800:3000:x", "--tau-s"),
        ("--dt0-c", "6:0:13", "--dt0-c"),
        ("--dt0-c=-2:-6:3", None, "START must be < STOP"),
        ("--tau-s=-100:100:3", None, "tau_s"),
        ("--dt0-c", "0:80:3", "dt0_c"),
    ],
)
def test_cli_bad_grid_is_one_line_exit_2(tmp_path, capsys, option, value, words):
    opt = [option] if value is None else [option, value]
    rc = main(["sweep", STEPS, *opt, "--region", "-50", "-30", "--out", str(tmp_path), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert not (tmp_path / "sweep.csv").exists()


def test_cli_replan_without_planner(tmp_path, capsys, monkeypatch):
    import schedsyn.cli.sweep as cli_sweep

    monkeypatch.setattr(cli_sweep, "_planner_available", lambda: False)
    rc = main(["sweep", "--replan", "--out", str(tmp_path), "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "re-planning needs the planner (schedsyn.planner)" in err and err.count("\n") == 1


def test_cli_replan_writes_rows(tmp_path, capsys, monkeypatch):
    import schedsyn.cli.sweep as cli_sweep

    monkeypatch.setattr(cli_sweep, "_planner_available", lambda: True)
    monkeypatch.setattr(cli_sweep, "PlanAtPoint", lambda *args: fake_plan)
    rc = main(
        [
            "sweep",
            "--replan",
            "--tau-s",
            "2000:2800:3",
            "--dt0-c",
            "0:6:3",
            "--region",
            "-50",
            "-30",
            "--out",
            str(tmp_path),
            "--workers",
            "1",
            "--no-progress",
        ]
    )
    assert rc == 0
    frame = pd.read_csv(tmp_path / "sweep.csv")
    assert len(frame) == 9 and (frame["status"] == "infeasible").sum() == 3
    assert (tmp_path / "sweep.png").stat().st_size > 0
    assert "6 plans found" in capsys.readouterr().out


def test_cli_needs_steps_without_replan(tmp_path, capsys):
    assert main(["sweep", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "STEPS.csv" in capsys.readouterr().err


def _result_with_coverage(cov):
    cov = np.asarray(cov, dtype=float)
    n_tau, n_dt0 = cov.shape
    return SweepResult(
        region_c=REGION,
        tau_s_values=2000.0 + 100.0 * np.arange(n_tau),
        dt0_c_values=np.arange(n_dt0, dtype=float),
        levels_required=6,
        deltas_c_per_min=(0.05,),
        coverage=cov[:, :, None],
        min_levels=np.where(cov[:, :, None] >= 1.0, 6, 3),
        t_min_c=np.zeros(cov.shape),
        t_max_c=np.zeros(cov.shape),
    )


def test_covered_box_is_the_largest_full_sub_box():
    cov = np.array(
        [
            [1.0, 1.0, 0.9, 1.0],
            [1.0, 1.0, 1.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
            [0.5, 1.0, 1.0, 1.0],
        ]
    )
    res = _result_with_coverage(cov)
    # the full 2 x 4 band (rows 1-2, 8 points) and the 3 x 2 block (rows 0-2, cols 0-1)
    # lose to rows 1-3 x cols 1-3 with 9 points
    assert res.covered_box() == {
        "tau_s_range": (2100.0, 2300.0),
        "dt0_c_range": (1.0, 3.0),
        "n_points": 9,
    }
    assert res.covered_box(0.5)["n_points"] == 16
    assert _result_with_coverage(np.zeros((3, 3))).covered_box() is None
    # brute force over every sub-box agrees on the size
    best = max(
        (i1 - i0) * (j1 - j0)
        for i0 in range(4)
        for i1 in range(i0 + 1, 5)
        for j0 in range(4)
        for j1 in range(j0 + 1, 5)
        if np.all(cov[i0:i1, j0:j1] >= 1.0)
    )
    assert best == 9


def test_cli_on_dask_matches_serial(tmp_path, dask_address):
    common = ["sweep", STEPS, "--tau-s", "2000:2800:3", "--dt0-c", "0:6:3", "--region", "-50"]
    common += ["-30", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "d"), "--dask", dask_address]) == 0
    assert main([*common, "--out", str(tmp_path / "s"), "--workers", "1"]) == 0
    pd.testing.assert_frame_equal(
        pd.read_csv(tmp_path / "d" / "sweep.csv"),
        pd.read_csv(tmp_path / "s" / "sweep.csv"),
        check_exact=True,
    )


def test_heatmaps_draw_mixed_and_single_point_grids(tmp_path):
    from schedsyn import plots

    mixed = _result_with_coverage([[1.0, 0.5], [1.0, 1.0], [0.2, 1.0]]).to_frame()
    single = _result_with_coverage([[0.75]]).to_frame()
    axes = plots.sweep_panels(
        [
            (mixed, "coverage", "mixed"),
            (mixed, "min_levels", "levels"),
            (single, "coverage", "one point"),
        ],
        nominal=(2100.0, 0.5),
    )
    assert len(axes) == 3 and axes[0].get_title() == "mixed"
    assert len(axes[0].collections) >= 2  # the mesh and the full-coverage outline
    plots.save_figure(axes[0], tmp_path / "h.png")
    assert (tmp_path / "h.png").stat().st_size > 0


def test_bad_dask_address_is_a_parameter_error():
    pytest.importorskip("distributed")
    with pytest.raises(ParameterError, match="unknown address scheme 'foo'"):
        run_map(abs, [1, 2], backend="foo://somewhere:8786")


def test_replan_adapter_builds_the_paper_spec(monkeypatch):
    from schedsyn import Limits
    from schedsyn.cli.sweep import PlanAtPoint, default_approx

    assert default_approx((-50.0, -30.0), Limits()) == (-52.0, -20.0)  # the paper's exp. 1
    assert default_approx((-30.0, 0.0), Limits()) == (-40.0, 10.0)
    assert default_approx((30.0, 60.0), Limits()) == (20.0, 62.0)
    planner = pytest.importorskip("schedsyn.planner")
    seen = {}

    def stub(spec, params, limits):
        seen.update(spec=spec, params=params, limits=limits)
        return _FakePlan(params.tau_s, params.dt0_c)

    monkeypatch.setattr(planner, "plan_experiment", stub)
    fn = PlanAtPoint((-50.0, -30.0), (-52.0, -20.0), 6, 0.05, Limits())
    fn(ThermalParams(tau_s=2100.0, dt0_c=1.0))
    spec = seen["spec"]
    assert (spec.working_lo_c, spec.working_hi_c, spec.approx_lo_c, spec.approx_hi_c) == (
        -50.0,
        -30.0,
        -52.0,
        -20.0,
    )
    assert spec.levels_required == 6 and spec.delta_c_per_min == 0.05
    assert seen["params"] == ThermalParams(tau_s=2100.0, dt0_c=1.0)


def test_cli_flags_grid_points_past_the_device_limits(tmp_path, capsys):
    """A programme that keeps the nominal device within 62 degC can take it past the limit
    elsewhere in the grid (a larger dT0); sweep must say where and by how much, not only
    report coverage (red team: 63.9 degC > 62 went unmentioned). The excess per point is
    re-made by scipy's ODE integration of the typed table (tests/independent.py)."""
    from independent import chamber_knots, ode_trajectories

    from schedsyn import Programme

    # 20 -> 57 degC at 1 degC/min, hold 300 min (T -> 57 + dT0), back to 20 at -1 degC/min
    prog = Programme(np.array([37.0, 300.0, 37.0]), np.array([1.0, 0.0, -1.0]), start_c=20.0)
    steps = prog.to_csv(tmp_path / "hot.csv")
    out = tmp_path / "sw"
    args = ["sweep", str(steps), "--region", "40", "50", "--tau-s", "1800:3000:3"]
    rc = main([*args, "--dt0-c", "0:8:5", "--out", str(out), "--workers", "1", "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    frame = pd.read_csv(out / "sweep.csv")
    knots_t, knots_tk = chamber_knots(steps)
    _, temp, _ = ode_trajectories(knots_t, knots_tk, frame["tau_s"].to_numpy(), frame["dt0_c"])
    want = np.maximum(temp.max(axis=1) - 62.0, 0.0)
    np.testing.assert_allclose(frame["device_excess_c"], want, atol=0.02)
    assert (want > 0.05).sum() == 6  # dT0 6 and 8 at every tau (57 + dT0 - 62 > 0)
    worst = int(np.argmax(want))
    assert "WARNING: the device goes past its limits [-52, 62] °C at 6 of 15 grid points" in text
    assert f"dT0 {frame['dt0_c'][worst]:g} °C: {temp[worst].max():.1f} °C > 62" in text
    # within the limits everywhere: said so, no warning
    rc = main([*args, "--dt0-c", "0:4:3", "--out", str(tmp_path / "ok"), "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "held at every grid point" in text and "WARNING" not in text


# -- the step table's own settings -------------------------------------------------------
def _table_with_meta(tmp_path, name="planned.csv", **meta):
    """The baseline programme under ``# key: value`` metadata lines (a plan's table)."""
    lines = [f"# {k}: {v}" for k, v in meta.items()]
    from pathlib import Path

    text = "\n".join(lines) + "\n" + Path(STEPS).read_text(encoding="utf-8")
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_cli_counts_coverage_at_the_tables_delta(tmp_path, capsys, programme):
    """A table planned for delta 0.08 is swept at 0.08 (judge: counted at 0.05, 57.5 %
    complete where 0.08 gave 49 %); the option overrides it, and the output says which."""
    steps = _table_with_meta(
        tmp_path, working_lo_c=-50.0, working_hi_c=-30.0, levels_required=5, delta_c_per_min=0.08
    )
    grid = ["--tau-s", "2000:2800:3", "--dt0-c", "0:6:3", "--workers", "1", "--quiet"]
    assert main(["sweep", str(steps), *grid, "--out", str(tmp_path / "a")]) == 0
    text = capsys.readouterr().out
    assert "coverage requirement: >= 5 levels 0.08 °C/min apart (from the step table)" in text
    frame = pd.read_csv(tmp_path / "a" / "sweep.csv")
    taus, dt0s = [2000.0, 2400.0, 2800.0], [0.0, 3.0, 6.0]
    want = sweep_fixed(
        programme, REGION, taus, dt0s, levels_required=5, deltas_c_per_min=(0.08, 0.1)
    ).to_frame()
    at_005 = sweep_fixed(programme, REGION, taus, dt0s, levels_required=5).to_frame()
    assert not np.array_equal(want["coverage"], at_005["coverage"])  # the test can tell
    np.testing.assert_array_equal(frame["coverage"], want["coverage"])
    assert {"coverage_delta_0p08", "coverage_delta_0p1"} <= set(frame.columns)
    # given explicitly: the option's delta, said so
    rc = main(
        ["sweep", str(steps), *grid, "--delta-c-per-min", "0.05", "--out", str(tmp_path / "b")]
    )
    assert rc == 0
    assert "(levels from the step table, delta given)" in capsys.readouterr().out
    frame = pd.read_csv(tmp_path / "b" / "sweep.csv")
    np.testing.assert_array_equal(frame["coverage"], at_005["coverage"])


@pytest.mark.parametrize(
    "region, approx, words",
    [
        (["13", "5"], [], "lo_c < hi_c"),
        (["-30", "-20"], ["--approx", "-25", "-10"], "must contain the working region"),
        (["-60", "-50"], [], "outside its limits -52 .. 62 °C"),
    ],
)
def test_cli_replan_refuses_a_bad_request_up_front(
    tmp_path, capsys, monkeypatch, region, approx, words
):
    """A request no point can plan is refused with plan's own checks, one line and exit 2
    (judge: exit 0 with every row "failed")."""
    import schedsyn.cli.sweep as cli_sweep

    monkeypatch.setattr(cli_sweep, "PlanAtPoint", lambda *args: fake_plan)  # never asked
    grid = ["--tau-s", "2000:2800:3", "--dt0-c", "0:6:3", "--workers", "1", "--quiet"]
    rc = main(["sweep", "--replan", "--region", *region, *approx, *grid, "--out", str(tmp_path)])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err and "Traceback" not in err
    assert not (tmp_path / "sweep.csv").exists()


def test_cli_says_where_the_nominal_point_came_from(tmp_path, capsys):
    """--nominal-* over a table that records a model: said so (judge: "from the step
    table" whatever the options)."""
    steps = _table_with_meta(
        tmp_path, working_lo_c=-50.0, working_hi_c=-30.0, tau_s=2900.0, dt0_c=1.5
    )
    grid = ["--tau-s", "2400", "--dt0-c", "3", "--workers", "1", "--quiet"]
    cases = [
        ([], "(tau 2900 s, dT0 1.5 °C)", "(nominal point: from the step table)"),
        (
            ["--nominal-tau-s", "2400"],
            "(tau 2400 s, dT0 1.5 °C)",
            "from the step table and the options",
        ),
        (
            ["--nominal-tau-s", "2400", "--nominal-dt0-c", "3"],
            "(tau 2400 s, dT0 3 °C)",
            "(nominal point: given)",
        ),
    ]
    for k, (opts, point, source) in enumerate(cases):
        assert main(["sweep", str(steps), *grid, *opts, "--out", str(tmp_path / f"o{k}")]) == 0
        (line,) = [
            x for x in capsys.readouterr().out.splitlines() if x.startswith("at the nominal")
        ]
        assert point in line and source in line, line


def test_cli_warns_of_a_tau_in_minutes(tmp_path, capsys):
    """plan's unit-slip warning, for the grid's ends and the nominal point (judge: none)."""
    rc = main(
        ["sweep", STEPS, "--region", "-50", "-30", "--tau-s", "30:50:3", "--dt0-c", "3"]
        + ["--nominal-tau-s", "40", "--workers", "1", "--quiet", "--out", str(tmp_path)]
    )
    assert rc == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3, err
    assert err[0].startswith("warning: --tau-s 30:50:3: tau_s = 30 s") and "give 1800" in err[0]
    assert err[1].startswith("warning: --tau-s 30:50:3: tau_s = 50 s") and "give 3000" in err[1]
    assert err[2].startswith("warning: nominal point: tau_s = 40 s") and "give 2400" in err[2]
    # a plausible grid and nominal: no warning
    rc = main(
        ["sweep", STEPS, "--region", "-50", "-30", "--tau-s", "2400", "--dt0-c", "3"]
        + ["--workers", "1", "--quiet", "--out", str(tmp_path / "ok")]
    )
    assert rc == 0 and capsys.readouterr().err == ""


def test_default_grid_is_around_the_nominal_and_takes_in_the_box():
    from schedsyn.sweep import default_grid

    taus, dt0s = default_grid(ThermalParams())  # the grid around 2400 s, 3 degC
    np.testing.assert_array_equal(taus, parse_grid("1800:3000:13"))
    np.testing.assert_array_equal(dt0s, parse_grid("0:6:13"))
    taus, dt0s = default_grid(ThermalParams(1600.0, -2.0), (1000.0, 2000.0), (-3.0, 2.0))
    assert (taus[0], taus[-1], dt0s[0], dt0s[-1]) == (1000.0, 2000.0, -5.0, 2.0)
    assert taus.size == dt0s.size == 13


def test_cli_default_grid_covers_the_tables_nominal_and_robust_box(tmp_path, capsys):
    """Judge: a table planned at tau 1600 s, dT0 -2 degC for the box 1200..2000 s x -3..-1
    degC was swept over 1800..3000 s x 0..6 degC without a word, nominal and box outside."""
    steps = _table_with_meta(
        tmp_path,
        working_lo_c=-50.0,
        working_hi_c=-30.0,
        tau_s=1600.0,
        dt0_c=-2.0,
        robust_tau_lo_s=1200.0,
        robust_tau_hi_s=2000.0,
        robust_dt0_lo_c=-3.0,
        robust_dt0_hi_c=-1.0,
    )
    assert (
        main(["sweep", str(steps), "--workers", "1", "--quiet", "--out", str(tmp_path / "d")]) == 0
    )
    text = capsys.readouterr().out
    frame = pd.read_csv(tmp_path / "d" / "sweep.csv")
    assert frame["tau_s"].min() <= 1200.0 and frame["tau_s"].max() >= 2000.0
    assert frame["dt0_c"].min() <= -3.0 and frame["dt0_c"].max() >= -1.0
    assert "grid (default)" in text and "robust box tau 1200 .. 2000 s x dT0 -3 .. -1 °C" in text
    assert "leaves out" not in text
    # a given grid that leaves them out is said to
    grid = ["--tau-s", "1800:3000:3", "--dt0-c", "0:6:3"]
    rc = main(
        ["sweep", str(steps), *grid, "--workers", "1", "--quiet", "--out", str(tmp_path / "g")]
    )
    assert rc == 0
    (note,) = [x for x in capsys.readouterr().out.splitlines() if x.startswith("note:")]
    assert "leaves out the step table's robust box" in note and "the nominal point" in note


def test_covered_box_can_be_held_to_a_mask_and_a_point():
    """The robust box check names the part around the nominal point where the device is
    within its limits too (``also``, ``containing``): the largest such box, not the
    largest overall."""
    cov = np.array(
        [
            [1.0, 1.0, 0.0, 1.0],
            [1.0, 1.0, 0.0, 1.0],
            [1.0, 1.0, 0.0, 1.0],
            [1.0, 1.0, 0.0, 1.0],
        ]
    )
    res = _result_with_coverage(cov)
    assert res.covered_box()["n_points"] == 8  # the two left columns
    right = res.covered_box(containing=(1, 3))
    assert right == {"tau_s_range": (2000.0, 2300.0), "dt0_c_range": (3.0, 3.0), "n_points": 4}
    also = np.ones(cov.shape, dtype=bool)
    also[0, :] = False  # the first tau row past a device limit
    assert res.covered_box(also=also) == {
        "tau_s_range": (2100.0, 2300.0),
        "dt0_c_range": (0.0, 1.0),
        "n_points": 6,
    }
    assert res.covered_box(also=also, containing=(0, 0)) is None


# -- an augmented model ----------------------------------------------------------------
TWO_MASS = {"tau2_s": 600.0}


def _two_mass_direct(programme, tau_s, dt0_c, tau2_s):
    """``tau2 dM/dt + M = Tk``, ``tau dT/dt + T = M + dT0`` by scipy's ODE solver, segment
    by segment (M starts at the chamber's start, T at 20 degC), on the sweep's times."""
    from scipy.integrate import solve_ivp

    from schedsyn.simulate import dense_times

    t_eval = dense_times(programme.total_min, 0.1)
    a, b = tau_s / 60.0, tau2_s / 60.0
    knots = np.concatenate([[0.0], np.cumsum(programme.durations_min)])
    state = np.array([20.0, programme.start_c])
    temp, grad = [], []
    for k in range(len(knots) - 1):
        t0, t1, rate = knots[k], knots[k + 1], programme.rates_c_per_min[k]
        tk0 = float(programme.chamber_at(np.array([t0]))[0])

        def rhs(t, y, t0=t0, tk0=tk0, rate=rate):
            tk = tk0 + rate * (t - t0)
            return [(y[1] + dt0_c - y[0]) / a, (tk - y[1]) / b]

        last = k == len(knots) - 2
        inside = t_eval[(t_eval >= t0) & ((t_eval < t1) | (last & (t_eval <= t1)))]
        sol = solve_ivp(
            rhs, (t0, t1), state, t_eval=inside, rtol=1e-11, atol=1e-11, method="DOP853"
        )
        temp.append(sol.y[0])
        grad.append((sol.y[1] + dt0_c - sol.y[0]) / a)
        state = solve_ivp(rhs, (t0, t1), state, rtol=1e-11, atol=1e-11, method="DOP853").y[:, -1]
    return np.concatenate(temp), np.concatenate(grad)


def test_sweep_through_an_augmented_model_equals_an_ode_solution(programme):
    """With a second thermal mass held at tau2 600 s, every grid point is the two-mass ODE
    at that point's tau and dT0 (scipy), not the first-order lag's; local workers (the
    chunks are pickled) give the same table."""
    from schedsyn.effects import ModelSpec

    model = ModelSpec(2400.0, 3.0, "second_time_constant", TWO_MASS)
    taus, dt0s = [1800.0, 2400.0, 3000.0], [0.0, 3.0, 6.0]
    swept = sweep_fixed(programme, REGION, taus, dt0s, model=model)
    plain = sweep_fixed(programme, REGION, taus, dt0s)
    assert not np.array_equal(swept.coverage, plain.coverage)  # the effect is not ignored
    frame = swept.to_frame().set_index(["tau_s", "dt0_c"])
    for tau, dt0 in [(2400.0, 3.0), (1800.0, 0.0), (3000.0, 6.0)]:
        temp, grad = _two_mass_direct(programme, tau, dt0, TWO_MASS["tau2_s"])
        row = frame.loc[(tau, dt0)]
        for delta, suffix in [(0.05, "0p05"), (0.1, "0p1")]:
            rep = coverage_report(temp, grad, BinGrid(*REGION), 6, delta)
            assert row[f"coverage_delta_{suffix}"] == rep.coverage
            assert row[f"min_levels_delta_{suffix}"] == rep.min_levels
        assert row["t_min_c"] == pytest.approx(temp.min(), abs=1e-6)
        assert row["t_max_c"] == pytest.approx(temp.max(), abs=1e-6)
    assert "through the model's second_time_constant (tau2_s 600)" in swept.summary()
    local = sweep_fixed(programme, REGION, taus, dt0s, model=model, backend="local", workers=2)
    pd.testing.assert_frame_equal(swept.to_frame(), local.to_frame(), check_exact=True)
    with pytest.raises(ParameterError, match="ModelSpec"):
        sweep_fixed(programme, REGION, taus, dt0s, model={"tau2_s": 600.0})


def test_cli_sweeps_the_model_the_table_records_or_the_file_given(tmp_path, capsys, programme):
    """A table planned with ``plan --model`` records the model: sweep holds its effect
    (it used to sweep the first-order lag alone); ``--model`` gives one, whose base is
    then the nominal point; a nonlinear one cannot be re-planned (one line, exit 2)."""
    import json

    from schedsyn.effects import ModelSpec
    from schedsyn.models_io import write_model

    model = ModelSpec(2600.0, 2.0, "second_time_constant", TWO_MASS)
    steps = _table_with_meta(
        tmp_path,
        working_lo_c=-50.0,
        working_hi_c=-30.0,
        tau_s=2600.0,
        dt0_c=2.0,
        model=json.dumps(model.to_json_dict()),
    )
    grid = ["--tau-s", "2000:2800:3", "--dt0-c", "0:6:3", "--workers", "1", "--quiet"]
    assert main(["sweep", str(steps), *grid, "--out", str(tmp_path / "t")]) == 0
    text = capsys.readouterr().out
    assert "model (from the step table): effect second_time_constant tau2_s 600" in text
    want = sweep_fixed(programme, REGION, [2000.0, 2400.0, 2800.0], [0.0, 3.0, 6.0], model=model)
    got = pd.read_csv(tmp_path / "t" / "sweep.csv")
    np.testing.assert_array_equal(got["coverage"], want.to_frame()["coverage"])
    np.testing.assert_array_equal(got["min_levels"], want.to_frame()["min_levels"])

    path = write_model(tmp_path / "m.json", replace_model(model, tau_s=2200.0, dt0_c=4.0))
    args = ["sweep", STEPS, "--region", "-50", "-30", *grid, "--model", str(path)]
    assert main([*args, "--out", str(tmp_path / "f")]) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines() if x.startswith("at the nominal")]
    assert "(tau 2200 s, dT0 4 °C)" in line and f"from {path}" in line

    limited = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.8, "max_heat_rate_c_per_min": 10.0},
    )
    path = write_model(tmp_path / "rl.json", limited)
    rc = main(["sweep", "--replan", "--region", "-50", "-30", *grid, "--model", str(path)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "not linear" in err and "leave out --replan" in err


def replace_model(model, **changes):
    from dataclasses import replace

    return replace(model, **changes)


def test_replan_adapter_plans_with_a_linear_augmented_model(monkeypatch):
    from schedsyn import Limits
    from schedsyn.cli.sweep import PlanAtPoint
    from schedsyn.effects import ModelSpec

    planner = pytest.importorskip("schedsyn.planner")
    seen = {}

    def stub(spec, params, limits, model=None):
        seen.update(params=params, limits=limits, model=model)
        return _FakePlan(params.tau_s, params.dt0_c)

    monkeypatch.setattr(planner, "plan_experiment", stub)
    fn = PlanAtPoint(
        (-50.0, -30.0),
        (-52.0, -20.0),
        6,
        0.05,
        Limits(),
        ModelSpec(2400.0, 3.0, "second_time_constant", TWO_MASS),
    )
    fn(ThermalParams(tau_s=2100.0, dt0_c=1.0))
    want = ModelSpec(2100.0, 1.0, "second_time_constant", TWO_MASS).linear_model()
    assert seen["model"] == want and seen["model"].tau2_s == 600.0
    assert seen["params"] == ThermalParams(tau_s=2100.0, dt0_c=1.0)


def test_an_asymmetric_tau_is_scaled_with_the_grids_tau(programme):
    """``asymmetric_tau`` ignores the base tau: the sweep scales its heating and cooling
    taus by tau / the model's own tau, so the model's own point is the model itself and
    the other points are the ODE with scaled taus (scipy, switching on the sign of
    ``Tk + dT0 - T``); along tau the coverage changes."""
    from scipy.integrate import solve_ivp

    from schedsyn.effects import ModelSpec
    from schedsyn.simulate import dense_times

    heat_s, cool_s = 2000.0, 3000.0
    model = ModelSpec(2400.0, 3.0, "asymmetric_tau", {"tau_heat_s": heat_s, "tau_cool_s": cool_s})
    taus = [1800.0, 2400.0, 3000.0]
    swept = sweep_fixed(programme, REGION, taus, [3.0], model=model)
    t_eval = dense_times(programme.total_min, 0.1)
    for i, tau in enumerate(taus):
        a, b = heat_s * tau / 2400.0 / 60.0, cool_s * tau / 2400.0 / 60.0

        def rhs(t, y, a=a, b=b):
            v = float(programme.chamber_at(np.array([t]))[0]) + 3.0
            return [(v - y[0]) / (a if v > y[0] else b)]

        sol = solve_ivp(rhs, (0.0, t_eval[-1]), [20.0], t_eval=t_eval, max_step=0.05, rtol=1e-9)
        temp = sol.y[0]
        v = programme.chamber_at(t_eval) + 3.0
        grad = (v - temp) / np.where(v > temp, a, b)
        rep = coverage_report(temp, grad, BinGrid(*REGION), 6, 0.05)
        assert abs(swept.coverage[i, 0, 0] - rep.coverage) <= 0.05 + 1e-12, (tau, rep.coverage)
        assert abs(swept.min_levels[i, 0, 0] - rep.min_levels) <= 1
        assert swept.t_min_c[i, 0] == pytest.approx(temp.min(), abs=0.01)
    own = model.predict(programme, t_eval)
    rep = coverage_report(own.t_c, own.g_c_per_min, BinGrid(*REGION), 6, 0.05)
    assert swept.coverage[1, 0, 0] == rep.coverage and swept.min_levels[1, 0, 0] == rep.min_levels
    assert len(set(swept.t_min_c[:, 0].round(3))) == 3  # tau moves the run
    assert "scaled with each point's tau" in swept.summary()
