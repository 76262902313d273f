"""The graded search's effort stays bounded (issue 13 item 6; schedsyn.planner.core:
_fewer_levels, _Effort): few level counts are searched, from a bound-guided first guess,
and an effort limit stops the optional searches without losing the graded answer."""

from __future__ import annotations

import dataclasses
import time

import pytest
from independent import table_check

from schedsyn.errors import InfeasiblePlanError, ParameterError
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, core, plan_experiment
from schedsyn.planner.lp import lp_nonzeros_solved
from schedsyn.planner.search import STOPPED

#: [-10, 0] degC asked for 10 levels in 240 min: the bound proves 10 (344 min) impossible;
#: 4 levels fit, 5 do not (found by the search).
SPEC = ExperimentSpec("E", -10.0, 0.0, -20.0, 10.0, levels_required=10)
LIMITS = Limits(duration_max_min=240.0)


class _Searched(list):
    """The level counts searched, in order; ``complete[k]``: did the search for k levels
    find a complete plan (False: it raised or came back incomplete)?"""

    def __init__(self) -> None:
        super().__init__()
        self.complete: dict[int, bool] = {}


def _spy_searched(mp: pytest.MonkeyPatch) -> _Searched:
    """The level counts the planner is asked to plan complete-or-nothing, in order, and
    what each search found."""
    calls = _Searched()
    inner = core._plan

    def spy(spec, *args, **kwargs):
        if not (kwargs.get("require_complete") and not kwargs.get("graded")):
            return inner(spec, *args, **kwargs)
        k = spec.levels_required
        calls.append(k)
        calls.complete[k] = False
        result = inner(spec, *args, **kwargs)
        calls.complete[k] = bool(result.complete)
        return result

    mp.setattr(core, "_plan", spy)
    return calls


@pytest.fixture()
def searched(monkeypatch):
    return _spy_searched(monkeypatch)


#: [-5, 0] degC asked for 10 levels in 190 min: the bound allows 2-6 levels (7 need 206
#: min); its first guess is 4, which fits, and 5 does not (found by the search). SPEC is
#: the same case with searches half as long again.
FAR = ExperimentSpec("F", -5.0, 0.0, -15.0, 10.0, levels_required=10)
FAR_LIMITS = Limits(duration_max_min=190.0)


@pytest.fixture(scope="module")
def unlimited():
    """FAR planned with no effort limit, and the level counts that plan searched: made
    once for the tests that need it (half a minute of LPs)."""
    with pytest.MonkeyPatch.context() as mp:
        calls = _spy_searched(mp)
        plan = plan_experiment(FAR, limits=FAR_LIMITS, effort_s=None)
    return plan, calls


def test_the_graded_search_plans_few_counts_and_finds_the_most_levels(unlimited, tmp_path):
    """Out of reach by far, the request costs two searches (the first guess and the count
    above it), not one per count below 10; the answer has the most levels a complete plan
    reaches: its count is complete by the independent check, the next one is not."""
    plan, searched = unlimited
    assert len(searched) <= 2, searched
    k = plan.levels_planned
    assert k is not None and k >= 2 and not plan.complete
    check = table_check(plan.programme.to_csv(tmp_path / "g.csv"), (-5.0, 0.0), k)
    assert check["coverage"] == 1.0 and check["min_levels"] >= k
    assert check["duration_min"] <= FAR_LIMITS.duration_max_min + 1e-9
    # one more level was searched, with no effort limit, and no complete plan found (the
    # search for k + 1 on its own, as `plan_experiment(..., require_complete=True)`)
    assert searched.complete.get(k + 1) is False, (searched, searched.complete)
    assert searched.complete[k] is True
    note = next(n for n in plan.notes if n.startswith("GRADED"))
    assert f"plans {k} in every bin" in note and "levels searched: " in note


def test_an_effort_limit_keeps_the_first_guess_and_says_what_it_skipped(searched, unlimited):
    """Spent at once, the effort limit still lets the graded search plan its first guess
    (so a graded answer comes back) but nothing after it, and the plan says so."""
    plan = plan_experiment(SPEC, limits=LIMITS, effort_s=1e-6)
    assert len(searched) == 1
    assert plan.levels_planned == searched[0]
    assert any("effort limit" in n and "effort_s" in n for n in plan.notes)
    assert not any("effort limit" in n for n in unlimited[0].notes)  # no limit: no note


def test_a_caller_can_cancel_every_search():
    """``stop`` returning True ends the search for the requested plan too: nothing is
    planned and the planner says so instead of running on."""
    spec = dataclasses.replace(SPEC, levels_required=3)
    with pytest.raises(InfeasiblePlanError, match="stopped"):
        plan_experiment(spec, limits=LIMITS, stop=lambda: True)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan"), float("inf")])
