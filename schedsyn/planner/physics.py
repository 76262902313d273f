"""Stage 2: how fast the device can pass a temperature -- the speed limits of a sweep.

Along a sweep the gradient ``g = dT/dt`` is a first-order lag of the chamber rate ``U``
(differentiate ``tau dT/dt + T = Tk + dT0``)::

    tau dg/dt = U - g,        U_min <= U <= U_max

and the chamber temperature ``Tk = T + tau g - dT0`` must stay within the chamber limits.
So the speed ``v = |g|`` of a sweep is bounded by

* the chamber limits at T: ``v <= (Tk_max + dT0 - T)/tau`` heating,
  ``v <= (T - Tk_min - dT0)/tau`` cooling (:func:`available_rate`);
* the distance it had to speed up: from rest at full rate ``r`` the speed ``v`` needs
  ``tau (-v - r ln(1 - v/r))`` degC (:func:`accel_distance`);
* the distance it needs to stop (turn round) before a limit: reversing at rate ``r``
  from ``v`` takes ``tau (v - r ln(1 + v/r))`` degC (:func:`stop_distance`,
  :func:`turning_speed`).

These are exact for the first-order lag at full chamber rate; the band design uses a
share ``turn_fraction`` of the rates for slack. This module is the one copy of these
formulas: band design, the shortfall explanation and the duration bound use it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ..params import Limits, ThermalParams

#: Share of the full-rate acceleration of g (rate/tau) a turnaround is planned with.
TURN_ACCEL_FRACTION = 0.85
#: Fraction of the gradient the chamber limits allow at T that the fastest band may use.
LIMIT_FRACTION = 0.92
#: Bisection steps of :func:`invert_increasing` (2^-60 of the interval: exact in floats).
BISECTION_STEPS = 60


def available_rate(
    direction: int, temp_c: float, params: ThermalParams, limits: Limits, cap: float
) -> float:
    """Largest |g| the chamber limits allow at T in this direction, capped (degC/min).

    ``g = (Tk + dT0 - T)/tau`` with ``Tk`` at its floor (cooling) or ceiling (heating);
    at most ``LIMIT_FRACTION`` of that and of the chamber rate (g only approaches the
    rate asymptotically).
    """
    tau = params.tau_min
    if direction < 0:
        limit_g = (temp_c - (limits.chamber_min_c + params.dt0_c)) / tau
        rate = -limits.rate_min_c_per_min
    else:
        limit_g = (limits.chamber_max_c + params.dt0_c - temp_c) / tau
        rate = limits.rate_max_c_per_min
    return min(cap, LIMIT_FRACTION * limit_g, LIMIT_FRACTION * rate)


def invert_increasing(fun: Callable[[float], float], target: float, hi: float) -> float:
    """Largest ``v`` in ``[0, hi]`` with ``fun(v) < target`` for increasing ``fun`` (bisection)."""
    lo_v, hi_v = 0.0, hi
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo_v + hi_v)
        if fun(mid) < target:
            lo_v = mid
        else:
            hi_v = mid
    return lo_v


def accel_distance(v, rate: float, tau_min: float):
    """Distance (degC) to speed up from rest to ``v`` at chamber rate ``rate`` (v < rate).

    ``dv/dt = (rate - v)/tau`` and ``dT = v dt`` give ``tau (-v - rate ln(1 - v/rate))``.
    Works on floats and arrays.
    """
    return tau_min * (-v - rate * np.log(np.maximum(1.0 - v / rate, 1e-12)))


def stop_distance(v, rate: float, tau_min: float):
    """Distance (degC) to stop from speed ``v`` reversing at chamber rate ``rate``.

    ``dv/dt = -(rate + v)/tau`` gives ``tau (v - rate ln(1 + v/rate))``. Floats and arrays.
    """
    return tau_min * (v - rate * np.log1p(v / rate))


def accel_time(v, rate: float, tau_min: float):
    """Time (min) to speed up from rest to ``v`` at chamber rate ``rate``:
    ``g(t) = rate (1 - exp(-t/tau))`` gives ``tau ln(rate / (rate - v))``."""
    return tau_min * np.log(rate / np.maximum(rate - v, 1e-12 * rate))


def stop_time(v, rate: float, tau_min: float):
    """Time (min) to stop from speed ``v`` reversing at ``rate``: ``tau ln(1 + v/rate)``."""
    return tau_min * np.log1p(v / rate)


def _inverse(fun: Callable, target, hi: float):
    """Elementwise largest ``v`` in ``[0, hi]`` with ``fun(v) <= target`` (``fun`` increasing,
    ``fun(0) = 0``): vectorised bisection, exact to 2^-60 of ``hi``."""
    target = np.asarray(target, dtype=float)
    lo_v, hi_v = np.zeros_like(target), np.full_like(target, hi)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo_v + hi_v)
        ok = fun(mid) <= target
        lo_v, hi_v = np.where(ok, mid, lo_v), np.where(ok, hi_v, mid)
    return lo_v


def speed_after_accel(v0, distance_c, rate: float, tau_min: float):
    """Fastest speed after ``distance_c`` degC of full-rate acceleration from ``v0``.

    Along the acceleration curve distances add: ``accel_distance(v) = accel_distance(v0) +
    distance``. The speed stays below ``rate``.
    """
    target = accel_distance(np.asarray(v0, dtype=float), rate, tau_min) + distance_c
    return _inverse(lambda v: accel_distance(v, rate, tau_min), target, rate * (1 - 1e-12))


def speed_after_decel(v0, distance_c, rate: float, tau_min: float):
    """Slowest speed after ``distance_c`` degC of full-rate braking from ``v0`` (0 if it stops)."""
    left = stop_distance(np.asarray(v0, dtype=float), rate, tau_min) - distance_c
    top = float(np.max(v0)) + 1.0
    return np.where(
        left > 0, _inverse(lambda v: stop_distance(v, rate, tau_min), np.maximum(left, 0), top), 0
    )


def speed_before_accel(v1, distance_c, rate: float, tau_min: float):
    """Slowest speed from which full-rate acceleration over ``distance_c`` reaches ``v1``."""
    left = accel_distance(np.asarray(v1, dtype=float), rate, tau_min) - distance_c
    return np.where(
        left > 0,
        _inverse(
            lambda v: accel_distance(v, rate, tau_min), np.maximum(left, 0), rate * (1 - 1e-12)
        ),
        0.0,
    )


def turning_speed(
    room_c: float,
    reverse_rate_c_per_min: float,
    tau_min: float,
    turn_fraction: float = TURN_ACCEL_FRACTION,
) -> float:
    """Fastest speed |g| from which the device stops within ``room_c`` (degC/min).

    Reversing at a share ``turn_fraction`` of the full reverse chamber rate; the inverse
    of :func:`stop_distance` (exact for the first-order lag), by bisection.
    """
    if room_c <= 0:
        return 0.0
    b = turn_fraction * reverse_rate_c_per_min
    return invert_increasing(lambda v: stop_distance(v, b, tau_min), room_c, 20.0)


def constant_decel_speed(room_c: float, decel_c_per_min2: float) -> float:
    """Speed that stops within ``room_c`` at constant deceleration: ``sqrt(2 a room)``."""
    return math.sqrt(max(2.0 * decel_c_per_min2 * room_c, 0.0))


def dynamic_tops(
    tops: Sequence[float],
    knots: Sequence[float],
    direction: int,
    tau_min: float,
    limits: Limits,
    turn_fraction: float = TURN_ACCEL_FRACTION,
) -> list[float]:
    """Lower the speed limits at the knots so that one sweep can follow them all.

    Speeding up between knots is limited by :func:`accel_distance` at the full rate in
    the travel direction, slowing down by :func:`stop_distance` at the full rate the
    other way (both with a share ``turn_fraction`` of the rates): a forward pass caps
    each knot by what the previous one allows, a backward pass by what the next needs.
    """
    up = limits.rate_max_c_per_min if direction > 0 else -limits.rate_min_c_per_min
    down = -limits.rate_min_c_per_min if direction > 0 else limits.rate_max_c_per_min
    a, b = turn_fraction * up, turn_fraction * down

    def speed_up(v: float) -> float:
        return accel_distance(v, a, tau_min)

    def slow_down(v: float) -> float:
        return stop_distance(v, b, tau_min)

    order = list(range(len(knots))) if direction > 0 else list(range(len(knots)))[::-1]
    v = list(tops)
    for i, j in zip(order[:-1], order[1:], strict=True):  # speeding up, forwards
        dist = abs(knots[j] - knots[i])
        v[j] = min(
            v[j], invert_increasing(speed_up, speed_up(min(v[i], 0.999 * a)) + dist, 0.999 * a)
        )
    for i, j in zip(order[::-1][:-1], order[::-1][1:], strict=True):  # slowing, backwards
        dist = abs(knots[j] - knots[i])
        v[j] = min(v[j], invert_increasing(slow_down, slow_down(v[i]) + dist, 10.0))
    return v


def turnaround_minutes(
    v_from: float, d_to: int, v_to: float, params: ThermalParams, limits: Limits
) -> float:
    """Time for g to go from ``-d_to * v_from`` to ``d_to * v_to`` at the full chamber rate.

    ``g(t) = U + (g0 - U) exp(-t/tau)`` under a constant rate U.
    """
    u = limits.rate_max_c_per_min if d_to > 0 else limits.rate_min_c_per_min
    g0, g1 = -d_to * v_from, d_to * v_to
    ratio = (g0 - u) / (g1 - u)
    return params.tau_min * math.log(ratio) if ratio > 1 else 0.0
