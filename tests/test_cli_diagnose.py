"""`schedsyn diagnose` in-process: JSON on stdout, model file that `simulate --model` takes."""

import json

import pandas as pd
import pytest

from schedsyn.cli import main
from schedsyn.effects import ModelSpec
from schedsyn.models_io import load_model
from schedsyn.synth import blind_programmes, synth_effect_log


def _no_nan(name):
    raise AssertionError(f"non-standard JSON constant {name} in the output")


@pytest.fixture(scope="module")
def rate_limited_log(tmp_path_factory):
    prog = blind_programmes()["cold"]
    truth = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.6, "max_heat_rate_c_per_min": 20.0},
    )
    frame = synth_effect_log(prog, truth, sample_s=10.0, noise_c=0.02, seed=4, with_air=False)
    path = tmp_path_factory.mktemp("log") / "run.csv"
    frame.drop(columns=["t_true_c", "g_true_c_per_min"]).to_csv(path, index=False)
    steps = tmp_path_factory.mktemp("steps") / "steps.csv"
    prog.to_csv(steps)
    return path, steps


def test_diagnose_json_model_file_and_simulate(rate_limited_log, tmp_path, capsys):
    log, steps = rate_limited_log
    out = tmp_path / "diag"
    rc = main(["diagnose", str(log), "--json", "--out", str(out), "--fit-step-s", "60"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    js = json.loads(captured.out, parse_constant=_no_nan)  # one strict JSON object
    assert js["effect"] == "chamber_rate_limit"
    assert js["parameters"]["max_cool_rate_c_per_min"] == pytest.approx(0.6, rel=0.05)
    assert js["parameters"]["max_heat_rate_c_per_min"] == 1e6  # never binding: no limit
    # ... and not "not determined by this log" either (its missing standard error is on
    # purpose)
    assert not [w for w in js["warnings"] if "not determined" in w], js["warnings"]
    assert js["rms_after_c"] < 0.5 * js["rms_before_c"]
    assert {c["effect"] for c in js["candidates"]} >= {"chamber_lag", "asymmetric_tau"}
    for name in (
        "model.json",
        "diagnosis.json",
        "candidates.csv",
        "residuals.png",
        "phase.png",
        "residual_segments.csv",
        "residual_by_temperature.csv",
    ):
        assert (out / name).is_file(), name
    model = load_model(out / "model.json")
    assert model.effect == "chamber_rate_limit"
    assert model.planner_limits().rate_min_c_per_min == pytest.approx(-0.6, rel=0.05)
    # simulate with the augmented model: the trajectory matches the measured log
    sim = tmp_path / "sim"
    assert (
        main(
            [
                "simulate",
                str(steps),
                "--model",
                str(out / "model.json"),
                "--out",
                str(sim),
                "--dt-min",
                "1",
                "--region",
                "-10",
                "0",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "effect chamber_rate_limit" in text
    assert "outside the chamber limits" in text  # the plan ramps faster than the chamber can
    traj = pd.read_csv(sim / "trajectory.csv")
    logged = pd.read_csv(log)
    measured = logged.set_index("time_s")["t_int_c"].reindex(traj["time_min"] * 60.0)
    gap = traj["t_c"].to_numpy() - measured.to_numpy()
    assert abs(gap).max() < 0.15


def test_diagnose_bad_log_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"time_s": [0.0, 10.0, 20.0], "t_int_c": [20.0, 20.1, 20.2]}).to_csv(
        bad, index=False
    )
    assert main(["diagnose", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("schedsyn diagnose: error:") and "Traceback" not in err


def test_simulate_rejects_a_bad_model_file(rate_limited_log, tmp_path, capsys):
    _, steps = rate_limited_log
    model = tmp_path / "m.json"
    model.write_text(json.dumps({"tau_s": 2400, "dt0_c": 3, "effect": "gremlins"}))
    argv = ["simulate", str(steps), "--model", str(model), "--region", "-10", "0"]
    assert main([*argv, "--out", str(tmp_path)]) == 2
    assert "unknown effect" in capsys.readouterr().err