def test_effort_s_must_be_a_positive_time(bad):
    with pytest.raises(ParameterError, match="effort_s"):
        plan_experiment(SPEC, limits=LIMITS, effort_s=bad)


def test_an_unlikely_request_gets_its_graded_plan_first(searched, monkeypatch):
    """3 levels in [-4, 0] degC within 135 min: the bound (about 110 min) allows it, but
    no complete plan known came within 1.3x of its bound. The graded plan (2 levels) is
    made first, and the search for 3 runs only while the effort lasts: spent at once, the
    answer is the graded plan, and the plan says the search was cut. (SPEC at 5 levels
    in 240 min is the same case, with a search three times as long.)"""
    spec = ExperimentSpec("U", -4.0, 0.0, -14.0, 10.0, levels_required=3)
    limits = Limits(duration_max_min=135.0)
    bound = core.duration_lower_bound(spec, limits=limits).lower_bound_min
    assert bound <= limits.duration_max_min < bound * core.GUESS_BOUND_RATIO
    stopped: list[bool] = []  # per search for 3 levels: was it cut?
    inner = core.synthesise

    def spy(spec_, *args, **kwargs):
        result = inner(spec_, *args, **kwargs)
        if spec_.levels_required == 3:
            stopped.append(STOPPED in result.reasons)
        return result

    monkeypatch.setattr(core, "synthesise", spy)
    # the band search's effort logic (the timetable stage, after it, would complete it)
    cut = plan_experiment(spec, limits=limits, effort_s=1e-6, timetable=False)
    assert searched[0] < 3 and cut.levels_planned == searched[0]
    assert any("effort limit" in n for n in cut.notes)
    assert stopped == [True]
    # no limit: the search for 3 runs to its end. One nonzero per reference second spends
    # any finite limit at once (the default's 45 s too), so None must not act as one
    monkeypatch.setattr(core, "LP_NONZEROS_PER_EFFORT_S", 1)
    full = plan_experiment(spec, limits=limits, effort_s=None, timetable=False)
    assert not any("effort limit" in n for n in full.notes)
    assert stopped[-1] is False
    assert full.complete or full.levels_planned is not None


def test_the_effort_limit_counts_lp_work_not_time():
    """Neither waiting nor other CPU work spends the effort: only the LPs solved do, so
    where a search is cut does not depend on the machine or its load."""
    effort = core._Effort(lp_nonzeros_solved(), 1e-3, None, answered=True)  # 400 nonzeros
    time.sleep(0.3)  # wall time passes
    t0 = time.process_time()
    while time.process_time() - t0 < 0.3:  # CPU time passes (another job's work)
        pass
    assert not effort.spent()
    plan_experiment(dataclasses.replace(SPEC, levels_required=2), limits=LIMITS)
    assert effort.spent() and effort.hit


def test_the_same_request_gets_the_same_answer_on_a_slower_machine(monkeypatch):
    """The effort limit cuts the graded search at the same place whatever the clocks say:
    a machine (or a load) that makes every CPU second count ten times gives the same
    plan, with the same levels and the same steps. Planned without the timetable stage:
    the effort limit is the band search's (the stage, after it, counts its work in LP
    solves, a budget the limit only scales; here it found nothing in half a minute per run,
    and the plan was the band search's either way). The limit must bite in both runs:
    the first run's note is asserted, the slow run's must be the same."""
    spec = dataclasses.replace(SPEC, levels_required=5)
    first = plan_experiment(spec, limits=LIMITS, effort_s=5.0, timetable=False)
    clocks = {"process_time": time.process_time, "perf_counter": time.perf_counter}
    monkeypatch.setattr(core.time, "process_time", lambda: 10.0 * clocks["process_time"]())
    monkeypatch.setattr(core.time, "perf_counter", lambda: 10.0 * clocks["perf_counter"]())
    slow = plan_experiment(spec, limits=LIMITS, effort_s=5.0, timetable=False)
    assert any("effort limit" in n for n in first.notes), first.notes  # the limit bit
    assert slow.levels_planned == first.levels_planned
    assert slow.programme.to_frame().equals(first.programme.to_frame())
    assert [n for n in slow.notes if "effort" in n] == [n for n in first.notes if "effort" in n]


