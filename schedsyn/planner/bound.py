"""A proven lower bound on the duration of any complete plan of a request.

Computed from the physics alone (:mod:`.physics`), independently of the search, for every
plan whose passes come from **sweeps**: monotone stretches of the internal temperature that
cross the whole working region (what the planner builds; a plan that turned round inside
the working region is not covered by the proof). The argument, in one direction (heating
or cooling; the other is the same with the roles of the chamber rates swapped):

1. **Counts.** Consecutive traversals of one bin alternate in direction, so a plan of
   ``N`` sweeps has ``ceil(N/2)`` in the first direction and ``floor(N/2)`` in the other,
   and every bin is passed ``N`` times. ``L`` levels need ``N >= L``; a plan may have more
   sweeps than levels (sweeps that repeat a level, so that the other direction can give
   more levels than ``N/2``, where one direction is slow), and the bound is the least over
   ``N`` (those with ``N - L`` up to ``MAX_SURPLUS_SWEEPS`` weighed as below, the rest
   bounded by their count times the least time of one sweep of each direction).
2. **Time of a sweep.** A sweep whose mean gradient in bin ``j`` is ``m_j`` (a harmonic mean
   over the bin: mean g over a pass = bin width / time in the bin) spends ``w / m_j`` in it.
   Before the region it sped up from rest (a turning point), which took at least the
   full-rate time to its entry speed; after it, it brakes to rest: at least the full-rate
   stopping time (:func:`~.physics.accel_time`, :func:`~.physics.stop_time`). The first
   sweep instead comes from the start (at least the time to reach the region at full rate),
   and after the last one the chamber must ramp back to ``end_c``.
3. **Speed limits.** At temperature T a sweep is no faster than the chamber limits allow
   (``Tk = T + tau g - dT0`` within the chamber range), than the distance it had to speed
   up from its turning point allows (turning points lie inside the device range and at
   ``Tk + dT0``), and -- unless it is the last -- than the distance left to stop before
   the device limit allows. So ``m_j <= V_j``, the largest such speed in the bin.
4. **Continuity.** Along a sweep the speed changes at most as fast as full-rate speeding
   up or braking allows, and over a stretch of full-rate speeding up from ``v_a`` to
   ``v_b`` the time is ``tau ln((r - v_a)/(r - v_b))`` (braking: ``tau ln((r' + v_a)/(r' +
   v_b))``). Given bin ``j``'s mean ``m_j``, the fastest bin ``j + 1`` follows the
   full-rate speed-up curve through both bins (had the speed at their boundary been
   higher, bin ``j``'s mean would have been higher too), the slowest the braking curve;
   and the entry speed is at least the start of the speed-up curve with mean ``m_0`` in
   the first bin, the exit speed at least the end of the braking curve with the last
   bin's mean.
5. **Levels.** In every bin the ``L`` levels come from the ``N`` passes, so at most
   ``S = N - L`` passes of a direction are not among them, and of the ``k`` fastest
   sweeps of a direction in a bin at least ``k - S`` are levels pairwise ``delta`` apart:
   the ``k``-th fastest is at most ``V_j - max(0, k - 1 - S) delta``. Sorting the sweeps'
   bin means bin by bin (rank ``k`` = the ``k``-th fastest) keeps the total time, the edge
   costs (the same speeds at each edge) and the continuity limits (order statistics of
   sequences with bounded steps have bounded steps). The last sweep of the plan needs no
   room to stop, so its cap ``V'`` may exceed the others' ``V``: in its direction the
   ``k``-th fastest is capped by ``V' - max(0, k - 1 - S) delta`` and, for ``k >= 2``, by
   ``V - max(0, k - 2 - S) delta`` (one of the faster may be the last), whichever rank
   pays its edge costs. Two relaxations of the ranks' joint problem are each a valid
   bound, and the larger counts: (a) each rank alone within those caps, with its own
   turns; (b) the fastest rank with its turns and continuity, the others charged only
   their crossing time at the fastest they may go, ``m_1 - max(0, k - 1 - S) delta``.
   Each is a shortest path over (bin, speed), solved exactly on a speed grid rounded in
   the bound's favour (speeds up for crossing times, down for turning times).
6. **The levels' dual.** Relaxation (a) lets the ranks share one profile where the caps
   do not bind; in truth the ``k``-th fastest is at least ``delta`` below the
   ``(k - 1 - S)``-th in every bin. Dualising that coupling with multipliers ``lam >= 0``
   keeps each rank a shortest path (with a linear term per bin) and any ``lam`` gives a
   valid bound (weak duality, :func:`_coupled`); a subgradient search raises it. It adds
   0-7 % on the benchmark's requests and costs about as much again, so by default it
   runs where it may decide whether a plan fits the budget.

The bound is the least, over the first sweep's direction, of the sum over ranks. It
ignores the chamber limits while turning and the separation between heating and cooling
levels, so it is loose where those bind; it is valid regardless.
"""

