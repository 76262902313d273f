"""What would meet a request: every advised change is planned (the planner's own answer to
that very request, recorded while advise planned it, else planned again here) and its
exported step table re-checked with separate code (scipy's ODE solver and plain level
counting, tests/independent.py); the value one step less generous is shown not to work, by
the proven bound or by planning it again.

Small requests only (4-6 degC regions, 2-4 levels), each searched once per module.
"""

from __future__ import annotations

import dataclasses
import json
import math

import pandas as pd
import pytest
from independent import table_check

import schedsyn.advise as advise_module
from schedsyn.advise import (
    NOT_BINDING,
    PROVEN_IMPOSSIBLE,
    VERIFIED,
    AdviceSettings,
    advise,
)
from schedsyn.cli import main
from schedsyn.errors import InfeasiblePlanError, ParameterError
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, duration_lower_bound, plan_experiment

pytestmark = [
    pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning"),
    pytest.mark.slow,
]

PARAMS = ThermalParams()
# 4 levels in [0, 6] degC do not fit in 110 min, proven (bound 118 min; 3 levels are
# proven out of reach too): advise plans no request it cannot complete, only the verifying
# plans (2 levels: under 1 s; 165 min: the band search's own complete plan, about 12 s).
# At 130 min the request itself and the values next to the planner's reach (135 and
# 140 min, 3 levels) each went to the timetable stage (25-35 s each, 2.5 min in all).
SHORT = ExperimentSpec("short", 0.0, 6.0, -5.0, 11.0, levels_required=4)
SHORT_LIMITS = dataclasses.replace(Limits(), duration_max_min=110.0)
#: the duration grid from 110 min: 165, 220, ... (the first value the bound leaves open)
SHORT_DURATION_STEP = 55.0
# within 130 min (above the bound) the request is not proven impossible: 3 levels are open
PLANNABLE_LIMITS = dataclasses.replace(Limits(), duration_max_min=130.0)
# a cold region with the chamber floor just below it: cooling gradients too small
# the region's edge at floor + dT0 (-49 degC): no floor of -52 can do, the advice finds
# one that does (at -48 degC the timetable stage plans it complete since 2026-12-03)
COLD = ExperimentSpec("cold", -49.0, -45.0, -52.0, -34.0, levels_required=2)
COLD_LIMITS = dataclasses.replace(Limits(), chamber_min_c=-52.0)
# bins below floor + dT0 = -49 degC cannot be reached at all
UNREACHABLE = ExperimentSpec("unreachable", -50.0, -46.0, -52.0, -36.0, levels_required=3)


#: What plan_experiment returned (or raised) for each request the module's advice planned:
#: (spec, params, limits, keyword arguments) -> Plan or InfeasiblePlanError
PLANNED: dict[tuple, object] = {}


def _advise_recording(*args, **kwargs):
    """advise(...), remembering the planner's own answer to each request it plans, so that
    a test re-checking the very same request (equal spec, params, limits and keywords)
    reads that answer instead of repeating a search of 15 s; a request advise did not
    plan, or planned with other settings, is planned by the test as before."""
    real = advise_module.plan_experiment

    def record(spec, params, limits, **kw):
        key = (spec, params, limits, tuple(sorted(kw.items())))
        try:
            PLANNED[key] = real(spec, params, limits, **kw)
        except InfeasiblePlanError as exc:
            PLANNED[key] = exc
            raise
        return PLANNED[key]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(advise_module, "plan_experiment", record)
        return advise(*args, **kwargs)


@pytest.fixture(scope="module")
def short_advice():
    settings = AdviceSettings(
        knobs=("duration", "levels", "floor"),
        duration_factor=1.5,
        duration_step_min=SHORT_DURATION_STEP,
    )
    return _advise_recording(SHORT, PARAMS, SHORT_LIMITS, settings=settings, backend="serial")


@pytest.fixture(scope="module")
def cold_advice():
    settings = AdviceSettings(knobs=("floor",), floor_reach_c=20.0)
    return _advise_recording(COLD, PARAMS, COLD_LIMITS, settings=settings, backend="serial")


def _item(advice, knob):
    (item,) = [k for k in advice.items if k.knob == knob]
    return item


def _request(spec, limits, changes):
    lim_fields = {f.name for f in dataclasses.fields(Limits)}
    lim = dataclasses.replace(limits, **{k: v for k, v in changes.items() if k in lim_fields})
    spec = dataclasses.replace(
        spec, **{k: int(v) for k, v in changes.items() if k not in lim_fields}
    )
    return spec, lim


