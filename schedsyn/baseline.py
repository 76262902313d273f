"""Paper-like chamber programmes: the hand-made kind of plan schedsyn is compared with.

The paper's experiment 1 was planned by simulation and a semi-heuristic choice of the
ramps: from +20 degC the chamber cools the device to the bottom of the approximation
region, then heats and cools it in alternating cycles across the region, and returns to
20 degC within 9 h. :func:`paper_like_programme` builds such a programme for any region
and duration:

1. **First leg**: ramp the chamber at its full rate towards the *far* edge of the
   approximation region (the one farther from the start temperature), hold ``H`` min.
2. **Cycles**: alternately towards the other edge and back, heating at the rates
   ``heat_rates_c_per_min`` and cooling at ``cool_rates_c_per_min`` (each list used in
   turn; the defaults 2.0, 1.4, 2.7 and 0.9 degC/min are those of the hand-made baseline
   ``data/baseline_exp1_steps.csv``), each ramp followed by a hold of ``H`` min.
3. **Return**: ramp to the end temperature at the next rate of its direction, then hold
   until ``duration_min``.

Each leg's chamber setpoint is found by bisection so that the device turns round where
wanted (it keeps moving after the chamber turns: the setpoint lies beyond the turning
point by ``dT0`` and the lag): the first leg ``edge_inset_c`` inside the far edge, the
cycles at varied depths like the hand-made baseline's, which turns at -19.7, -46.1,
-23.4 and -51.7 degC in its approximation region [-52, -20] degC: ``cycle_insets``
(0, 0.18, 0.11, 0.01) of the region's width inside the edge, in turn (at least
``edge_inset_c``). Varied turning points spread the passes over the phase plane. The number of
cycles is the largest that fits with holds of at least ``min_hold_min``; the common hold
``H`` then stretches so the programme lasts ``duration_min`` (whole minutes, 0.1 degC,
as an operator types it, via :meth:`schedsyn.programme.Programme.rounded`).

For W1 and the hand-made baseline's 496 min this gives the same structure (a cooling,
then three heating and two cooling cycles, the last heating the return); the tests check
its coverage and information against the hand-made table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import ParameterError
from .params import Limits, ThermalParams
from .programme import Programme
from .simulate import simulate

#: The hand-made baseline's rates (``scripts/make_baseline.py``), degC/min.
HEAT_RATES_C_PER_MIN = (2.0, 1.4, 2.7)
COOL_RATES_C_PER_MIN = (0.9,)
#: Shortest hold at a turning setpoint, min.
MIN_HOLD_MIN = 10.0
#: The device turns at least this far inside the approximation region's edges, degC.
EDGE_INSET_C = 0.5
#: Turning depths of the cycles, fractions of the approximation region's width inside
#: the edge, in turn: the hand-made baseline's (-19.7, -46.1, -23.4, -51.7 degC in
#: [-52, -20] degC).
CYCLE_INSETS = (0.0, 0.18, 0.11, 0.01)
#: Simulation step of the setpoint search, min.
_STEP_MIN = 0.5


def _evolve(
    t_c: float, tk_c: float, durations: Sequence[float], rates: Sequence[float], params
) -> tuple[float, float]:
    """Device and chamber temperature after the segments, from state ``(t_c, tk_c)``."""
    prog = Programme(np.asarray(durations, float), np.asarray(rates, float), tk_c)
    traj = simulate(prog, params, times_min=np.array([0.0, prog.total_min]), t0_c=t_c)
    return float(traj.t_c[-1]), float(traj.tk_c[-1])


def _extreme(
    t_c: float,
    tk_c: float,
    setpoint_c: float,
    rate: float,
    hold_min: float,
    next_rate: float,
    direction: int,
    params: ThermalParams,
) -> float:
    """Device extreme (min when cooling) of: ramp to ``setpoint``, hold, next ramp."""
    durations: list[float] = []
    rates: list[float] = []
    if abs(setpoint_c - tk_c) > 1e-9:
        durations.append(abs(setpoint_c - tk_c) / rate)
        rates.append(math.copysign(rate, setpoint_c - tk_c))
    if hold_min > 0:
        durations.append(hold_min)
        rates.append(0.0)
    # after the hold the chamber turns: the device stops within a few tau
    durations.append(4.0 * params.tau_min)
    rates.append(-direction * next_rate)
    prog = Programme(np.array(durations), np.array(rates), tk_c)
    traj = simulate(prog, params, dt_min=_STEP_MIN, t0_c=t_c)
    return float(traj.t_c.min() if direction < 0 else traj.t_c.max())


def _setpoint(
    t_c: float,
    tk_c: float,
    target_c: float,
    rate: float,
    hold_min: float,
    next_rate: float,
    direction: int,
    params: ThermalParams,
    limits: Limits,
) -> float:
    """Chamber setpoint at which the device turns at ``target_c`` (bisection)."""
    # the device never passes setpoint + dT0 before the chamber turns, so the setpoint
    # lies beyond target - dT0; the chamber limit bounds it
    near = target_c - params.dt0_c
    far = limits.chamber_min_c if direction < 0 else limits.chamber_max_c
    if direction * (near - tk_c) < 0:  # already beyond: no ramp needed in this direction
        near = tk_c
    if direction * (far - near) <= 0:
        return far

    def reached(s: float) -> bool:
        ext = _extreme(t_c, tk_c, s, rate, hold_min, next_rate, direction, params)
        return direction * (ext - target_c) >= 0

    if not reached(far):
        return far  # the chamber limit stops the device short of the target
    lo, hi = near, far  # reached(hi) is True
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if reached(mid):
            hi = mid
        else:
            lo = mid
        if abs(hi - lo) < 0.02:
            break
    return hi


def _legs(
    n_turns: int,
    hold_min: float,
    first_direction: int,
    targets: Sequence[tuple[float, float]],
    heat: Sequence[float],
    cool: Sequence[float],
    params: ThermalParams,
    limits: Limits,
) -> tuple[list[float], list[float]]:
    """Segments ``(durations, rates)`` of ``n_turns`` turning legs and the return ramp."""
    directions = [first_direction * (-1) ** k for k in range(n_turns + 1)]
    n_heat = n_cool = 0
    leg_rates = []
    for k, d in enumerate(directions):
        if k == 0:
            leg_rates.append(limits.rate_max_c_per_min if d > 0 else -limits.rate_min_c_per_min)
        elif d > 0:
            leg_rates.append(heat[n_heat % len(heat)])
            n_heat += 1
        else:
            leg_rates.append(cool[n_cool % len(cool)])
            n_cool += 1
    t_c, tk_c = limits.t_init_c, limits.start_c
    durations: list[float] = []
    rates: list[float] = []
    for k in range(n_turns):
        d = directions[k]
        target = targets[k % len(targets)][0 if d < 0 else 1]
        s = _setpoint(
            t_c, tk_c, target, leg_rates[k], hold_min, leg_rates[k + 1], d, params, limits
        )
        seg_d, seg_u = [], []
        if abs(s - tk_c) > 1e-9:
            seg_d.append(abs(s - tk_c) / leg_rates[k])
            seg_u.append(math.copysign(leg_rates[k], s - tk_c))
        seg_d.append(hold_min)
        seg_u.append(0.0)
        t_c, tk_c = _evolve(t_c, tk_c, seg_d, seg_u, params)
        durations += seg_d
        rates += seg_u
    # return to the end temperature at the next rate of its direction
    d_end = limits.end_c - tk_c
    if abs(d_end) > 1e-9:
        r = leg_rates[n_turns] if math.copysign(1, d_end) == directions[n_turns] else None
        if r is None:
            r = limits.rate_max_c_per_min if d_end > 0 else -limits.rate_min_c_per_min
        durations.append(abs(d_end) / r)
        rates.append(math.copysign(r, d_end))
    return durations, rates


def paper_like_programme(
    working_lo_c: float,
    working_hi_c: float,
    approx_lo_c: float,
    approx_hi_c: float,
    duration_min: float,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    heat_rates_c_per_min: Sequence[float] = HEAT_RATES_C_PER_MIN,
    cool_rates_c_per_min: Sequence[float] = COOL_RATES_C_PER_MIN,
    min_hold_min: float = MIN_HOLD_MIN,
    edge_inset_c: float = EDGE_INSET_C,
    cycle_insets: Sequence[float] = CYCLE_INSETS,
) -> Programme:
    """A paper-like programme of ``duration_min`` for a region (see the module docstring).

    Parameters
    ----------
    working_lo_c, working_hi_c : float
        Working region, degC (checked to lie inside the approximation region).
    approx_lo_c, approx_hi_c : float
        Approximation region, degC: the device turns inside its edges.
    duration_min : float
        Length of the programme, min (whole minutes after rounding; at most the limit).
    params, limits : ThermalParams, Limits
        Device model and chamber limits (defaults as everywhere).
    heat_rates_c_per_min, cool_rates_c_per_min : sequence of float
        Rates of the heating and cooling cycles, each in turn, degC/min (> 0, within
        the chamber limits). The first leg uses the full chamber rate.
    min_hold_min : float
        Shortest hold at a turning setpoint, min.
    edge_inset_c : float
        How far inside the far edge the first leg turns, and the least any leg does, degC.
    cycle_insets : sequence of float
        Turning depths of the cycles as fractions of the approximation region's width
        (each in [0, 0.4]), in turn; ``(0,)`` turns every cycle at the edges.

    Raises
    ------
    ParameterError
        Inconsistent regions, rates outside the chamber limits, a region outside the
        device limits, or a duration too short for one leg and the return.
    """
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    if not (approx_lo_c <= working_lo_c < working_hi_c <= approx_hi_c):
        raise ParameterError(
            f"need approx_lo <= working_lo < working_hi <= approx_hi, got approximation "
            f"{approx_lo_c:g} .. {approx_hi_c:g} and working {working_lo_c:g} .. "
            f"{working_hi_c:g} °C"
        )
    if approx_lo_c < limits.device_min_c or approx_hi_c > limits.device_max_c:
        raise ParameterError(
            f"the approximation region {approx_lo_c:g} .. {approx_hi_c:g} °C leaves the "
            f"device limits {limits.device_min_c:g} .. {limits.device_max_c:g} °C"
        )
    if not 0 <= edge_inset_c < 0.5 * (approx_hi_c - approx_lo_c):
        raise ParameterError(f"edge_inset_c must be >= 0 and small, got {edge_inset_c!r}")
    heat = [float(r) for r in heat_rates_c_per_min]
    cool = [float(r) for r in cool_rates_c_per_min]
    if not heat or not all(0 < r <= limits.rate_max_c_per_min for r in heat):
        raise ParameterError(
            f"heat_rates_c_per_min must be in (0, {limits.rate_max_c_per_min:g}] °C/min, got {heat}"
        )
    if not cool or not all(0 < r <= -limits.rate_min_c_per_min for r in cool):
        raise ParameterError(
            f"cool_rates_c_per_min must be in (0, {-limits.rate_min_c_per_min:g}] °C/min, "
            f"got {cool}"
        )
    if not (math.isfinite(duration_min) and 0 < duration_min <= limits.duration_max_min):
        raise ParameterError(
            f"duration_min must be in (0, {limits.duration_max_min:g}] min, got {duration_min!r}"
        )
    if not (math.isfinite(min_hold_min) and min_hold_min >= 0):
        raise ParameterError(f"min_hold_min must be >= 0 min, got {min_hold_min!r}")
    insets = [float(f) for f in cycle_insets]
    if not insets or not all(0 <= f <= 0.4 for f in insets):
        raise ParameterError(f"cycle_insets must be fractions in [0, 0.4], got {insets}")
    width = approx_hi_c - approx_lo_c
    depths = [edge_inset_c] + [max(edge_inset_c, f * width) for f in insets]
    start = limits.t_init_c
    first = -1 if abs(start - approx_lo_c) >= abs(start - approx_hi_c) else 1

    # leg k turns at depths[k] (the first leg) or at the cycles' depths in turn
    def _targets(n: int) -> list[tuple[float, float]]:
        ks = [0] + [1 + (k % len(insets)) for k in range(max(n - 1, 0))]
        return [(approx_lo_c + depths[k], approx_hi_c - depths[k]) for k in ks]

    def total(n: int, hold: float) -> float:
        d, _ = _legs(n, hold, first, _targets(n), heat, cool, params, limits)
        return float(sum(d))

    # an odd number of turning legs ends at the far edge, so that the return crosses the
    # whole region (the paper's last heating); the most that fit with the shortest holds
    n = -1
    while n < 39 and total(n + 2, min_hold_min) <= duration_min:
        n += 2
    if n < 1:
        raise ParameterError(
            f"{duration_min:g} min is too short for a paper-like programme over "
            f"{approx_lo_c:g} .. {approx_hi_c:g} °C (one leg and the return take "
            f"{total(1, min_hold_min):.0f} min)"
        )
    lo_h, hi_h = min_hold_min, min_hold_min + duration_min / n
    for _ in range(30):  # the longest common hold that still fits
        mid = 0.5 * (lo_h + hi_h)
        if total(n, mid) <= duration_min:
            lo_h = mid
        else:
            hi_h = mid
    durations, rates = _legs(n, lo_h, first, _targets(n), heat, cool, params, limits)
    rest = duration_min - sum(durations)
    if rest > 1e-6:
        durations.append(rest)
        rates.append(0.0)
    prog = Programme(np.array(durations), np.array(rates), limits.start_c).rounded(limits)
    return _fit_length(prog, duration_min, limits)


def _fit_length(prog: Programme, duration_min: float, limits: Limits) -> Programme:
    """Pad (hold at the end) or trim the last hold so the programme lasts the duration."""
    target = float(round(duration_min))
    diff = target - prog.total_min
    d = prog.durations_min.copy()
    u = prog.rates_c_per_min.copy()
    if diff > 0:
        if abs(u[-1]) < 1e-12:
            d[-1] += diff
        else:
            d = np.append(d, diff)
            u = np.append(u, 0.0)
    elif diff < 0:
        holds = np.flatnonzero(np.abs(u) < 1e-12)
        k = int(holds[-1]) if holds.size else -1
        if k < 0 or d[k] + diff <= 0:
            raise ParameterError(
                f"cannot fit the paper-like programme into {duration_min:g} min"
            )  # pragma: no cover - holds are at least min_hold_min long
        d[k] += diff
    return Programme(d, u, prog.start_c)
