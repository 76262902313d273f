"""The level-split structures (issue 12): more sweeps than levels, the levels shared
unevenly between the directions, the surplus sweeps of a direction repeating a level.

Levels are counted on all passes of a bin (the largest subset ``delta`` apart), so where
one direction is squeezed (a chamber ceiling or floor near the region, a slow chamber) the
other may give more levels; the search tries such structures only when the usual ones
found nothing that fits.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from pathlib import Path

import pytest
from independent import assert_plan_complete

from schedsyn.campaign import load_campaign
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import plan_experiment
from schedsyn.planner.bands import BAND_SAFETY_C_PER_MIN, Band, order_bands, transit_band
from schedsyn.planner.search import level_splits

ROOT = Path(__file__).resolve().parents[1]
KNOTS = (-0.25, 1.5, 8.5, 10.25)


def flat(direction: int, rank: int, lo: float, hi: float, top: bool = False) -> Band:
    return Band(direction, rank, KNOTS, (lo,) * 4, (hi,) * 4, top=top)


def brute_turnaround_total(directions, bands, tau_min, heat, cool) -> float:
    """Sum over consecutive sweeps of the full-rate time for g to go from the previous
    exit gradient to the next entry gradient: g(t) = U + (g0 - U) exp(-t / tau)."""
    total, g_prev = 0.0, 0.0
    for d, b in zip(directions, bands, strict=True):
        u = heat if d > 0 else -cool
        g_to = d * b.lo_c_per_min[0]  # flat bands: entry = exit speed = lo
        ratio = (g_prev - u) / (g_to - u)
        total += tau_min * math.log(ratio) if ratio > 1 else 0.0
        g_prev = d * b.lo_c_per_min[0]
    return total


def test_order_bands_with_repeated_bands_is_the_least_turnaround_assignment():
    # C H C H C H C H: four heating levels, two cooling levels and two cooling transits
    directions = [-1, +1] * 4
    heat = [flat(+1, r, 0.1 * r, 0.1 * r + 0.04, top=r == 4) for r in (1, 2, 3, 4)]
    cool = [flat(-1, 1, 0.05, 0.09), flat(-1, 2, 0.15, 0.2, top=True)]
    spec = load_campaign(ROOT / "data" / "bench" / "m45-m35-floor-m52.toml").experiments[0]
    transit = transit_band(cool[-1], spec)
    # given fastest first, so that the order given is not the best one (checked below)
    pool = {+1: heat[::-1], -1: [transit, transit, *cool[::-1]]}
    params = ThermalParams(tau_s=2400.0, dt0_c=3.0)
    limits = Limits(rate_min_c_per_min=-0.5, rate_max_c_per_min=1.5)
    order = order_bands(directions, pool, params, limits)
    assert [b.direction for b in order] == directions
    # every band is used as often as it was given (the transit twice)
    for d in (+1, -1):
        got = [b for b in order if b.direction == d]
        assert sorted(map(repr, got)) == sorted(map(repr, pool[d]))
    # and the order is the least total turnaround over every assignment (brute force)
    best = math.inf
    for h in itertools.permutations(heat):
        for c in set(itertools.permutations(pool[-1])):
            seq = [c[k // 2] if d < 0 else h[k // 2] for k, d in enumerate(directions)]
            best = min(best, brute_turnaround_total(directions, seq, params.tau_min, 1.5, 0.5))
    given = [pool[d][k // 2] for k, d in enumerate(directions)]
    assert brute_turnaround_total(directions, given, params.tau_min, 1.5, 0.5) > best + 1.0
    got_total = brute_turnaround_total(directions, order, params.tau_min, 1.5, 0.5)
    assert got_total == pytest.approx(best, rel=1e-9, abs=1e-9)


def test_transit_band_keeps_its_direction_and_top_and_opens_down_to_the_floor():
    spec = load_campaign(ROOT / "data" / "bench" / "m45-m35-floor-m52.toml").experiments[0]
    fastest = flat(-1, 3, 0.3, 0.35, top=True)
    t = transit_band(fastest, spec)
    assert t.direction == -1
    assert t.hi_c_per_min == fastest.hi_c_per_min
    floor = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    assert t.lo_c_per_min == pytest.approx((floor,) * 4)
    # still delta from every pass of the other direction
    assert 2 * min(t.lo_c_per_min) >= spec.delta_c_per_min


def test_level_splits_give_the_squeezed_direction_fewer_levels_best_width_first():
    sep = 0.062
    n_by_dir = {+1: 4, -1: 4}  # eight sweeps
    rooms = {+1: 0.5, -1: 0.15}  # cooling squeezed (a floor close to the region)
    splits = level_splits(6, n_by_dir, rooms, sep)
    assert splits, "some split must be offered"
    for s in splits:
        assert s[+1] + s[-1] == 6
        assert 1 <= s[-1] < s[+1] <= 4
    # ranked by the narrower direction's band width (room - (l - 1) sep) / l, by hand:
    # (4 heat, 2 cool): min((0.5 - 0.186) / 4, (0.15 - 0.062) / 2) = min(0.0785, 0.044)
    # (5, 1) is out (five heating levels in four sweeps)
    assert splits[0] == {+1: 4, -1: 2}
    assert len(splits) == 1
    # the other way round when heating is squeezed (a ceiling close to the region)
    flipped = level_splits(6, n_by_dir, {+1: 0.07, -1: 0.5}, sep)
    assert flipped[0] == {+1: 2, -1: 4}
    # more sweeps: more splits, best first
    wide = level_splits(7, {+1: 5, -1: 4}, {+1: 0.6, -1: 0.2}, sep)
    widths = [min((r - (s[d] - 1) * sep) / s[d] for d, r in ((+1, 0.6), (-1, 0.2))) for s in wide]
    assert widths == sorted(widths, reverse=True)
    assert {s[-1] for s in wide} == {2, 3}  # (4 heat, 3 cool) and (5, 2); not (6, 1) > 5


@pytest.mark.slow
def test_a_ceiling_close_to_the_region_plans_complete_with_levels_shared(tmp_path):
    """data/bench/50-60-ceiling-62 with 5 levels: near 60 degC a 62 degC chamber ceiling
    caps heating at ~0.1 degC/min, so three heating levels 0.062 apart do not fit and the
    usual structures (3 heating + 2 cooling sweeps, or 2 + 3 starting the other way) got
    stuck at 4 levels. With six sweeps, 2 heating + 3 cooling levels and one heating
    transit, every bin gets 5. Planned here on its hot 2 degC (58..60, approximation from
    48): the same structures get stuck there and the six-sweep one is taken (without the
    level-split family the search ends elsewhere, with no such structure note), in about
    10 s of CPU instead of 23 (12 on 56..60)."""
    config = load_campaign(ROOT / "data" / "bench" / "50-60-ceiling-62.toml")
    spec = config.experiments[0]
    assert (spec.working_lo_c, spec.working_hi_c, spec.approx_lo_c) == (50.0, 60.0, 40.0)
    spec = replace(spec, working_lo_c=58.0, approx_lo_c=48.0, levels_required=5)
    params, limits = config.params, config.limits
    plan = plan_experiment(spec, params, limits)
    # the independent re-check (scipy's ODE solver, plain counting), every limit
    assert_plan_complete(plan, tmp_path)
    assert plan.complete
    assert plan.levels_planned is None  # the requested levels, not a graded plan
    # the plan says how it shares the levels (six sweeps, two heating levels)
    (note,) = [n for n in plan.notes if n.startswith("structure:")]
    assert "6 sweeps for 5 levels" in note and "2 heating and 3 cooling" in note
