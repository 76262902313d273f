"""The diagnosis workflow: blind on logs with hidden effects, and its parts on their own.

The blind run draws 5 logs per effect (and 10 without one; each of the three
programmes -- the two blind ones and the paper-like baseline -- at least once) from
realistic parameter ranges (schedsyn.synth.blind_case), diagnoses each without knowing
the truth and asks more of each log than the issue does: every log named right with its
main parameter within 25 % (the issue: 9 of 10), every clean log called clean (the
issue: 19 of 20). To fit the test budget it samples every 10 s and fits on 60 s blocks;
scripts/bench_diagnose.py tabulates a blind run of the issue's size (10 logs per effect,
20 clean, its own seeds) with 1-10 s sampling and the default fit step (a table to read,
not a check that fails).
"""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from independent import ode_trajectories

from schedsyn import Programme, discrepancy, read_steps
from schedsyn.discrepancy import (
    DiagnoseSettings,
    analyse_residuals,
    diagnose,
    diagnose_frame,
    setpoint_programme,
)
from schedsyn.effects import EFFECTS, ModelSpec
from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.logs import log_from_frame
from schedsyn.synth import blind_case, blind_programmes, synth_effect_log

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = DiagnoseSettings(fit_step_s=60.0)
N_PER_EFFECT, N_CLEAN = 5, 10


def _programmes():
    progs = dict(blind_programmes())
    progs["exp1"] = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    return progs


def _main_error(effect, truth, found):
    if effect == "asymmetric_tau":  # the asymmetry itself, not the (easy) mean
        t = truth["tau_cool_s"] / truth["tau_heat_s"] - 1.0
        f = found["tau_cool_s"] / found["tau_heat_s"] - 1.0
        return abs(f - t) / abs(t)
    name = EFFECTS[effect].main_param
    key = name if name in found else next(iter(found))  # twin: tau2_s for tau_chamber_s
    return abs(found[key] - truth[name]) / abs(truth[name])


def _run(job):
    effect, seed = job
    progs = _programmes()
    names = sorted(progs)
    frame, truth, noise = blind_case(
        effect, 7919 * (seed + 1) + len(effect), progs[names[seed % len(names)]], sample_s=10.0
    )
    d = diagnose_frame(frame, SETTINGS)
    correct = d.effect == effect or (effect != "none" and effect in d.ambiguous_with)
    return {
        "truth": effect,
        "seed": seed,
        "found": d.effect,
        "correct": correct,
        "err": _main_error(effect, truth.parameters, d.parameters)
        if correct and effect != "none"
        else math.nan,
        "before": d.rms_before_c,
        "after": d.rms_after_c,
        "noise": noise,
        "found_params": dict(d.parameters),
        "truth_params": dict(truth.parameters),
        "ambiguous_with": d.ambiguous_with,
        "has_air": d.has_air,
    }


def _blind_rows(effect: str) -> pd.DataFrame:
    """The blind run's logs with this hidden effect ("none": clean ones), each diagnosed
    without knowing the truth. Each test draws and diagnoses only its own effect's logs
    (fixed seeds), so pytest-xdist spreads them over its workers instead of one worker, with
    a process pool of its own, doing all of them before the first test."""
    n = N_CLEAN if effect == "none" else N_PER_EFFECT
    return pd.DataFrame([_run((effect, seed)) for seed in range(n)])


@pytest.mark.slow
@pytest.mark.parametrize("effect", list(EFFECTS))
def test_blind_names_effect_and_parameter(effect):
    rows = _blind_rows(effect)
    assert (rows["truth"] == effect).all() and len(rows) == N_PER_EFFECT
    good = rows[rows["correct"] & (rows["err"] <= 0.25)]
    detail = rows[["found", "err", "before", "after", "truth_params", "found_params"]]
    # named right AND main parameter within 25 % in every log (the issue: 9 of 10; this
    # test's own 10 logs per effect, before it was halved for time: every log named right,
    # main parameters within 7.3 %)
    assert len(good) == N_PER_EFFECT, detail.to_string()
    # where the effect is material (gap well above the noise) the gap at least halves
    material = rows[rows["before"] > 3 * rows["noise"]]
    assert (material["after"] <= 0.5 * material["before"]).all(), detail.to_string()
    if effect == "chamber_cycling":  # amplitude and period reported
        for _, r in good.iterrows():
            assert r["found_params"]["period_s"] == pytest.approx(
                r["truth_params"]["period_s"], rel=0.25
            )


@pytest.mark.slow
def test_blind_says_none_on_clean_logs():
    rows = _blind_rows("none")
    assert (rows["truth"] == "none").all() and len(rows) == N_CLEAN
    # every clean log called clean (the issue: 19 of 20; 20 of 20 before halving)
    assert (rows["found"] == "none").all(), rows[["found", "before"]].to_string()


def _lag_log(with_air, seed=3):
    prog = blind_programmes()["cold"]
    truth = ModelSpec(2400.0, 3.0, "chamber_lag", {"tau_chamber_s": 400.0})
    return synth_effect_log(prog, truth, sample_s=10.0, noise_c=0.02, seed=seed, with_air=with_air)


def test_lag_vs_second_mass_needs_the_air_channel():
    without = diagnose_frame(_lag_log(False), SETTINGS)
    assert without.effect == "second_time_constant"
    assert "chamber_lag" in without.ambiguous_with
    assert any("cannot be told apart" in w for w in without.warnings)
    assert without.parameters["tau2_s"] == pytest.approx(400.0, rel=0.05)
    # a sensor lagging the device reads the same (red team: named without a word)
    lag = f"lags the device by {without.parameters['tau2_s']:.0f} s"
    assert any(lag in w and "--sensor-tau-s" in w for w in without.warnings), without.warnings
    with_air = diagnose_frame(_lag_log(True), SETTINGS)
    assert with_air.effect == "chamber_lag"
    assert "second_time_constant" not in with_air.ambiguous_with
    # the air channel shows the lag: not a sensor's
    assert not any("lags the device" in w for w in with_air.warnings), with_air.warnings
    assert with_air.parameters["tau_chamber_s"] == pytest.approx(400.0, rel=0.05)
    # held out: fitted on the first 70 %, the augmented model predicts the rest better
    assert with_air.holdout_rms_after_c < 0.5 * with_air.holdout_rms_before_c
    # the augmented model reproduces the measured log through the public simulator path
    js = with_air.to_json_dict()
    assert js["effect"] == "chamber_lag"
    assert js["rms_after_c"] < js["rms_before_c"]