def test_when_no_count_is_complete_the_part_of_the_region_that_fits_is_planned(tmp_path):
    """A floor 2.7 degC below the region's cold edge (1.3 degC dT0, tau 3600 s): cooling
    to past -31 degC is a crawl, so no level count gives a plan of the whole region in
    240 min. The graded search's plan of a sub-region with fewer levels is returned
    (it was dropped: 'no programme covers any part', exit 2), its coverage re-counted
    from an independent ODE solution of the exported table."""
    spec = ExperimentSpec(
        "cold",
        -31.0,
        -25.0,
        -33.0,
        -20.0,
        levels_required=4,
        delta_c_per_min=0.08,
        segment_min=15.0,
    )
    params = ThermalParams(tau_s=3600.0, dt0_c=1.3)
    limits = Limits(chamber_min_c=-33.7, duration_max_min=240.0)
    plan = plan_experiment(spec, params, limits)
    assert not plan.complete and plan.status == "incomplete"
    k = plan.levels_planned
    assert k is not None and 2 <= k < spec.levels_required
    (note,) = [n for n in plan.notes if n.startswith("PARTIAL")]
    assert f"even {k} levels" in note
    # the cold-edge limit is named, and a bin that cannot be reached is not hidden
    assert any("chamber floor -33.7" in n for n in plan.notes)
    steps = plan.programme.to_csv(tmp_path / "steps.csv")
    res = table_check(
        steps,
        (spec.working_lo_c, spec.working_hi_c),
        k,
        tau_s=params.tau_s,
        dt0_c=params.dt0_c,
        delta=spec.delta_c_per_min,
    )
    assert 0.0 < res["coverage"] < 1.0  # part of the region at k levels, not all
    assert f"{k} levels to {res['coverage']:.0%} of the bins" in note
    assert plan.coverage.min_levels == res["min_levels"]
    assert res["duration_min"] <= limits.duration_max_min + 1e-9
    assert res["device_min_c"] >= limits.device_min_c
    assert abs(res["chamber_end_c"] - limits.end_c) <= limits.end_tol_c
    rates = res["rates_c_per_min"]
    assert (
        limits.rate_min_c_per_min - 1e-3
        <= rates.min()
        <= rates.max()
        <= limits.rate_max_c_per_min + 1e-3
    )


@pytest.mark.parametrize("complete_at", [3, None])
def test_the_walk_down_searches_sub_regions_for_the_first_guess_and_the_fewest_only(
    monkeypatch, complete_at
):
    """Red team: planning 6 levels in [5, 35] degC for a tau-600 s device, the graded
    search walked from 5 levels down to 3 and searched sub-regions at every count (90 of
    its 245 s), although a lower count's complete plan replaces those partial plans. The
    first guess and the fewest levels (the partial that covers most, when no count
    completes) still get them."""
    import types

    seen: dict[int, bool] = {}

    def fake_plan(spec_, params, limits, progress, effort, **kwargs):
        seen[spec_.levels_required] = effort.partials
        if complete_at is not None and spec_.levels_required <= complete_at:
            return types.SimpleNamespace(complete=True)
        raise InfeasiblePlanError("none", best_coverage=0.5)

    monkeypatch.setattr(core, "_plan_nominal", fake_plan)
    monkeypatch.setattr(
        core, "duration_lower_bound", lambda *a, **k: types.SimpleNamespace(lower_bound_min=1.0)
    )
    spec = dataclasses.replace(SPEC, levels_required=7)
    effort = core._Effort(lp_nonzeros_solved(), None, None)
    found = core._fewer_levels(spec, ThermalParams(), LIMITS, None, effort, partials=[])
    if complete_at is None:
        assert found is None and seen == {6: True, 5: False, 4: False, 3: False, 2: True}
    else:
        assert found is not None and found.levels == 3
        assert seen == {6: True, 5: False, 4: False, 3: False}
    assert effort.partials  # restored for the searches after the walk


def test_a_small_effort_limit_shrinks_the_timetable_stage_once_a_plan_is_in_hand(monkeypatch):
    """Red team: with --effort-s 15 the timetable stage still spent its full 500 LPs
    (110 s) after the graded answer. With a plan in hand its budget scales with the limit;
    with nothing in hand, or no limit, it keeps the whole budget."""
    import types

    from schedsyn.planner import timetable

    budgets: list[int] = []

    def fake_search(*args, max_lps, **kwargs):
        budgets.append(max_lps)
        return None

    monkeypatch.setattr(timetable, "timetable_search", fake_search)
    band = types.SimpleNamespace(duration_min=300.0)
    for plan, effort_s in [(band, 15.0), (band, None), (None, 15.0), (band, 1e-6), (band, 90.0)]:
        core._timetable_plan(SPEC, ThermalParams(), LIMITS, None, None, plan, 0.0,
                             effort_s=effort_s)  # fmt: skip
    full = timetable.MAX_LPS
    assert budgets == [round(full * 15.0 / core.EFFORT_S), full, full, core.MIN_TIMETABLE_LPS,
                       full]  # fmt: skip
