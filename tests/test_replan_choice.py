"""Which rest a re-plan takes: the plan unchanged against the planner's continuations.

Red team (2026-12-03): a W4 re-plan at minute 30 took a continuation predicted to cover
47 % over the plan unchanged's 57 %, whose table had 117 new steps against max_steps 80,
with ``predicted.problems`` empty and a reason that did not say the plan unchanged was
predicted to take the device past its limit (with two rival models); and a W3 re-plan at
minute 60 took a rest that covered more bins but left bins 0..6 with no level at all,
where the plan unchanged gave each of them 3 or 6.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_monitor import write_plan_dir
from test_replan import (
    _hot_hold_run,
    _plan_each_start_once,
    _prepare_each_log_once,
    _short_plan_dir,
    effect_log,
)

from schedsyn.effects import ModelSpec
from schedsyn.logs import log_from_frame
from schedsyn.monitor import RivalModel, read_plan_dir
from schedsyn.programme import Programme
from schedsyn.replan import (
    PlannerAttempt,
    predict_run,
    refuse_continuation,
    replan_run,
    with_table_problems,
)
from schedsyn.synth import synth_effect_log

TOO_MANY = "the re-planned rest has 117 steps, more than max_steps = 80"


def test_a_continuation_whose_table_breaks_the_step_limit_is_not_taken(tmp_path, monkeypatch):
    """The short plan at minute 60: the planner's (incomplete) rest is taken over the plan
    unchanged (test_replan). Flagged by the planner as breaking max_steps, as the red
    team's W4 rest was, it is not: the controller cannot be loaded with it. The reason,
    the summary and replan.json say why."""
    import schedsyn.planner as planner_module

    _plan_each_start_once(monkeypatch)
    _prepare_each_log_once(monkeypatch)
    prog, plan_dir = _short_plan_dir(tmp_path)
    plan = read_plan_dir(plan_dir)
    frame = synth_effect_log(prog, ModelSpec(2400.0, 5.5), sample_s=10.0, noise_c=0.01, seed=1)
    log = log_from_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]), "r")
    assert replan_run(log, plan, 60.0).choice == "new"  # the planner's rest, within limits

    cached = planner_module.plan_experiment

    def too_many_steps(*args, **kwargs):
        p = cached(*args, **kwargs)
        return replace(p, status="limits violated", violations=(*p.violations, TOO_MANY))

    monkeypatch.setattr(planner_module, "plan_experiment", too_many_steps)
    res = replan_run(log, plan, 60.0)
    assert res.choice == "keep", res.reason
    assert "max_steps = 80" in res.reason and "not taken" in res.reason, res.reason
    assert "max_steps = 80" in res.summary()
    out = res.to_json_dict()
    planned = [a for a in out["planner_attempts"] if a["error"] is None]
    assert planned and len(out["refused_continuations"]) == len(planned)
    assert all(TOO_MANY in a["problems"] and not a["predicted_complete"] for a in planned)


def _with_rival(monkeypatch, dt0_extra_c: float) -> None:
    """A rival model (dT0 ``dt0_extra_c`` higher) that fits the log as well as the one
    used: prepare_replan's effect check is given it."""
    import schedsyn.replan as replan_module

    real = replan_module.prepare_replan

    def with_rival(*args, **kwargs):
        rq = real(*args, **kwargs)
        rival = RivalModel(
            "selfheat_slope",
            replace(rq.model, dt0_c=rq.model.dt0_c + dt0_extra_c),
            rq.model_t0_c,
            dt0_extra_c,
        )
        return replace(rq, effect=replace(rq.effect, rivals=(rival,)))

    monkeypatch.setattr(replan_module, "prepare_replan", with_rival)


def test_a_rest_taken_because_a_rival_breaks_the_limit_says_so(tmp_path, monkeypatch):
    """The plan unchanged keeps the device within its 34.5 degC limit with the model used
    (33.97) but not with a rival 3 degC hotter (35.95); the continuation turns home
    sooner and keeps within it under both. It is taken for the limit, and the reason
    says so: which limit, with which model (red team, W4: "the plan unchanged reaches
    57 %" hid that both rivals took the device to 65.8 and 72.1 degC)."""
    import schedsyn.replan as replan_module

    prog, plan_dir, _, log = _hot_hold_run(tmp_path, device_max_c=34.5)
    late = Programme(
        np.array([10.0, 20.0, 10.0, 130.0]), np.array([1.0, 0.0, -1.0, 0.0]), meta=prog.meta
    )

    def turn_home(rq, start, progress, say, label="identified", stop=None):
        return PlannerAttempt(start, None, predict_run(rq, late), None, 0.0, label)

    monkeypatch.setattr(replan_module, "_plan_from", turn_home)
    _with_rival(monkeypatch, 3.0)
    res = replan_run(log, read_plan_dir(plan_dir), 30.0, find_effect=False)
    assert not res.unchanged.problems  # within its limits with the model used
    assert res.choice == "new", res.reason
    assert "rival model selfheat_slope" in res.reason and "outside its limits" in res.reason, (
        res.reason
    )
    assert "keeps the device within its limits under every model" in res.reason, res.reason


def _slow_device_run(plan):
    """The test plan at minute 60 of a device of tau 3600 s: the plan unchanged ends at
    70 % with levels [2 2 2 3 4 4 4 4 4 3] (3 required)."""
    frame = effect_log(ModelSpec(3600.0, 3.0), seed=1)
    return log_from_frame(frame[frame.time_s <= 3600].reset_index(drop=True), "slow")