def test_json_schema_and_frame():
    d = diagnose_frame(_lag_log(True, seed=5), SETTINGS)
    js = json.loads(json.dumps(d.to_json_dict()))
    assert isinstance(js["effect"], str) and isinstance(js["parameters"], dict)
    assert isinstance(js["rms_before_c"], float) and isinstance(js["rms_after_c"], float)
    assert len(js["candidates"]) == len(EFFECTS)
    for c in js["candidates"]:
        assert set(c) >= {"effect", "score", "rms_c", "parameters"}
        assert isinstance(c["score"], float)
    scores = [c["score"] for c in js["candidates"]]
    assert scores == sorted(scores)  # ranked
    frame = d.to_frame()
    assert frame["effect"].iloc[0] == "none" and frame["chosen"].sum() == 1
    assert set(js["uncertainty"]) >= set(js["parameters"])
    # the chosen model written to a file simulates to the reported after-RMS
    model = ModelSpec.from_json_dict(js["model"])
    t = d.time_min
    prog = setpoint_programme(d.time_min * 60.0, _lag_log(True, seed=5)["tk_set_c"].to_numpy())
    pred = model.predict(prog, t, t0_c=d.candidates[0].t0_c)
    assert math.sqrt(np.mean((pred.t_c - d.measured_c) ** 2)) == pytest.approx(
        d.rms_after_c, rel=1e-6
    )


def test_setpoint_reconstruction_recovers_breakpoints():
    prog = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    t = np.arange(0.0, prog.total_min * 60.0 + 1, 7.0)
    sp = np.round(prog.chamber_at(t / 60.0), 2)  # a setpoint logged to 0.01 degC
    rec = setpoint_programme(t, sp, tol_c=0.05)
    dense = np.linspace(0, t[-1] / 60.0, 5000)
    assert np.max(np.abs(rec.chamber_at(dense) - prog.chamber_at(dense))) < 0.15
    assert rec.n_segments <= 2 * prog.n_segments


#: a chamber programme whose rate changes fall between the 10-s samples of its log:
#: ramps and holds, minutes (durations) and degC/min (rates), from 20 degC
OFF_GRID = (
    (47.37, 2.1),
    (61.83, 0.0),
    (52.29, -0.83),
    (75.11, 0.0),
    (33.53, 1.37),
    (58.71, 0.0),
    (41.17, -1.0),
    (49.93, 0.0),
)


def _off_grid_log(noise_c: float, seed: int = 3) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """A clean 10-s log of OFF_GRID (first-order lag, default model; scipy's ODE
    solver), with the programme's knots (min, degC)."""
    dur = np.array([d for d, _ in OFF_GRID])
    rate = np.array([r for _, r in OFF_GRID])
    knots_t = np.concatenate(([0.0], np.cumsum(dur)))
    knots_tk = 20.0 + np.concatenate(([0.0], np.cumsum(dur * rate)))
    t_min, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=10.0 / 60.0)
    rng = np.random.default_rng(seed)
    frame = pd.DataFrame(
        {
            "time_s": np.round(t_min * 60.0, 6),
            "t_int_c": temp[0] + noise_c * rng.standard_normal(t_min.size),
            "tk_set_c": np.round(np.interp(t_min, knots_t, knots_tk), 4),
        }
    )
    return frame, knots_t, knots_tk


def test_a_setpoint_that_changes_rate_between_samples_is_rebuilt_with_flat_holds():
    """Corners off the sample grid: the rebuilt setpoint is the programme, segment for
    segment, to well below the sensor noise, also within a sample of a corner
    (Douglas-Peucker alone put the corners on samples and made the holds slow ramps up
    to 0.05 degC off, which the diagnosis read as a device effect; a corner it bracketed
    with breakpoints on both neighbouring samples was cut, 0.06 degC off, until the
    one-step segment was replaced by its neighbours' crossing)."""
    frame, knots_t, knots_tk = _off_grid_log(0.0)
    rec = setpoint_programme(frame["time_s"].to_numpy(), frame["tk_set_c"].to_numpy())
    dense = np.linspace(0.0, knots_t[-1] - 1e-6, 20001)
    err = np.abs(rec.chamber_at(dense) - np.interp(dense, knots_t, knots_tk))
    assert np.max(err) < 2e-3
    assert rec.n_segments == len(OFF_GRID)


def test_a_clean_log_with_rate_changes_between_samples_names_no_effect():
    """The false alarms the setpoint's sampled corners caused (self-heating slopes and
    second time constants on clean 10-s logs) are gone."""
    frame, _, _ = _off_grid_log(0.005)
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect == "none", (d.effect, d.parameters)


def _rate_limited_log(
    cool_c_per_min: float,
    heat_c_per_min: float,
    air: bool,
    knots_min: tuple[float, ...] = (0, 60, 100, 136, 196, 246, 300),
    knots_c: tuple[float, ...] = (20, -40, -40, 50, 50, 0, 0),
    tau_s: float = 2400.0,
    dt0_c: float = 3.0,
) -> pd.DataFrame:
    """A 10-s log of a chamber that cannot follow its setpoint faster than the given
    rates (its air a 5-s lag of the setpoint, clipped to them) driving the default
    device; scipy's ODE solver, not the package's model."""
    from scipy.integrate import solve_ivp

    knots_s = np.asarray(knots_min, dtype=float) * 60.0
    rc, rh = cool_c_per_min / 60.0, heat_c_per_min / 60.0

    def rhs(t, y):
        setpoint = np.interp(t, knots_s, knots_c)
        return [np.clip((setpoint - y[0]) / 5.0, -rc, rh), (y[0] + dt0_c - y[1]) / tau_s]

    t = np.arange(0.0, knots_s[-1] + 1e-9, 10.0)
    start = [knots_c[0], knots_c[0] + dt0_c]
    sol = solve_ivp(rhs, (0.0, t[-1]), start, t_eval=t, max_step=5.0, rtol=1e-8)
    rng = np.random.default_rng(3)
    frame = pd.DataFrame(
        {
            "time_s": t,
            "t_int_c": sol.y[1] + 0.02 * rng.standard_normal(t.size),
            "tk_set_c": np.interp(t, knots_s, knots_c),
        }
    )
    if air:
        frame["tk_air_c"] = sol.y[0] + 0.05 * rng.standard_normal(t.size)
    return frame


