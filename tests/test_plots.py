"""The pictures say what they show (issue 13, item 7): every pass in its own colour with its
direction, start and end marked, the bin grid; coverage bars that show the margin; limits
and step marks on programme plots; residuals without a line across a logging gap."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from schedsyn import Limits, Programme, ThermalParams, plots, simulate, trajectory_coverage
from schedsyn.coverage import distinct_levels, level_separation

PROG = Programme([70, 20, 70, 30, 60, 60, 40], [-1.0, 0.0, 1.0, 0.0, -0.8, 0.9, -0.3])


def _runs_of_sign(g):
    """Independent count of the sign runs of g (no merging; g has no zeros here)."""
    s = np.sign(g)
    return 1 + int(np.sum(s[1:] != s[:-1]))


def test_phase_portrait_colours_each_sweep_and_marks_direction_start_end_and_bins():
    traj = simulate(PROG, ThermalParams(2400.0, -1.0))  # cools from the first sample on
    g = traj.g_c_per_min
    assert np.all(g != 0)
    ax = plots.phase_plot(traj.t_c, g, region=(-30.0, -10.0))
    sweeps = [ln for ln in ax.get_lines() if ln.get_label().startswith("sweep ")]
    assert len(sweeps) == _runs_of_sign(g)
    assert len({tuple(ln.get_color()) for ln in sweeps}) == len(sweeps)  # own colours
    # each arrow points the way T moves: right while heating (g > 0), left while cooling
    arrows = [a for a in ax.texts if getattr(a, "arrow_patch", None) is not None]
    assert len(arrows) == len(sweeps)
    for line, arrow in zip(sweeps, arrows, strict=True):
        heating = "heating" in line.get_label()
        dx = arrow.xy[0] - arrow.xyann[0]
        assert (dx > 0) == heating, line.get_label()
        assert np.mean(line.get_ydata()) > 0 if heating else np.mean(line.get_ydata()) < 0
    labels = [ln.get_label() for ln in ax.get_lines()]
    start = ax.get_lines()[labels.index(next(lb for lb in labels if lb.startswith("start")))]
    end = ax.get_lines()[labels.index(next(lb for lb in labels if lb.startswith("end")))]
    assert start.get_xdata()[0] == traj.t_c[0] and end.get_xdata()[0] == traj.t_c[-1]
    bins = [ln for ln in ax.get_lines() if ln.get_color() == plots.REGION_COLOUR]
    assert sorted(ln.get_xdata()[0] for ln in bins) == list(np.arange(-30.0, -9.0, 1.0))
    assert "°C" in ax.get_xlabel() and "°C/min" in ax.get_ylabel()
    assert ax.get_legend() is not None


def test_sweeps_of_merges_only_tiny_runs():
    g = np.array([1.0] * 50 + [-1.0] * 50 + [1.0] + [-1.0] * 49 + [1.0] * 50)
    assert plots.sweeps_of(g) == [(0, 50), (50, 150), (150, 200)]
    assert plots.sweeps_of(g, min_samples=1) == [
        (0, 50),
        (50, 100),
        (100, 101),
        (101, 150),
        (150, 200),
    ]


@pytest.mark.parametrize("seed", range(6))
def test_level_separation_is_the_best_subset_by_brute_force(seed):
    rng = np.random.default_rng(seed)
    g = rng.uniform(-1, 1, size=int(rng.integers(3, 9)))
    for k in range(2, g.size + 1):
        # widest min-gap over all subsets of k passes, by enumeration
        best = max(np.min(np.diff(np.sort(c))) for c in itertools.combinations(g, k))
        assert level_separation(g, k) == pytest.approx(best, abs=1e-12)
        assert distinct_levels(g, level_separation(g, k)) >= k
    assert np.isnan(level_separation(g, g.size + 1))


def test_coverage_bars_show_the_margin_and_name_the_tightest_bin():
    from schedsyn import read_steps

    # the paper-like baseline over W1: bins short, bins with 1.01 delta, bins with 2 delta
    traj = simulate(read_steps("data/baseline_exp1_steps.csv"), ThermalParams())
    rep = trajectory_coverage(traj, -50, -30, levels_required=6, delta_c_per_min=0.05)
    ax = plots.coverage_plot(rep)
    sep = rep.separations_c_per_min
    ok = rep.covered
    i = int(np.flatnonzero(ok)[np.argmin(sep[ok])])
    title = ax.get_title()
    assert f"[{rep.grid.lower_c[i]:g}, {rep.grid.lower_c[i] + 1:g}) °C" in title
    assert f"{sep[i] / 0.05:.2f} Δ" in title
    # one number per covered bin above its bar: its separation relative to delta
    texts = [t.get_text() for t in ax.texts]
    want = ["≥2" if r >= 2 else f"{r:.2f}" for r in sep[ok] / 0.05]
    assert texts == want
    bars = ax.patches[: rep.grid.n_bins]
    assert [b.get_height() for b in bars] == rep.levels.tolist()
    colour = {int(k): tuple(bars[k].get_facecolor()) for k in range(rep.grid.n_bins)}
    thin = [k for k in np.flatnonzero(ok) if sep[k] / 0.05 < 1.1]
    wide = [k for k in np.flatnonzero(ok) if sep[k] / 0.05 >= 1.9]
    short = list(np.flatnonzero(~ok))
    assert thin and wide and short
    assert {colour[k] for k in thin}.isdisjoint({colour[k] for k in wide})
    assert {colour[k] for k in short}.isdisjoint({colour[k] for k in thin + wide})


def test_programme_plot_marks_limits_and_step_boundaries():
    traj = simulate(PROG, ThermalParams())
    lim = Limits()
    ax = plots.programme_plot(traj, region=(-30, -10), limits=lim, programme=PROG)
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert any(lb.startswith("chamber limits -70 .. 80 °C") for lb in labels)
    assert any(lb.startswith("device limits -52 .. 62 °C") for lb in labels)
    steps = [ln for ln in ax.get_lines() if ln.get_color() == "0.55"]
    assert sorted(ln.get_xdata()[0] for ln in steps) == pytest.approx(PROG.starts_min[1:])
    assert ax.get_xlabel() == "time, min" and ax.get_ylabel() == "temperature, °C"


def test_residual_plot_keeps_both_curves_and_breaks_at_gaps():
    t = np.concatenate([np.arange(0, 100, 1.0), np.arange(150, 200, 1.0)])
    before = np.sin(t / 10)
    after = 0.1 * before
    ax = plots.residual_plot(t, before, after, labels=("base", "augmented"))
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    b, a = lines["base"], lines["augmented"]
    assert a.get_zorder() > b.get_zorder() and b.get_linewidth() > a.get_linewidth()
    for ln in (a, b):
        x, y = ln.get_xdata(), ln.get_ydata()
        k = int(np.flatnonzero(np.isnan(y))[0])  # a break ...
        assert x[k - 1] == 99.0 and x[k + 1] == 150.0  # ... exactly at the gap
        assert np.isnan(y).sum() == 1
    assert "°C" in ax.get_ylabel()


def test_saving_leaves_the_backend_alone(tmp_path):
    import matplotlib

    before = matplotlib.get_backend()
    ax = plots.phase_plot([0, 1, 2], [0.1, 0.2, 0.1])
    path = plots.save_figure(ax, tmp_path / "p.png")
    assert path.stat().st_size > 1000 and matplotlib.get_backend() == before