def _independently_complete(plan, spec, limits, tmp_path) -> bool:
    """The exported table, read back as plain numbers and integrated by scipy: every bin
    has its levels, and the table keeps the duration, rate and chamber limits."""
    path = tmp_path / f"{spec.name}-{spec.levels_required}.csv"
    plan.programme.to_csv(path)
    res = table_check(
        path,
        (spec.working_lo_c, spec.working_hi_c),
        spec.levels_required,
        PARAMS.tau_s,
        PARAMS.dt0_c,
        spec.delta_c_per_min,
    )
    rates = res["rates_c_per_min"]
    knots = pd.read_csv(path, comment="#")[["tk_start_c", "tk_end_c"]].to_numpy()
    return (
        res["coverage"] == 1.0
        and res["duration_min"] <= limits.duration_max_min
        and rates.min() >= limits.rate_min_c_per_min - 1e-3
        and rates.max() <= limits.rate_max_c_per_min + 1e-3
        and knots.min() >= limits.chamber_min_c - 1e-9
        and knots.max() <= limits.chamber_max_c + 1e-9
    )


def _known_complete(spec, limits):
    """The complete plan the planner itself returned for this very request (equal spec,
    params and limits, planned complete-or-nothing) while advise ran, or None: planning
    it again would repeat a search of 10 s with the same answer."""
    known = PLANNED.get((spec, PARAMS, limits, (("graded", False),)))
    return known if getattr(known, "complete", False) else None


def _fails(spec, limits, reason) -> bool:
    """The request does not plan complete: proven by the bound, or planned again."""
    bound = duration_lower_bound(spec, PARAMS, limits).lower_bound_min
    if reason == "proven":
        return bound > limits.duration_max_min
    known = PLANNED.get((spec, PARAMS, limits, (("graded", False),)))
    if known is not None:  # the planner's answer to this very request, made by advise
        return isinstance(known, InfeasiblePlanError) or not known.complete
    try:
        return not plan_experiment(spec, PARAMS, limits, graded=False).complete
    except InfeasiblePlanError:
        return True


@pytest.mark.parametrize(
    "case, knob, step",
    [
        ("short", "duration", SHORT_DURATION_STEP),
        ("short", "levels", 1.0),
        ("cold", "floor", 1.0),
    ],
)
def test_advised_change_plans_complete_and_one_step_less_does_not(
    case, knob, step, short_advice, cold_advice, tmp_path
):
    advice, spec, limits = {
        "short": (short_advice, SHORT, SHORT_LIMITS),
        "cold": (cold_advice, COLD, COLD_LIMITS),
    }[case]
    assert not advice.complete
    item = _item(advice, knob)
    assert item.status == VERIFIED, item.line
    assert item.adjacent and math.isclose(abs(item.value - item.failing_value), step)
    # the advised change is complete by separate code: the planner's own plan of that
    # very request (recorded while advise planned it), else planned again from scratch
    spec_ok, lim_ok = _request(spec, limits, item.changes)
    plan = _known_complete(spec_ok, lim_ok)
    if plan is None:
        plan = plan_experiment(spec_ok, PARAMS, lim_ok)
    assert plan.complete
    assert _independently_complete(plan, spec_ok, lim_ok, tmp_path)
    # one grid step less generous does not work (the bound proves it, or the planner
    # finds no complete plan there either)
    field = next(iter(item.changes))
    less = {field: item.failing_value}
    if knob == "levels":
        less = {"levels_required": item.failing_value}
    spec_no, lim_no = _request(spec, limits, less)
    if (spec_no, lim_no) == (spec, limits) and item.failing_reason == "planned":
        # the request itself, which advise planned and found incomplete: planning it
        # again here would repeat that very computation
        assert not advice.complete
    else:
        assert _fails(spec_no, lim_no, item.failing_reason)
    # the request itself is less generous still: it fails too
    assert item.current == {"duration": 110.0, "levels": 4.0, "floor": -52.0}[knob]


def test_advice_lines_say_what_is_proven_and_what_is_verified(short_advice):
    dur = _item(short_advice, "duration")
    bound = duration_lower_bound(SHORT, PARAMS, SHORT_LIMITS).lower_bound_min
    assert dur.line.startswith(f"duration: needs at least {bound:.0f} min (proven)")
    assert f"within {dur.value:g} min: verified by a complete plan" in dur.line
    assert dur.changes == {"duration_max_min": dur.value}
    assert dur.plan is not None and dur.plan.complete and dur.plan.duration_min <= dur.value
    lines = short_advice.lines()
    assert len(lines) == 3 and all(line.startswith("short: ") for line in lines)


def test_a_knob_that_does_not_bind_is_skipped_without_planning():
    # within 130 min the bound leaves the request open, and a lower floor moves neither
    # the bound nor the notes (within 110 min, where the bound excludes the request at
    # any floor, short_advice's floor is proven impossible instead)
    settings = AdviceSettings(knobs=("floor",))
    adv = advise(
        SHORT, PARAMS, PLANNABLE_LIMITS, assume_incomplete=True, settings=settings, backend="serial"
    )
    (floor,) = adv.items
    assert floor.status == NOT_BINDING and floor.plans == 0
    assert "does not bind" in floor.line