@pytest.mark.parametrize("air", [True, False])
def test_a_chamber_limited_both_ways_is_found_with_both_limits(air):
    """Cooling held to 0.5 and heating to 1.0 degC/min under a programme of -1 and +2.5:
    both limits found, the gap closed to the noise. A start grid scored with the base
    fit's device (tau and dT0 bent to absorb the limits) found a chamber lag of 1855 s
    with the air logged, and a heating limit of 'none' on other logs."""
    d = diagnose_frame(_rate_limited_log(0.5, 1.0, air), SETTINGS)
    assert d.effect == "chamber_rate_limit", (d.effect, d.parameters)
    assert d.parameters["max_cool_rate_c_per_min"] == pytest.approx(0.5, rel=0.05)
    assert d.parameters["max_heat_rate_c_per_min"] == pytest.approx(1.0, rel=0.05)
    assert d.rms_after_c < 0.03


def test_a_rate_limited_chamber_under_setpoint_steps_is_one_air_finding_in_plain_numbers():
    """Judge, session 52: setpoint steps (-40 and +50 degC jumps) on a chamber held to 1.5
    / 3 degC/min. The air was also said to lag by 1098 s (its air gap 4 degC against the
    rate limit's 0.02: a shadow), and a lag's sentence took a step for the fastest ramp
    ("a 3e+02 degC/min ramp runs 3e+03 degC behind")."""
    frame = _rate_limited_log(
        1.5, 3.0, True, knots_min=(0, 60, 60, 240, 240, 420, 420, 540),
        knots_c=(20, 20, -40, -40, 50, 50, 20, 20),
    )  # fmt: skip
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect == "chamber_rate_limit"
    assert [f.effect for f in d.air_findings] == ["chamber_rate_limit"], [
        f.text for f in d.air_findings
    ]
    assert discrepancy._fastest_ramp_c_per_min(frame["time_s"].to_numpy(), frame["tk_set_c"]) == 0.0
    ramp = frame["time_s"].to_numpy() / 60.0  # 1 degC/min, with one step
    ramp[100:] += 20.0
    assert discrepancy._fastest_ramp_c_per_min(frame["time_s"].to_numpy(), ramp) == pytest.approx(
        1.0
    )


def test_air_logged_as_the_setpoint_is_no_air_finding_not_a_crash():
    """Judge, session 52: a chamber that logs its setpoint as the air (tk_air_c equal to
    tk_set_c) crashed diagnose with a math domain error (log of a zero variance)."""
    frame = _effect_frame("cold", "none", {}, air=True)
    frame["tk_air_c"] = frame["tk_set_c"]
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect == "none" and d.air_findings == ()


def test_a_huge_fitted_offset_is_called_doubtful():
    """Judge, session 52: t_int_c in Fahrenheit on a log too short for the unit check was
    diagnosed with dT0 -50 degC and no word. A device 30 degC off its chamber (a wrong
    unit or column) gets a warning; the same log as it was, none."""
    frame = _effect_frame("cold", "none", {}, air=False)
    assert not any("far beyond" in w for w in diagnose_frame(frame, SETTINGS).warnings)
    frame["t_int_c"] = frame["t_int_c"] + 30.0
    d = diagnose_frame(frame, SETTINGS)
    assert d.model.dt0_c == pytest.approx(33.0, abs=0.5)
    assert any("fitted dT0 of +33 °C is far beyond" in w for w in d.warnings), d.warnings


def test_a_heating_limit_under_a_programme_that_ramps_both_ways_is_found():
    """The red team's log (a random programme: ramps of -1..+2.1 degC/min and holds, 540
    min; cooling limited to 0.5 and heating to 1.5; tau 2820 s, dT0 3.11 degC; no air
    channel). Ranked with the base fit's device, the starts with the right limits lost and
    the heating limit came out 'none' with 0.21 degC left (10x the noise)."""
    frame = _rate_limited_log(
        0.5,
        1.5,
        False,
        knots_min=(
            0.0,
            58.29,
            106.15,
            223.68,
            246.7,
            260.83,
            309.97,
            319.31,
            337.1,
            414.5,
            447.6,
            476.67,
            526.47,
            540.0,
        ),
        knots_c=(
            20.0,
            -38.26,
            -38.26,
            11.01,
            11.01,
            40.59,
            40.59,
            57.48,
            57.48,
            -10.44,
            -10.44,
            25.41,
            25.41,
            18.19,
        ),
        tau_s=2820.5,
        dt0_c=3.11,
    )
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect == "chamber_rate_limit", (d.effect, d.parameters)
    assert d.parameters["max_cool_rate_c_per_min"] == pytest.approx(0.5, rel=0.05)
    assert d.parameters["max_heat_rate_c_per_min"] == pytest.approx(1.5, rel=0.05)
    assert d.rms_after_c < 0.03


def test_an_effect_that_stands_in_for_something_else_is_flagged():
    """The device's temperature logged with a gain 1.5x off (a miscalibrated sensor), the
    setpoint right: no effect of the library explains it, and the best one ends at the
    edge of its search range with many times the noise left. Named without a word before;
    now both are said. (The first case was a log in degF: the reader refuses that now.)"""
    from scipy.integrate import solve_ivp

    knots_min = np.array([0, 60, 120, 200, 260, 320, 380.0])
    knots_c = np.array([20, -10, -10, 40, 40, 20, 20.0])
    t_min = np.arange(0.0, knots_min[-1] + 1e-9, 10.0 / 60.0)
    sol = solve_ivp(
        lambda t, y: [(np.interp(t, knots_min, knots_c) + 3.0 - y[0]) / 40.0],
        (0.0, t_min[-1]),
        [23.0],
        t_eval=t_min,
        max_step=0.1,
        rtol=1e-9,
    )
    temp_c = sol.y[0] + 0.01 * np.random.default_rng(1).standard_normal(t_min.size)
    frame = pd.DataFrame(
        {
            "time_s": t_min * 60.0,
            "t_int_c": temp_c * 9.0 / 5.0 + 32.0,  # in degF
            "tk_set_c": np.interp(t_min, knots_min, knots_c),
        }
    )
    with pytest.raises(LogFormatError, match="t_int_c looks like Fahrenheit"):
        diagnose_frame(frame, SETTINGS)
    frame["t_int_c"] = 1.5 * temp_c + 5.0  # the mistake
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect != "none"
    assert any("edge of its search range" in w for w in d.warnings), d.warnings
    assert any("x the sensor noise" in w for w in d.warnings), d.warnings


