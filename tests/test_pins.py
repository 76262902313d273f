"""Edge bins held by their crossing times (:class:`~schedsyn.planner.lp.EdgePins`, issue 12).

Held pointwise to its band, a sweep leaves the region at band speed and turns round
outside it; held by the crossing times of its two edge bins it may brake and speed up
inside them, as long as it crosses each bin within the band's range of times (so its
mean gradient there, the level the bin is counted at, is in the band). Checked here
against scipy's ODE solver and a plain count of the passes (``independent``), not the
planner's own response maths.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from independent import assert_plan_complete, ode_trajectories

from schedsyn.model import FirstOrderLag
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, LpStats, lp, plan_experiment, search
from schedsyn.planner.bands import BAND_SAFETY_C_PER_MIN, order_bands
from schedsyn.planner.lp import PIN_EXIT_C, PIN_MIN, Context, Responses
from schedsyn.planner.request import Scenario, first_directions, sweep_directions
from schedsyn.planner.search import Guided, candidate_bands, place_sweep

PARAMS = ThermalParams()
#: a slow chamber: turning round is dear, which is where the pins pay
SLOW = {"rate_min_c_per_min": -0.5, "rate_max_c_per_min": 1.5}
SPEC = ExperimentSpec("pins", -10.0, 0.0, -15.0, 5.0)
LIMITS = Limits(duration_max_min=900.0, **SLOW)
#: crossing times are read off a 0.01-min simulation
DT_MIN = 0.01


def _chamber(u: np.ndarray, seg_min: float, start_c: float = 20.0):
    times = seg_min * np.arange(u.size + 1)
    return times, start_c + np.concatenate(([0.0], np.cumsum(u * seg_min)))


def test_the_temperature_between_samples_is_the_ode_solution():
    """``Responses.t_rows_at`` (T at any time, affine in the rates) against ``solve_ivp``
    at random times between the planner's minute samples."""
    rng = np.random.default_rng(3)
    seg, n = 3.0, 40
    u = rng.uniform(-1.0, 3.0, n)
    responses = Responses([Scenario(PARAMS, FirstOrderLag(PARAMS))], n, seg, Limits())
    times = np.sort(rng.uniform(0.0, n * seg - 1.0, 30))
    a, b = responses.t_rows_at(0, times)
    ours = a @ u + b
    t, temp, _ = ode_trajectories(*_chamber(u, seg), PARAMS.tau_s, PARAMS.dt0_c, dt_min=DT_MIN)
    assert np.max(np.abs(ours - np.interp(times, t, temp[0]))) < 2e-4
    # cached rows are the same rows
    a2, b2 = responses.t_rows_at(0, times[::-1])
    np.testing.assert_allclose(a2 @ u + b2, ours[::-1])


def test_the_rows_between_samples_are_kept_in_bounded_memory(monkeypatch):
    """A long pinned search asks for many times: the cache is emptied when full, and the
    rows asked for after that are still right."""
    monkeypatch.setattr(lp, "T_ROWS_CACHE_MAX", 10)
    seg, n = 3.0, 20
    u = np.linspace(-1.0, 2.0, n)
    responses = Responses([Scenario(PARAMS, FirstOrderLag(PARAMS))], n, seg, Limits())
    first = 0.37 + np.arange(4) * 7.1
    a, b = responses.t_rows_at(0, first)
    expect = a @ u + b
    for k in range(1, 8):
        # a time already kept beside new ones, as a search asks: the emptying must not
        # lose the kept one
        times = np.concatenate(([first[0]], 0.37 + k + np.arange(3) * 7.1))
        a, b = responses.t_rows_at(0, times)
        assert len(responses._t_rows) <= 10
        np.testing.assert_allclose((a @ u + b)[0], expect[0])
    a, b = responses.t_rows_at(0, first)
    np.testing.assert_allclose(a @ u + b, expect)


def _runs_in(temp: np.ndarray, lo: float, hi: float) -> list[tuple[int, int]]:
    """Maximal runs of samples with ``lo <= T < hi`` (a plain loop), as (first, last)."""
    runs, start = [], None
    for i, x in enumerate(temp):
        inside = lo <= x < hi
        if inside and start is None:
            start = i
        if not inside and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, temp.size - 1))
    return runs