from __future__ import annotations

import functools
import heapq
import math
from dataclasses import dataclass, replace

import numpy as np

from ..params import Limits, ThermalParams
from .physics import (
    accel_time,
    speed_after_accel,
    speed_after_decel,
    stop_distance,
    stop_time,
)
from .request import ExperimentSpec

#: Speed grid of the dynamic programme, degC/min, at most delta / GRID_PER_DELTA.
GRID_C_PER_MIN = 0.005
GRID_PER_DELTA = 8
#: Points of the tabulated full-rate curves (speed-up, braking) across one bin.
CURVE_POINTS = 20001
#: Temperatures per bin at which the speed limits are evaluated (their maximum is used).
CAP_POINTS_PER_BIN = 21
#: Longest approach searched from the start to the region, min.
MAX_APPROACH_MIN = 1e4
#: Sweeps beyond ``levels_required`` whose plans the bound weighs explicitly (some sweeps
#: repeat a level so that the other direction can give more); plans with still more are
#: bounded by their count times the least time of one sweep.
MAX_SURPLUS_SWEEPS = 12


@dataclass(frozen=True, slots=True)
class DurationBound:
    """A lower bound on the duration of any complete plan and where the time goes.

    ``lower_bound_min`` is ``inf`` when no sweep can cross some bin at all. ``ranks``: per
    direction (+1 heating, -1 cooling) the least time of each rank's sweeps, min, and
    ``profiles`` the rank's bin-mean speeds in travel order (the optimum of the bound's
    relaxation; a guide, not a plan); ``sweeps`` the number of sweeps of that optimum
    (more than ``levels_required`` where repeating a level is cheaper).
    """

    lower_bound_min: float
    first_direction: int
    crossing_min: float
    turning_min: float
    ranks: dict[int, tuple[float, ...]]
    profiles: dict[int, tuple[np.ndarray, ...]]
    sweeps: int = 0

    def to_dict(self) -> dict:
        return {
            "duration_lower_bound_min": self.lower_bound_min,
            "first_direction": self.first_direction,
            "crossing_min": self.crossing_min,
            "turning_min": self.turning_min,
            "sweeps": self.sweeps,
        }


@dataclass(frozen=True, slots=True)
class _Side:
    """One travel direction's rates and turning limits."""

    d: int
    r_fwd: float  # full chamber rate in the travel direction, degC/min
    r_back: float  # full rate the other way (braking)
    floor_c: float  # lowest turning point behind the region (in travel order)
    ceiling_c: float  # furthest turning point ahead of it


def _sides(params: ThermalParams, limits: Limits) -> dict[int, _Side]:
    heat, cool = limits.rate_max_c_per_min, -limits.rate_min_c_per_min
    # a turning point (g = 0) has T = Tk + dT0 and lies inside the device range
    lowest = max(limits.device_min_c, limits.chamber_min_c + params.dt0_c)
    highest = min(limits.device_max_c, limits.chamber_max_c + params.dt0_c)
    return {+1: _Side(+1, heat, cool, lowest, highest), -1: _Side(-1, cool, heat, highest, lowest)}


def _caps(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, side: _Side, last: bool
) -> np.ndarray:
    """Largest speed a sweep can have anywhere in each bin, in travel order (degC/min)."""
    grid = spec.grid
    tau = params.tau_min
    frac = np.linspace(0.0, 1.0, CAP_POINTS_PER_BIN)
    temps = grid.lower_c[:, None] + grid.bin_c * frac[None, :]  # (bins, points)
    if side.d > 0:
        chamber = (limits.chamber_max_c + params.dt0_c - temps) / tau
    else:
        chamber = (temps - limits.chamber_min_c - params.dt0_c) / tau
    behind = side.d * (temps - side.floor_c)  # room to speed up, degC
    ahead = side.d * (side.ceiling_c - temps)  # room to stop
    cap = np.minimum(chamber, side.r_fwd * (1 - 1e-12))
    cap = np.minimum(
        cap, speed_after_accel(np.zeros_like(behind), np.maximum(behind, 0), side.r_fwd, tau)
    )
    cap = np.where(behind > 0, cap, 0.0)
    if not last:
        room = np.maximum(ahead, 0.0)
        stop_cap = _speed_for_stop(room, side.r_back, tau)
        cap = np.minimum(cap, np.where(ahead > 0, stop_cap, 0.0))
    v = np.max(np.maximum(cap, 0.0), axis=1)
    # a sweep crossing a bin passes every point of it moving: where the chamber's limit
    # stops the device short of the bin's far edge (T >= Tk_max + dT0 heating), no sweep
    # of this direction crosses the bin at all (red team: dT0 -2.1 with the chamber at
    # 60 °C stops the device at 57.9 °C; the bound for a region up to 58 °C was 726 min)
    v = np.where(np.any(chamber <= 0.0, axis=1), 0.0, v)
    return v if side.d > 0 else v[::-1]