def test_residual_analysis_white_periodic_and_where():
    rng = np.random.default_rng(0)
    prog = Programme([100.0, 100.0, 100.0], [-0.5, 0.0, 0.5], 20.0)
    t = np.arange(0.0, 300.0, 0.25)
    temp = prog.chamber_at(t)
    white = analyse_residuals(t, 0.02 * rng.standard_normal(t.size), temp, prog)
    assert white.white and not white.periodic
    r = 0.02 * rng.standard_normal(t.size) + 0.1 * np.sin(2 * np.pi * t * 60 / 900.0)
    rep = analyse_residuals(t, r, temp, prog)
    assert not rep.white and rep.periodic
    assert rep.period_s == pytest.approx(900.0, rel=0.05)
    r[t < 100] += 0.3  # large during the cooling segment
    rep = analyse_residuals(t, r, temp, prog)
    assert rep.rms_cooling_c > 2 * rep.rms_heating_c
    worst = rep.segments.sort_values("rms_c").iloc[-1]
    assert worst["kind"] == "cooling" and worst["step"] == 1
    assert "cooling" in rep.summary()


def test_bad_input_is_a_clear_error():
    frame = _lag_log(False).drop(columns=["tk_set_c"])
    with pytest.raises(LogFormatError, match="tk_set_c"):
        diagnose(log_from_frame(frame))
    with pytest.raises(ParameterError, match="unknown effect"):
        DiagnoseSettings(effects=("gremlins",))
    with pytest.raises(ParameterError, match="holdout_fraction"):
        DiagnoseSettings(holdout_fraction=1.5)


TCLAB = Path(__file__).resolve().parent / "data" / "tclab"  # real logs, BSD-3 (README there)