def _rest_with_levels(monkeypatch, levels):
    """The planner's continuation (every start) is the plan's own steps, predicted with
    these levels per bin."""
    import schedsyn.replan as replan_module

    def crafted(rq, start, progress, say, label="identified", stop=None):
        run = predict_run(rq, rq.plan.programme)
        run = replace(run, coverage=replace(run.coverage, levels=np.array(levels)))
        return PlannerAttempt(start, None, run, None, 0.0, label)

    monkeypatch.setattr(replan_module, "_plan_from", crafted)


def test_a_rest_that_leaves_a_bin_with_no_level_is_not_taken_for_more_coverage(
    tmp_path, monkeypatch
):
    """Red team, W3 (tau 3000 s) at minute 60: 73 % with bins 0..6 at no level was taken
    over 53 % with every bin at 1 or more. A bin with no level cannot be calibrated;
    the weakest bin of the rest must not fall below the plan unchanged's."""
    plan = read_plan_dir(write_plan_dir(tmp_path / "plan"))
    log = _slow_device_run(plan)
    _rest_with_levels(monkeypatch, [0, 0, 3, 3, 3, 3, 3, 3, 3, 3])  # 80 %, min 0
    res = replan_run(log, plan, 60.0, find_effect=False)
    assert res.unchanged.coverage.min_levels == 2 and res.unchanged.coverage.coverage < 0.8
    assert res.choice == "keep", res.reason
    assert "weakest bin with 0 levels, the plan unchanged 2" in res.reason, res.reason


def test_a_rest_taken_with_fewer_levels_in_some_bins_names_them(tmp_path, monkeypatch):
    """A rest that covers more bins at the same weakest level is taken, but the bins it
    leaves short with fewer levels than the plan unchanged would are named (summary and
    replan.json)."""
    plan = read_plan_dir(write_plan_dir(tmp_path / "plan"))
    log = _slow_device_run(plan)
    _rest_with_levels(monkeypatch, [2, 3, 3, 3, 3, 3, 3, 3, 3, 2])  # 80 %, min 2
    res = replan_run(log, plan, 60.0, find_effect=False)
    assert res.choice == "new", res.reason
    assert "leave 1 bin(s) with fewer levels than the plan unchanged would: [4, 5) 2 (plan 3)" in (
        res.summary()
    )
    assert res.to_json_dict()["bins_fewer_levels_than_unchanged"] == [
        {"bin_lo_c": 4.0, "levels": 2, "unchanged_plan_levels": 3}
    ]


@pytest.fixture
def fake(tmp_path):
    """``fake(levels, problems=(), table=())``: the test plan's run at minute 60 predicted,
    with these levels per bin (10 bins, 3 required), problems and table problems."""
    from schedsyn.replan import prepare_replan

    plan = read_plan_dir(write_plan_dir(tmp_path / "plan"))
    frame = effect_log(ModelSpec(2400.0, 3.0), seed=1)
    log = log_from_frame(frame[frame.time_s <= 3600].reset_index(drop=True), "x")
    base = predict_run(prepare_replan(log, plan, 60.0, find_effect=False), plan.programme)

    def make(levels, problems=(), table=()):
        cov = replace(base.coverage, levels=np.array(levels))
        return with_table_problems(replace(base, coverage=cov, problems=tuple(problems)), table)

    return make


def test_the_rules_of_refuse_continuation(fake):
    """The decision itself: a table past a limit is never taken; while the plan unchanged
    keeps the limits, neither is a rest covering less or weaker in its weakest bin; a plan
    unchanged that breaks a limit lets a worse rest through (the caller says why)."""
    unchanged = fake([2, 2, 2, 3, 4, 4, 4, 4, 4, 3])
    ukey = unchanged.preference()
    ok = fake([2, 3, 3, 3, 3, 3, 3, 3, 3, 3])
    assert refuse_continuation(ok, ok.preference(), unchanged, ukey) is None
    steps = fake([3] * 10, table=[TOO_MANY])
    assert "max_steps" in str(refuse_continuation(steps, steps.preference(), unchanged, ukey))
    assert not steps.complete
    empty_bin = fake([0, 3, 3, 3, 3, 3, 3, 3, 3, 3])
    assert "weakest bin with 0 levels" in str(
        refuse_continuation(empty_bin, empty_bin.preference(), unchanged, ukey)
    )
    less = fake([2, 2, 2, 2, 2, 2, 2, 3, 3, 3])
    assert "cover 30%" in str(refuse_continuation(less, less.preference(), unchanged, ukey))
    # a complete rest is never refused for its weakest bin (it is at the requirement)
    rich = fake([5, 5, 5, 5, 5, 5, 5, 5, 5, 5])
    complete = fake([3] * 10)
    assert refuse_continuation(complete, complete.preference(), rich, rich.preference()) is None
    # the plan unchanged breaks a limit: a worse rest within the limits may be taken
    hot = fake([2, 2, 2, 3, 4, 4, 4, 4, 4, 3], problems=["the device is predicted to reach"])
    assert refuse_continuation(less, less.preference(), hot, hot.preference()) is None
    assert refuse_continuation(steps, steps.preference(), hot, hot.preference()) is not None
