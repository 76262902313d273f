"""Sweeps out of the chamber's reach are ruled out before their starts are scanned.

Where a chamber floor or ceiling is close to the region, a band may ask for passes
faster than the first-order lag can ever make there: ``g = (Tk + dT0 - T) / tau`` at
every instant, with Tk within the chamber limits. :func:`search.band_out_of_reach` and
:func:`search.pins_out_of_reach` say so up front, so :func:`search.place_sweep` does not
scan hundreds of LPs for a sweep that cannot fit (a 4 degC region 4 degC above the
floor: 20 s of search, now 0.5 s, the same answer).

The cap is checked against scipy's ODE solver, and the rule against the scan itself:
every placement it rules out is scanned again without it and fails.
"""

from __future__ import annotations

import numpy as np
import pytest
from independent import ode_trajectories

from schedsyn.model import FirstOrderLag
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, LpStats, plan_experiment, search
from schedsyn.planner.bands import Band
from schedsyn.planner.lp import Context, Responses
from schedsyn.planner.request import Scenario

PARAMS = ThermalParams()
#: [-48, -45] degC over a -52 degC floor: the coldest bins allow cooling at 0.025 degC/min
NEAR_FLOOR = ExperimentSpec("near-floor", -48.0, -45.0, -52.0, -35.0, levels_required=2)
NEAR_FLOOR_LIMITS = Limits(chamber_min_c=-52.0, duration_max_min=300.0)