def _speed_for_stop(room_c: np.ndarray, rate: float, tau_min: float) -> np.ndarray:
    """Fastest speed that stops within ``room_c`` (inverse of ``stop_distance``)."""
    lo, hi = np.zeros_like(room_c), np.full_like(room_c, 50.0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = stop_distance(mid, rate, tau_min) <= room_c
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return lo


def approach_minutes(
    t0_c: float, g0_c_per_min: float, target_c: float, rate: float, tau_min: float
) -> float:
    """Least time (min) from ``(T0, g0)`` to reach ``target_c`` at full chamber rate.

    Under a constant rate ``U`` towards the target, ``g(t) = U + (g0 - U) e^{-t/tau}`` and
    ``T(t) = T0 + U t + tau (g0 - U)(1 - e^{-t/tau})``; no control reaches it sooner.
    """
    d = 1.0 if target_c > t0_c else -1.0
    if target_c == t0_c:
        return 0.0
    u = d * rate

    def ahead(t: float) -> float:
        return d * (t0_c + u * t + tau_min * (g0_c_per_min - u) * -math.expm1(-t / tau_min))

    lo, hi = 0.0, 1.0
    while ahead(hi) < d * target_c:
        hi *= 2.0
        if hi > MAX_APPROACH_MIN:
            return math.inf
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if ahead(mid) < d * target_c:
            lo = mid
        else:
            hi = mid
    return lo


_Plan = list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]


def _range_plan(lo: np.ndarray, hi: np.ndarray) -> _Plan:
    """How :func:`_range_min` answers the ranges ``[lo[i], hi[i]]``: per sparse-table level,
    the indices it answers and the two overlapping spans' starts."""
    length = hi - lo + 1
    ok = length > 0
    k = np.zeros_like(length)
    k[ok] = np.floor(np.log2(length[ok])).astype(int)
    plan = []
    for level in np.unique(k[ok]):
        sel = np.flatnonzero(ok & (k == level))
        plan.append((int(level), sel, lo[sel], hi[sel] - (1 << int(level)) + 1))
    return plan


def _range_min(
    values: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    plan: _Plan | None = None,
) -> np.ndarray:
    """``min(values[..., lo[i] : hi[i] + 1])`` for every i (inf where the range is empty),
    along the last axis (a sparse table: the minima over spans of 1, 2, 4, ...);
    ``plan`` from :func:`_range_plan` when the ranges are used again."""
    plan = _range_plan(lo, hi) if plan is None else plan
    table = [values]
    top = max((level for level, *_ in plan), default=0)
    span = 1
    for _ in range(top):
        prev = table[-1]
        table.append(np.minimum(prev[..., : prev.shape[-1] - span], prev[..., span:]))
        span *= 2
    out = np.full((*values.shape[:-1], lo.size), np.inf)
    for level, sel, a, b in plan:
        t = table[level]
        out[..., sel] = np.minimum(t[..., a], t[..., b])
    return out


class _Curves:
    """Full-rate speed-up and braking across one bin, tabulated on a dense speed grid.

    Speeding up from ``u`` at rate ``r``: the end speed from :func:`speed_after_accel`, the
    time ``tau ln((r - u)/(r - end))``; braking at ``r'``: ``tau ln((r' + u)/(r' + end))``
    (a curve that stops inside the bin has mean 0). Means grow with the start speed, so
    each is inverted by a search on the table, rounded towards the bound's favour.
    """

    def __init__(self, side: _Side, width_c: float, tau_min: float, top_c_per_min: float):
        u = np.linspace(0.0, top_c_per_min, CURVE_POINTS)
        self.u = u
        a_end = speed_after_accel(u, width_c, side.r_fwd, tau_min)
        b_end = speed_after_decel(u, width_c, side.r_back, tau_min)
        with np.errstate(divide="ignore", invalid="ignore"):
            a_time = tau_min * np.log((side.r_fwd - u) / np.maximum(side.r_fwd - a_end, 1e-300))
            b_time = tau_min * np.log((side.r_back + u) / (side.r_back + b_end))
            self.a_mean = np.where(a_time > 0, width_c / a_time, u)
            self.b_mean = np.where((b_end > 0) & (b_time > 0), width_c / b_time, 0.0)
        self.a_mean = np.maximum.accumulate(self.a_mean)
        self.b_mean = np.maximum.accumulate(self.b_mean)
        self.a_end, self.b_end = a_end, b_end

    def _at(self, x: np.ndarray, up: bool) -> np.ndarray:
        """Table index of each speed ``x``: the grid point at or above (``up``) or below."""
        i = np.searchsorted(self.u, x, side="left" if up else "right")
        i = i if up else i - 1
        return np.clip(i, 0, self.u.size - 1)

    def accel_start(self, mean: np.ndarray, up: bool) -> np.ndarray:
        """Start speed of the speed-up curve with this mean over the bin."""
        i = np.searchsorted(self.a_mean, mean, side="left" if up else "right")
        return self.u[np.clip(i if up else i - 1, 0, self.u.size - 1)]

    def brake_start(self, mean: np.ndarray) -> np.ndarray:
        """Start speed of the braking curve with this mean (rounded down)."""
        i = np.searchsorted(self.b_mean, mean, side="right") - 1
        return self.u[np.clip(i, 0, self.u.size - 1)]

    def fastest_next(self, mean: np.ndarray) -> np.ndarray:
        """Upper bound on the next bin's mean: speed-up continued (rounded up)."""
        end = self.a_end[self._at(self.accel_start(mean, up=True), up=True)]
        return self.a_mean[self._at(end, up=True)]

    def slowest_next(self, mean: np.ndarray) -> np.ndarray:
        """Lower bound on the next bin's mean: braking continued (rounded down)."""
        end = self.b_end[self._at(self.brake_start(mean), up=False)]
        return self.b_mean[self._at(end, up=False)]

    def entry_speed(self, mean: np.ndarray) -> np.ndarray:
        """Lower bound on the speed entering a bin whose mean is ``mean``."""
        return self.accel_start(mean, up=False)

    def exit_speed(self, mean: np.ndarray) -> np.ndarray:
        """Lower bound on the speed leaving a bin whose mean is ``mean``."""
        return self.b_end[self._at(self.brake_start(mean), up=False)]