def test_real_tclab_sine_run_finds_a_low_pass_in_the_input_path():
    """Real heater/thermistor board, 5-min sine: the missing effect smooths the heater
    input. Since the rate-limit fit starts from every pair of limits (2026-11-26) a
    symmetric slew limit of the pseudo setpoint (which moves in 1-s heater steps) fits
    and predicts the held-out tail better than the heater-to-sensor lag that was found
    before (held out 2.9 -> 0.53 degC against 1.26): both are low-pass elements."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "tclab_diagnose", ROOT / "scripts" / "tclab_diagnose.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    log, k = mod.tclab_log(TCLAB / "validation_experiment_env_2_sin_5_50_run_1.csv")
    d = diagnose(log, mod.SETTINGS)
    assert 0.5 < k < 1.5  # degC per % heater
    if d.effect == "chamber_rate_limit":  # symmetric: a smoother, not a chamber's limits
        cool = d.parameters["max_cool_rate_c_per_min"]
        heat = d.parameters["max_heat_rate_c_per_min"]
        assert abs(cool / heat - 1.0) < 0.1
    else:
        assert d.effect == "second_time_constant" and "chamber_lag" in d.ambiguous_with
        assert 5.0 < d.parameters["tau2_s"] < 60.0
    assert d.rms_after_c < 0.5 * d.rms_before_c
    assert d.holdout_rms_after_c < 0.6 * d.holdout_rms_before_c


# --------------------------------------------------------------------------------------
# the chamber-air channel and lag-type ambiguity (issue 14, item 4)
# --------------------------------------------------------------------------------------
def _effect_frame(prog_name, effect, params, *, air, noise_c=0.02, seed=1):
    truth = ModelSpec(2400.0, 3.0, effect, params)
    prog = blind_programmes()[prog_name]
    return synth_effect_log(prog, truth, sample_s=10.0, noise_c=noise_c, seed=seed, with_air=air)


@pytest.mark.parametrize("seed", [1, 2])
def test_air_cycling_too_fast_for_the_device_is_reported_as_seen_not_none(seed):
    amp, period = 1.2, 40.0
    params = {"amplitude_c": amp, "period_s": period, "phase_rad": 0.3}
    d = diagnose_frame(_effect_frame("cold", "chamber_cycling", params, air=True, seed=seed))
    assert d.effect == "none"  # nothing the device feels ...
    (f,) = [f for f in d.air_findings if f.effect == "chamber_cycling"]  # ... but seen
    assert f.parameters["amplitude_c"] == pytest.approx(amp, rel=0.05)
    assert f.parameters["period_s"] == pytest.approx(period, rel=0.01)
    # first-order attenuation at the device: A / sqrt(1 + (2 pi tau / P)^2)
    theory = amp / math.hypot(1.0, 2.0 * math.pi * 2400.0 / period)
    assert 0.5 * theory < f.device_shift_c < 2.0 * theory
    assert f.below_noise and "attenuated below the sensor noise" in d.summary()
    assert "±1.2 °C every 40 s" in f.text
    seen = d.to_json_dict()["seen_in_air"]
    assert seen and seen[0]["effect"] == "chamber_cycling"


def test_material_air_cycling_is_not_called_below_the_noise():
    params = {"amplitude_c": 2.0, "period_s": 1200.0, "phase_rad": 0.3}
    d = diagnose_frame(_effect_frame("cold", "chamber_cycling", params, air=True))
    (f,) = [f for f in d.air_findings if f.effect == "chamber_cycling"]
    assert not f.below_noise and f.device_shift_c > 0.1
    assert f.parameters["period_s"] == pytest.approx(1200.0, rel=0.02)


def test_air_lag_is_measured_from_the_air_channel():
    d = diagnose_frame(_effect_frame("cold", "chamber_lag", {"tau_chamber_s": 20.0}, air=True))
    (f,) = [f for f in d.air_findings if f.effect == "chamber_lag"]
    assert f.parameters["tau_chamber_s"] == pytest.approx(20.0, rel=0.15)


def test_a_sensor_gain_error_is_named_as_its_exact_twin_with_a_warning():
    """A sensor reading 20 + G (T - 20) is, in a first-order lag, exactly a self-heating
    slope s = 1 - 1/G with tau/G: the diagnosis names the one in its library and says
    which sensor error would read the same (it said nothing; stress test)."""
    frame = _effect_frame("cold", "none", {}, air=False)
    gain = 1.03
    frame["t_int_c"] = 20.0 + gain * (frame["t_int_c"] - 20.0)
    d = diagnose_frame(frame)
    assert d.effect == "selfheat_slope"
    assert d.parameters["dt0_slope_c_per_c"] == pytest.approx(1.0 - 1.0 / gain, rel=0.02)
    (w,) = [w for w in d.warnings if "sensor whose gain" in w]
    assert "+3.0" in w and "with tau 2400 s" in w, w


@pytest.mark.parametrize("even", [True, False])
def test_first_order_response_matches_an_ode_solver(even, rng):
    from scipy.integrate import solve_ivp

    from schedsyn.discrepancy import _first_order_response

    n = 120
    t = np.cumsum(np.full(n, 10.0) if even else rng.uniform(5.0, 20.0, n)) - 10.0
    x = np.cumsum(rng.normal(0.0, 0.5, n))
    tau = 200.0
    sol = solve_ivp(
        lambda s, y: [(np.interp(s, t, x) - y[0]) / tau],
        (t[0], t[-1]),
        [x[0]],
        t_eval=t,
        rtol=1e-10,
        atol=1e-10,
        max_step=1.0,
    )
    np.testing.assert_allclose(_first_order_response(t, x, tau), sol.y[0], atol=1e-6)


@pytest.mark.parametrize(
    ("prog", "effect", "params"),
    [
        ("cold", "chamber_lag", {"tau_chamber_s": 480.0}),
        ("warm", "chamber_lag", {"tau_chamber_s": 180.0}),
        ("cold", "chamber_rate_limit", {"max_cool_rate_c_per_min": 0.5,
                                        "max_heat_rate_c_per_min": 99.0}),
    ],
)  # fmt: skip
def test_a_lagging_or_slow_chamber_is_not_also_called_cycling(prog, effect, params):
    """The air of a lagging (or rate-limited) chamber follows the programme's sweeps:
    what a static regression left of the lag passed the cycling test as a period of the
    sweeps, and a rate limit also showed as a lag (stress test). One finding, the right
    one, with the lag measured by the exact first-order response."""
    d = diagnose_frame(_effect_frame(prog, effect, params, air=True))
    assert d.effect == effect
    assert [f.effect for f in d.air_findings] == [effect], [f.text for f in d.air_findings]
    if effect == "chamber_lag":
        (f,) = d.air_findings
        assert f.parameters["tau_chamber_s"] == pytest.approx(params["tau_chamber_s"], rel=0.03)


@pytest.mark.parametrize("seed", range(4))
def test_clean_air_shows_nothing(seed):
    d = diagnose_frame(_effect_frame("cold", "none", {}, air=True, seed=seed))
    assert d.air_findings == ()


def test_nearly_equal_lag_type_effects_are_all_listed_with_fits_and_how_to_tell():
    d = diagnose_frame(
        _effect_frame("warm", "dead_time", {"delay_s": 40.0}, air=False, noise_c=0.03)
    )
    names = [a.effect for a in d.lag_ambiguity]
    assert set(names) == {"dead_time", "second_time_constant", "chamber_lag"}
    assert names[0] == d.effect
    assert {"dead_time", "second_time_constant", "chamber_lag"} - {d.effect} <= set(
        d.ambiguous_with
    )
    for a in d.lag_ambiguity:
        (v,) = a.parameters.values()
        assert v == pytest.approx(40.0, rel=0.2)  # every one fitted, with its number
        assert a.tell_apart
    tips = " ".join(t for a in d.lag_ambiguity for t in a.tell_apart)
    assert "tk_air_c" in tips and "step" in tips
    assert d.to_json_dict()["lag_ambiguity"][0]["effect"] == d.effect


def test_lag_type_effects_told_apart_are_not_called_ambiguous():
    d = diagnose_frame(_effect_frame("cold", "dead_time", {"delay_s": 120.0}, air=False))
    assert d.effect == "dead_time"
    assert d.lag_ambiguity == () and "second_time_constant" not in d.ambiguous_with


def test_bic_penalty_decides_against_an_extra_parameter_on_a_clean_log():
    """A case where the penalty decides: on a log of the base model itself (white noise),
    a nested candidate with one more parameter fits the noise slightly better (SSE a
    fraction of a percent lower: N ln(SSE_c/SSE_b) is about -1 against k ln N = +6.3 for
    N = 541 blocks), so only the k ln N term keeps BIC on the base model. Scores are also
    checked against the Gaussian log-likelihood computed by scipy: BIC = -2 ln L + k ln N
    (up to a constant shared by all candidates)."""
    from scipy import stats

    prog = blind_programmes()["cold"]
    frame = synth_effect_log(
        prog, ModelSpec(2400.0, 3.0), sample_s=10.0, noise_c=0.02, quant_c=0.0, seed=0
    )
    settings = DiagnoseSettings(
        fit_step_s=60.0,
        effects=("second_time_constant", "dead_time", "selfheat_slope"),
        bic_margin=0.0,  # no margin and no minimum improvement: BIC alone decides
        min_rel_improvement=0.0,
    )
    d = diagnose_frame(frame.drop(columns=["tk_air_c", "t_true_c", "g_true_c_per_min"]), settings)
    base = d.base_fit
    n = base.n_residuals
    assert base.n_params == 3  # tau, dT0, T0

    def minus2_log_likelihood(fit):
        sigma = math.sqrt(fit.sse / fit.n_residuals)  # the ML noise level
        r = np.full(fit.n_residuals, sigma)  # any residuals with this SSE give the same L
        return -2.0 * float(np.sum(stats.norm.logpdf(r, scale=sigma)))

    better_fits = [c for c in d.candidates if c.sse < base.sse]
    assert better_fits, [(c.effect, c.sse / base.sse) for c in d.candidates]
    for c in d.candidates:
        assert c.n_params == 4 and c.n_residuals == n
        bic_gap = (minus2_log_likelihood(c) + c.n_params * math.log(n)) - (
            minus2_log_likelihood(base) + base.n_params * math.log(n)
        )
        assert c.score - base.score == pytest.approx(bic_gap, abs=1e-6)
    for c in better_fits:
        assert minus2_log_likelihood(c) < minus2_log_likelihood(base)  # fits better ...
        assert c.score > base.score, c.effect  # ... and loses on the penalty
    assert d.effect == "none"
    assert not any("held-out" in w for w in d.warnings), d.warnings  # BIC decided


def test_an_asymmetric_fit_that_runs_out_of_evaluations_goes_on_to_the_optimum():
    """A red-team log (tests/data/diagnose/README.md: independent simulator, heating tau
    1892 s, cooling 1645.2 s): the fit stopped at its evaluation limit 8-10 standard
    errors short, the asymmetry 14 % low, with the standard errors taken there. Going on
    from where it stopped, both time constants are within 3 standard errors and the
    asymmetry within 5 % (2 % here)."""
    from schedsyn.logs import read_log

    d = diagnose(read_log(ROOT / "tests" / "data" / "diagnose" / "asymmetric_tau_60s.csv"))
    assert d.effect == "asymmetric_tau", d.summary()
    truth = {"tau_heat_s": 1892.0, "tau_cool_s": 1645.2}
    for name, value in truth.items():
        z = (d.parameters[name] - value) / d.stderr[name]
        assert abs(z) <= 3.0, (name, d.parameters[name], d.stderr[name])
    assert _main_error("asymmetric_tau", truth, d.parameters) < 0.05, d.parameters
    # tau_s is not a parameter of this model (two time constants replace it): no warning
    # that the log does not determine it
    assert not any(w.startswith("tau_s =") for w in d.warnings), d.warnings


def test_a_short_lag_is_not_at_the_edge_of_a_range_of_decades():
    """A 16-s second time constant (tau2_s searched in [0.001, 20000] s) was flagged as
    at the edge of its range, on a linear scale (red team); on the range's logarithm it is
    far inside, and the fit finds it."""
    truth = ModelSpec(2400.0, 3.0, "second_time_constant", {"tau2_s": 16.0})
    prog = blind_programmes()[sorted(blind_programmes())[0]]
    frame = synth_effect_log(prog, truth, sample_s=10.0, noise_c=0.003, seed=3, with_air=False)
    d = diagnose_frame(frame, SETTINGS)
    assert d.effect == "second_time_constant", d.summary()
    assert d.parameters["tau2_s"] == pytest.approx(16.0, abs=3 * d.stderr["tau2_s"])
    assert not [w for w in d.warnings if "edge of its search range" in w], d.warnings


def test_standard_errors_of_parameters_the_log_does_not_determine_are_unbounded():
    """The pseudo-inverse gave an undetermined parameter a standard error of zero (a zero
    column) or next to it; scaled columns and the null directions give it inf, and leave
    a determined problem's errors as the textbook formula's."""
    from schedsyn.discrepancy import _stderr

    rng = np.random.default_rng(0)
    jac = rng.normal(size=(200, 3)) * [1.0, 1e3, 1e-2]
    want = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)) * 0.5)
    np.testing.assert_allclose(_stderr(jac, 0.5), want, rtol=1e-9)
    zero = jac.copy()
    zero[:, 1] = 0.0
    se = _stderr(zero, 0.5)
    assert np.isinf(se[1]) and np.isfinite(se[[0, 2]]).all()
    twin = jac.copy()
    twin[:, 2] = 3.0 * twin[:, 0]  # only their sum is seen
    se = _stderr(twin, 0.5)
    assert np.isinf(se[[0, 2]]).all() and np.isfinite(se[1])


def test_a_soak_at_equilibrium_says_its_time_constant_is_not_determined():
    """Four hours at 20 degC with the device settled 3 degC above: tau moves nothing. It was
    reported as 10630 +- 5e-11 s (red team); now its standard error is at least half its
    value and a warning says not to use it."""
    t = np.arange(0.0, 14400.0, 10.0)
    noise = np.random.default_rng(1).normal(0.0, 0.02, t.size)
    frame = pd.DataFrame({"time_s": t, "t_int_c": 23.0 + noise, "tk_set_c": 20.0})
    d = diagnose_frame(frame, SETTINGS)
    assert d.stderr["tau_s"] > 0.5 * d.model.tau_s, (d.model.tau_s, d.stderr)
    assert any(w.startswith("tau_s = ") and "not determined" in w for w in d.warnings), d.warnings


def test_a_better_scoring_candidate_that_was_rejected_is_not_almost_as_good():
    """The "almost as good" warning names the candidates scoring worse than the chosen
    one by less than the ambiguity margin; one that scores better was tried and rejected
    (held-out check or too small a gain, said in its own warning), and calling it "almost
    as good" contradicted that (red team)."""
    from schedsyn.discrepancy import CandidateFit, close_rivals

    def fit(effect, score):
        return CandidateFit(effect, ModelSpec(), 20.0, {}, {}, 2, 100, 1.0, score, 0.01, None)

    chosen = fit("dead_time", 100.0)
    ranked = [
        fit("chamber_lag", 90.0),
        chosen,
        fit("dt0_drift", 103.0),
        fit("selfheat_slope", 140.0),
    ]
    rivals = close_rivals(ranked, chosen, ambiguity_bic=6.0)
    assert [c.effect for c in rivals] == ["dt0_drift"]
    assert close_rivals(ranked, chosen, ambiguity_bic=50.0)[-1].effect == "selfheat_slope"


