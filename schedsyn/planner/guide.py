"""Band design guided by the bound: how fast each sweep should go, bin by bin.

The duration bound (:mod:`.bound`) solves, per direction, a shortest path over (bin, speed)
whose optimum already has the right shape for a fast plan: slow near the edges (so turning
round costs little), fast in the middle (so crossing costs little). This module solves the
same problem for the ``n`` sweeps of a direction **together**, as parallel ranks: the
slowest sweep's bin means ``v_j`` and the others at ``v_j + k sep`` (``sep`` = delta plus
the planner's safety gap plus a band width), with each bin costing ``sum_k w / (v_j + k
sep)``, every copy within the speed limits and the continuity limits. To leave the LP
room to follow them with piecewise-constant chamber rates, the profiles are designed with
a share of the chamber rates (``rate_share``). The bands are then the corridors between
neighbouring profiles (:func:`guided_bands`); the profiles also time the sweeps' knot
crossings.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..params import Limits, ThermalParams
from .bands import BAND_SAFETY_C_PER_MIN, Band
from .bound import (
    GRID_C_PER_MIN,
    GRID_PER_DELTA,
    _caps,
    _Curves,
    _RankProblem,
    _sides,
    _solve_rank,
)
from .physics import LIMIT_FRACTION, accel_time, stop_time
from .request import ExperimentSpec

#: Knot insets (degC from each working edge) of guided bands: dense near the edges, where
#: the profiles bend most.
GUIDED_KNOT_INSETS_C = (1.5, 4.0, 8.0, 12.0)
#: Highest speed the fastest guided band allows above its profile, degC/min (it bounds
#: no other band: only shapes the plan).
TOP_HEADROOM_C_PER_MIN = 0.5


def parallel_profiles(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    n_by_dir: dict[int, int],
    sep_c_per_min: float,
    rate_share: float,
    edge: str = "mean",
    chamber_share: bool = False,
) -> dict[int, list[np.ndarray]] | None:
    """Per direction, ``n`` bin-mean speed profiles ``sep`` apart, fastest first, in travel
    order; None when the ranks cannot be kept ``sep`` apart within the speed limits.

    ``edge``: how a profile's turns are costed. ``"mean"`` as the bound does: a sweep may
    speed up and brake inside the edge bins, so it enters and leaves slower than their
    mean. ``"speed"``: at the edge bins' mean itself, as if the sweep entered and left
    at it (a sweep held within a band to past the edge does, roughly). The two give
    different profiles (on W2 the second is a little faster throughout): another shape
    for the search to try when the first does not fit.

    ``chamber_share``: the chamber floor's or ceiling's speed limit is taken, like the
    chamber rates, at ``rate_share`` -- and at each bin's side nearest the limit
    (:func:`_chamber_caps`) -- instead of the bound's cap at the bin's most favourable
    point. Slower where the limit binds (W1 465 -> 480 min), so the search tries it after
    every other design (:data:`~.search.CANDIDATES`)."""
    tau = params.tau_min
    w = spec.grid.bin_c
    sides = {
        d: replace(s, r_fwd=rate_share * s.r_fwd, r_back=rate_share * s.r_back)
        for d, s in _sides(params, limits).items()
    }
    step = min(GRID_C_PER_MIN, spec.delta_c_per_min / GRID_PER_DELTA)
    k_sep = max(1, int(round(sep_c_per_min / step)))
    v_top = max(s.r_fwd for s in sides.values())
    v = step * np.arange(1, int(math.ceil(v_top / step)) + 1)
    n_grid = v.size
    out: dict[int, list[np.ndarray]] = {}
    for d, side in sides.items():
        n = n_by_dir[d]
        if n == 0:
            out[d] = []
            continue
        curves = _Curves(side, w, tau, v_top + step)
        up = np.ceil(np.maximum(curves.fastest_next(v), v) / step) * step
        down = np.floor(np.minimum(curves.slowest_next(np.maximum(v - step, 0.0)), v) / step)
        down *= step
        src_lo = np.searchsorted(up, v - 1e-12, side="left")
        src_hi = np.minimum(np.searchsorted(down, v + 1e-12, side="right") - 1, n_grid - 1)
        if edge == "speed":
            entry, exit_ = accel_time(v, side.r_fwd, tau), stop_time(v, side.r_back, tau)
        else:
            entry = accel_time(curves.entry_speed(np.maximum(v - step, 0.0)), side.r_fwd, tau)
            exit_ = stop_time(curves.exit_speed(np.maximum(v - step, 0.0)), side.r_back, tau)
        caps = np.minimum(
            np.ceil(_caps(spec, params, limits, side, False) / step) * step,
            LIMIT_FRACTION * side.r_fwd,
        )
        if chamber_share:  # the limit's speed throughout the bin, rate_share of it
            caps = np.minimum(
                caps, np.floor(rate_share * _chamber_caps(spec, params, limits, d) / step) * step
            )

        def shifted(a: np.ndarray, k: int, fill: float) -> np.ndarray:
            out_k = np.full(n_grid, fill, dtype=float)
            out_k[: n_grid - k * k_sep] = a[k * k_sep :]
            return out_k

        crossing, e_sum, x_sum = np.zeros(n_grid), np.zeros(n_grid), np.zeros(n_grid)
        lo, hi = src_lo.copy(), src_hi.copy()
        for k in range(n):
            crossing += shifted(w / v, k, np.inf)
            e_sum += shifted(entry, k, np.inf)
            x_sum += shifted(exit_, k, np.inf)
            if k:  # a transition must be allowed for every copy
                lo_k = shifted(src_lo.astype(float), k, n_grid) - k * k_sep
                hi_k = shifted(src_hi.astype(float), k, -1) - k * k_sep
                lo = np.maximum(lo, lo_k.astype(int))
                hi = np.minimum(hi, hi_k.astype(int))
        prob = _RankProblem(
            v,
            caps - (n - 1) * k_sep * step,
            w,
            np.clip(lo, 0, n_grid - 1),
            np.clip(hi, -1, n_grid - 1),
            e_sum,
            x_sum,
        )
        cost, slowest = _solve_rank(prob, crossing=crossing)
        if not math.isfinite(cost):
            return None
        out[d] = [slowest + (n - 1 - k) * k_sep * step for k in range(n)]
    return out


def _chamber_caps(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, d: int
) -> np.ndarray:
    """Fastest speed the chamber floor (cooling) or ceiling (heating) allows throughout
    each bin -- at its side nearest that limit --, in travel order, degC/min.

    ``g = (Tk + dT0 - T) / tau``: heating at most ``(ceiling + dT0 - T) / tau``, cooling
    at most ``(T - floor - dT0) / tau``. The bound's caps (:func:`~.bound._caps`) take
    each bin's most favourable point instead, in the bound's favour; a profile at that
    speed leaves its band no room at the bin's other side (a 25-degC region below a
    ceiling of 35.8 degC: the fast heating band's floor 0.954 degC/min at 11 degC, where
    the ceiling allows 0.953, and every plan of it stuck).
    """
    lower = spec.grid.lower_c
    upper = lower + spec.grid.bin_c
    tau = params.tau_min
    if d > 0:
        v = (limits.chamber_max_c + params.dt0_c - upper) / tau
    else:
        v = (lower - limits.chamber_min_c - params.dt0_c) / tau
    v = np.maximum(v, 0.0)
    return v if d > 0 else v[::-1]


def guided_bands(
    spec: ExperimentSpec,
    params_list: list[ThermalParams],
    limits: Limits,
    n_by_dir: dict[int, int],
    width_c_per_min: float,
    rate_share: float,
    sep_extra_c_per_min: float = 0.0,
    edge: str = "mean",
    chamber_share: bool = False,
) -> dict[int, list[Band]] | None:
    """Bands around parallel profiles: the corridor between neighbouring profiles, split
    at their midpoint with the gap ``delta + safety`` (+ ``sep_extra`` for robust plans)
    between bands; the fastest band open above, the slowest down to ``delta/2 + safety``.

    The profiles are designed for the slowest scenario (largest tau). Returns bands per
    direction (rank 1 = slowest first, like :func:`~.bands.make_bands`), or None.
    """
    gap = spec.delta_c_per_min + BAND_SAFETY_C_PER_MIN + sep_extra_c_per_min
    params = max(params_list, key=lambda p: p.tau_s)
    profiles = parallel_profiles(
        spec, params, limits, n_by_dir, gap + width_c_per_min, rate_share, edge, chamber_share
    )
    if profiles is None:
        return None
    lo_c, hi_c, m = spec.working_lo_c, spec.working_hi_c, spec.edge_margin_c
    inner = {lo_c + k for k in GUIDED_KNOT_INSETS_C if lo_c + k < hi_c - 0.5}
    inner |= {hi_c - k for k in GUIDED_KNOT_INSETS_C if hi_c - k > lo_c + 0.5}
    knots = np.array((lo_c - m, *sorted(inner), hi_c + m))
    centres = spec.grid.centres_c
    floor = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    out: dict[int, list[Band]] = {}
    for d, profs in profiles.items():
        n = len(profs)
        # profiles in ascending temperature, at the knots (edge bins held beyond the edges)
        vals = [np.interp(knots, centres, p if d > 0 else p[::-1]) for p in profs]
        bands = []
        for r in range(n):  # r = 0 fastest
            hi = (
                vals[r] + TOP_HEADROOM_C_PER_MIN
                if r == 0
                else 0.5 * (vals[r - 1] + vals[r]) - gap / 2
            )
            lo = (
                np.full(knots.size, floor)
                if r == n - 1
                else 0.5 * (vals[r] + vals[r + 1]) + gap / 2
            )
            if np.any(hi - lo <= 0):
                return None
            bands.append(
                Band(
                    d,
                    n - r,
                    tuple(float(k) for k in knots),
                    tuple(float(x) for x in lo),
                    tuple(float(x) for x in hi),
                    top=r == 0,
                    speed_c_per_min=tuple(float(x) for x in vals[r]),
                )
            )
        out[d] = bands[::-1]
    return out
