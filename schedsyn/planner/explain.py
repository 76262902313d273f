"""Why a request falls short: which limit binds, in words with numbers."""

from __future__ import annotations

import dataclasses
import math

from ..params import Limits, ThermalParams
from .bands import BAND_SAFETY_C_PER_MIN
from .physics import TURN_ACCEL_FRACTION, turning_speed
from .request import ExperimentSpec

#: Gradient headroom (degC/min) above the levels' own spread under which a chamber limit
#: is reported as binding at a working edge.
HEADROOM_C_PER_MIN = 0.1


def explain_shortfall(spec: ExperimentSpec, params: ThermalParams, limits: Limits) -> list[str]:
    """Which limit makes the region's edges hard to cover, in words with numbers."""
    notes = []
    tau = params.tau_min
    n_cool = spec.levels_required // 2
    n_heat = spec.levels_required - n_cool
    delta = spec.delta_c_per_min
    # g = (Tk + dT0 - T)/tau with the chamber at its floor / ceiling
    g_cool = (spec.working_lo_c - (limits.chamber_min_c + params.dt0_c)) / tau
    if g_cool <= 0:
        floor_t = limits.chamber_min_c + params.dt0_c
        reach = spec.working_lo_c - spec.edge_margin_c - params.dt0_c
        notes.append(
            f"the chamber floor {limits.chamber_min_c:g} °C cannot bring the device below "
            f"{floor_t:g} °C (floor + dT0), so the bins below it are unreachable; "
            + _limit_needed(spec, params, limits, "chamber_min_c", reach, -1.0)
        )
    elif g_cool < n_cool * delta + HEADROOM_C_PER_MIN:
        notes.append(
            f"at {spec.working_lo_c:g} °C the chamber floor {limits.chamber_min_c:g} °C "
            f"allows cooling gradients of at most {g_cool:.3f} °C/min "
            f"(g = (Tk_min + dT0 - T)/tau); "
            + (
                f"{n_cool} cooling levels {delta:g} °C/min apart need at least about "
                f"{n_cool * delta:.2f} °C/min there"
                if n_cool > 1
                else f"even one cooling level needs at least {delta / 2:g} °C/min there"
            )
            + f", and planning gets hard below {n_cool * delta + HEADROOM_C_PER_MIN:.2f} "
            "°C/min (the sweeps must also pass the edge at speed): lower the floor or the "
            "level count"
        )
    g_heat = (limits.chamber_max_c + params.dt0_c - spec.working_hi_c) / tau
    if g_heat <= 0:
        reach = spec.working_hi_c + spec.edge_margin_c - params.dt0_c
        notes.append(
            f"the chamber ceiling {limits.chamber_max_c:g} °C cannot bring the device above "
            f"{limits.chamber_max_c + params.dt0_c:g} °C (ceiling + dT0), so the bins above "
            "it are unreachable; "
            + _limit_needed(spec, params, limits, "chamber_max_c", reach, 1.0)
        )
    elif g_heat < n_heat * delta + HEADROOM_C_PER_MIN:
        notes.append(
            f"at {spec.working_hi_c:g} °C the chamber ceiling {limits.chamber_max_c:g} °C "
            f"allows heating gradients of at most {g_heat:.3f} °C/min; "
            + (
                f"{n_heat} heating levels {delta:g} °C/min apart need at least about "
                f"{n_heat * delta:.2f} °C/min there"
                if n_heat > 1
                else f"even one heating level needs at least {delta / 2:g} °C/min there"
            )
            + f", and planning gets hard below {n_heat * delta + HEADROOM_C_PER_MIN:.2f} "
            "°C/min (the sweeps must also pass the edge at speed): raise the ceiling or lower the "
            "level count"
        )
    # turning room between the working edges and the device limits
    n_dir = max(n_cool, n_heat)
    for edge, room, rate, word in (
        (
            spec.working_lo_c,
            spec.working_lo_c - limits.device_min_c,
            limits.rate_max_c_per_min,
            "heating",
        ),
        (
            spec.working_hi_c,
            limits.device_max_c - spec.working_hi_c,
            -limits.rate_min_c_per_min,
            "cooling",
        ),
    ):
        v_room = turning_speed(room, rate, tau, TURN_ACCEL_FRACTION)
        if v_room < 2 * n_dir * (delta + BAND_SAFETY_C_PER_MIN):
            notes.append(
                f"at {edge:g} °C the device limit leaves {room:g} °C to turn round; with "
                f"the chamber {word} at {rate:g} °C/min the passes there cannot be faster "
                f"than about {v_room:.2f} °C/min, so {n_dir} levels per direction there "
                "need slow, long passes: widen the device limits, lower the level count or "
                "lengthen the experiment"
            )
    if spec.approx_lo_c < limits.device_min_c or spec.approx_hi_c > limits.device_max_c:
        notes.append(
            f"the approximation region [{spec.approx_lo_c:g}, {spec.approx_hi_c:g}] °C "
            f"exceeds the device limits {limits.device_min_c:g} .. {limits.device_max_c:g} °C"
        )
    return notes


