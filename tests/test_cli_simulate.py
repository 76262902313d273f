import pandas as pd

from schedsyn.cli import main


def test_simulate_writes_outputs(tmp_path, capsys):
    out = tmp_path / "o"
    rc = main(["simulate", "data/baseline_exp1_steps.csv", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "coverage of [-50, -30]" in text
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
    assert main(["simulate", str(src), "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert src.read_bytes() == before


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
