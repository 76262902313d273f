"""Fewest experiments for a range: the experiments tile the range with no gap, each step
table is complete by separate code (scipy's ODE solver and plain level counting), each
region is as wide as the planner can make it, and the proven minimum never exceeds the
fewest any split can have (checked against a brute force over every region)."""

from __future__ import annotations

import dataclasses
import fcntl
import functools
import json
import math
import pickle

import numpy as np
import pandas as pd
import pytest
from independent import table_check

import schedsyn.split as split_module
from schedsyn.campaign import load_campaign
from schedsyn.cli import main
from schedsyn.errors import InfeasiblePlanError, ParameterError
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, duration_lower_bound, plan_experiment
from schedsyn.split import SplitSettings, proven_minimum, split_range

pytestmark = [
    pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning"),
    pytest.mark.slow,
]

# [-5, 5] degC, 2 levels: one 10-degC experiment needs at least 79.5 min (proven bound),
# so within 78 min the range takes two (the split: [-5, -1] in 76 min, [-1, 5] in 74; four
# plans of about 8 s, where [-10, 10] within 93 min took five of 12-15 s)
RANGE = (-5.0, 5.0)
LEVELS = 2
LIMITS = dataclasses.replace(Limits(), duration_max_min=78.0)
# approximation regions 3 degC wider than the working ones (the paper's 10 would reach past
# both ends of so short a range from every region, and the rule would be seen clipped only)
MARGIN = 3.0


#: How split_range plans each probe (no effort limit, not graded: "is there a complete
#: plan?"), and whether the planner planned complete each request the module's split
#: planned: (spec without its name, params, limits) -> bool
PLAN_KW = {"effort_s": None, "graded": False}
PLANNED: dict[tuple, bool] = {}


def _key(spec, params, limits) -> tuple:
    return (dataclasses.replace(spec, name="key"), params, limits)  # the name plans nothing


def _split(out) -> int:
    """The split, remembering the planner's own answer to each probe it plans, so that a
    test asking about the very same request (equal spec but for its name, params, limits,
    and split's keywords) reads that answer instead of repeating a search of 10 s."""
    argv = ["split", "--range", *(f"{x:g}" for x in RANGE), "--levels", str(LEVELS)]
    argv += ["--duration-max-min", f"{LIMITS.duration_max_min:g}"]
    argv += ["--approx-margin-c", f"{MARGIN:g}"]
    argv += ["--backend", "serial", "--out", str(out), "--quiet"]
    real = split_module.plan_experiment

    def record(spec, params, limits, **kw):
        if kw != PLAN_KW:  # not the question the tests ask: not remembered
            return real(spec, params, limits, **kw)
        try:
            plan = real(spec, params, limits, **kw)
        except InfeasiblePlanError:
            PLANNED[_key(spec, params, limits)] = False
            raise
        PLANNED[_key(spec, params, limits)] = plan.complete
        return plan

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(split_module, "plan_experiment", record)
        return main(argv)