def test_the_block_mean_correction_s_second_derivative_is_exact_for_a_parabola():
    """The fits add ``var/2 f''`` to each predicted block mean, with ``f''`` by the
    three-point formula on the blocks' irregular times and the spacings worked out once
    per log (``_Data``): exact for a parabola, the same numbers with the kept spacings
    as without, and the log's own spacings kept."""
    from schedsyn.discrepancy import _prepare, _second_derivative, _spacing

    rng = np.random.default_rng(2)
    t = np.cumsum(rng.uniform(0.2, 3.0, 40))
    f = 0.7 * t**2 - 3.0 * t + 1.0
    d2 = _second_derivative(t, f)
    np.testing.assert_allclose(d2, 1.4, rtol=1e-9)
    np.testing.assert_array_equal(_second_derivative(t, f, _spacing(t)), d2)
    frame, _, _ = blind_case("none", 3, blind_programmes()["cold"], sample_s=10.0)
    data, _ = _prepare(log_from_frame(frame), SETTINGS)
    for got, want in zip(data.t_spacing, _spacing(data.time_min), strict=True):
        np.testing.assert_array_equal(got, want)
    half = data.subset(float(data.time_min[len(data.time_min) // 2]))
    for got, want in zip(half.t_spacing, _spacing(half.time_min), strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("sample_s", [1.0, 10.0])
def test_a_setpoint_logged_to_a_tenth_of_a_degree_is_rebuilt_as_its_ramps(sample_s):
    """The paper-like table and the blind programmes, their setpoint logged to 0.1 degC:
    rebuilt with the table's own number of segments and within 0.01 degC RMS of the
    table's setpoint (evaluated here by interpolating the table's knots). With the 0.05
    degC tolerance alone, 1-s logs became staircases (6566 segments for a 58-step plan,
    450 s to diagnose) and, once that was widened, the corners stayed on samples half a
    step off (0.027 degC RMS, a false 'chamber_lag' on a clean log)."""
    progs = dict(blind_programmes())
    progs["exp1"] = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    for name, prog in progs.items():
        knots_min = np.concatenate(([0.0], np.cumsum(prog.durations_min)))
        knots_c = prog.start_c + np.concatenate(
            ([0.0], np.cumsum(prog.durations_min * prog.rates_c_per_min))
        )
        time_s = np.arange(0.0, knots_min[-1] * 60.0 + 1e-9, sample_s)
        true_c = np.interp(time_s / 60.0, knots_min, knots_c)
        rebuilt = setpoint_programme(time_s, np.round(true_c, 1))
        err = rebuilt.chamber_at(time_s / 60.0) - true_c
        assert rebuilt.n_segments == prog.n_segments, name
        assert math.sqrt(float(np.mean(err**2))) < 0.01, name


def test_a_clean_log_with_a_setpoint_to_a_tenth_of_a_degree_is_clean():
    """1-s readings, setpoint logged to 0.1 degC, no effect: 'none' (red team: 'none'
    after 450 s with the staircase; 'chamber_lag' of 0.3 s with corners left on samples)."""
    prog = blind_programmes()["cold"]
    frame = synth_effect_log(
        prog, ModelSpec(2400.0, 3.0, "none", {}), sample_s=1.0, noise_c=0.01, seed=4,
        with_air=False,
    )  # fmt: skip
    frame["tk_set_c"] = np.round(frame["tk_set_c"], 1)
    assert diagnose_frame(frame).effect == "none"


@pytest.mark.parametrize(
    ("name", "share", "air"),
    [("warm", 0.95, True), ("exp1", 0.95, True), ("w3", 0.97, False), ("w3", 0.985, True)],
)
def test_a_rate_limit_just_below_the_fastest_ramp_is_found(name, share, air):
    """The chamber cools at 95 % of the programme's fastest cooling ramp: from the start
    grid's limits at 85 % and 105 % of it the fit found no limit (red team; here without
    the 94 % start: chamber_lag on 'warm', chamber_cycling on the paper-like table).
    97-98.5 % of a plan's: the misfit rises so steeply either side of the limit that the
    94 % start scored worse than the unbinding ones (red team, without the 0.97-0.995
    starts: selfheat_slope, chamber_lag)."""
    progs = dict(blind_programmes())
    progs["exp1"] = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    w3 = read_steps(ROOT / "tests" / "data" / "plans" / "w3_steps.csv")
    rates = w3.rates_c_per_min.copy()
    rates[rates < 0] *= 0.8  # fastest cooling 0.8 degC/min, within the blind range
    progs["w3"] = Programme(w3.durations_min, rates, start_c=w3.start_c)
    prog = progs[name]
    cool = -float(prog.rates_c_per_min.min())
    truth = ModelSpec(
        2400.0, 3.0, "chamber_rate_limit",
        {"max_cool_rate_c_per_min": share * cool, "max_heat_rate_c_per_min": 1e6},
    )  # fmt: skip
    frame = synth_effect_log(prog, truth, sample_s=10.0, noise_c=0.02, seed=2, with_air=air)
    d = diagnose_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]))
    assert d.effect == "chamber_rate_limit", (d.effect, d.warnings)
    assert d.parameters["max_cool_rate_c_per_min"] == pytest.approx(share * cool, rel=0.02)


def test_a_lagging_air_sensor_on_a_clean_device_is_not_a_chamber_effect():
    """The chamber-air sensor lags 30 s; the device follows the programme. A candidate
    that fits the air better and the internal temperature worse was taken (red team:
    chamber_rate_limit at the fastest heating, internal RMS 0.020 -> 0.066 degC)."""
    prog = read_steps(ROOT / "data" / "baseline_exp1_steps.csv")
    frame = synth_effect_log(prog, ModelSpec(2400.0, 3.0), sample_s=10.0, seed=4, with_air=True)
    frame = frame.drop(columns=["t_true_c", "g_true_c_per_min"])
    air = frame["tk_air_c"].to_numpy()
    lagged = air.copy()
    for i in range(1, air.size):  # a first-order sensor, 30 s, sampled every 10 s
        lagged[i] = lagged[i - 1] + (10.0 / 30.0) * (air[i] - lagged[i - 1])
    frame["tk_air_c"] = lagged
    d = diagnose_frame(frame)
    assert d.effect == "none", d.summary()
    assert any("internal temperature worse" in w for w in d.warnings), d.warnings
    # the air finding does not claim the device moved: a lagging sensor reads the same
    (lag,) = [f for f in d.air_findings if f.effect == "chamber_lag"]
    assert "a lagging air sensor reads the same" in lag.text, lag.text


# --------------------------------------------------------------------------------------
# an effect the first part of the log does not show
# --------------------------------------------------------------------------------------
def _late_fast_cooling():
    """Slow ramps for the first 70 % of 9 h; the one fast cooling ramp after that."""
    d = [40, 60, 67, 60, 40, 140, 40, 30, 20, 43]
    r = [1.0, 0.0, -0.3, 0.0, 0.5, 0.0, -1.0, 0.0, 1.0, 0.0]
    return Programme(np.array(d, dtype=float), np.array(r, dtype=float))


@pytest.mark.parametrize("air", [False, True])
def test_a_limit_reached_only_in_the_held_out_part_is_checked_the_other_way_round(air):
    """Red team: a cooling limit reached only by a ramp after 70 % of the run was not
    taken (fitted on the first 70 %, where it never binds, it predicts the rest no
    better) and asymmetric_tau was named in its place, or none with the air channel."""
    truth = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.45, "max_heat_rate_c_per_min": 10.0},
    )
    prog = _late_fast_cooling()
    assert prog.durations_min[:6].sum() / prog.total_min > 0.7  # the fast ramp is late
    frame = synth_effect_log(prog, truth, sample_s=10.0, noise_c=0.02, seed=4, with_air=air)
    d = diagnose_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]), SETTINGS)
    assert d.effect == "chamber_rate_limit", d.summary()
    assert d.parameters["max_cool_rate_c_per_min"] == pytest.approx(0.45, rel=0.05)
    assert d.holdout_part == "first" and d.holdout_start_min == 0.0
    assert d.holdout_rms_after_c < 0.1 * d.holdout_rms_before_c
    assert "held-out (the first 162 min" in d.summary()
    assert json.loads(json.dumps(d.to_json_dict()))["holdout"]["part"] == "first"


