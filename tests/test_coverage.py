"""The coverage metric on hand-built trajectories whose answer is known by construction."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schedsyn import BinGrid, coverage_report, read_steps, simulate
from schedsyn.coverage import distinct_levels, passes


def _sweep(t_from, t_to, grad, n=200):
    return np.linspace(t_from, t_to, n), np.full(n, grad)


def test_grid_edges_and_index():
    g = BinGrid(-50, -30)
    assert g.n_bins == 20
    assert g.index(np.array([-50.0, -49.0001, -30.0, -30.0001, -51, np.nan])).tolist() == [
        0,
        0,
        -1,
        19,
        -1,
        -1,
    ]


def test_grid_rejects_partial_bins():
    with pytest.raises(ValueError, match="whole number"):
        BinGrid(0, 10.5)


def test_monotone_sweeps_count_one_pass_per_bin_each():
    grid = BinGrid(0, 5)
    segs = [_sweep(-1, 6, g) for g in (0.1, 0.2, 0.3)] + [_sweep(6, -1, -0.1)]
    t = np.concatenate([s[0] for s in segs])
    g = np.concatenate([s[1] for s in segs])
    rep = coverage_report(t, g, grid, levels_required=4, delta_c_per_min=0.05)
    assert rep.pass_counts.tolist() == [4] * 5
    assert rep.levels.tolist() == [4] * 5
    assert rep.coverage == 1.0
    np.testing.assert_allclose(np.sort(rep.gradients[2]), [-0.1, 0.1, 0.2, 0.3])


def test_close_gradients_count_as_one_level():
    grid = BinGrid(0, 2)
    segs = [_sweep(-1, 3, g) for g in (0.10, 0.13, 0.16, 0.30)]
    t = np.concatenate([s[0] for s in segs])
    g = np.concatenate([s[1] for s in segs])
    rep = coverage_report(t, g, grid, levels_required=3, delta_c_per_min=0.05)
    # {0.10, 0.16, 0.30} is the largest subset 0.05 apart
    assert rep.levels.tolist() == [3, 3]
    rep2 = coverage_report(t, g, grid, levels_required=3, delta_c_per_min=0.1)
    assert rep2.levels.tolist() == [2, 2]
    assert rep2.coverage == 0.0


def test_pass_gradient_is_mean_over_the_run_and_partial_regions():
    grid = BinGrid(0, 3)
    # 0.5 -> 2.1 and back to 0.9, gradient varying within each run; 3.5 is outside
    t = np.array([0.5, 0.8, 1.2, 1.4, 2.1, 1.4, 0.9, 3.5])
    g = np.array([9.0, 9.0, 1.0, 2.0, 7.0, 3.0, 9.0, 5.0])
    kb, mg, first, last = passes(t, g, grid)
    assert kb.tolist() == [0, 1, 2, 1, 0]
    assert mg.tolist() == [9.0, 1.5, 7.0, 3.0, 9.0]
    assert first.tolist() == [0, 2, 4, 5, 6] and last.tolist() == [1, 3, 4, 5, 6]
    rep = coverage_report(t, g, grid, levels_required=2, delta_c_per_min=0.05)
    assert rep.pass_counts.tolist() == [2, 2, 1]
    assert rep.levels.tolist() == [1, 2, 1]  # bin 0 passed twice at the same gradient
    assert rep.coverage == pytest.approx(1 / 3)
    assert rep.short_bins() == [(0.0, 1.0, 1), (2.0, 3.0, 1)]


def test_distinct_levels_greedy_is_maximal():
    assert distinct_levels([0, 0.04, 0.08, 0.12], 0.05) == 2
    assert distinct_levels([0.3, 0.0, 0.1, 0.2], 0.1) == 4
    assert distinct_levels([], 0.05) == 0


def test_adding_samples_never_lowers_coverage_of_dense_sim():
    prog = read_steps("data/baseline_exp1_steps.csv")
    coarse = simulate(prog, dt_min=0.5)
    dense = simulate(prog, dt_min=0.1)
    g = BinGrid(-50, -30)
    rc = coverage_report(coarse.t_c, coarse.g_c_per_min, g)
    rd = coverage_report(dense.t_c, dense.g_c_per_min, g)
    # the baseline is paper-like: partial coverage, and the metric is stable in dt
    assert 0.3 < rd.coverage < 0.8
    assert abs(rd.coverage - rc.coverage) <= 0.1


def test_report_frame_has_per_bin_columns():
    t, g = _sweep(0, 3, 0.2)
    frame = coverage_report(t, g, BinGrid(0, 3), levels_required=1).to_frame()
    assert list(frame.columns[:5]) == [
        "bin_lo_c",
        "bin_hi_c",
        "passes",
        "distinct_levels",
        "covered",
    ]
    assert frame["passes"].tolist() == [1, 1, 1]


# ---------------------------------------------------------------------------------------
# the distinct-level threshold, from its definition
# ---------------------------------------------------------------------------------------
def _passes_at(grads, lo=0.0, hi=4.0):
    """One monotone sweep over [lo - 1, hi + 1] per gradient (one pass per bin each)."""
    segs = [_sweep(lo - 1.0, hi + 1.0, g) for g in grads]
    return np.concatenate([s[0] for s in segs]), np.concatenate([s[1] for s in segs])


def test_levels_exactly_delta_apart_count_and_closer_ones_do_not():
    """Six passes exactly delta apart are six levels; six passes 0.95 delta apart are three
    (a level needs a full delta from the previous one: 0, 1.9 delta, 3.8 delta)."""
    delta = 0.05
    grid = BinGrid(0, 4)
    at = 0.1 + delta * np.arange(6)
    rep = coverage_report(*_passes_at(at), grid, levels_required=6, delta_c_per_min=delta)
    assert rep.pass_counts.tolist() == [6] * 4
    assert rep.levels.tolist() == [6] * 4 and rep.complete
    close = 0.1 + 0.95 * delta * np.arange(6)
    rep = coverage_report(*_passes_at(close), grid, levels_required=6, delta_c_per_min=delta)
    assert rep.pass_counts.tolist() == [6] * 4
    assert rep.levels.tolist() == [3] * 4 and rep.coverage == 0.0
    # the same passes, judged with a threshold they all meet
    rep = coverage_report(*_passes_at(close), grid, 6, delta_c_per_min=0.9 * delta)
    assert rep.levels.tolist() == [6] * 4


def _largest_separated_subset(units, min_gap):
    """Brute force over every subset: the largest whose members differ pairwise by at
    least ``min_gap`` (integers, so the comparison is exact)."""
    for size in range(len(units), 0, -1):
        for sub in itertools.combinations(units, size):
            if all(abs(a - b) >= min_gap for a, b in itertools.combinations(sub, 2)):
                return size
    return 0


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 120), min_size=0, max_size=9))
def test_distinct_levels_is_the_largest_separated_subset(units):
    """Gradients on a lattice of delta/20: pairs 18 or 19 steps apart are closer than delta,
    pairs 20 apart are exactly delta apart; brute force decides the true answer."""
    delta = 0.05
    grads = np.array(units, dtype=float) * (delta / 20)
    assert distinct_levels(grads, delta) == _largest_separated_subset(units, 20)
