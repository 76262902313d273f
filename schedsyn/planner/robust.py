"""Stage 8: robust plans -- one programme for every (tau, dT0) in a box.

For fixed (tau, dT0), T and g are affine in the rates, so the constraints of several
scenarios together stay linear: the box centre (the reference the sweeps are placed for),
three tau values x both ends of the dT0 range (T and g are affine in dT0, so its ends
bound it; :func:`~.request.robust_scenarios`). A robust plan is verified on a dense grid
over the whole box (:func:`verify_robust`) and is complete only if coverage holds at every
grid point. When its search finds no programme for the box, :func:`search_robust` falls
back to the nominal point with the widest margins if its programme holds on the box after
all, else searches the box again with the scenarios held closer to their bands, then the
box's inner half, its inner quarter, and last takes that nominal plan. Before the inner
boxes (``whole_box``), and when the programme the planner keeps does not hold on the
whole box, the ramp rung (:mod:`.ramps`) searches ramp-and-hold programmes for the whole
box; a box :func:`~.ramps.box_spread_proof` proves no programme covers is not searched
as a whole.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import partial

import numpy as np
import pandas as pd

from ..model import FirstOrderLag
from ..params import Limits, ThermalParams
from ..programme import Programme
from .check import REPORT_DELTA_C_PER_MIN, Plan
from .lp import LpStats
from .request import ExperimentSpec, robust_scenarios
from .search import Progress, Search, synthesise

Range = tuple[float, float] | None

#: How far past a device limit a grid point of the box check may go and still hold, degC
#: (rounding: the planner's own device check allows 1e-6 degC).
DEVICE_TOL_C = 1e-6

#: The slack (how far outside its band a scenario other than the reference may stray)
#: tried for the whole box after the default (:data:`~.lp.ROBUST_SLACK_C_PER_MIN`),
#: degC/min: the bands' spacing shrinks with it, so more levels fit, but the scenarios are
#: held closer to them (red team: a 6-level box with cooling at 0.6 degC/min had no
#: room for the default's bands and fitted at half of it).
NARROWER_SLACKS_C_PER_MIN = (0.025, 0.0125)
#: Shares of the box (each range about its centre) tried when the whole box does not fit.
INNER_SHARES = ((0.5, "half"), (0.25, "quarter"))


def box_scenarios(params: ThermalParams, tau_s: Range, dt0_c: Range) -> list[ThermalParams]:
    """The reference scenario (the box centre) followed by the scenarios of the box."""
    centre = replace(
        params,
        tau_s=float(np.mean(tau_s)) if tau_s else params.tau_s,
        dt0_c=float(np.mean(dt0_c)) if dt0_c else params.dt0_c,
    )
    return [centre, *robust_scenarios(params, tau_s, dt0_c)]


def _inner(rng: Range, share: float) -> Range:
    if rng is None:
        return None
    mid, half = 0.5 * (rng[0] + rng[1]), 0.5 * share * (rng[1] - rng[0])
    return (mid - half, mid + half)


def search_robust(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    tau_s: Range,
    dt0_c: Range,
    progress: Progress,
    stats: LpStats,
    holds_on_box: Callable[[Search], bool] | None = None,
    stop: Callable[[str], bool] | None = None,
    whole_box: Callable[[], bool] | None = None,
    proven_impossible: bool = False,
) -> tuple[Search, list[str], str | None]:
    """Search a programme for the whole box, else the fallbacks: the search, notes saying
    which was used, and the fallback's name (None: the whole box).

    The fallbacks: the nominal plan with the widest margins when ``holds_on_box`` (the
    dense check of its programme over the box) says it holds after all; else the whole
    box again with the scenarios held closer to their bands
    (:data:`NARROWER_SLACKS_C_PER_MIN`); else a programme for the box's inner half, then
    its inner quarter; else that nominal plan. The search is stricter than the dense
    check (each scenario's windows are placed from the box centre, its bands spaced for
    the slack), and finding nothing is not a proof that no programme fits: the notes say
    "the search found none", never "none fits". The nominal plan is one scenario's
    search: checked first, it spares the other searches and answers for the whole box
    where the inner boxes would answer for a part. ``stop(phrase)`` is asked before
    each later search (the nominal plan is then in hand) and by it, ``phrase`` saying
    which search that skips or cuts ("... was not searched", "... was not searched to
    the end"): True skips the rest (an effort limit; a wide box's search ran 10 min per
    rung). ``whole_box()`` is asked before the inner boxes are searched, the effort limit
    aside: True (another search planned the whole box) skips them. ``proven_impossible``
    (no programme covers the whole box: :func:`~.ramps.box_spread_proof`) skips the
    searches for the whole box.
    """
    params_list = box_scenarios(params, tau_s, dt0_c)
    models = [FirstOrderLag(p) for p in params_list]
    if proven_impossible:
        not_found = (
            "FALLBACK: no programme meets the target for every scenario of the robust box "
            "(proven: see the note that says why), so it was not searched"
        )
    else:
        search = synthesise(spec, params_list, limits, models, progress, stats)
        if search.best is not None:
            return search, [], None
        not_found = (
            "FALLBACK: the search found no single programme meeting the target for every "
            "scenario of the robust box (not a proof that none exists: the search holds "
            "every scenario to bands placed from the box centre)"
        )
    if progress:
        progress(
            "no programme for the robust box; checking the nominal plan with the widest "
            "margins on it"
        )
    spec_margin = replace(spec, objective="margin")
    margin = synthesise(spec_margin, [params], limits, [FirstOrderLag(params)], progress, stats)
    if holds_on_box is not None and holds_on_box(margin):
        note = (
            f"{not_found}; planned at the nominal point with the widest margins that fit, "
            "whose programme as first planned (before its steps were shaped) held on the "
            "whole box by the dense check"
        )
        return margin, [note], "nominal point"
    skipped = ""

    def stopped(what: str, begun: bool = False) -> bool:
        """The effort limit, asked before the search ``what`` (``begun``: by it): the
        phrase given to ``stop`` says which, for the effort note."""
        nonlocal skipped
        phrase = f"{what} was {'not searched to the end' if begun else 'not searched'}"
        if stop is not None and stop(phrase):
            skipped = what
            return True
        return False

    # the bands spaced for the default slack may leave too little room for the levels
    # (many levels, slow rate limits): the same box, the scenarios held closer to their
    # bands. Only then: where the bands fitted, the slack was not what failed, and the
    # inner boxes deserve the effort more (red team: a wide box's slack rungs spent it)
    for slack in NARROWER_SLACKS_C_PER_MIN if not proven_impossible and search.no_room else ():
        what = f"the robust box with its scenarios held within {slack:g} °C/min of their bands"
        if stopped(what):
            break
        if progress:
            progress(f"the search found no programme for the robust box; trying {what}")
        search = synthesise(
            spec,
            params_list,
            limits,
            models,
            progress,
            stats,
            stop=partial(stopped, what, True),
            robust_slack_c_per_min=slack,
        )
        if search.best is not None:
            return search, [], None
        if skipped or not search.no_room:  # the limit cut it, or the bands now fit
            break
    if whole_box is not None and whole_box():
        # another search covered the whole box (the ramp rung): the inner boxes could
        # only answer for a part of it
        return margin, [f"{not_found}; planned for the whole box otherwise"], "nominal point"
    for share, word in INNER_SHARES if not skipped else ():
        what = f"the robust box's inner {word}"
        if stopped(what):
            break
        in_tau, in_dt0 = _inner(tau_s, share), _inner(dt0_c, share)
        if progress:
            progress(f"the search found no programme for the robust box; trying its inner {word}")
        inner_list = [params_list[0], *robust_scenarios(params, in_tau, in_dt0)]
        search = synthesise(
            spec,
            inner_list,
            limits,
            [FirstOrderLag(p) for p in inner_list],
            progress,
            stats,
            stop=partial(stopped, what, True),
        )
        if search.best is not None:
            box = " x ".join(
                f"{name} {r[0]:g}..{r[1]:g} {unit}"
                for name, r, unit in (("tau", in_tau, "s"), ("dT0", in_dt0, "°C"))
                if r is not None
            )
            return (
                search,
                [f"{not_found}; planned robustly for its inner {word} ({box})"],
                (f"inner {word}"),
            )
        if skipped:
            break
    if skipped:
        if progress:
            progress(f"effort limit: {skipped} and what follows it are not searched")
        tail = f"; the search stopped at its effort limit before finishing {skipped}"
    else:
        tail = ", nor for its inner half or quarter"
    return (
        margin,
        [f"{not_found}{tail}; planned at the nominal point with the widest margins that fit"],
        "nominal point",
    )


#: The robust box check's grid: tau x dT0 points, ends included. Two passes' gradients
#: can cross between the points of a coarser grid: at 9 x 7 a fallback's "it holds for"
#: sub-box failed between its points (red team: 90 % at tau 1800 s, dT0 2 degC, inside a
#: sub-box claimed from 48 grid points). A 25 x 19 check takes about 0.7 s.
BOX_CHECK_N_TAU = 25
BOX_CHECK_N_DT0 = 19


def verify_robust(
    programme: Programme,
    spec: ExperimentSpec,
    params: ThermalParams,
    tau_range: Range,
    dt0_range: Range,
    limits: Limits,
) -> dict:
    """Dense check of a robust plan over its whole box (:data:`BOX_CHECK_N_TAU` x
    :data:`BOX_CHECK_N_DT0` grid, ends included)."""
    from ..sweep import verify_box

    res = verify_box(
        programme,
        (spec.working_lo_c, spec.working_hi_c),
        tau_range if tau_range is not None else (params.tau_s, params.tau_s),
        dt0_range if dt0_range is not None else (params.dt0_c, params.dt0_c),
        n_tau=BOX_CHECK_N_TAU,
        n_dt0=BOX_CHECK_N_DT0,
        levels_required=spec.levels_required,
        # (once: the table's own delta may be the reported one)
        deltas_c_per_min=tuple(dict.fromkeys((spec.delta_c_per_min, REPORT_DELTA_C_PER_MIN))),
        t0_c=limits.t_init_c,
    )
    # a point holds where coverage does and the device stays within its limits (a table
    # that takes the low-dT0 device past its limit was said to hold there: red team)
    within = res.device_excess_c(limits.device_min_c, limits.device_max_c) <= DEVICE_TOL_C
    # the part named is around the nominal point where that holds (a nominal-point
    # plan named a corner of the box, leaving out the point it was made for: red team)
    nominal = (
        int(np.argmin(np.abs(res.tau_s_values - params.tau_s))),
        int(np.argmin(np.abs(res.dt0_c_values - params.dt0_c))),
    )
    part = res.covered_box(also=within, containing=nominal) or res.covered_box(also=within)
    return {
        "holds": res.holds() and bool(within.all()),
        "full_share": res.full_share,
        "worst": res.worst(),
        "min_levels": int(res.min_levels_grid.min()),
        "covered_box": part,
        "grid_points": int(np.prod(res.shape)),
        "device_held": bool(within.all()),
    }


def box_note(box_check: dict) -> str:
    """Where coverage fails in the box and which part of it it holds on, in words."""
    part = box_check["covered_box"]
    worst = box_check["worst"]
    device = not box_check.get("device_held", True)
    held = (
        f"it holds{' (coverage and device limits)' if device else ''} for tau "
        f"{part['tau_s_range'][0]:g}..{part['tau_s_range'][1]:g} s "
        f"x dT0 {part['dt0_c_range'][0]:g}..{part['dt0_c_range'][1]:g} °C"
        if part
        else "no grid point holds"
    )
    past = "the device passes its limits at some points of the box"
    if worst["coverage"] >= 1.0:  # only the device limits fail
        return f"coverage holds everywhere in the robust box, but {past}; {held}"
    return (
        "coverage does not hold everywhere in the robust box (worst point tau "
        f"{worst['tau_s']:g} s, dT0 {worst['dt0_c']:g} °C: {worst['coverage']:.0%})"
        + (f" and {past}" if device else "")
        + f"; {held}"
    )


def held_note(fallback: str, box_check: dict) -> str:
    """A fallback's programme that holds on the whole box after all: the note that says so
    (instead of the fallback's, which said no programme for the whole box was found)."""
    return (
        f"no programme was found by the search for the whole robust box, but the one "
        f"planned for its fallback ({fallback}) holds at all {box_check['grid_points']} "
        "points of the box's grid (dense check): complete for the whole box"
    )


def robustness_price(
    nominal: Plan,
    robust: Plan,
    tau_s_range: Range,
    dt0_c_range: Range,
) -> pd.DataFrame:
    """The price of robustness: a nominal and a robust plan side by side.

    Both plans are checked on the same dense grid over the box (:func:`verify_robust`,
    25 x 19 points); one row per plan with its duration, steps, coverage at
    delta and at 0.1 degC/min (``coverage_basis``: the robust plan's worst design
    scenario, the nominal plan's nominal point), ``coverage_nominal`` (both at the nominal
    point), and over the box the worst coverage, the fewest levels and the share of grid
    points fully covered. The extra duration of the robust plan is in ``extra_min``.
    """
    rows = []
    for name, plan in (("nominal", nominal), ("robust", robust)):
        box = plan.box_check  # a robust plan was checked on this box's grid already
        taus = [p.tau_s for p in plan.scenarios]
        dt0s = [p.dt0_c for p in plan.scenarios]
        same_box = tau_s_range in (None, (min(taus), max(taus))) and dt0_c_range in (
            None,
            (min(dt0s), max(dt0s)),
        )
        if box is None or not same_box:
            box = verify_robust(
                plan.programme, plan.spec, nominal.params, tau_s_range, dt0_c_range, plan.limits
            )
        rows.append(
            {
                "plan": name,
                "duration_min": plan.duration_min,
                "extra_min": plan.duration_min - nominal.duration_min,
                "steps": plan.steps,
                "coverage": plan.coverage.coverage,
                "coverage_delta_0p1": plan.coverage_0p1.coverage,
                # what the two columns above are: a robust plan's coverage is its worst
                # design scenario's, a nominal plan's the nominal point's
                "coverage_basis": (
                    "worst design scenario" if plan.coverage_nominal is not None else "nominal"
                ),
                "coverage_nominal": (
                    plan.coverage.coverage
                    if plan.coverage_nominal is None
                    else plan.coverage_nominal.coverage
                ),
                "box_worst_coverage": box["worst"]["coverage"],
                "box_min_levels": box["min_levels"],
                "box_full_share": box["full_share"],
                "complete_over_box": bool(box["holds"]),
            }
        )
    return pd.DataFrame(rows)