def test_a_warning_says_when_both_held_out_checks_failed(monkeypatch):
    """The late limit of the test above, with the held-out checks asked for an
    impossible gain: not taken, and the warning says that the check the other way round
    was tried too (it had said only "does not predict its held-out last 30 %")."""
    monkeypatch.setattr(discrepancy, "HOLDOUT_MIN_GAIN", 1.0)
    truth = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.45, "max_heat_rate_c_per_min": 10.0},
    )
    frame = synth_effect_log(_late_fast_cooling(), truth, sample_s=10.0, noise_c=0.02, seed=4)
    d = diagnose_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]), SETTINGS)
    assert d.effect == "none", d.summary()
    said = [w for w in d.warnings if w.startswith("chamber_rate_limit fits the log but")]
    assert said and "nor, fitted on the last 70%" in said[0], d.warnings


def test_a_clean_log_of_a_late_fast_ramp_is_still_none():
    frame = synth_effect_log(
        _late_fast_cooling(), ModelSpec(2400.0, 3.0), sample_s=10.0, noise_c=0.02, seed=5
    )
    d = diagnose_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]), SETTINGS)
    assert d.effect == "none", d.summary()
    assert d.holdout_part == "last"


def test_a_setpoint_gap_is_named_in_the_diagnosis():
    """Red team: 20 min of rows lost on a clean 10-s log of a plan (two corners inside the
    hole) gave dt0_drift and nothing said the setpoint there was guessed."""
    prog = read_steps(ROOT / "tests" / "data" / "plans" / "w2_steps.csv")
    frame = synth_effect_log(prog, ModelSpec(2400.0, 3.0), sample_s=10.0, seed=6, with_air=False)
    frame = frame.drop(columns=["t_true_c", "g_true_c_per_min"])
    holed = frame[(frame["time_s"] < 120 * 60) | (frame["time_s"] > 140 * 60)]
    d = diagnose_frame(holed, SETTINGS)
    gap = [w for w in d.warnings if w.startswith("the setpoint is not logged")]
    assert len(gap) == 1 and "(120-140 min; the longest 20 min)" in gap[0], d.warnings
    # one missing row is no gap
    d = diagnose_frame(frame.drop(index=frame.index[700]), SETTINGS)
    assert not any(w.startswith("the setpoint is not logged") for w in d.warnings), d.warnings