def _ctx(spec: ExperimentSpec, limits: Limits, params: ThermalParams = PARAMS) -> Context:
    n_seg = int(limits.duration_max_min // spec.segment_min)
    responses = Responses(
        [Scenario(params, FirstOrderLag(params))], n_seg, spec.segment_min, limits
    )
    return Context(spec, limits, responses, LpStats())


def _flat(direction: int, speed: float, knots: tuple[float, ...]) -> Band:
    n = len(knots)
    return Band(direction, 1, knots, (speed,) * n, (speed + 0.04,) * n)


def test_the_cap_is_the_fastest_a_device_crosses_at_the_chamber_floor():
    """With the chamber held at its floor from any earlier state, the device (scipy)
    cools through a temperature at exactly the cap there; a band asking 20 % less is
    left to the search, 20 % more is ruled out (both directions, other tau and dT0)."""
    for params, d in ((PARAMS, -1), (ThermalParams(tau_s=1500.0, dt0_c=2.0), -1), (PARAMS, +1)):
        limits = Limits(chamber_min_c=-52.0, chamber_max_c=62.0)
        edge_c = -48.25 if d < 0 else 58.25
        # the chamber sits at its limit; the device starts 6 degC on the far side
        held_c = limits.chamber_min_c if d < 0 else limits.chamber_max_c
        knots_t = np.array([0.0, 400.0])
        knots_tk = np.array([held_c, held_c])
        t0_c = edge_c - d * 6.0
        _, temp, grad = ode_trajectories(
            knots_t, knots_tk, params.tau_s, params.dt0_c, t0_c=t0_c, dt_min=0.01
        )
        k = int(np.argmin(np.abs(temp[0] - edge_c)))
        cap_ode = d * grad[0][k] + d * (temp[0][k] - edge_c) / params.tau_min
        spec = ExperimentSpec("cap", -48.0, -45.0, -52.0, -35.0)
        if d > 0:
            spec = ExperimentSpec("cap", 55.0, 58.0, 45.0, 60.0)
        ctx = _ctx(spec, limits, params)
        knots = (edge_c, edge_c + 4.0) if d < 0 else (edge_c - 4.0, edge_c)
        assert not search.band_out_of_reach(ctx, d, _flat(d, 0.8 * cap_ode, knots))
        assert search.band_out_of_reach(ctx, d, _flat(d, 1.2 * cap_ode, knots))


def test_robust_and_augmented_models_are_never_ruled_out():
    """The cap is exact for one first-order model only: with a second scenario (a robust
    box) the check stands aside, however far out of reach the band is."""
    limits = Limits(chamber_min_c=-52.0)
    params_b = ThermalParams(tau_s=2600.0)
    responses = Responses(
        [Scenario(p, FirstOrderLag(p)) for p in (PARAMS, params_b)],
        20,
        NEAR_FLOOR.segment_min,
        limits,
    )
    ctx = Context(NEAR_FLOOR, limits, responses, LpStats())
    assert ctx.robust
    assert not search.band_out_of_reach(ctx, -1, _flat(-1, 1.0, (-48.25, -44.75)))


@pytest.fixture(scope="module")
def ruled_out():
    """Every place_sweep call of planning NEAR_FLOOR that the rule stopped, with its
    arguments and the LP solves it took, and the notes of the plan (no complete plan: a
    partial one for [-47, -45] °C, whose notes name the floor; it was an error "no
    programme covers any part" before the bound-guided sub-regions)."""
    calls = []
    real = search.place_sweep

    def spy(ctx, u_fixed, d, band, max_seg, slow=False, every_sample=False, pinned=False):
        before = ctx.stats.solves
        res = real(ctx, u_fixed, d, band, max_seg, slow, every_sample, pinned)
        stopped = (
            search.pins_out_of_reach(ctx, d, band, search.pinned_timings(ctx.spec, band, slow)[1])
            if pinned and search.pinned_timings(ctx.spec, band, slow) is not None
            else (not pinned and search.band_out_of_reach(ctx, d, band))
        )
        if stopped:
            args = (ctx, u_fixed, d, band, max_seg, slow, every_sample, pinned)
            calls.append((args, ctx.stats.solves - before, res))
        return res

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(search, "place_sweep", spy)
        # the band search alone: since 2026-12-03 the timetable stage plans this request
        # complete (249 min), and the rule under test is the band search's
        plan = plan_experiment(NEAR_FLOOR, PARAMS, NEAR_FLOOR_LIMITS, timetable=False)
    assert not plan.complete and plan.coverage.coverage < 1.0
    return calls, " ".join(plan.notes)


def test_a_ruled_out_sweep_fails_the_full_scan_too(ruled_out):
    """The rule is a shortcut, never a different answer: placements it stopped (pointwise
    and pinned) are scanned again with it switched off, every start and timing, and none
    fits. The stopped calls took no LP at all."""
    calls, error = ruled_out
    assert "chamber floor -52 °C" in error
    kinds = {args[7] for args, _, _ in calls}
    assert kinds == {False, True}, "both a pointwise and a pinned window are ruled out"
    assert all(solves == 0 and res is None for _, solves, res in calls)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(search, "band_out_of_reach", lambda *a, **k: False)
        mp.setattr(search, "pins_out_of_reach", lambda *a, **k: False)
        for pinned in (False, True):
            args = next(a for a, _, _ in calls if a[7] is pinned)
            ctx = args[0]
            before = ctx.stats.solves
            assert search.place_sweep(*args) is None
            assert ctx.stats.solves - before > 20  # the full scan ran


def test_a_pinned_edge_bin_cannot_be_crossed_faster_than_at_the_chamber_floor():
    """Pinned windows hold their edge bins by crossing times: the exit bin [-48, -47] of
    a cooling sweep must be crossed within its pins' most minutes. The fastest crossing
    there is the device's with the chamber at its floor all along (scipy); pins allowing
    10 % less than that are ruled out, 10 % more are left to the search."""
    limits = Limits(chamber_min_c=-52.0)
    ctx = _ctx(NEAR_FLOOR, limits)
    _, temp, _ = ode_trajectories(
        np.array([0.0, 600.0]),
        np.array([-52.0, -52.0]),
        PARAMS.tau_s,
        PARAMS.dt0_c,
        t0_c=-44.0,
        dt_min=0.01,
    )
    entered = np.flatnonzero(temp[0] < -47.0)[0]
    left = np.flatnonzero(temp[0] < -48.0)[0]
    fastest_min = 0.01 * (left - entered)
    band = _flat(-1, 0.01, (-48.25, -44.75))  # slow enough for the inner bins
    roomy = 1000.0  # the entry bin [-46, -45] is not what is tested
    assert search.pins_out_of_reach(ctx, -1, band, (0.0, roomy, 0.0, 0.9 * fastest_min))
    assert not search.pins_out_of_reach(ctx, -1, band, (0.0, roomy, 0.0, 1.1 * fastest_min))
    # and the entry bin alike: the cooling sweep enters at the top, [-46, -45]
    entry_min = 0.01 * (np.flatnonzero(temp[0] < -46.0)[0] - np.flatnonzero(temp[0] < -45.0)[0])
    assert search.pins_out_of_reach(ctx, -1, band, (0.0, 0.9 * entry_min, 0.0, roomy))
    assert not search.pins_out_of_reach(ctx, -1, band, (0.0, 1.1 * entry_min, 0.0, roomy))