@dataclass(frozen=True, slots=True)
class _RankProblem:
    """One rank's shortest path over (bin, speed): caps, continuity, edge costs."""

    v: np.ndarray  # speed grid, degC/min
    caps: np.ndarray  # per bin, travel order
    width_c: float
    src_lo: np.ndarray  # per speed index: the source speeds it can follow (index range)
    src_hi: np.ndarray
    entry: np.ndarray  # per speed of the first bin, min
    exit: np.ndarray  # per speed of the last bin, min


def _solve_rank(
    prob: _RankProblem, linear: np.ndarray | None = None, crossing: np.ndarray | None = None
):
    """Least ``entry + sum_j (crossing(m_j) + linear_j m_j) + exit`` and its speed sequence
    (``crossing`` per grid speed, default ``w / m``)."""
    lin = None if linear is None else linear[None, :]
    values, paths = _solve_many(
        prob.v,
        prob.caps[None, :],
        prob.width_c,
        prob.src_lo,
        prob.src_hi,
        prob.entry[None, :],
        prob.exit[None, :],
        lin,
        crossing,
    )
    return float(values[0]), paths[0]


def _solve_many(
    v: np.ndarray,
    caps: np.ndarray,
    width_c: float,
    src_lo: np.ndarray,
    src_hi: np.ndarray,
    entry: np.ndarray,
    exit_: np.ndarray,
    linear: np.ndarray | None = None,
    crossing: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_solve_rank` for ``R`` problems on one speed grid and continuity at once:
    ``caps`` and ``linear`` are (R, bins), ``entry`` and ``exit_`` (R, speeds). Returns
    the least values (R,) and the speed sequences (R, bins; NaN where infeasible)."""
    n_rows, n_bins = caps.shape
    lin = np.zeros((n_rows, n_bins)) if linear is None else linear
    crossing = width_c / v if crossing is None else crossing
    cost = np.where(v <= caps[:, :1], crossing + lin[:, :1] * v + entry, np.inf)
    back = []
    plan = _range_plan(src_lo, src_hi)
    for j in range(1, n_bins):
        best_prev = _range_min(cost, src_lo, src_hi, plan)
        back.append(cost)
        here = crossing + lin[:, j : j + 1] * v + best_prev
        cost = np.where(v <= caps[:, j : j + 1], here, np.inf)
    total = cost + exit_
    ends = np.argmin(total, axis=1)
    values = total[np.arange(n_rows), ends]
    paths = np.full((n_rows, n_bins), np.nan)
    for r in range(n_rows):
        if not math.isfinite(values[r]):
            values[r] = math.inf
            continue
        path = [int(ends[r])]
        for prev_cost in reversed(back):
            lo, hi = src_lo[path[-1]], src_hi[path[-1]]
            path.append(int(lo + np.argmin(prev_cost[r, lo : hi + 1])))
        paths[r] = v[np.array(path[::-1])]
    return values, paths


def _lowered(caps: np.ndarray, by: float, step: float) -> np.ndarray:
    """Grid caps lowered by ``by`` and rounded up to the grid again (a true speed at most
    the lowered cap rounds to a grid speed at most this; ``delta`` need not be a multiple
    of the grid step)."""
    return np.ceil((caps - by) / step - 1e-9) * step


def _dominated(
    generic: _RankProblem,
    entry: np.ndarray,
    exit_: np.ndarray,
    shifts: list[int],
    delta: float,
) -> tuple[float, np.ndarray]:
    """Lower bound on the ranks held by the fastest: rank 1 pays its crossings, turns and
    continuity; rank ``k`` is at most ``m_1 - shifts[k] delta`` in every bin, so it spends
    at least ``w / (m_1 - shifts[k] delta)`` there (its own turns and continuity
    dropped)."""
    v = generic.v
    slow = v[:, None] - delta * np.asarray(shifts, float)[None, :]
    with np.errstate(divide="ignore"):
        crossing = np.where(slow.min(axis=1) > 0, (generic.width_c / slow).sum(axis=1), np.inf)
    prob = _RankProblem(
        v, generic.caps, generic.width_c, generic.src_lo, generic.src_hi, entry, exit_
    )
    return _solve_rank(prob, crossing=crossing)


def duration_lower_bound(
    spec: ExperimentSpec,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    tighten: bool | None = None,
) -> DurationBound:
    """Lower bound (min) on the duration of any complete plan for the request.

    See the module doc for the argument and its one assumption (sweeps cross the whole
    working region). ``inf`` when some bin cannot be crossed at all. ``tighten``: whether
    the levels' dual (module doc, 6) refines it; by default only where the bound without
    it lies within :data:`DUAL_WINDOW` below the budget (where it may decide whether a
    complete plan can fit). Every variant is a valid bound.

    Results are remembered per request (:data:`BOUND_CACHE_SIZE` of them, per process):
    a plan near its budget asks for the same bound to decide and to report it, and the
    dual costs about half a second. The profiles of a remembered bound are read-only.
    """
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    return _bound_cached(spec, params, limits, tighten)


#: How many bounds :func:`duration_lower_bound` remembers (requests are frozen, hashable).
BOUND_CACHE_SIZE = 256


@functools.lru_cache(maxsize=BOUND_CACHE_SIZE)
def _bound_cached(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, tighten: bool | None
) -> DurationBound:
    bound = _duration_lower_bound(spec, params, limits, tighten)
    for profs in bound.profiles.values():
        for p in profs:
            p.setflags(write=False)
    return bound


def _duration_lower_bound(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, tighten: bool | None
) -> DurationBound:
    tau = params.tau_min
    w = spec.grid.bin_c
    n_levels = spec.levels_required
    delta = spec.delta_c_per_min
    sides = _sides(params, limits)
    t0, g0 = limits.t_init_c, (limits.start_c + params.dt0_c - limits.t_init_c) / tau
    lo_c, hi_c = spec.working_lo_c, spec.working_hi_c
    step = min(GRID_C_PER_MIN, delta / GRID_PER_DELTA)
    v_top = max(s.r_fwd for s in sides.values())
    v = step * np.arange(1, int(math.ceil(v_top / step)) + 1)

    curves = {d: _Curves(side, w, tau, v_top + step) for d, side in sides.items()}
    continuity = {}
    for d, c in curves.items():
        up = np.ceil(np.maximum(c.fastest_next(v), v) / step) * step
        down = np.floor(np.minimum(c.slowest_next(np.maximum(v - step, 0.0)), v) / step) * step
        src_lo = np.searchsorted(up, v - 1e-12, side="left")
        src_hi = np.minimum(np.searchsorted(down, v + 1e-12, side="right") - 1, v.size - 1)
        continuity[d] = (src_lo, src_hi)

    def entry_cost(side: _Side, first: bool) -> np.ndarray:
        # in the bound's favour: the entry speed of a mean one grid step lower
        v_in = curves[side.d].entry_speed(np.maximum(v - step, 0.0))
        generic = accel_time(v_in, side.r_fwd, tau)
        if not first:
            return generic
        entry_edge = lo_c if side.d > 0 else hi_c
        if side.d * (entry_edge - t0) >= 0:  # the start lies before the region: come in
            return np.full(v.shape, approach_minutes(t0, g0, entry_edge, side.r_fwd, tau))
        # the start is inside or beyond the region: get behind it, turn, then come in
        return approach_minutes(t0, g0, entry_edge, side.r_back, tau) + generic

    def exit_cost(side: _Side, last: bool) -> np.ndarray:
        v_out = curves[side.d].exit_speed(np.maximum(v - step, 0.0))
        if not last:
            return stop_time(v_out, side.r_back, tau)
        # the chamber ramps back to end_c from Tk = T + tau g - dT0 at the exit edge
        exit_edge = hi_c if side.d > 0 else lo_c
        tk = exit_edge + side.d * tau * v_out - params.dt0_c
        if side.d > 0:
            return np.maximum(tk - (limits.end_c + limits.end_tol_c), 0.0) / (
                -limits.rate_min_c_per_min
            )
        return np.maximum(limits.end_c - limits.end_tol_c - tk, 0.0) / limits.rate_max_c_per_min

    problems: dict[tuple[int, bool, bool], _RankProblem] = {}

    def problem(side: _Side, first: bool, last: bool) -> _RankProblem:
        key = (side.d, first, last)
        if key not in problems:
            caps = np.ceil(_caps(spec, params, limits, side, last) / step) * step
            src_lo, src_hi = continuity[side.d]
            problems[key] = _RankProblem(
                v, caps, w, src_lo, src_hi, entry_cost(side, first), exit_cost(side, last)
            )
        return problems[key]

    def rank_caps(side: _Side, k: int, surplus: int, has_last: bool) -> np.ndarray:
        """Caps of the ``k``-th fastest sweep (from 0) of a direction in every bin. The
        last sweep of the plan needs no room to stop, so it may exceed the others' caps
        ``V``: where the direction holds it, the fastest is capped only by ``V'``, and the
        ``k``-th by ``V' - shift_k delta`` and by ``V`` lowered one level less (of the
        ``k`` faster sweeps one may be the last)."""
        strict = problem(side, False, False).caps
        if not has_last:
            return _lowered(strict, max(0, k - surplus) * delta, step)
        caps = _lowered(problem(side, False, True).caps, max(0, k - surplus) * delta, step)
        if k >= 1:
            caps = np.minimum(caps, _lowered(strict, max(0, k - 1 - surplus) * delta, step))
        return caps

    solved: dict[tuple, tuple[float, np.ndarray]] = {}

    def rank(
        side: _Side, first: bool, last: bool, k: int, surplus: int, has_last: bool
    ) -> tuple[float, np.ndarray]:
        """Least time of the ``k``-th fastest sweep of a direction in a role (its edge
        costs), within :func:`rank_caps`, and its speed profile."""
        # the caps depend on k and S only through the two shifts: share the solves
        shifts = (max(0, k - surplus), max(0, k - 1 - surplus) if has_last and k else -1)
        key = (side.d, first, last, shifts, has_last)
        if key not in solved:
            q = problem(side, first, last)
            caps = rank_caps(side, k, surplus, has_last)
            solved[key] = _solve_rank(_RankProblem(v, caps, w, q.src_lo, q.src_hi, q.entry, q.exit))
        return solved[key]

    def rank_cost(
        side: _Side, first: bool, last: bool, k: int, surplus: int, has_last: bool
    ) -> float:
        return rank(side, first, last, k, surplus, has_last)[0]

    def direction(
        side: _Side, n: int, surplus: int, is_first: bool, is_last: bool
    ) -> tuple[float, tuple[float, ...], tuple[np.ndarray, ...]]:
        """Least time of the ``n`` sweeps of one direction (see the module doc, 5)."""
        shifts = [max(0, k - surplus) for k in range(n)]
        # (a) the ranks on their own, each with its turns (levels kept apart only by
        # the caps V - shift delta)
        base = [rank_cost(side, False, False, k, surplus, is_last) for k in range(n)]
        wanted = [(True, False)] * is_first + [(False, True)] * is_last
        wanted += [(True, True)] * (is_first and is_last)
        alt = {
            key: [rank_cost(side, *key, k, surplus, is_last) for k in range(n)] for key in wanted
        }
        value_a = sum(base) + (_role_adjustment(base, alt, is_first, is_last) if wanted else 0)
        # (b) the ranks held by the fastest; the first sweep pays at least the approach
        # whichever rank it is, the last at least nothing more
        generic = problem(side, False, False)
        entry, exit_ = generic.entry, generic.exit
        if is_first:
            f_entry = problem(side, True, False).entry
            approach = float(np.min(f_entry - np.minimum(f_entry, generic.entry)))
            entry = np.minimum(generic.entry + approach, f_entry)
        caps_prob = problem(side, False, is_last)
        if is_last:
            exit_ = np.minimum(generic.exit, caps_prob.exit)
        value_b, prof_b = _dominated(caps_prob, entry, exit_, shifts, delta)
        value = max(value_a, value_b)
        if value_b >= value_a:
            profs = tuple(prof_b - sh * delta for sh in shifts)
        else:
            profs = tuple(rank(side, False, False, k, surplus, is_last)[1] for k in range(n))
        return value, tuple(base), profs

    # the least time one sweep of a direction takes, whatever its role: a plan of N sweeps
    # (ceil(N/2) in the first direction) takes at least the sum over its sweeps
    per_sweep = {
        d: min(rank_cost(side, f, la, 0, 0, la) for f in (False, True) for la in (False, True))
        for d, side in sides.items()
    }

    def at_least(first: int, n_sweeps: int) -> float:
        return (n_sweeps + 1) // 2 * per_sweep[first] + n_sweeps // 2 * per_sweep[-first]

    dual: dict[tuple[int, int, int, bool, bool], float] = {}

    def shape(first: int, n_sweeps: int, tight: bool) -> DurationBound:
        """The bound on plans of ``n_sweeps`` sweeps, the first in direction ``first``
        (``tight``: with the levels' dual, :func:`_coupled`, where it is larger)."""
        counts = {first: (n_sweeps + 1) // 2, -first: n_sweeps // 2}
        last_dir = first if n_sweeps % 2 else -first
        total = crossing = 0.0
        ranks: dict[int, tuple[float, ...]] = {}
        profiles: dict[int, tuple[np.ndarray, ...]] = {}
        for d, side in sides.items():
            args = (counts[d], n_sweeps - n_levels, d == first, d == last_dir)
            value, base, profs = direction(side, *args)
            if tight and math.isfinite(value):
                key = (d, *args)
                if key not in dual:
                    dual[key] = _direction_dual(side, *args, value)
                value = max(value, dual[key])
            if not math.isfinite(value):
                total = math.inf
                break
            total += value
            ranks[d] = base
            profiles[d] = profs
            crossing += sum(float(np.sum(w / p)) for p in profs if np.all(np.isfinite(p)))
        return DurationBound(
            lower_bound_min=total,
            first_direction=first,
            crossing_min=crossing,
            turning_min=total - crossing if math.isfinite(total) else math.inf,
            ranks=ranks,
            profiles=profiles,
            sweeps=n_sweeps,
        )

    def _direction_dual(
        side: _Side, n: int, surplus: int, is_first: bool, is_last: bool, start: float
    ) -> float:
        if n <= surplus + 1:
            return -math.inf  # no two of these sweeps need to be levels of one bin
        caps = [rank_caps(side, k, surplus, is_last) for k in range(n)]
        roles = [(False, False)] + [(True, False)] * is_first + [(False, True)] * is_last
        roles += [(True, True)] * (is_first and is_last)
        probs = {role: problem(side, *role) for role in roles}
        return _coupled(probs, caps, surplus, delta, step, start)

    # Best first over the plans' shapes (first direction, number of sweeps): each is
    # known first by the least time of its sweeps (at_least), then by its relaxation,
    # then by its relaxation with the levels' dual; the bound is the least shape once
    # the least is refined as far as it goes. Shapes with more sweeps than
    # MAX_SURPLUS_SWEEPS allows stay at at_least.
    heap: list[tuple[float, int, int, int]] = []  # (value, stage, first, n_sweeps)
    firsts = [
        f for f in (-1, +1) if not ((f < 0 and t0 < lo_c) or (f > 0 and t0 > hi_c))
    ]  # the first sweep heads into the region from where the start lies
    many = n_levels + MAX_SURPLUS_SWEEPS + 1
    for first in firsts:
        for n_sweeps in range(n_levels, many + 1):
            heapq.heappush(heap, (at_least(first, n_sweeps), 0, first, n_sweeps))

    def dual_wanted(value: float) -> bool:
        if tighten is None:  # where it may decide whether a complete plan fits the budget
            return value <= limits.duration_max_min < value * (1.0 + DUAL_WINDOW)
        return tighten

    last_stage = 1
    shapes: dict[tuple[int, int], DurationBound] = {}
    while True:
        value, stage, first, n_sweeps = heapq.heappop(heap)
        if n_sweeps == many or not math.isfinite(value):
            break
        if stage == last_stage:
            if last_stage == 2 or not dual_wanted(value):
                break
            last_stage = 2  # the least shape's relaxation: refine it, and any that overtakes
        bound = shape(first, n_sweeps, tight=stage + 1 == 2)
        shapes[first, n_sweeps] = bound
        heapq.heappush(heap, (max(value, bound.lower_bound_min), stage + 1, first, n_sweeps))
    if (first, n_sweeps) in shapes:
        return replace(shapes[first, n_sweeps], lower_bound_min=value)
    # a bare count (more sweeps than weighed, or nothing finite): the least relaxation
    # found is still the guide
    known = min(shapes.values(), key=lambda b: b.lower_bound_min, default=None)
    if known is None:
        known = shape(firsts[0], n_levels, tight=False)
    return replace(known, lower_bound_min=value, sweeps=n_sweeps)


def _role_adjustment(
    base: list[float], alt: dict[tuple[bool, bool], list[float]], first: bool, last: bool
) -> float:
    """Least extra cost of giving the first and/or last sweep's role to some ranks."""
    n = len(base)
    options = []
    for a in range(n):
        for b in range(n):
            if first and last:
                if a == b:
                    options.append(alt[True, True][a] - base[a])
                else:
                    options.append(alt[True, False][a] - base[a] + alt[False, True][b] - base[b])
            elif first and b == 0:
                options.append(alt[True, False][a] - base[a])
            elif last and a == 0:
                options.append(alt[False, True][b] - base[b])
    return min(options)


#: Subgradient steps of the levels' Lagrangian dual (:func:`_coupled`).
DUAL_ITERATIONS = 60
#: The dual stops when its step has been halved below this share without progress.
DUAL_MIN_SCALE = 1 / 16
#: By default the dual runs only where the bound without it lies this share or less below
#: the budget (it raised the benchmark's bounds by 0-7 %), where it may decide whether a
#: complete plan can fit; it costs about as much again as the rest of the bound.
DUAL_WINDOW = 0.1


def _coupled(
    probs: dict[tuple[bool, bool], _RankProblem],
    caps_by_rank: list[np.ndarray],
    surplus: int,
    delta: float,
    step: float,
    start: float,
) -> float:
    """Lower bound on a direction's sweeps with their levels kept apart in every bin.

    Sorted bin by bin, the ``k``-th fastest sweep is at least ``delta`` slower than the
    ``(k - 1 - S)``-th in every bin (of those ``S + 2`` passes at least two are levels).
    That couples the ranks; its Lagrangian dual decouples them again: for multipliers
    ``lam >= 0`` (one per coupled pair and bin) the least of ``sum_k cost_k(m_k) +
    sum lam (m_k - m_i + delta)`` over the ranks' own feasible profiles is a lower bound
    (weak duality), and each rank's part is the same shortest path with a linear term per
    bin. A profile's grid point lies up to one grid step above its true mean speed, so a
    positive linear coefficient can gain up to ``coef * step`` per bin: that is
    subtracted. The multipliers follow projected subgradient steps (Polyak's, towards a
    target above the best value so far); the best value of any step is returned.
    """
    n = len(caps_by_rank)
    caps = np.array(caps_by_rank)
    pairs = [(k, k - 1 - surplus) for k in range(surplus + 1, n)]
    generic = probs[False, False]
    n_bins = generic.caps.size
    lam = np.zeros((len(pairs), n_bins))
    best = -math.inf
    scale = 1.0
    stall = 0
    for _ in range(DUAL_ITERATIONS):
        coef = np.zeros((n, n_bins))
        for p, (k, i) in enumerate(pairs):
            coef[k] += lam[p]
            coef[i] -= lam[p]
        correction = step * np.maximum(coef, 0.0).sum(axis=1)
        roles = list(probs)
        vals, rows = _solve_many(
            generic.v,
            np.tile(caps, (len(roles), 1)),
            generic.width_c,
            generic.src_lo,
            generic.src_hi,
            np.repeat([probs[r].entry for r in roles], n, axis=0),
            np.repeat([probs[r].exit for r in roles], n, axis=0),
            np.tile(coef, (len(roles), 1)),
        )
        values = {r: list(vals[i * n : (i + 1) * n] - correction) for i, r in enumerate(roles)}
        paths = {r: rows[i * n : (i + 1) * n] for i, r in enumerate(roles)}
        chosen = _assign_roles(values, n)
        total = sum(values[role][k] for k, role in enumerate(chosen)) + delta * float(lam.sum())
        if not math.isfinite(total):
            return math.inf  # every way of giving out the roles has a rank that cannot cross
        if total > best + 1e-9:
            best, stall = total, 0
        else:
            stall += 1
            if stall >= 5:
                scale, stall = scale / 2, 0
                if scale < DUAL_MIN_SCALE:
                    break  # no progress at ever shorter steps
        m = np.array([paths[role][k] for k, role in enumerate(chosen)])
        sub = np.array([m[k] - m[i] + delta for k, i in pairs])
        sub = np.where((lam > 0) | (sub > 0), sub, 0.0)  # the projection's active face
        norm = float(np.sum(sub**2))
        if norm < 1e-12:
            break  # the ranks' own optima keep their levels apart: the dual is tight
        target = max(best, start) * 1.05 + 1.0
        lam = np.maximum(lam + scale * (target - total) / norm * sub, 0.0)
    return best


def _assign_roles(values: dict[tuple[bool, bool], list[float]], n: int) -> list[tuple[bool, bool]]:
    """The roles (first sweep, last sweep) given to the ranks at the least total cost:
    every rank generic except the one (or two) holding the roles there are."""
    has_first = (True, False) in values or (True, True) in values
    has_last = (False, True) in values or (True, True) in values
    best_cost, best = math.inf, None
    for a in range(n) if has_first else [None]:
        for b in range(n) if has_last else [None]:
            roles = [(False, False)] * n
            if a is not None and a == b:
                roles[a] = (True, True)
            else:
                if a is not None:
                    roles[a] = (True, False)
                if b is not None:
                    roles[b] = (False, True)
            cost = sum(values[r][k] if r in values else math.inf for k, r in enumerate(roles))
            if best is None or cost < best_cost:  # (all infinite: any, its total too)
                best_cost, best = cost, roles
    assert best is not None
    return best
