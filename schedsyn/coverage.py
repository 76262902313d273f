"""The coverage metric: how many distinct gradients each 1 degC bin is passed with.

Definition (used by plans, runs, sweeps and benchmarks alike):

* Simulate densely (every 0.1 min). Split the working region ``[lo, hi]`` into bins
  ``[lo + k, lo + k + 1)`` (:class:`~schedsyn.grid.BinGrid`).
* A **pass** through a bin is a maximal run of consecutive samples with T inside the bin;
  its gradient is the mean g over the run.
* The **distinct levels** of a bin is the size of the largest subset of its passes whose
  gradients differ pairwise by at least ``delta`` (greedy from the smallest is optimal on
  a line).
* **Coverage** is the fraction of bins with at least ``levels_required`` distinct levels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import ParameterError
from .grid import BinGrid


def passes(temps_c: np.ndarray, grads_c_per_min: np.ndarray, grid: BinGrid):
    """All passes: ``(bin_index, mean_gradient, first_sample, last_sample)`` arrays."""
    t = np.asarray(temps_c, dtype=float)
    g = np.asarray(grads_c_per_min, dtype=float)
    if t.shape != g.shape or t.ndim != 1:
        raise ParameterError(
            f"temperatures and gradients must be 1-D of equal length, got {t.shape} and {g.shape}"
        )
    k = grid.index(t)
    if t.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, np.zeros(0), empty, empty
    change = np.flatnonzero(np.diff(k) != 0) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [t.size]))  # exclusive
    kb = k[starts]
    keep = kb >= 0
    starts, ends, kb = starts[keep], ends[keep], kb[keep]
    # g is NaN where an estimator has no value: such samples do not count in the mean
    gz = np.where(np.isfinite(g), g, 0.0)
    cs = np.concatenate(([0.0], np.cumsum(gz)))
    cn = np.concatenate(([0], np.cumsum(np.isfinite(g))))
    n = cn[ends] - cn[starts]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_g = (cs[ends] - cs[starts]) / n
    ok = n > 0
    return kb[ok], mean_g[ok], starts[ok], ends[ok] - 1


def distinct_levels(gradients: np.ndarray, delta_c_per_min: float) -> int:
    """Largest subset of ``gradients`` whose members differ pairwise by >= ``delta``."""
    g = np.sort(np.asarray(gradients, dtype=float))
    count, last = 0, -np.inf
    for x in g:
        if x - last >= delta_c_per_min - 1e-12:
            count += 1
            last = x
    return count


def level_separation(gradients: np.ndarray, levels_required: int) -> float:
    """The widest separation at which ``gradients`` still hold ``levels_required`` levels.

    ``max d`` such that ``distinct_levels(gradients, d) >= levels_required``: how far
    apart the bin's best ``levels_required`` passes are, in degC/min. Compared with the
    required ``delta`` it says how thin the margin is (``separation / delta`` just above
    1: one slightly different gradient and the bin falls short). NaN when the bin has
    fewer passes than ``levels_required``; ``inf`` when one level is required.

    The optimum is one of the pairwise differences (the greedy count only changes
    there), found by bisection over them.
    """
    g = np.sort(np.asarray(gradients, dtype=float))
    k = int(levels_required)
    if g.size < k:
        return float("nan")
    if k <= 1:
        return float("inf")
    cand = np.unique((g[None, :] - g[:, None])[np.triu_indices(g.size, 1)])
    lo, hi = 0, cand.size - 1  # distinct_levels(g, cand[0]) >= k always holds
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if distinct_levels(g, float(cand[mid])) >= k:
            lo = mid
        else:
            hi = mid - 1
    return float(cand[lo])


@dataclass(frozen=True, slots=True)
class CoverageReport:
    """Per-bin pass counts, distinct levels and gradients for one working region."""

    grid: BinGrid
    levels_required: int
    delta_c_per_min: float
    pass_counts: np.ndarray
    levels: np.ndarray
    gradients: tuple[np.ndarray, ...]

    @property
    def covered(self) -> np.ndarray:
        return self.levels >= self.levels_required

    @property
    def coverage(self) -> float:
        """Fraction of bins with at least ``levels_required`` distinct levels."""
        return float(np.mean(self.covered))

    @property
    def min_levels(self) -> int:
        return int(self.levels.min())

    @property
    def separations_c_per_min(self) -> np.ndarray:
        """Per bin, the widest separation of ``levels_required`` of its passes, degC/min
        (:func:`level_separation`; NaN where a bin has fewer passes)."""
        return np.array([level_separation(g, self.levels_required) for g in self.gradients])

    @property
    def complete(self) -> bool:
        return bool(np.all(self.covered))

    def short_bins(self) -> list[tuple[float, float, int]]:
        """``(lo_c, hi_c, levels)`` of every bin below the requirement."""
        lo = self.grid.lower_c
        return [
            (float(lo[i]), float(lo[i] + self.grid.bin_c), int(self.levels[i]))
            for i in np.flatnonzero(~self.covered)
        ]

    def to_frame(self) -> pd.DataFrame:
        lo = self.grid.lower_c
        return pd.DataFrame(
            {
                "bin_lo_c": lo,
                "bin_hi_c": lo + self.grid.bin_c,
                "passes": self.pass_counts,
                "distinct_levels": self.levels,
                "covered": self.covered,
                "gradients_c_per_min": [
                    " ".join(f"{x:.4f}" for x in np.sort(g)) for g in self.gradients
                ],
            }
        )

    def summary(self) -> str:
        short = self.short_bins()
        text = (
            f"coverage of [{self.grid.lo_c:g}, {self.grid.hi_c:g}] °C: {self.coverage:.1%} "
            f"({int(self.covered.sum())}/{self.grid.n_bins} bins with >= {self.levels_required} "
            f"gradient levels {self.delta_c_per_min:g} °C/min apart; min {self.min_levels})"
        )
        if short:
            text += "; short: " + ", ".join(f"[{a:g},{b:g}):{n}" for a, b, n in short[:8])
            if len(short) > 8:
                text += f" and {len(short) - 8} more"
        return text


def coverage_report(
    temps_c: np.ndarray,
    grads_c_per_min: np.ndarray,
    grid: BinGrid,
    levels_required: int = 6,
    delta_c_per_min: float = 0.05,
) -> CoverageReport:
    """Coverage of ``grid`` by a sampled trajectory (see the module doc for the metric)."""
    if int(levels_required) != levels_required or levels_required < 1:
        raise ParameterError(f"levels_required must be a whole number >= 1, got {levels_required}")
    if not (np.isfinite(delta_c_per_min) and delta_c_per_min > 0):
        raise ParameterError(f"delta_c_per_min must be > 0 °C/min, got {delta_c_per_min}")
    kb, mg, _, _ = passes(temps_c, grads_c_per_min, grid)
    order = np.argsort(kb, kind="stable")
    kb, mg = kb[order], mg[order]
    split = np.searchsorted(kb, np.arange(grid.n_bins + 1))
    grads = tuple(mg[split[i] : split[i + 1]].copy() for i in range(grid.n_bins))
    counts = np.array([g.size for g in grads], dtype=np.int64)
    levels = np.array([distinct_levels(g, delta_c_per_min) for g in grads], dtype=np.int64)
    return CoverageReport(grid, int(levels_required), float(delta_c_per_min), counts, levels, grads)


def trajectory_coverage(
    trajectory,
    lo_c: float,
    hi_c: float,
    levels_required: int = 6,
    delta_c_per_min: float = 0.05,
    bin_c: float = 1.0,
) -> CoverageReport:
    """Coverage of ``[lo_c, hi_c]`` by a :class:`~schedsyn.simulate.Trajectory`."""
    return coverage_report(
        trajectory.t_c,
        trajectory.g_c_per_min,
        BinGrid(lo_c, hi_c, bin_c),
        levels_required,
        delta_c_per_min,
    )
