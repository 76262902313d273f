import pandas as pd

from schedsyn.cli import main


def test_simulate_writes_outputs(tmp_path, capsys):
    out = tmp_path / "o"
    rc = main(
        ["simulate", "data/baseline_exp1_steps.csv", "--region", "-50", "-30", "--out", str(out)]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "coverage of [-50, -30]" in text
    assert "degC" not in text  # one spelling of units: °C
    for name in ("trajectory.csv", "coverage.csv", "program.png", "phase.png", "coverage.png"):
        assert (out / name).stat().st_size > 0
    traj = pd.read_csv(out / "trajectory.csv")
    assert list(traj.columns) == ["time_min", "tk_c", "t_c", "g_c_per_min"]
    assert (
        traj["time_min"].iloc[1] - traj["time_min"].iloc[0] == 0.1
        or abs(traj["time_min"].iloc[1] - 0.1) < 1e-12
    )


def test_bad_input_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("step,start_min\n1,0\n")
    assert main(["simulate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing column" in err
    assert main(["simulate", str(tmp_path / "nope.csv")]) == 2


def test_output_never_overwrites_input(tmp_path, capsys):
    import shutil

    src = tmp_path / "trajectory.csv"
    shutil.copy("data/baseline_exp1_steps.csv", src)
    before = src.read_bytes()
    assert main(["simulate", str(src), "--region", "-50", "-30", "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert src.read_bytes() == before
    # refused before anything was written: no other output, no staging folder left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trajectory.csv"]


def test_import_does_not_load_matplotlib():
    import subprocess
    import sys

    code = "import sys, schedsyn; print('matplotlib' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "False"


def test_outputs_get_normal_permissions(tmp_path):
    import os

    from schedsyn.io import write_text_atomic

    umask = os.umask(0o022)
    try:
        out = write_text_atomic(tmp_path / "x.txt", "hello")
    finally:
        os.umask(umask)
    assert out.read_text() == "hello"
    assert (out.stat().st_mode & 0o777) == 0o644
    assert not list(tmp_path.glob(".x.txt.*"))  # no temporary file left behind


def test_a_table_without_a_region_is_refused_not_guessed(tmp_path, capsys):
    """The issue: W3's table simulated over W1's default region printed 0 % and exit 0."""
    out = tmp_path / "o"
    assert main(["simulate", "data/baseline_exp1_steps.csv", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "carries no working region; give --region LO HI" in err
    assert not out.exists()


def test_region_model_and_levels_come_from_the_table(tmp_path, capsys):
    import numpy as np

    from schedsyn import Programme, ThermalParams, simulate, trajectory_coverage
    from schedsyn.programme import StepTableMeta

    meta = StepTableMeta(
        experiment="W3x",
        working_lo_c=-5.0,
        working_hi_c=5.0,
        tau_s=1800.0,
        dt0_c=1.0,
        levels_required=2,
        delta_c_per_min=0.1,
    )
    prog = Programme([40, 20, 40, 40, 40], [-1.0, 0.0, 0.5, -0.5, 0.5], meta=meta)
    steps = prog.to_csv(tmp_path / "w3.csv")
    out = tmp_path / "o"
    assert main(["simulate", str(steps), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "tau 1800 s, dT0 1 °C (from the step table)" in text
    assert "working region: [-5, 5] °C (from the step table)" in text
    # the same numbers, computed here independently of the command
    traj = simulate(Programme(prog.durations_min, prog.rates_c_per_min), ThermalParams(1800, 1))
    rep = trajectory_coverage(traj, -5, 5, levels_required=2, delta_c_per_min=0.1)
    assert f"coverage of [-5, 5] °C: {rep.coverage:.1%}" in text
    written = pd.read_csv(out / "trajectory.csv")
    np.testing.assert_allclose(written["t_c"], traj.t_c, atol=1e-9)
    # options still win over the table
    assert (
        main(["simulate", str(steps), "--tau-s", "2400", "--region", "-10", "0", "--out", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    assert "tau 2400 s, dT0 1 °C (from the step table and the options)" in text
    assert "coverage of [-10, 0] °C" in text


def test_a_robust_table_says_it_is_simulated_at_its_nominal_point(tmp_path, capsys):
    from schedsyn import Programme
    from schedsyn.programme import StepTableMeta

    meta = StepTableMeta(
        working_lo_c=-5.0,
        working_hi_c=5.0,
        tau_s=2400.0,
        dt0_c=3.0,
        robust_tau_lo_s=2200.0,
        robust_tau_hi_s=2600.0,
        robust_dt0_lo_c=2.0,
        robust_dt0_hi_c=4.0,
    )
    steps = Programme([40, 40], [-1.0, 1.0], meta=meta).to_csv(tmp_path / "r.csv")
    assert main(["simulate", str(steps), "--out", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert "robust box tau 2200 .. 2600 s x dT0 2 .. 4 °C; this is its nominal point" in text