@pytest.fixture(scope="module")
def split_out(tmp_path_factory, worker_id):
    """The split, run once per test run: under pytest-xdist the module's tests may land on
    both workers, and the second one reads the first one's output and answers (pytest-xdist's
    documented way to run a fixture once: a lock in the run's shared temporary folder)."""
    root = tmp_path_factory.getbasetemp()
    if worker_id != "master":
        root = root.parent  # shared by this run's workers
    shared = root / "split-once"
    with open(root / "split-once.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        done = shared / "answers.pickle"
        if not done.exists():
            rc = _split(shared / "out")
            done.write_bytes(pickle.dumps((rc, dict(PLANNED))))
        rc, answers = pickle.loads(done.read_bytes())
    PLANNED.update(answers)
    return rc, shared / "out"


def test_split_covers_the_range_with_no_gap_each_plan_complete_by_separate_code(split_out):
    rc, out = split_out
    assert rc == 0
    frame = pd.read_csv(out / "split.csv")
    assert len(frame) >= 2  # one experiment cannot do it in 78 min (see below)
    lo = frame["working_lo_c"].to_numpy()
    hi = frame["working_hi_c"].to_numpy()
    assert lo[0] == RANGE[0] and hi[-1] == RANGE[1]
    assert np.array_equal(lo[1:], hi[:-1])  # consecutive: no gap, no overlap
    assert np.all(hi > lo)
    for name, a, b in zip(frame["experiment"], lo, hi, strict=True):
        steps = out / name / "steps.csv"
        res = table_check(steps, (a, b), LEVELS)  # scipy + plain counting
        assert res["coverage"] == 1.0, name
        assert res["duration_min"] <= LIMITS.duration_max_min
        assert res["chamber_start_c"] == 20.0 and abs(res["chamber_end_c"] - 20.0) <= 0.5
        rates = res["rates_c_per_min"]
        assert rates.min() >= LIMITS.rate_min_c_per_min - 1e-3
        assert rates.max() <= LIMITS.rate_max_c_per_min + 1e-3
        doc = json.loads((out / name / "plan.json").read_text(encoding="utf-8"))
        assert doc["complete"] and doc["spec"]["levels_required"] == LEVELS


def test_approximation_regions_follow_the_paper_rule_inside_the_range(split_out):
    _, out = split_out
    frame = pd.read_csv(out / "split.csv")
    for _, row in frame.iterrows():
        assert row["approx_lo_c"] == max(row["working_lo_c"] - MARGIN, RANGE[0])
        assert row["approx_hi_c"] == min(row["working_hi_c"] + MARGIN, RANGE[1])
    # both sides seen inside the range, not only clipped to its ends
    assert (frame["approx_lo_c"] > RANGE[0]).any() and (frame["approx_hi_c"] < RANGE[1]).any()
    assert SplitSettings().approx_margin_c == 10.0  # the paper's, by default


def test_each_region_but_the_last_is_the_widest_the_planner_completes(split_out):
    rc, out = split_out
    frame = pd.read_csv(out / "split.csv")
    assert rc == 0 and len(frame) >= 2 and frame["working_hi_c"].iloc[-1] == RANGE[1]
    params = ThermalParams()
    for _, row in frame.iloc[:-1].iterrows():
        a, b = row["working_lo_c"], row["working_hi_c"] + 1.0  # one degree wider
        approx = (max(a - MARGIN, RANGE[0]), min(b + MARGIN, RANGE[1]))
        spec = ExperimentSpec("wider", a, b, *approx, LEVELS)
        assert not _plans_complete(spec, params), (a, b)
    # and the whole range in one experiment does not fit either
    whole = ExperimentSpec("whole", *RANGE, *RANGE, levels_required=LEVELS)
    assert not _plans_complete(whole, params)


def _plans_complete(spec, params) -> bool:
    """Does the planner, asked as split_range asks it, plan ``spec`` complete? (Its answer
    when the split planned this very request, else planned here.)"""
    known = PLANNED.get(_key(spec, params, LIMITS))
    if known is not None:
        return known
    try:
        return plan_experiment(spec, params, LIMITS, **PLAN_KW).complete
    except InfeasiblePlanError:  # not even part of the region fits
        return False


def test_the_campaign_file_plans_the_same_experiments_again(split_out):
    _, out = split_out
    cfg = load_campaign(out / "campaign.toml")
    frame = pd.read_csv(out / "split.csv")
    assert [e.name for e in cfg.experiments] == list(frame["experiment"])
    for e, (_, row) in zip(cfg.experiments, frame.iterrows(), strict=True):
        assert (e.working_lo_c, e.working_hi_c) == (row["working_lo_c"], row["working_hi_c"])
        assert (e.approx_lo_c, e.approx_hi_c) == (row["approx_lo_c"], row["approx_hi_c"])
        assert e.levels_required == LEVELS
    assert cfg.limits == LIMITS and cfg.params == ThermalParams()


@functools.cache
def _bound_ok(a: float, b: float, budget: float) -> bool:
    spec = ExperimentSpec("b", a, b, a, b, levels_required=6)
    lim = dataclasses.replace(Limits(), duration_max_min=budget)
    # as split.py screens: without the levels' dual
    bound = duration_lower_bound(spec, ThermalParams(), lim, tighten=False)
    return bound.lower_bound_min <= budget


def test_proven_minimum_is_a_lower_bound_on_every_split_brute_force():
    """Brute force: the fewest consecutive regions (whole degrees) each of which the bound
    does not exclude. Any split the planner could verify is one of these, so the proven
    minimum must not exceed it; with the bound monotone in the width they are equal."""
    # 6 degC (21 regions) where each experiment reaches 2 degC: three needed
    lo, hi, budget = -40, -34, 175.0
    n, jumps = proven_minimum(
        lo, hi, None, dataclasses.replace(Limits(), duration_max_min=budget), {}
    )
    best = {lo: 0}
    for a in range(lo, hi):
        if a not in best:
            continue
        for b in range(a + 1, hi + 1):
            if _bound_ok(float(a), float(b), budget):
                best[b] = min(best.get(b, math.inf), best[a] + 1)
    assert n is not None and hi in best
    assert 1 <= n <= best[hi]
    assert n >= 3  # the case is meant to need a split
    # each jump stops just before an edge the bound really excludes
    for x, r in jumps:
        assert _bound_ok(float(x), float(r), budget)
        if r < hi:
            assert not _bound_ok(float(x), float(r + 1), budget)


def test_an_uncoverable_bin_is_proven_and_nothing_is_planned():
    lim = dataclasses.replace(Limits(), chamber_min_c=-52.0)  # the device cannot pass -49
    res = split_range(-50, -40, None, lim, {"levels_required": 2}, backend="serial")
    assert res.min_experiments is None and res.uncoverable_bin_c == -50.0
    assert res.plans == 0 and not res.covered and res.experiments == ()
    assert "cannot be covered by any experiment" in res.lines()[0]


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"lo_c": 0.0, "hi_c": 0.5}, "whole number"),
        ({"lo_c": 60.0, "hi_c": -50.0}, "runs backwards: give the low end first (--range -50 60)"),
        ({"lo_c": 0.0, "hi_c": 80.0}, "outside its limits"),
        ({"spec_settings": {"levels": 3}}, "unknown experiment setting"),
    ],
)
def test_bad_input_is_a_one_line_error(kw, words):
    args = {"lo_c": -10.0, "hi_c": 10.0, **kw}
    with pytest.raises(ParameterError) as exc:
        split_range(backend="serial", **args)
    assert "\n" not in str(exc.value) and words in str(exc.value)


@pytest.mark.parametrize(
    "kw",
    [{"max_experiments": 0}, {"max_plans": 0}, {"approx_margin_c": -1.0}, {"name_prefix": "a/b"}],
)
def test_bad_split_settings_are_refused(kw):
    with pytest.raises(ParameterError) as exc:
        SplitSettings(**kw)
    assert "\n" not in str(exc.value)