def _pinned_structure():
    """Context, sample limit, sweep directions and ordered bands of a pinned guided
    structure on SPEC / LIMITS."""
    seg = SPEC.segment_min
    max_seg = int(LIMITS.duration_max_min // seg)
    responses = Responses([Scenario(PARAMS, FirstOrderLag(PARAMS))], max_seg, seg, LIMITS)
    ctx = Context(SPEC, LIMITS, responses, LpStats())
    directions = sweep_directions(SPEC, first_directions(SPEC, LIMITS)[0])
    n_by_dir = {d: directions.count(d) for d in (+1, -1)}
    sep = SPEC.delta_c_per_min + BAND_SAFETY_C_PER_MIN
    bands = candidate_bands(Guided(0.9, 0.04, pinned=True), SPEC, [PARAMS], LIMITS, n_by_dir, sep)
    assert bands is not None
    return ctx, max_seg, directions, order_bands(directions, bands, PARAMS, LIMITS)


@pytest.fixture(scope="module")
def pinned_sweeps():
    """The first four sweeps of a pinned guided structure, placed as the greedy does."""
    seg = SPEC.segment_min
    ctx, max_seg, directions, order = _pinned_structure()
    u, windows = np.zeros(0), []
    for d, band in list(zip(directions, order, strict=True))[:4]:
        res = place_sweep(ctx, u, d, band, max_seg, pinned=True)
        if res is None:
            res = place_sweep(ctx, u, d, band, max_seg, slow=True, pinned=True)
        assert res is not None
        u_new, win = res
        assert win.pins is not None
        u = np.concatenate((u, u_new))
        windows.append(win)
    t, temp, grad = ode_trajectories(*_chamber(u, seg), PARAMS.tau_s, PARAMS.dt0_c, dt_min=DT_MIN)
    return windows, t, temp[0], grad[0]


def test_a_pinned_sweep_crosses_its_edge_bins_within_its_pins(pinned_sweeps):
    """Each sweep enters its entry and exit bins within PIN_MIN of the planned times and
    crosses each within the band's range of times, one pass each; its mean gradient there
    is between bin / max and bin / min; it ends PIN_EXIT_C beyond the region."""
    windows, t, temp, grad = pinned_sweeps
    w = SPEC.grid.bin_c
    lo, hi = SPEC.working_lo_c, SPEC.working_hi_c
    tol = 2 * DT_MIN
    for win in windows:
        p, d = win.pins, win.direction
        bins = ((lo, lo + w), (hi - w, hi))
        entry_bin, exit_bin = (bins[0], bins[1]) if d > 0 else (bins[1], bins[0])
        for (b_lo, b_hi), t0, dmin, dmax in (
            (entry_bin, p.entry_min, p.entry_min_min, p.entry_max_min),
            (exit_bin, p.exit_min, p.exit_min_min, p.exit_max_min),
        ):
            runs = [
                (a, b)
                for a, b in _runs_in(temp, b_lo, b_hi)
                if t0 - tol <= t[a] <= t0 + PIN_MIN + tol
            ]
            assert len(runs) == 1, (win.direction, win.band.rank, b_lo, t0, runs)
            a, b = runs[0]
            # it goes through (enters on one side, leaves on the other)
            assert d * temp[max(a - 1, 0)] < d * temp[min(b + 1, temp.size - 1)]
            took = t[b + 1] - t[a]
            assert dmin - tol <= took <= dmax + tol, (took, dmin, dmax)
            mean = float(np.mean(d * grad[a : b + 1]))
            assert w / (dmax + tol) - 0.005 <= mean <= w / (dmin - tol) + 0.005
        end = int(round(p.end_min / DT_MIN))
        edge = lo if d < 0 else hi
        assert d * temp[end] >= d * edge + PIN_EXIT_C - 1e-3


def test_pinned_sweeps_brake_inside_the_exit_bin(pinned_sweeps):
    """The point of the pins: some sweep leaves the region slower than its band allows at
    the edge (a pointwise band would hold it to that speed until past the edge)."""
    windows, t, temp, grad = pinned_sweeps
    lo, hi = SPEC.working_lo_c, SPEC.working_hi_c
    slower = 0
    for win in windows:
        d = win.direction
        edge = lo if d < 0 else hi
        i = int(np.argmax((d * temp >= d * edge) & (t >= win.pins.exit_min)))
        band_lo, _ = win.band.bounds(edge)
        slower += d * grad[i] < float(band_lo) - 0.01
    assert slower >= 1


#: a slow chamber on [-10, 0] degC in 480 min: the guided design's usual structure needs
#: 498 min, pinned it plans complete in about 462
BUDGET = Limits(duration_max_min=480.0, **SLOW)
GUIDED = Guided(0.9, 0.04)


def test_where_the_usual_structure_overruns_the_pinned_one_plans_complete(tmp_path, monkeypatch):
    """One design only, to keep it short: its usual structure does not fit the budget, the
    same design pinned plans complete (re-checked by scipy's ODE solver and plain
    counting) and no shorter than the proven bound."""
    monkeypatch.setattr(search, "CANDIDATES", (GUIDED,))
    monkeypatch.setattr(search, "PINNED", (replace(GUIDED, pinned=True),))
    monkeypatch.setattr(search, "SECOND_CHANCE", ())  # another profile would do too
    usual = search.synthesise(
        SPEC, [PARAMS], BUDGET, [FirstOrderLag(PARAMS)], None, LpStats(), max_candidates=1
    )
    assert usual.best is None  # the case is as meant
    plan = plan_experiment(SPEC, PARAMS, BUDGET, graded=False, effort_s=None)
    assert plan.complete
    assert_plan_complete(plan, tmp_path)
    assert plan.duration_lower_bound_min is not None
    assert plan.duration_lower_bound_min <= plan.duration_min <= BUDGET.duration_max_min


def test_a_pinned_sweep_that_fits_nowhere_scans_pin_scan_min_of_starts(monkeypatch):
    """Every start minute matters to a pinned sweep, but not for ever: one that fits at
    no start scans every minute for PIN_SCAN_MIN from the first start the rate limits do
    not rule out, then gives up (before, all of MAX_TRANSITION_MIN: 20-45 s per stuck
    sweep on w4-ceiling-65). The LP is made to find nothing; the starts asked are read
    off the windows it was given."""
    ctx, max_seg, directions, order = _pinned_structure()
    d, band = directions[0], order[0]
    starts: list[int] = []
    window = lp.SubLP.window

    def recording_window(self, win, **kwargs):
        starts.append(win.start_sample)
        return window(self, win, **kwargs)

    def nothing_fits(self, cost, l1_weight=0.0):
        self.ctx.stats.record("infeasible", 0.0)  # solved, not ruled out by bounds
        return None

    monkeypatch.setattr(lp.SubLP, "window", recording_window)
    monkeypatch.setattr(lp.SubLP, "solve_direct", nothing_fits)
    assert place_sweep(ctx, np.zeros(0), d, band, max_seg, pinned=True) is None
    span = int(round(search.PIN_SCAN_MIN / lp.SAMPLE_MIN))
    assert sorted(set(starts)) == list(range(starts[0], starts[0] + span))
