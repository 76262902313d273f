"""The synthetic gyro: polynomial, noise statistics, TOML files, random gyros, its log and
`schedsyn simulate --gyro`."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from schedsyn.cli import main
from schedsyn.errors import ParameterError
from schedsyn.gyro import Gyro, drift_noise, gyro_from_dict, gyro_log, load_gyro, random_gyro
from schedsyn.logs import read_log
from schedsyn.params import ThermalParams
from schedsyn.programme import read_steps
from schedsyn.terms import EXPONENTS, TERMS

BASELINE = "data/baseline_exp1_steps.csv"


def test_drift_polynomial_by_hand():
    gyro = Gyro({"1": 0.5, "t": -0.02, "g": 0.7, "t2g": 1e-3, "g3": -0.1}, t_ref_c=-36.0)
    t, g = np.array([-50.0, -20.0]), np.array([0.4, -0.6])
    dt = t + 36.0
    want = 0.5 - 0.02 * dt + 0.7 * g + 1e-3 * dt**2 * g - 0.1 * g**3
    np.testing.assert_allclose(gyro.drift_dph(t, g), want, rtol=1e-12)
    assert gyro.has_gradient_terms
    assert not Gyro({"1": 1.0, "t3": 1e-5}).has_gradient_terms


def test_noise_statistics(rng):
    """White noise: std N/sqrt(h) per row; walk: increments of std K sqrt(h / 1 h)."""
    gyro = Gyro({}, white_noise_dph_per_rt_hz=0.3, bias_walk_dph_per_rt_h=0.02)
    h = 10.0
    t = h * np.arange(200_001)
    white, walk = drift_noise(t, gyro, rng)
    assert white.std() == pytest.approx(0.3 / math.sqrt(h), rel=0.01)
    assert np.diff(walk).std() == pytest.approx(0.02 * math.sqrt(h / 3600.0), rel=0.01)
    assert walk[0] == 0.0
    # after one hour the walk has wandered by K (one sigma), over many hours
    per_hour = walk[:: int(3600 / h)]
    assert np.diff(per_hour).std() == pytest.approx(0.02, rel=0.05)


def test_toml_round_trip(tmp_path, rng):
    gyro = random_gyro(rng, (-52.0, -20.0), name='FOG "A"')
    path = tmp_path / "gyro.toml"
    path.write_text(gyro.to_toml())
    back = load_gyro(path)
    assert back == gyro


@pytest.mark.parametrize(
    "doc, words",
    [
        ({}, "no [gyro] table"),
        ({"drift_dph": {"t4": 1.0}}, "unknown drift term(s) t4"),
        ({"white_noise_dph_per_rt_hz": -1.0}, "white_noise_dph_per_rt_hz must be >= 0"),
        ({"t_ref_c": "warm"}, "t_ref_c must be a number"),
        ({"bias": 1.0}, "unknown key(s) ['bias']"),
        # a missing key would silently take a default (t_ref 20 degC, no noise, no drift)
        ({"t_ref_c": None}, "[gyro] lacks t_ref_c; give each"),
        ({"white_noise_dph_per_rt_hz": None, "bias_walk_dph_per_rt_h": None},
         "lacks white_noise_dph_per_rt_hz, bias_walk_dph_per_rt_h"),
        ({"drift_dph": None}, "no [gyro.drift_dph] table"),
    ],
)  # fmt: skip
def test_bad_gyro_files_name_the_problem(doc, words):
    """Each change to a good [gyro] table (None: the key left out) is refused in one line
    naming the key."""
    good = {
        "t_ref_c": 20.0,
        "white_noise_dph_per_rt_hz": 0.3,
        "bias_walk_dph_per_rt_h": 0.0,
        "drift_dph": {"1": 0.5},
    }
    assert gyro_from_dict({"gyro": good}, "g.toml").coefficients_dph["1"] == 0.5
    table = {k: v for k, v in {**good, **doc}.items() if v is not None}
    with pytest.raises(ParameterError) as exc:
        gyro_from_dict({"gyro": table} if doc else {}, "g.toml")
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_a_misspelt_gyro_table_is_named():
    """Red team: [gyros] for [gyro] was told "no [gyro] table" without the table it saw."""
    with pytest.raises(ParameterError, match=r"\[gyros\]: did you mean \[gyro\]"):
        gyro_from_dict({"gyros": {"t_ref_c": 20.0}}, "g.toml")
    with pytest.raises(ParameterError, match=r"its tables: \[limits\]"):
        gyro_from_dict({"limits": {"a": 1}}, "g.toml")
    # [gyros] beside [gyro.drift_dph]: the keys are under the misspelt table
    doc = {"gyros": {"t_ref_c": 20.0}, "gyro": {"drift_dph": {"1": 0.1}}}
    with pytest.raises(ParameterError, match=r"under \[gyros\]: did you mean \[gyro\]"):
        gyro_from_dict(doc, "g.toml")


def test_random_gyros(rng):
    with_g = random_gyro(np.random.default_rng(1), (30.0, 60.0))
    without = random_gyro(np.random.default_rng(1), (30.0, 60.0), gradient_terms=False)
    assert with_g.has_gradient_terms and not without.has_gradient_terms
    assert with_g.t_ref_c == 45.0
    # same seed, same T-only part
    for t in TERMS:
        if EXPONENTS[t][1] == 0:
            assert with_g.coefficients_dph[t] == without.coefficients_dph[t]
    assert random_gyro(np.random.default_rng(1), (30.0, 60.0)) == with_g
    # the main gradient sensitivity lies in its documented range
    g = [
        abs(random_gyro(np.random.default_rng(s), (0, 30)).coefficients_dph["g"]) for s in range(50)
    ]
    assert 0.3 <= min(g) and max(g) <= 1.0


def test_log_is_the_polynomial_at_the_true_state_plus_noise():
    prog = read_steps(BASELINE)
    params = ThermalParams(2600.0, 2.0)
    gyro = Gyro({"1": 0.2, "t": 0.01, "g": 0.5, "tg2": 0.01}, t_ref_c=-36.0,
                white_noise_dph_per_rt_hz=0.2, bias_walk_dph_per_rt_h=0.01)  # fmt: skip
    f = gyro_log(prog, gyro, params, sample_s=10.0, seed=3)
    assert list(f.columns) == [
        "time_s", "t_int_c", "tk_set_c", "tk_air_c", "drift_dph",
        "t_true_c", "g_true_c_per_min", "drift_true_dph", "bias_walk_dph",
    ]  # fmt: skip
    # the true temperature: an independent ODE solution of tau dT/dt + T = Tk + dT0
    tau = params.tau_s / 60.0
    sol = solve_ivp(
        lambda t, y: [(prog.chamber_at(t) + params.dt0_c - y[0]) / tau],
        (0.0, prog.total_min),
        [20.0],
        t_eval=f["time_s"].to_numpy() / 60.0,
        rtol=1e-9,
        atol=1e-9,
        max_step=1.0,
    )
    np.testing.assert_allclose(f["t_true_c"], sol.y[0], atol=1e-4)
    np.testing.assert_allclose(
        f["drift_true_dph"], gyro.drift_dph(f["t_true_c"], f["g_true_c_per_min"]), rtol=1e-12
    )
    noise = f["drift_dph"] - f["drift_true_dph"] - f["bias_walk_dph"]
    assert noise.std() == pytest.approx(0.2 / math.sqrt(10.0), rel=0.05)
    assert abs(noise.mean()) < 5 * 0.2 / math.sqrt(10.0) / math.sqrt(len(f))
    # the sensor: the gyro's resolution
    q = f["t_int_c"].to_numpy() / gyro.sensor_quant_c
    np.testing.assert_allclose(q, np.round(q), atol=1e-6)
    # reproducible, and the drift noise independent of the sensor's
    again = gyro_log(prog, gyro, params, sample_s=10.0, seed=3)
    pd.testing.assert_frame_equal(f, again)
    assert abs(np.corrcoef(noise, f["t_int_c"] - f["t_true_c"])[0, 1]) < 0.1


def test_simulate_writes_a_gyro_log(tmp_path, capsys):
    gyro_path = tmp_path / "gyro.toml"
    gyro_path.write_text(random_gyro(np.random.default_rng(2), (-52.0, -20.0)).to_toml())
    log_path = tmp_path / "log.csv"
    rc = main(["simulate", BASELINE, "--region", "-50", "-30", "--gyro", str(gyro_path),
               "--log-out", str(log_path), "--log-sample-s", "30",
               "--out", str(tmp_path / "sim")])  # fmt: skip
    assert rc == 0
    text = capsys.readouterr().out
    assert "gyro log" in text and "drift-fit design" in text and "I-efficiency" in text
    assert "predicted drift-fit error (full model, white noise" in text
    log = read_log(log_path)
    assert log.drift_dph is not None and np.isfinite(log.drift_dph).all()
    assert np.allclose(np.diff(log.time_s), 30.0)
    assert (tmp_path / "sim" / "design.csv").stat().st_size > 0
    # --log-out without --gyro, and a bad gyro file: one line, exit 2
    args = ["simulate", BASELINE, "--region", "-50", "-30", "--log-out", str(tmp_path / "x.csv")]
    assert main([*args, "--out", str(tmp_path / "sim")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--gyro" in err
    bad = tmp_path / "bad.toml"
    bad.write_text(
        "[gyro]\nt_ref_c = 20\nbias_walk_dph_per_rt_h = 0\nwhite_noise_dph_per_rt_hz = -2\n"
        "[gyro.drift_dph]\n"
    )
    assert (
        main(
            [
                "simulate",
                BASELINE,
                "--region",
                "-50",
                "-30",
                "--gyro",
                str(bad),
                "--out",
                str(tmp_path / "s2"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "white_noise_dph_per_rt_hz" in err and str(bad) in err


def test_example_gyro_file_loads():
    gyro = load_gyro("data/example_gyro.toml")
    assert gyro.has_gradient_terms and gyro.t_ref_c == -36.0
    assert gyro.coefficients_dph["g"] == 0.6
