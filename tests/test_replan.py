"""Re-planning machinery that needs no planner: inputs, executed steps, state at M, model,
levels so far and missing, and the whole-run plan directory.

Truth comes from the noise-free model (scipy's solve_ivp for the model's own T(M)); the
passes are counted by a plain loop written here.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from test_monitor import LEVELS, REGION, own_passes, plan_programme, write_plan_dir

from schedsyn.coverage import distinct_levels
from schedsyn.effects import ModelSpec
from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.logs import log_from_frame
from schedsyn.monitor import read_plan_dir
from schedsyn.programme import Programme
from schedsyn.replan import (
    cut_programme,
    join_programmes,
    prepare_replan,
    rest_of_programme,
    write_replan_dir,
)
from schedsyn.synth import synth_effect_log


def effect_log(truth, seed=0, noise_c=0.01, drop_truth=True):
    f = synth_effect_log(plan_programme(), truth, sample_s=10.0, noise_c=noise_c, seed=seed)
    return f.drop(columns=["t_true_c", "g_true_c_per_min"]) if drop_truth else f


@pytest.fixture
def plan(tmp_path):
    return read_plan_dir(write_plan_dir(tmp_path / "plan"))


def test_cut_and_rest_rejoin_to_the_same_chamber_path():
    prog = plan_programme()
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, prog.total_min, 2001)
    for m in [*rng.uniform(1.0, prog.total_min - 1.0, 25), 45.0, 85.0]:
        pre, rest = cut_programme(prog, m), rest_of_programme(prog, m)
        assert pre.total_min == pytest.approx(m) and pre.end_c == pytest.approx(rest.start_c)
        whole = join_programmes(pre, rest)
        np.testing.assert_allclose(whole.chamber_at(t), prog.chamber_at(t), atol=1e-9)
        np.testing.assert_allclose(pre.chamber_at(t[t <= m]), prog.chamber_at(t[t <= m]))


def test_state_levels_and_missing_at_m_match_the_truth(plan):
    truth = ModelSpec(2600.0, 2.0)
    frame = effect_log(truth, seed=2, noise_c=0.005, drop_truth=False)
    m = 300.0
    req = prepare_replan(
        log_from_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]), "r"), plan, m
    )
    t_true = truth.predict(plan.programme, np.array([m])).t_c[0]
    assert abs(req.state.t_c - t_true) < max(4 * req.state.t_std_c, 0.02)
    assert req.state.tk_set_c == pytest.approx(plan.programme.chamber_at([m])[0])
    # passes ended by M, counted by a plain loop on the true trajectory
    tt = np.arange(0.0, m + 1e-9, 0.1)
    pr = truth.predict(plan.programme, tt)
    found = own_passes(pr.t_c, pr.g_c_per_min, *REGION)
    for b in range(10):
        mine = np.array(sorted(g for k, g, closed in found if k == b and closed))
        assert req.existing_gradients[b].size == mine.size, b
        np.testing.assert_allclose(req.existing_gradients[b], mine, atol=0.01)
        lv = distinct_levels(mine, plan.delta_c_per_min)
        assert req.existing_levels[b] == lv
        assert req.missing_levels[b] == max(LEVELS - lv, 0)
    # identified from the log up to M only
    assert abs(req.identified.tau_s - 2600.0) < 30.0
    assert req.effect.effect == "none" and req.model.effect == "none"


def test_start_correction_is_measured_minus_the_models_own_t_at_m(plan):
    truth = ModelSpec(2400.0, 3.0, "second_time_constant", {"tau2_s": 30.0})
    req = prepare_replan(log_from_frame(effect_log(truth, seed=5), "r"), plan, 200.0)
    model = req.model.linear_model()
    assert model.tau2_s == 0.0 or req.effect.material
    prog = req.prefix
    tau = req.model.tau_s / 60.0

    def rhs(t, y):  # the base model: tau dT/dt + T = Tk + dT0
        return [(prog.chamber_at([t])[0] + req.model.dt0_c - y[0]) / tau]

    if req.model.effect == "none":
        sol = solve_ivp(rhs, (0.0, 200.0), [req.model_t0_c], rtol=1e-10, atol=1e-10)
        assert req.start_correction_c == pytest.approx(req.state.t_c - sol.y[0][-1], abs=1e-4)
    assert abs(req.start_correction_c) < 0.3


def test_a_material_effect_is_kept_and_a_clean_log_keeps_the_base_model(plan):
    lagged = ModelSpec(2400.0, 3.0, "second_time_constant", {"tau2_s": 600.0})
    req = prepare_replan(log_from_frame(effect_log(lagged, seed=1), "lag"), plan, 240.0)
    assert req.effect.effect in ("second_time_constant", "chamber_lag")
    assert req.effect.material and req.effect.max_shift_c > 0.2
    assert req.model.effect == req.effect.effect
    assert req.model.parameters[next(iter(req.model.parameters))] == pytest.approx(600.0, rel=0.1)
    clean = prepare_replan(log_from_frame(effect_log(ModelSpec(2400, 3), seed=1), "c"), plan, 240)
    assert clean.model.effect == "none"


def _with_gap(frame, a_s, b_s):
    return frame[(frame["time_s"] < a_s) | (frame["time_s"] > b_s)].reset_index(drop=True)


@pytest.mark.parametrize(
    "make, at, err, words",
    [
        (lambda f: f[f["time_s"] <= 6000], 150.0, ParameterError, "beyond the end of the log"),
        (lambda f: f, 445.0, ParameterError, "end of the plan"),
        (lambda f: _with_gap(f, 8400, 9600), 150.0, LogFormatError, "gap"),
        (
            lambda f: f.assign(
                t_int_c=np.where(f["time_s"].between(8700, 9300), np.nan, f["t_int_c"])
            ),
            150.0,
            LogFormatError,
            "missing",
        ),
        (lambda f: f.assign(tk_set_c=f["tk_set_c"] - 3.0), 150.0, LogFormatError, "setpoint"),
        (lambda f: f.assign(time_s=f["time_s"] + 1800.0), 150.0, LogFormatError, "start"),
        (lambda f: f, -5.0, ParameterError, "> 0"),
    ],
    ids=["m-past-log", "m-past-plan", "gap", "nan-run", "other-programme", "start", "negative"],
)
def test_bad_inputs_give_one_line_errors(plan, make, at, err, words):
    log = log_from_frame(make(effect_log(ModelSpec(2400, 3))), "bad")
    with pytest.raises(err) as info:
        prepare_replan(log, plan, at, find_effect=False)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_rows_after_m_may_follow_another_programme(plan):
    f = effect_log(ModelSpec(2400, 3))
    f = f.assign(tk_set_c=np.where(f["time_s"] > 200 * 60, f["tk_set_c"] + 4.0, f["tk_set_c"]))
    req = prepare_replan(log_from_frame(f, "changed"), plan, 190.0, find_effect=False)
    assert req.prefix.total_min == pytest.approx(190.0)


def test_the_replan_directory_is_a_plan_directory_that_can_be_replanned_again(plan, tmp_path):
    log = log_from_frame(effect_log(ModelSpec(2500.0, 2.5), seed=3), "r")
    req = prepare_replan(log, plan, 150.0, find_effect=False)
    whole = join_programmes(req.prefix, rest_of_programme(plan.programme, 150.0))
    out = tmp_path / "re"
    write_replan_dir(out, req, whole, continuation={"note": "the plan's own rest"})
    again = read_plan_dir(out)
    t = np.linspace(0.0, whole.total_min, 3001)
    np.testing.assert_allclose(again.programme.chamber_at(t), whole.chamber_at(t), atol=0.006)
    assert (again.working_lo_c, again.working_hi_c) == REGION
    assert again.params.tau_s == pytest.approx(req.model.tau_s)
    meta = json.loads((out / "replan.json").read_text())
    assert meta["at_min"] == 150.0 and len(meta["bins"]) == 10
    assert meta["levels_missing_total"] == int(req.missing_levels.sum())
    assert meta["continuation"] == {"note": "the plan's own rest"}
    steps = pd.read_csv(out / "steps.csv")
    assert list(steps.columns[:6]) == [
        "step",
        "start_min",
        "duration_min",
        "tk_start_c",
        "tk_end_c",
        "rate_c_per_min",
    ]
    req2 = prepare_replan(log, again, 300.0, find_effect=False)
    assert req2.prefix.total_min == pytest.approx(300.0)
    assert req2.existing_levels.sum() >= req.existing_levels.sum()


def test_the_writer_refuses_a_run_that_does_not_begin_with_the_executed_steps(plan, tmp_path):
    log = log_from_frame(effect_log(ModelSpec(2400, 3)), "r")
    req = prepare_replan(log, plan, 150.0, find_effect=False)
    other = Programme(np.array([150.0, 100.0]), np.array([-0.2, 0.2]))
    with pytest.raises(ParameterError, match="begin with the steps executed"):
        write_replan_dir(tmp_path / "x", req, other)
    hot_end = join_programmes(
        req.prefix, Programme(np.array([100.0]), np.array([0.3]), req.prefix.end_c)
    )
    with pytest.raises(ParameterError, match="breaks a limit"):
        write_replan_dir(tmp_path / "x", req, hot_end)
    assert not (tmp_path / "x").exists()
