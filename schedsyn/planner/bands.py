"""Stage 3: gradient bands -- the level each sweep is held to, piecewise linear in T.

Each sweep of one direction gets its own band ``lo(T) <= d * g <= hi(T)``; the bands of
one direction are stacked ``delta`` plus a safety gap apart at every temperature, so every
pass of a bin by different sweeps has a distinct level. The bands sit as high as the
physics allows (slow sweeps cost time; :mod:`.physics`) and are linear between knots, so
that inside a sweep -- where the planner knows which samples lie between which knots --
every band constraint is linear in the rates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cache, partial

import numpy as np

from ..params import Limits, ThermalParams
from .physics import (
    TURN_ACCEL_FRACTION,
    available_rate,
    constant_decel_speed,
    dynamic_tops,
    turnaround_minutes,
    turning_speed,
)
from .request import ExperimentSpec

#: Extra separation between neighbouring bands beyond delta, degC/min (sampling, rounding).
BAND_SAFETY_C_PER_MIN = 0.012
#: Preferred width of one gradient band, degC/min (room for the LP to manoeuvre).
BAND_WIDTH_C_PER_MIN = 0.05
#: Distances of the inner band knots from the working edges, degC.
KNOT_INSETS_C = (1.5, 4.0)
#: Points per piece for the crossing-time integral of :meth:`Band.minutes`.
MINUTES_POINTS = 50
#: Slowest speed :meth:`Band.minutes` divides by, degC/min (a band touching zero).
MINUTES_FLOOR_C_PER_MIN = 1e-3
#: Where in a band sweeps are first timed: top, three quarters, half, a quarter.
BAND_FRACTIONS = (1.0, 0.75, 0.5, 0.25)
#: Shares of a guided band's design speed sweeps are timed at, fastest first.
PROFILE_SHARES = (1.0, 0.95, 0.9, 0.8)
#: Where in a band a sweep is timed when none of the usual timings fits (near the
#: bottom): long segments cannot hold a sweep high in its band right after a turnaround.
SLOW_BAND_FRACTIONS = (0.1, 0.0)
#: Relative tolerance within which two band orders count as equally fast.
ORDER_TIE_TOL = 1e-9


@dataclass(frozen=True, slots=True)
class Band:
    """Gradient band of one sweep, piecewise linear in T between ``knots_c``.

    ``lo(T) <= d * g <= hi(T)``; ``lo`` and ``hi`` are linear between the knots. Inside
    a sweep the samples between two knots are held to that piece's affine bounds, which
    keeps every constraint linear in the rates.
    """

    direction: int
    rank: int
    knots_c: tuple[float, ...]
    lo_c_per_min: tuple[float, ...]
    hi_c_per_min: tuple[float, ...]
    #: the fastest band of its direction: no band above it, so its upper bound only
    #: shapes the plan, it is not needed for distinct levels
    top: bool = False
    #: the speed the band was designed around at each knot (guided bands; see
    #: :mod:`.guide`): sweeps are timed by it rather than by the band's edges
    speed_c_per_min: tuple[float, ...] | None = None

    def bounds(self, temp_c):
        t = np.asarray(temp_c, dtype=float)
        return (
            np.interp(t, self.knots_c, self.lo_c_per_min),
            np.interp(t, self.knots_c, self.hi_c_per_min),
        )

    def widened(self, extra_c: float) -> Band:
        """The band with its end knots ``extra_c`` further out, its bounds and speeds at
        the ends held (a robust sweep's reference placed beyond the edges)."""
        knots = (self.knots_c[0] - extra_c, *self.knots_c[1:-1], self.knots_c[-1] + extra_c)
        return replace(self, knots_c=knots)

    def piece(self, i: int) -> tuple[float, float, float, float, float]:
        """``(t_ref, lo0, lo1, hi0, hi1)`` of the affine piece between knots i and i+1."""
        t0, t1 = self.knots_c[i], self.knots_c[i + 1]
        lo0, lo_1 = self.lo_c_per_min[i], self.lo_c_per_min[i + 1]
        hi0, hi_1 = self.hi_c_per_min[i], self.hi_c_per_min[i + 1]
        return t0, lo0, (lo_1 - lo0) / (t1 - t0), hi0, (hi_1 - hi0) / (t1 - t0)

    def timing_options(self, slow: bool = False) -> list[np.ndarray]:
        """Minutes per piece (ascending T) to time a sweep by, in order of preference.

        A band designed around a speed profile is crossed at that profile and then a little
        slower (``PROFILE_SHARES``); otherwise at its top, three quarters, half and a
        quarter of its width (``BAND_FRACTIONS``). ``slow``: the last resort, near the
        bottom of the band (``SLOW_BAND_FRACTIONS``), either kind.
        """
        return [minutes_between(speed, self.knots_c) for speed in self.timing_speeds(slow)]

    def timing_speeds(self, slow: bool = False) -> list[Callable[[np.ndarray], np.ndarray]]:
        """The speeds (degC/min, functions of T) behind :meth:`timing_options`, in its order."""
        if slow or self.speed_c_per_min is None:
            fractions = SLOW_BAND_FRACTIONS if slow else BAND_FRACTIONS

            def at_fraction(t: np.ndarray, f: float) -> np.ndarray:
                lo, hi = self.bounds(t)
                return lo + f * (hi - lo)

            return [partial(at_fraction, f=f) for f in fractions]

        profile = self.speed_c_per_min

        def at_share(t: np.ndarray, share: float) -> np.ndarray:
            return np.interp(t, self.knots_c, profile) * share

        return [partial(at_share, share=share) for share in PROFILE_SHARES]

    def bin_minutes(self, lo_c: float, hi_c: float) -> tuple[float, float]:
        """Least and most time a sweep held to the band takes to cross ``[lo_c, hi_c]``:
        ``(integral of dT / hi(T), integral of dT / lo(T))``, min."""
        t = np.linspace(lo_c, hi_c, MINUTES_POINTS)
        lo, hi = self.bounds(t)
        floor = MINUTES_FLOOR_C_PER_MIN
        return (
            float(np.trapezoid(1.0 / np.maximum(hi, floor), t)),
            float(np.trapezoid(1.0 / np.maximum(lo, floor), t)),
        )

    def edge_speeds(self) -> tuple[float, float]:
        """``(entry, exit)`` lower-bound speed of a sweep in this band, degC/min."""
        lo = self.lo_c_per_min
        return (lo[-1], lo[0]) if self.direction < 0 else (lo[0], lo[-1])


def band_knots(spec: ExperimentSpec, insets_c: Sequence[float] | None = None) -> tuple[float, ...]:
    """Knots of the piecewise-linear bands: the extended edges and, inside each edge,
    knots at ``insets_c`` (default ``KNOT_INSETS_C``) where they fit (the device must
    slow down near the device limits to turn round, so the bands bend there)."""
    m = spec.edge_margin_c
    lo, hi = spec.working_lo_c, spec.working_hi_c
    insets_c = KNOT_INSETS_C if insets_c is None else insets_c
    inner = [k for k in insets_c if 2 * k + 2 <= hi - lo]
    return (lo - m, *(lo + k for k in inner), *(hi - k for k in reversed(inner)), hi + m)


def minutes_between(
    speed: Callable[[np.ndarray], np.ndarray], points_c: Sequence[float]
) -> np.ndarray:
    """Minutes to travel between consecutive temperatures of ``points_c`` at ``speed(T)``."""
    out = []
    for a, b in zip(points_c[:-1], points_c[1:], strict=True):
        t = np.linspace(min(a, b), max(a, b), MINUTES_POINTS)
        v = np.maximum(speed(t), MINUTES_FLOOR_C_PER_MIN)
        out.append(float(np.trapezoid(1.0 / v, t)))
    return np.array(out)


@dataclass(frozen=True, slots=True)
class BandDesign:
    """How band tops are derived from the physics.

    ``room``: ``"sqrt"`` bounds the speed near a device limit by a constant-deceleration
    estimate at half the planned deceleration (conservative), ``"exact"`` by the exact
    first-order stopping distance (:func:`~.physics.turning_speed`), which allows faster
    passes near the edges. ``knot_insets_c``: inner knots (more knots let the bands
    follow the curved speed limits). ``turn_fraction``: share of the full chamber rate
    assumed when speeding up or turning.
    """

    room: str = "sqrt"
    knot_insets_c: tuple[float, ...] = KNOT_INSETS_C
    turn_fraction: float = TURN_ACCEL_FRACTION


#: The band designs the search tries (see ``search.CANDIDATES``).
DESIGNS = {
    "sqrt": BandDesign(),
    "exact": BandDesign(room="exact", knot_insets_c=(1.5, 4.0, 8.0, 12.0), turn_fraction=0.9),
}


def _room_speed(
    design: BandDesign, room_lo: float, room_hi: float, limits: Limits, tau_min: float
) -> float:
    """Fastest speed from which the device turns round before either device limit.

    Turning up near the floor of the device range uses the heating rate, turning down
    near its ceiling the cooling rate.
    """
    k = design.turn_fraction
    heat, cool = limits.rate_max_c_per_min, -limits.rate_min_c_per_min
    if design.room == "exact":
        return min(
            turning_speed(room_lo, heat, tau_min, k), turning_speed(room_hi, cool, tau_min, k)
        )
    # constant deceleration at half the planned rate k * rate / tau (conservative)
    return min(
        constant_decel_speed(room_lo, 0.5 * k * heat / tau_min),
        constant_decel_speed(room_hi, 0.5 * k * cool / tau_min),
    )


def make_bands(
    spec: ExperimentSpec,
    n_dir: int,
    direction: int,
    sep_c_per_min: float,
    params_list: Sequence[ThermalParams],
    limits: Limits,
    width_c_per_min: float = BAND_WIDTH_C_PER_MIN,
    caps: tuple[float, float] | None = None,
    dynamic: bool = True,
    knot_insets_c: Sequence[float] | None = None,
    design: BandDesign | None = None,
) -> list[Band]:
    """``n_dir`` bands ``sep`` apart, stacked down from the fastest gradient available.

    Slow sweeps cost time (a sweep lasts span / gradient), so the bands sit as high as
    the chamber allows. At each knot the top of the fastest band is ``V(T)``, the least
    of: the cap of that side (``caps = (cap at lo, cap at hi)``, linear in between), the
    gradient the chamber limits allow at T (for the least favourable scenario), and the
    speed from which the device can still turn round before its limit (``design.room``).
    With ``dynamic`` the tops are then lowered to what one sweep can follow
    (:func:`~.physics.dynamic_tops`). Bands are ``width`` wide where there is room and
    narrower where a limit squeezes them, never closer than ``delta/2`` to zero, so
    heating and cooling passes stay ``delta`` apart.
    """
    design = DESIGNS["sqrt"] if design is None else design
    if knot_insets_c is None:
        knot_insets_c = design.knot_insets_c
    knots = band_knots(spec, knot_insets_c)
    v_min = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    cap0 = spec.max_cool_c_per_min if direction < 0 else spec.max_heat_c_per_min
    cap_lo, cap_hi = caps or (cap0, cap0)
    tau_max = max(p.tau_min for p in params_list)
    tops = []
    for t in knots:
        f = (t - knots[0]) / (knots[-1] - knots[0])
        cap = cap_lo + f * (cap_hi - cap_lo)
        v_lim = min(available_rate(direction, t, p, limits, cap) for p in params_list)
        v_room = _room_speed(
            design, t - limits.device_min_c, limits.device_max_c - t, limits, tau_max
        )
        tops.append(min(v_lim, v_room))
    if dynamic:
        tops = dynamic_tops(tops, knots, direction, tau_max, limits, design.turn_fraction)
    widths = [min(width_c_per_min, (v - v_min - (n_dir - 1) * sep_c_per_min) / n_dir) for v in tops]
    bands = []
    for r in range(1, n_dir + 1):  # rank 1 = slowest
        hi = tuple(v - (n_dir - r) * (w + sep_c_per_min) for v, w in zip(tops, widths, strict=True))
        lo = tuple(h - w for h, w in zip(hi, widths, strict=True))
        bands.append(Band(direction, r, tuple(knots), lo, hi, top=r == n_dir))
    return bands


def band_feasibility(bands: Sequence[Band]) -> float:
    """Smallest band width at any knot (negative: the bands do not fit)."""
    return float(min(np.min(np.subtract(b.hi_c_per_min, b.lo_c_per_min)) for b in bands))


def transit_band(fastest: Band, spec: ExperimentSpec) -> Band:
    """A band for a sweep that repeats a level of its direction (a transit).

    Levels are counted on all passes of a bin (the largest subset ``delta`` apart), so a
    sweep beyond its direction's levels may go at any speed: it keeps the fastest band's
    top (and speed profile, which times it) but may drop to ``delta/2 + safety`` (still
    ``delta`` from every pass of the other direction). ``rank`` 0 marks it.
    """
    floor = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    lo = tuple(min(floor, x) for x in fastest.lo_c_per_min)
    return replace(fastest, rank=0, lo_c_per_min=lo, top=True)


def order_bands(
    directions: Sequence[int],
    bands_by_dir: dict[int, list[Band]],
    params: ThermalParams,
    limits: Limits,
) -> list[Band]:
    """Assign bands to sweeps so that the estimated turnaround time is smallest.

    ``bands_by_dir[d]`` holds one band per sweep of direction ``d``; a band may appear
    more than once (sweeps that repeat a level: :func:`transit_band`), and copies of one
    band are interchangeable, so only the first unused copy is tried.

    Between consecutive sweeps the gradient must go from the previous sweep's exit speed
    to the next one's entry speed at the full chamber rate
    (:func:`~.physics.turnaround_minutes`); the sweeps' own times do not depend on the
    order. The least total is a shortest path over (bands of each direction used so far,
    last band): exact, and cheap for any level count (the 518,400 permutations of 12
    levels took minutes). That estimate is nearly separable in the exit and entry speeds,
    so many orders tie; ties go to the first in the natural order (bands slowest first,
    heating sweeps before cooling ones).
    """
    idx_of = {d: [k for k, dd in enumerate(directions) if dd == d] for d in (+1, -1)}
    pool = {d: list(bands_by_dir.get(d, [])) for d in (+1, -1)}
    if any(len(pool[d]) != len(idx_of[d]) for d in (+1, -1)):
        raise ValueError("one band per sweep of each direction is needed")
    n = len(directions)
    # equal bands are interchangeable: of their unused copies only the first is tried
    earlier_copies = {
        d: [[j for j in range(i) if pool[d][j] == pool[d][i]] for i in range(len(pool[d]))]
        for d in (+1, -1)
    }

    def turn(prev: Band | None, nxt: Band) -> float:
        v_out = 0.0 if prev is None else prev.edge_speeds()[1]
        return turnaround_minutes(v_out, nxt.direction, nxt.edge_speeds()[0], params, limits)

    @cache
    def rest(pos: int, used: tuple[int, int], last: tuple[int, int] | None, pins: tuple) -> float:
        """Least turnaround time of sweeps ``pos..``; ``pins`` fixes some sweeps' bands."""
        if pos == n:
            return 0.0
        d = directions[pos]
        k = 0 if d > 0 else 1
        prev = None if last is None else pool[last[0]][last[1]]
        choices = [pins[pos]] if pins[pos] is not None else range(len(pool[d]))
        best = math.inf
        for i in choices:
            if used[k] >> i & 1:
                continue
            if pins[pos] is None and any(not used[k] >> j & 1 for j in earlier_copies[d][i]):
                continue
            nu = (used[0] | 1 << i, used[1]) if d > 0 else (used[0], used[1] | 1 << i)
            best = min(best, turn(prev, pool[d][i]) + rest(pos + 1, nu, (d, i), pins))
        return best

    optimum = rest(0, (0, 0), None, (None,) * n)
    if not math.isfinite(optimum):
        raise ValueError("no assignment of the bands to the sweeps was found")
    tol = ORDER_TIE_TOL * max(1.0, abs(optimum))
    pinned: list[int | None] = [None] * n
    for d in (+1, -1):  # pin sweep by sweep the lowest band index that keeps the optimum
        for pos in idx_of[d]:
            taken = {pinned[j] for j in idx_of[d]}
            for i in range(len(pool[d])):
                if i in taken:
                    continue
                pinned[pos] = i
                if rest(0, (0, 0), None, tuple(pinned)) <= optimum + tol:
                    break
    return [pool[d][i] for d, i in zip(directions, pinned, strict=True) if i is not None]
