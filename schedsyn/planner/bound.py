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
   sequences with bounded steps have bounded steps). Two relaxations of the ranks' joint
   problem are each a valid bound, and the larger counts: (a) each rank alone, capped at
   ``V_j - max(0, k - 1 - S) delta``, with its own turns; (b) the fastest rank with its
   turns and continuity, the others charged only their crossing time at the fastest they
   may go, ``m_1 - max(0, k - 1 - S) delta``. Each is a shortest path over (bin, speed),
   solved exactly on a speed grid rounded in the bound's favour (speeds up for crossing
   times, down for turning times).

The bound is the least, over the first sweep's direction, of the sum over ranks. It
ignores the chamber limits while turning and the separation between heating and cooling
levels, so it is loose where those bind; it is valid regardless.
"""

from __future__ import annotations

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


def _range_min(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``min(values[lo[i] : hi[i] + 1])`` for every i (inf where the range is empty)."""
    n = values.size
    table = [values]
    span = 1
    while 2 * span <= n:
        prev = table[-1]
        table.append(np.minimum(prev[: prev.size - span], prev[span:]))
        span *= 2
    length = hi - lo + 1
    out = np.full(lo.shape, np.inf)
    ok = length > 0
    k = np.zeros_like(length)
    k[ok] = np.floor(np.log2(length[ok])).astype(int)
    for level in np.unique(k[ok]):
        sel = ok & (k == level)
        t = table[level]
        a = lo[sel]
        b = hi[sel] - (1 << level) + 1
        out[sel] = np.minimum(t[a], t[b])
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
    v, caps = prob.v, prob.caps
    n_bins = caps.size
    lin = np.zeros(n_bins) if linear is None else linear
    crossing = prob.width_c / v if crossing is None else crossing
    cost = np.where(v <= caps[0], crossing + lin[0] * v + prob.entry, np.inf)
    back = []
    for j in range(1, n_bins):
        best_prev = _range_min(cost, prob.src_lo, prob.src_hi)
        back.append(cost)
        cost = np.where(v <= caps[j], crossing + lin[j] * v + best_prev, np.inf)
    total = cost + prob.exit
    i = int(np.argmin(total))
    if not math.isfinite(total[i]):
        return math.inf, np.full(n_bins, np.nan)
    path = [i]
    for prev_cost in reversed(back):
        lo, hi = prob.src_lo[path[-1]], prob.src_hi[path[-1]]
        path.append(int(lo + np.argmin(prev_cost[lo : hi + 1])))
    return float(total[i]), v[np.array(path[::-1])]


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
) -> DurationBound:
    """Lower bound (min) on the duration of any complete plan for the request.

    See the module doc for the argument and its one assumption (sweeps cross the whole
    working region). ``inf`` when some bin cannot be crossed at all.
    """
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
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

    def problem(side: _Side, first: bool, last: bool) -> _RankProblem:
        caps = np.ceil(_caps(spec, params, limits, side, last) / step) * step
        src_lo, src_hi = continuity[side.d]
        return _RankProblem(
            v, caps, w, src_lo, src_hi, entry_cost(side, first), exit_cost(side, last)
        )

    solved: dict[tuple[int, bool, bool, int], tuple[float, np.ndarray]] = {}

    def rank(side: _Side, first: bool, last: bool, shift: int) -> tuple[float, np.ndarray]:
        """Least time of one sweep (in its role) whose caps are lowered by ``shift``
        delta, and its speed profile."""
        key = (side.d, first, last, shift)
        if key not in solved:
            q = problem(side, first, last)
            caps = q.caps - shift * delta
            solved[key] = _solve_rank(_RankProblem(v, caps, w, q.src_lo, q.src_hi, q.entry, q.exit))
        return solved[key]

    def rank_cost(side: _Side, first: bool, last: bool, shift: int) -> float:
        return rank(side, first, last, shift)[0]

    def direction(
        side: _Side, n: int, surplus: int, is_first: bool, is_last: bool
    ) -> tuple[float, tuple[float, ...], tuple[np.ndarray, ...]]:
        """Least time of the ``n`` sweeps of one direction (see the module doc, 5)."""
        shifts = [max(0, k - surplus) for k in range(n)]
        # (a) the ranks on their own, each with its turns (levels kept apart only by
        # the caps V - shift delta)
        base = [rank_cost(side, False, False, sh) for sh in shifts]
        wanted = [(True, False)] * is_first + [(False, True)] * is_last
        wanted += [(True, True)] * (is_first and is_last)
        alt = {key: [rank_cost(side, *key, sh) for sh in shifts] for key in wanted}
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
            profs = tuple(rank(side, False, False, sh)[1] for sh in shifts)
        return value, tuple(base), profs

    best: DurationBound | None = None
    # the least time one sweep of a direction takes, whatever its role: a plan of N sweeps
    # (ceil(N/2) in the first direction) takes at least the sum over its sweeps
    per_sweep = {
        d: min(rank_cost(side, f, la, 0) for f in (False, True) for la in (False, True))
        for d, side in sides.items()
    }

    def at_least(first: int, n_sweeps: int) -> float:
        return (n_sweeps + 1) // 2 * per_sweep[first] + n_sweeps // 2 * per_sweep[-first]

    for first in (-1, +1):
        if (first < 0 and t0 < lo_c) or (first > 0 and t0 > hi_c):
            continue  # the first sweep heads into the region from where the start lies
        for n_sweeps in range(n_levels, n_levels + MAX_SURPLUS_SWEEPS + 1):
            if best is not None and at_least(first, n_sweeps) >= best.lower_bound_min:
                break  # more sweeps cannot be faster
            counts = {first: (n_sweeps + 1) // 2, -first: n_sweeps // 2}
            last_dir = first if n_sweeps % 2 else -first
            total = 0.0
            crossing = 0.0
            ranks: dict[int, tuple[float, ...]] = {}
            profiles: dict[int, tuple[np.ndarray, ...]] = {}
            for d, side in sides.items():
                value, base, profs = direction(
                    side, counts[d], n_sweeps - n_levels, d == first, d == last_dir
                )
                if not math.isfinite(value):
                    total = math.inf
                    break
                total += value
                ranks[d] = base
                profiles[d] = profs
                crossing += sum(float(np.sum(w / p)) for p in profs if np.all(np.isfinite(p)))
            bound = DurationBound(
                lower_bound_min=total,
                first_direction=first,
                crossing_min=crossing,
                turning_min=total - crossing if math.isfinite(total) else math.inf,
                ranks=ranks,
                profiles=profiles,
                sweeps=n_sweeps,
            )
            if best is None or bound.lower_bound_min < best.lower_bound_min:
                best = bound
    assert best is not None  # at least one first direction is possible
    # plans with more sweeps than were weighed: each sweep takes at least per_sweep
    many = n_levels + MAX_SURPLUS_SWEEPS + 1
    beyond = min(
        at_least(first, many)
        for first in (-1, +1)
        if not ((first < 0 and t0 < lo_c) or (first > 0 and t0 > hi_c))
    )
    if beyond < best.lower_bound_min:
        best = replace(best, lower_bound_min=beyond, sweeps=many)
    return best


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