#: How far past the reach (degC) :func:`_limit_needed` looks for a chamber limit the
#: duration bound allows, and to what resolution.
LIMIT_SEARCH_C = 40.0
LIMIT_RESOLUTION_C = 0.25


def _limit_needed(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    name: str,
    reach_c: float,
    sign: float,
) -> str:
    """What a chamber limit (``name``, moved in the direction ``sign``) must at least be:
    past ``reach_c`` (limit + dT0 past the region's edge and its margin: the device only
    approaches limit + dT0) and far enough that the proven duration bound fits the
    budget, found by bisection to :data:`LIMIT_RESOLUTION_C`. Said as necessary, not
    sufficient (red team: "a floor of at most -54.25 °C is needed" read as a fix, but the
    bound there was 624 min against a 540-min budget; planning found -57 °C). The
    figure is the last one the bound rules out (a red team found "-44.25 needed" where
    -43.3 fits the bound and -44 plans: one degree too many, then rounded outward)."""
    from .bound import duration_lower_bound

    word = "floor" if sign < 0 else "ceiling"
    past = "below" if sign < 0 else "above"

    def fits(value: float) -> bool:
        try:
            moved = dataclasses.replace(limits, **{name: value})
        except (ValueError, TypeError):
            return False
        bound = duration_lower_bound(spec, params, moved).lower_bound_min
        return math.isfinite(bound) and bound <= limits.duration_max_min

    near, far = reach_c, reach_c + sign * LIMIT_SEARCH_C
    if not fits(far):
        return (
            f"a {word} {past} {reach_c:g} °C is needed to reach the region ({word} + dT0 "
            f"past the edge and its {spec.edge_margin_c:g} °C margin), and even {far:g} °C "
            f"leaves the proven duration bound above the {limits.duration_max_min:g}-min "
            "budget (see --advise)"
        )
    if not fits(near):  # bisect: near does not fit, far does
        while abs(far - near) > LIMIT_RESOLUTION_C:
            mid = 0.5 * (near + far)
            near, far = (near, mid) if fits(mid) else (mid, far)
    # the last value ruled out, to the resolution, rounded towards the region (still ruled
    # out); the device never quite reaches limit + dT0, so reach_c itself is ruled out
    step = LIMIT_RESOLUTION_C
    shown = math.ceil(near / step) * step if sign < 0 else math.floor(near / step) * step
    shown = max(shown, near) if sign < 0 else min(shown, near)
    return (
        f"a {word} {past} {shown:g} °C is needed (to reach the region and for the proven "
        f"duration bound to fit {limits.duration_max_min:g} min; {far:.2f} °C fits the "
        "bound; necessary, not sufficient: --advise plans with it to check)"
    )