def test_a_setpoint_logged_to_whole_degrees_asks_more_of_an_effect():
    """Red team: a clean log of a plan with the setpoint rounded to 1 degC was named
    asymmetric_tau (the rebuilt ramps miss by up to the resolution; the effect took 5 %
    of that misfit). A real effect still stands out."""
    prog = read_steps(ROOT / "tests" / "data" / "plans" / "w2_steps.csv")
    for truth, want in (
        (ModelSpec(2400.0, 3.0), "none"),
        (ModelSpec(2400.0, 3.0, "chamber_cycling",
                   {"amplitude_c": 0.6, "period_s": 900.0, "phase_rad": 0.3}), "chamber_cycling"),
    ):  # fmt: skip
        frame = synth_effect_log(prog, truth, sample_s=10.0, seed=3, with_air=False)
        frame = frame.drop(columns=["t_true_c", "g_true_c_per_min"])
        frame["tk_set_c"] = np.round(frame["tk_set_c"])
        d = diagnose_frame(frame)
        assert d.effect == want, d.summary()
        assert any("the setpoint is logged to 1 degC" in w for w in d.warnings), d.warnings


def test_exact_ramps_that_land_on_a_grid_are_not_a_rounded_setpoint():
    """Red team: 1 and 0.5 degC/min ramps sampled every 60 s land on whole and half
    degrees; the setpoint was taken as logged to 0.5 degC and a real 0.3 degC cycling
    then needed a 10 % gain (it had 8 %) and was not named."""
    from schedsyn.discrepancy import setpoint_quantum_c

    prog = Programme(
        np.array([50.0, 90.0, 40.0, 60.0, 30.0, 90.0, 20.0, 160.0]),
        np.array([1.0, 0.0, -0.5, 0.0, 1.0, 0.0, -0.5, 0.0]),
    )
    for sample_s in (60.0, 10.0, 1.0):
        t_min = np.arange(0.0, prog.total_min * 60.0 + 1.0, sample_s) / 60.0
        exact = prog.chamber_at(t_min)
        assert setpoint_quantum_c(exact) is None, sample_s
        if sample_s < 60.0:  # rounded: steps of 0 and 1 grid step along a ramp
            assert setpoint_quantum_c(np.floor(exact + 0.5)) == 1.0, sample_s
            assert setpoint_quantum_c(np.floor(exact * 10.0 + 0.5) / 10.0) == 0.1, sample_s
