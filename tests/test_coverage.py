"""The coverage metric on hand-built trajectories whose answer is known by construction."""

import numpy as np
import pytest

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