def test_unreachable_bins_are_proven_impossible_for_every_knob_but_the_floor():
    lim = dataclasses.replace(Limits(), chamber_min_c=-52.0)
    settings = AdviceSettings(knobs=("duration", "rates", "levels", "ceiling"))
    adv = advise(
        UNREACHABLE, PARAMS, lim, assume_incomplete=True, settings=settings, backend="serial"
    )
    by = {k.knob: k for k in adv.items}
    for knob in ("duration", "rates", "levels", "ceiling"):
        assert by[knob].status == PROVEN_IMPOSSIBLE and by[knob].plans == 0, by[knob].line
        assert "some bin cannot be crossed at all" in by[knob].line
    assert not math.isfinite(adv.bound_min)


def test_a_complete_plan_needs_nothing(short_advice):
    dur = _item(short_advice, "duration")
    spec, lim = _request(SHORT, SHORT_LIMITS, dur.changes)
    adv = advise(spec, PARAMS, lim, plan=dur.plan, backend="serial")
    assert adv.complete and adv.items == ()
    assert adv.lines() == ["short: the request is planned complete; nothing to change"]


def test_the_plan_budget_is_honoured():
    settings = AdviceSettings(knobs=("levels",), max_plans=1)
    adv = advise(
        SHORT, PARAMS, PLANNABLE_LIMITS, assume_incomplete=True, settings=settings, backend="serial"
    )
    (item,) = adv.items
    assert item.plans == 1
    # the one plan is the most generous value (2 levels): verified, but maybe not the least
    assert item.status == VERIFIED and item.value == 2.0
    assert item.adjacent is False and "a smaller change may also do" in item.line


def test_advice_frame_and_dict_have_one_row_per_knob(short_advice):
    frame = short_advice.to_frame()
    assert list(frame["knob"]) == ["duration", "floor", "levels"]
    doc = json.loads(json.dumps(short_advice.to_dict()))  # JSON-serialisable
    assert [k["knob"] for k in doc["knobs"]] == ["duration", "floor", "levels"]
    assert "plan" not in doc["knobs"][0]


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"knobs": ("speed",)}, "knobs must be some of"),
        ({"duration_step_min": 2.5}, "whole minutes"),
        ({"duration_factor": 1.0}, "duration_factor must be in"),
        ({"max_plans": 0}, "max_plans must be a whole number >= 1"),
        ({"time_budget_s": float("nan")}, "time_budget_s must be a finite number"),
    ],
)
def test_bad_settings_are_one_line_errors(kw, words):
    with pytest.raises(ParameterError, match=words) as exc:
        AdviceSettings(**kw)
    assert "\n" not in str(exc.value)


def test_plan_advise_writes_advice_and_the_verifying_plan(tmp_path, capsys):
    # 110 min: the bound proves 4 and 3 levels impossible, so the plan (graded, 2 levels)
    # and the advice (one plan, at 2 levels) cost seconds; at 130 min each level
    # count is planned in full, over a minute for the same CLI path
    out = tmp_path / "p"
    argv = ["plan", "--working", "0", "6", "--levels", "4", "--duration-max-min", "110"]
    argv += ["--advise", "--advise-knobs", "levels", "--out", str(out), "--quiet"]
    assert main(argv) == 1  # the plan itself stays incomplete
    text = capsys.readouterr().out
    assert "what would make plan complete" in text and "levels: " in text
    frame = pd.read_csv(out / "advice.csv")
    assert list(frame["knob"]) == ["levels"] and frame["status"][0] == VERIFIED
    doc = json.loads((out / "plan.json").read_text(encoding="utf-8"))
    (knob,) = doc["advice"]["knobs"]
    levels = int(knob["value"])
    res = table_check(out / "advice" / "levels" / "steps.csv", (0.0, 6.0), levels)
    assert res["coverage"] == 1.0
    sub = json.loads((out / "advice" / "levels" / "plan.json").read_text(encoding="utf-8"))
    assert sub["complete"] and sub["spec"]["levels_required"] == levels


def test_campaign_advise_on_an_experiment_that_cannot_be_planned(tmp_path, capsys):
    toml = tmp_path / "c.toml"
    toml.write_text(
        "[limits]\nchamber_min_c = -52\n[settings]\nlevels_required = 3\n"
        '[[experiment]]\nname = "U"\nworking_lo_c = -50\nworking_hi_c = -46\n'
        "approx_lo_c = -52\napprox_hi_c = -36\n",
        encoding="utf-8",
    )
    out = tmp_path / "out"
    argv = ["campaign", str(toml), "--advise", "--advise-knobs", "duration", "levels"]
    assert main([*argv, "--out", str(out), "--backend", "serial", "--quiet"]) == 1
    text = capsys.readouterr().out
    assert "COULD NOT BE PLANNED" in text
    assert "duration: not even" in text and "(proven: some bin cannot be crossed at all)" in text
    frame = pd.read_csv(out / "U" / "advice.csv")
    assert list(frame["status"]) == [PROVEN_IMPOSSIBLE, PROVEN_IMPOSSIBLE]
    assert list(frame["plans"]) == [0, 0]


def test_advise_refuses_a_robust_box(tmp_path):
    argv = ["plan", "--working", "0", "6", "--advise", "--robust-dt0-c", "2:4"]
    assert main([*argv, "--out", str(tmp_path / "r"), "--quiet"]) == 2
