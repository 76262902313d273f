"""Stage 5: the search -- where each sweep's window lies in time.

The combinatorial part of the synthesis: for a sequence of sweep directions and bands,
place the sweeps one after another (:func:`greedy`), each as early and as short as the
small LP over its segments allows (:func:`place_sweep`); try a few band designs
(``CANDIDATES``) and keep the shortest structure that fits the duration limit
(:func:`synthesise`), and when none does, structures with more sweeps than levels whose
surplus sweeps repeat a level (:func:`level_splits`). When none fits, :func:`subregions`
finds the widest parts of the region that do, and :func:`truncate` cuts an over-long
structure at the limit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from ..model import FirstOrderLag, LinearThermalModel
from ..params import Limits, ThermalParams
from .bands import (
    BAND_SAFETY_C_PER_MIN,
    DESIGNS,
    Band,
    band_feasibility,
    make_bands,
    minutes_between,
    order_bands,
    transit_band,
)
from .guide import guided_bands
from .lp import (
    KNOT_TOL_C,
    PIN_MIN,
    PIN_TIME_SAFETY_MIN,
    ROBUST_SLACK_C_PER_MIN,
    SAMPLE_MIN,
    Context,
    EdgePins,
    LpStats,
    Responses,
    SubLP,
    Window,
    count_work,
    lp_nonzeros_solved,
)
from .request import Continuation, ExperimentSpec, Scenario, first_directions, sweep_directions

Progress = Callable[[str], None] | None

#: A search that has reported nothing for this long says where it is (a robust box's
#: first sweep can be searched for minutes without one being placed), s.
HEARTBEAT_S = 30.0


class Heartbeat:
    """``progress`` passed through, remembering when it last spoke; :meth:`beat` speaks
    only when that is :data:`HEARTBEAT_S` ago (the text is built only then). Only the
    progress lines depend on the clock, never the search."""

    def __init__(self, progress: Callable[[str], None], clock: Callable[[], float]):
        self.progress, self.clock = progress, clock
        self.last_s = clock()

    def __call__(self, message: str) -> None:
        self.progress(message)
        self.last_s = self.clock()

    def beat(self, text: Callable[[], str]) -> None:
        if self.clock() - self.last_s >= HEARTBEAT_S:
            self(text())


#: Longest transition (turnaround) searched before a sweep, min.
MAX_TRANSITION_MIN = 150.0
#: Weight of |rate| in a probe's objective (among equally slow exits, the calmest rates).
PROBE_L1_WEIGHT = 1e-4
#: Robust plans: segments simulated past a sweep's planned end to find where the lagging
#: scenarios leave the region (the last rate is held).
SCENARIO_LOOKAHEAD_SEG = 6
#: Robust plans: times a sweep's reference is placed further beyond the edges for the
#: scenarios that turn round short of them (:func:`edge_shortfall_c`), and the margin
#: added each time beyond the shortfall, degC.
WIDEN_TRIES = 3
WIDEN_PAD_C = 0.1


@dataclass(frozen=True, slots=True)
class Guided:
    """Bands around parallel speed profiles designed with ``rate_share`` of the chamber
    rates, ``width`` wide (:func:`~.guide.guided_bands`)."""

    rate_share: float
    width_c_per_min: float
    #: how the profiles' turns are costed (:func:`~.guide.parallel_profiles`)
    edge: str = "mean"
    #: the chamber floor's and ceiling's speed limit taken at ``rate_share`` too
    chamber_share: bool = False
    #: edge bins held by their crossing times (:class:`~.lp.EdgePins`)
    pinned: bool = False


@dataclass(frozen=True, slots=True)
class Classic:
    """Bands stacked down from the fastest speed (:func:`~.bands.make_bands`): edge caps
    (cooling at lo, cooling at hi, heating at lo, heating at hi) as fractions of
    ``max_cool_c_per_min`` / ``max_heat_c_per_min``, whether the tops are lowered to what a
    sweep can follow, and the band design (``DESIGNS``)."""

    caps: tuple[float, float, float, float]
    dynamic: bool
    design: str
    #: edge bins held by their crossing times (:class:`~.lp.EdgePins`)
    pinned: bool = False


#: The structures the search tries, in order. Guided bands first: designed around the
#: speed profiles of the duration bound's relaxation (slow near the edges, where turning
#: round is dear, fast in the middle), they give the shortest plans; once one of them has
#: given a structure, the classic designs are not tried. Those follow, tuned on the
#: paper's four regions, for what guided bands cannot place: heating -> cooling
#: turnarounds happen at the upper edge and are slow (the chamber cools at only
#: 1 degC/min), so sweeps are slower there; the exact turning room with more knots allows
#: faster passes near a device limit (W4's hot edge has 2 degC of room below +62 degC).
#: Every candidate yields a valid plan or none.
CANDIDATES: tuple[Guided | Classic, ...] = (
    Guided(0.9, 0.04),
    Guided(0.9, 0.05),
    Guided(0.8, 0.06),
    Classic((1.0, 0.7, 1.0, 0.9), True, "sqrt"),
    Classic((1.0, 0.7, 1.0, 0.9), False, "sqrt"),
    Classic((1.0, 0.7, 1.4, 0.9), False, "sqrt"),
    Classic((0.7, 0.7, 1.0, 0.9), True, "sqrt"),
    Classic((1.0, 0.7, 1.0, 0.9), True, "exact"),
    Classic((1.0, 1.0, 1.0, 1.0), True, "exact"),
    # last: guided profiles that keep clear of the chamber floor and ceiling throughout
    # each bin (slower where a limit binds: W1 465 -> 480 min, so only where no guided
    # design above gave a structure). A 25-degC region under a ceiling 11.6 degC above it
    # (counting dT0) got stuck with every other candidate (its fast band asked for the
    # ceiling's own speed at 11 degC) and ended with 2 of 3 levels; with this one it
    # plans complete in 249 min.
    Guided(0.9, 0.04, chamber_share=True),
)
#: Tried last, when nothing else fits (slow retries, level splits and the second chance
#: included): the same designs with each sweep's edge bins held by their crossing times
#: instead of pointwise (:class:`~.lp.EdgePins`), so that it may brake and speed up
#: inside them and turn round just past the edge. Their starts are scanned minute by
#: minute (about three times the LPs), so only where the usual structures fail: a slow
#: chamber (-0.5 / +1.5 degC/min) on [-50, -30] degC in 720 min was 90 % covered at 5
#: levels and is complete in 717 min with them.
PINNED: tuple[Guided | Classic, ...] = tuple(replace(c, pinned=True) for c in CANDIDATES)
#: Tried when no structure fits (slow retries and level splits included) but one came
#: within NEAR_MISS_SHARE of the limit (before ``PINNED``): guided
#: profiles whose turns are costed at the edge bins' speed (another placement of the
#: same levels; min over both sets: [-20, 0] °C with 8 levels 558 -> 537 min, under its
#: 540; others within +-5 % either way).
SECOND_CHANCE: tuple[Guided, ...] = (
    Guided(0.9, 0.04, "speed"),
    Guided(0.9, 0.05, "speed"),
    Guided(0.8, 0.06, "speed"),
)
NEAR_MISS_SHARE = 0.1
#: The slow retry (a stuck candidate's greedy, once more) also scans each stuck sweep's
#: window start minute by minute, not in segment steps, where segments are longer than
#: this (min). The segment-step scan tries the window at one phase of the segment grid;
#: with segments as long as the device's time constant, a sweep fits only where its
#: band's bends meet the rate changes at segment ends: [43, 58] degC at 5 levels,
#: tau 600 s, 10-min segments, under a 62.7 degC ceiling, had its middle heating band fit
#: at 3 of every 10 minutes and never at the phase scanned, so no candidate planned.
PHASE_RETRY_MIN_SEGMENT_MIN = 3.0
#: Segments' worth of window starts that scan covers from the first start the rate
#: limits alone do not rule out (a sweep that fits at no phase over a few segments after
#: the device can first reach its window only waits longer at the same phases).
PHASE_SCAN_SEGMENTS = 3
#: A pinned sweep's scan covers at least this long from that first start, min: on
#: w1-slow-chamber-720 its sweeps fitted at most 10 min after it, while a pinned sweep
#: that fits nowhere scanned every minute of ``MAX_TRANSITION_MIN`` (20-45 s each on
#: w4-ceiling-65, most of that request's search).
PIN_SCAN_MIN = 30.0


def candidate_bands(
    candidate: Guided | Classic,
    spec: ExperimentSpec,
    params_list: list[ThermalParams],
    limits: Limits,
    n_by_dir: dict[int, int],
    sep: float,
) -> dict[int, list[Band]] | None:
    """The bands of one candidate structure, or None when they do not fit."""
    if isinstance(candidate, Guided):
        extra = sep - (spec.delta_c_per_min + BAND_SAFETY_C_PER_MIN)
        return guided_bands(
            spec,
            params_list,
            limits,
            n_by_dir,
            candidate.width_c_per_min,
            candidate.rate_share,
            sep_extra_c_per_min=extra,
            edge=candidate.edge,
            chamber_share=candidate.chamber_share,
        )
    caps = candidate.caps
    cap_by_dir = {
        -1: (caps[0] * spec.max_cool_c_per_min, caps[1] * spec.max_cool_c_per_min),
        +1: (caps[2] * spec.max_heat_c_per_min, caps[3] * spec.max_heat_c_per_min),
    }
    bands = {
        d: make_bands(
            spec,
            n_by_dir[d],
            d,
            sep,
            params_list,
            limits,
            caps=cap_by_dir[d],
            dynamic=candidate.dynamic,
            design=DESIGNS[candidate.design],
        )
        if n_by_dir[d]
        else []
        for d in (+1, -1)
    }
    if any(bands[d] and band_feasibility(bands[d]) <= 0 for d in (+1, -1)):
        return None
    return bands


#: Sweeps beyond ``levels_required`` the level-split family tries (issue 12), fewest first.
SPLIT_SURPLUS_SWEEPS = (1, 2)
#: Level splits the family tries per sweep count and first direction, best first.
SPLIT_TRIES = 2


def band_room(
    spec: ExperimentSpec,
    params_list: list[ThermalParams],
    limits: Limits,
    direction: int,
    sep: float,
) -> float:
    """Room for the levels of one direction, degC/min: the least, over the band knots, of
    the fastest gradient the chamber and device allow (one band, :func:`make_bands`) above
    the slowest any band may go (``delta/2 + safety``). Negative: not even one band fits.
    """
    (band,) = make_bands(spec, 1, direction, sep, params_list, limits)
    floor = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    return float(min(band.hi_c_per_min)) - floor


def level_splits(
    levels: int, n_by_dir: dict[int, int], room_by_dir: dict[int, float], sep: float
) -> list[dict[int, int]]:
    """Ways to share ``levels`` between the directions of ``n_by_dir`` sweeps, best first.

    Each direction gets at least one level and at most one per sweep; the squeezed
    direction (the smaller room) gets fewer levels than the other. Ranked by the width
    the narrower direction's bands would get, ``(room - (l - 1) sep) / l`` (stacked
    ``sep`` apart in ``room``): the split whose tightest direction has most room first.
    """
    squeezed = min((+1, -1), key=lambda d: room_by_dir[d])
    other = -squeezed
    out = []
    for l_sq in range(1, levels):
        split = {squeezed: l_sq, other: levels - l_sq}
        if split[squeezed] >= split[other]:
            continue
        if any(split[d] > n_by_dir[d] for d in (+1, -1)):
            continue
        width = min((room_by_dir[d] - (split[d] - 1) * sep) / split[d] for d in (+1, -1))
        out.append((width, split))
    out.sort(key=lambda ws: -ws[0])
    return [split for _, split in out]


def split_note(levels_by_dir: dict[int, int], n_sweeps: int) -> str:
    """The plan note of a level-split structure: how its levels are shared."""
    heat, cool = levels_by_dir[+1], levels_by_dir[-1]
    return (
        f"structure: {n_sweeps} sweeps for {heat + cool} levels -- {heat} heating and "
        f"{cool} cooling levels, the other {n_sweeps - heat - cool} sweeps repeat a level "
        "(one direction is too constrained for an even share)"
    )


#: The reason a search gives when its ``stop()`` ended it early.
STOPPED = "the search was stopped at its effort limit"
#: The greedy may run past the duration limit by this factor; such a structure is only
#: used (cut at the limit) when nothing fits, to give the best reachable coverage.
OVERRUN_FACTOR = 1.3
#: Extra band separations (degC/min) the ``margin`` objective tries, widest first.
MARGIN_SEPARATIONS = (0.04, 0.02, 0.0)
#: Sub-regions tried when the full region does not fit: bins cut from one side, and
#: shares of the bins for regions far too wide for the time.
SUBREGION_CUTS = (2, 4, 7)
SUBREGION_CUTS_BOTH = (4, 7)
SUBREGION_WIDE_SHARES = (0.3, 0.45)
#: ... and, where none of those fits, the widest sub-region per side whose proven lower
#: bound is at most each of these shares of the duration limit (the greedy's plans take
#: about 1.2-1.3x their bound). Red team: [-51, 19] degC with 3 levels in 200 min (bound
#: 384 min) was refused as "no programme covers any part" although [10, 19] plans
#: complete in 144 min: the shares above cut at most 31 of its 70 bins.
SUBREGION_BOUND_SHARES = (0.8, 0.6)


@dataclass(slots=True)
class Structure:
    """Sweep windows and the rates that realise them (``n_seg`` segments)."""

    windows: list[Window]
    n_seg: int
    u: np.ndarray


#: Slack of :func:`band_out_of_reach`, degC/min: a band is ruled out only when its lower
#: speed exceeds the chamber's reach by more than this (numerical and rounding room).
REACH_TOL_C_PER_MIN = 0.002
#: How far back against its direction a sweep may stray between two samples, degC
#: (:func:`band_out_of_reach`; its samples all move forward at the band's lower speed).
REACH_STRAY_C = 0.1


def _first_order_cap(ctx: Context, d: int) -> Callable[[np.ndarray], np.ndarray] | None:
    """The fastest ``d g`` the chamber limits allow at ``T`` (degC/min, a function of T),
    or None where no such cap is exact (robust scenarios, an augmented model)."""
    if ctx.robust:
        return None
    scenario = ctx.responses.scenarios[0]
    if not isinstance(scenario.model, FirstOrderLag):
        return None
    p, lim = scenario.params, ctx.limits
    if d > 0:
        return lambda t: (lim.chamber_max_c + p.dt0_c - t) / p.tau_min
    return lambda t: (t - lim.chamber_min_c - p.dt0_c) / p.tau_min


def band_out_of_reach(ctx: Context, d: int, band: Band) -> bool:
    """Whether no sweep can hold ``band`` pointwise, whatever the chamber does: a
    necessary condition checked before :func:`place_sweep` scans its starts.

    For the first-order lag ``g = (Tk + dT0 - T) / tau`` holds at every instant, whatever
    the device's earlier history, and the chamber stays within its limits, so a heating
    pass at ``T`` is no faster than ``(Tk_max + dT0 - T) / tau`` and a cooling one no
    faster than ``(T - Tk_min - dT0) / tau``. A window (not pinned) holds ``d g >= lo(T)``
    at every sample (one a minute) from beyond one extended edge to beyond the other, and
    no faster than the cap the device moves between them, so every temperature ``T*`` in
    between has a held sample within a minute's travel at the cap of it. Where the
    band's least lower speed over that interval exceeds the cap's largest value there,
    no sample near ``T*`` can hold the band, every start fails, and the scan (hundreds
    of LPs where a chamber floor or ceiling is close) is spared. Only for one
    first-order model (robust scenarios stray from the band by a slack; an augmented
    model has no such cap).
    """
    cap_at = _first_order_cap(ctx, d)
    tau_min = ctx.responses.scenarios[0].params.tau_min
    if cap_at is None or SAMPLE_MIN >= 0.5 * tau_min:
        return False
    knots = np.asarray(band.knots_c, dtype=float)
    temps = np.union1d(np.linspace(knots[0], knots[-1], 65), knots)
    # the travel between two held samples near T*: the device never moves faster than
    # the cap, which grows by 1/tau per degC towards the favourable side, where it may
    # also have strayed back REACH_STRAY_C: S (cap(T*) + stray/tau) / (1 - S/tau)
    cap_here = np.maximum(cap_at(temps), 0.0)
    travel = SAMPLE_MIN * (cap_here + REACH_STRAY_C / tau_min) / (1.0 - SAMPLE_MIN / tau_min)
    a, b = temps - travel, temps + travel
    lo = np.minimum(band.bounds(a)[0], band.bounds(b)[0])
    for k in knots:  # a piecewise-linear lower bound is least at an end or a knot
        inside = (a <= k) & (k <= b)
        lo[inside] = np.minimum(lo[inside], band.bounds(k)[0])
    cap = np.maximum(cap_at(a), cap_at(b))  # the cap is monotone in T
    return bool(np.any(lo > cap + REACH_TOL_C_PER_MIN))


#: Slack of :func:`pins_out_of_reach`, min.
REACH_TOL_MIN = 0.2


def pins_out_of_reach(
    ctx: Context, d: int, band: Band, spans_min: tuple[float, float, float, float]
) -> bool:
    """Whether no pinned sweep in ``band`` can keep its pins, whatever the chamber does.

    Each edge bin must be crossed within the most minutes its pins allow (it is not in
    the bin at its pin and is out of it that many minutes later: ``spans_min[1]`` entry,
    ``spans_min[3]`` exit, from :func:`pinned_timings`), and no crossing is faster than
    the chamber's cap allows at every temperature on the way: ``integral dT / cap(T)``.
    (Its inner bins are held pointwise too, but from samples whose temperatures the pins
    leave loose near the edge bins: not checked here.)
    """
    cap_at = _first_order_cap(ctx, d)
    if cap_at is None:
        return False
    lo, hi, w = ctx.spec.working_lo_c, ctx.spec.working_hi_c, ctx.spec.grid.bin_c
    e_in, e_out = (hi, lo) if d < 0 else (lo, hi)
    for edge, most_min in ((e_in, spans_min[1]), (e_out - d * w, spans_min[3])):
        temps = np.linspace(min(edge, edge + d * w), max(edge, edge + d * w), 65)
        cap = cap_at(temps)
        if np.any(cap <= 0.0):
            return True
        fastest_min = float(np.trapezoid(1.0 / cap, temps))
        if fastest_min > most_min + REACH_TOL_MIN:
            return True
    return False


def place_sweep(
    ctx: Context,
    u_fixed: np.ndarray,
    d: int,
    band: Band,
    max_seg: int,
    slow: bool = False,
    every_sample: bool = False,
    pinned: bool = False,
) -> tuple[np.ndarray, Window] | None:
    """Shortest transition + window for one sweep.

    The window may start at any planner sample after the fixed segments; its knot
    crossings are planned fast first, then slower (:meth:`~.bands.Band.timing_options`;
    ``slow``: only the last-resort timings near the bottom of the band).
    The transition is scanned in segment steps (feasibility is not monotone enough for
    bisection over the whole range), then refined to the minute. ``every_sample``: scanned
    minute by minute instead, for ``PHASE_SCAN_SEGMENTS`` segments from the first start
    the rate limits do not rule out. The segment-step scan tries the window at one phase
    of the segment grid only; where a segment is as long as the device's time constant,
    whether a sweep fits depends on that phase (its band's bends must meet the rate
    changes at segment ends), and the phase tried may never fit
    (:data:`PHASE_RETRY_MIN_SEGMENT_MIN`).

    ``pinned``: the edge bins are held by their crossing times (:class:`~.lp.EdgePins`):
    the window starts where the sweep enters the region, its knot crossings and the
    entry of its exit bin are timed from there (:func:`pinned_timings`), and it ends
    when it has left the exit bin; every start is scanned for ``PIN_SCAN_MIN`` (at least
    ``PHASE_SCAN_SEGMENTS`` segments) from the first the rate limits do not rule out.
    None when the band leaves no room for the pins.
    """
    spec, r = ctx.spec, ctx.responses
    if not pinned and band_out_of_reach(ctx, d, band):
        return None
    seg = spec.segment_min
    s_start = r.sample_of(u_fixed.size)
    s_max = r.sample_of(max_seg)
    pin_plan = pinned_timings(spec, band, slow) if pinned else None
    if pinned and (pin_plan is None or pins_out_of_reach(ctx, d, band, pin_plan[1])):
        return None
    # piece durations (samples) in travel order, from the band's top speed down; pinned:
    # the samples of the knot crossings after the window start
    options = []
    if pin_plan is not None:
        options = [np.asarray(cuts, dtype=int) for cuts, _, _ in pin_plan[0]]
    else:
        options = [_piece_samples(minutes, d) for minutes in band.timing_options(slow)]
    d_fast = int(options[0].sum())

    def solve_window(
        win: Window, j1: int, scenarios: list[int] | None, extra_edge_c: float = 0.0
    ) -> np.ndarray | None:
        lp = SubLP(ctx, u_fixed, j1, extra=1, scenarios=scenarios)
        lp.chamber()
        lp.device()
        lp.window(win, extra_edge_c=extra_edge_c)
        lp.exit_speed(win, 0)
        # leave the window slowly: the next turnaround is then shorter
        cost = np.zeros(lp.n + 1)
        cost[-1] = 1.0
        sol = lp.solve_direct(cost, l1_weight=PROBE_L1_WEIGHT)
        return None if sol is None else sol[:-1]

    def attempt(x: int) -> tuple[np.ndarray, Window] | None:
        for k_opt, steps in enumerate(options):
            s0 = s_start + x
            bounds = s0 + np.concatenate(([0], np.cumsum(steps)))
            s1, cuts = int(bounds[-1]), tuple(int(c) for c in bounds[1:-1])
            pins = None
            if pin_plan is not None:  # steps: the knot crossings' samples from s0
                _, exit_after, x_hi = pin_plan[0][k_opt]
                e_lo, e_hi, x_lo, _ = pin_plan[1]
                pins = EdgePins(s0, e_lo, e_hi, s0 + exit_after, x_lo, x_hi)
                cuts = tuple(int(s0 + c) for c in steps)
                s1 = int(math.ceil(pins.end_min / SAMPLE_MIN - 1e-9))
            if s1 > s_max:
                return None
            j1 = min(r.segments_to(s1), max_seg)
            win = Window(d, band, s0, s1, cuts, pins=pins)
            if not ctx.robust:
                sol = solve_window(win, j1, None)
                if sol is not None:
                    return sol, win
                continue
            # robust: place the sweep for the reference scenario (the box centre), read
            # off where every scenario then crosses the edges and knots, and solve for
            # all scenarios at once with those per-scenario windows
            sol = solve_window(win, j1, [0])
            if sol is None:
                continue
            found = scenario_windows(ctx, u_fixed, sol, win, max_seg)
            if found is None and pins is None:
                found = wider_reference(sol, win, k_opt)
            if found is None:
                continue
            win_all, j1_all = found
            sol_all = solve_window(win_all, j1_all, None)
            if sol_all is not None:
                return sol_all, win_all
        return None

    def wider_reference(sol: np.ndarray, win: Window, k_opt: int) -> tuple[Window, int] | None:
        """Robust: when a scenario falls short of an edge under the reference's solution
        ``sol`` (it turns round before it), the reference placed as far again beyond
        the edges (its band held constant out there, timed alike), up to
        ``WIDEN_TRIES`` times; the scenarios' windows then, or None."""
        extra = 0.0
        for _ in range(WIDEN_TRIES):
            short = edge_shortfall_c(ctx, u_fixed, sol, d, max_seg)
            if short <= 0.0:
                return None  # every scenario passes the edges: it failed elsewhere
            extra += short + WIDEN_PAD_C
            wide = band.widened(extra)
            steps = _piece_samples(wide.timing_options(slow)[k_opt], d)
            bounds = win.start_sample + np.concatenate(([0], np.cumsum(steps)))
            if int(bounds[-1]) > s_max:
                return None
            wide_win = Window(
                d, wide, win.start_sample, int(bounds[-1]), tuple(int(c) for c in bounds[1:-1])
            )
            j1 = min(r.segments_to(wide_win.end_sample), max_seg)
            wide_sol = solve_window(wide_win, j1, [0], extra)
            if wide_sol is None:
                return None
            sol = wide_sol
            found = scenario_windows(ctx, u_fixed, sol, win, max_seg)
            if found is not None:
                return found
        return None

    if pin_plan is not None:
        d_fast = int(math.ceil(pin_plan[0][0][1] + pin_plan[0][0][2]))
    hi_x = min(s_max - s_start - d_fast, int(MAX_TRANSITION_MIN / SAMPLE_MIN))
    if hi_x < 0:
        return None
    seg_samples = max(1, int(round(seg / SAMPLE_MIN)))
    # pinned: its crossing times are fixed to a tenth of a minute, so whether it fits
    # depends on where they fall between the rate changes: every start is tried
    step = 1 if every_sample or pinned else seg_samples
    stats = ctx.stats

    def scan_note(x: int, last: int) -> str:
        return (
            f"still searching ({ctx.where}): a {'heating' if d > 0 else 'cooling'} sweep in "
            f"band {band.rank} after minute {r.edges_min[u_fixed.size]:g}, turnaround "
            f"{x * SAMPLE_MIN:g} of {last * SAMPLE_MIN:g} min scanned; {stats.solves} LPs so far"
        )

    prev, found, last_x, capped = -1, None, hi_x, False
    for x in range(0, hi_x + 1, step):
        if x > last_x:
            break
        if ctx.beat is not None:
            ctx.beat(partial(scan_note, x, min(last_x, hi_x)))
        solved = stats.solves - stats.infeasible_by_bounds
        res = attempt(x)
        if res is not None:
            found = (x, res)
            break
        reached = stats.solves - stats.infeasible_by_bounds > solved
        if (every_sample or pinned) and not capped and reached:
            # the first start the rate limits alone do not rule out: the scan covers
            # PHASE_SCAN_SEGMENTS segments from here, pinned sweeps at least
            # PIN_SCAN_MIN (later starts wait longer at the same phases)
            span = PHASE_SCAN_SEGMENTS * seg_samples
            if pinned:
                span = max(span, int(round(PIN_SCAN_MIN / SAMPLE_MIN)))
            last_x, capped = x + span - 1, True
        prev = x
    if found is None:
        return None
    lo_x, hi_ok = prev, found[0]
    while hi_ok - lo_x > 1:
        mid = (lo_x + hi_ok) // 2
        res = attempt(mid)
        if res is not None:
            found, hi_ok = (mid, res), mid
        else:
            lo_x = mid
    return found[1]


def _piece_samples(minutes: np.ndarray, d: int) -> np.ndarray:
    """Samples per band piece in travel order, from its minutes per piece (ascending T):
    the planned knot times are rounded, not each piece (rounded pieces drift)."""
    if d < 0:
        minutes = minutes[::-1]
    at = np.round(np.cumsum(minutes) / SAMPLE_MIN)
    return np.maximum(1, np.diff(np.concatenate(([0.0], at)))).astype(int)


#: A pinned sweep leaves its exit bin at most this long after the timing speed would.
PIN_EXIT_SLACK_MIN = 0.5


def pinned_timings(
    spec: ExperimentSpec, band: Band, slow: bool
) -> tuple[list[tuple[tuple[int, ...], float, float]], tuple[float, float, float, float]] | None:
    """How a pinned sweep (:class:`~.lp.EdgePins`) in ``band`` is timed, or None when
    the band leaves no room for the pins.

    Returns, per timing speed of the band (:meth:`~.bands.Band.timing_speeds`), the
    samples after the entry pin at which it crosses the inner knots, the minutes after it
    at which it enters the exit bin and the most minutes it may take over the exit bin
    (the timing speed's crossing time plus ``PIN_EXIT_SLACK_MIN``, within the band's:
    the next sweep can start only after it); and the least and most minutes the band
    allows over the entry and over the exit bin (``PIN_TIME_SAFETY_MIN`` inside them).
    None where the region has fewer than three bins, a knot lies inside an edge bin, or
    the band's crossing times of an edge bin span less than ``PIN_MIN``.
    """
    d, w = band.direction, spec.grid.bin_c
    lo, hi = spec.working_lo_c, spec.working_hi_c
    if spec.grid.n_bins < 3:
        return None
    e_in, e_out = (hi, lo) if d < 0 else (lo, hi)
    knots = [k for k in band.knots_c[1:-1] if d * (e_in + d * w) < d * k < d * (e_out - d * w)]
    if len(knots) != len(band.knots_c) - 2:
        return None  # a knot inside an edge bin: the pins would cut its piece
    knots = sorted(knots, key=lambda k: d * k)
    points = [e_in, *knots, e_out - d * w]
    safety = PIN_TIME_SAFETY_MIN
    spans = []
    for a, b in ((e_in, e_in + d * w), (e_out - d * w, e_out)):
        fast, slow_ = band.bin_minutes(min(a, b), max(a, b))
        spans += [fast + safety, slow_ - safety]
    if spans[1] - spans[0] < PIN_MIN or spans[3] - spans[2] < PIN_MIN:
        return None
    plans = []
    for speed in band.timing_speeds(slow):
        times = np.cumsum(minutes_between(speed, [*points, e_out]))
        cuts = tuple(int(c) for c in np.maximum(1, np.round(times[:-2] / SAMPLE_MIN)))
        # out of the exit bin about when the timing speed would be (not at the band's
        # slowest: the next sweep could start only after that)
        exit_bin = float(times[-1] - times[-2]) + PIN_EXIT_SLACK_MIN
        exit_max = min(spans[3], max(exit_bin, spans[2] + PIN_MIN))
        plans.append((cuts, float(times[-2]), exit_max))
    return plans, (spans[0], spans[1], spans[2], spans[3])


def _sweep_edges(spec: ExperimentSpec, d: int) -> tuple[float, float]:
    """The temperatures a sweep in direction ``d`` starts beyond and ends beyond, degC."""
    m = spec.edge_margin_c
    lo, hi = spec.working_lo_c - m, spec.working_hi_c + m
    return (hi, lo) if d < 0 else (lo, hi)


def _scenario_traces(
    ctx: Context, u_fixed: np.ndarray, u_new: np.ndarray, max_seg: int
) -> tuple[int, list[np.ndarray]]:
    """Every scenario's device temperature from the start of ``u_new`` to
    ``SCENARIO_LOOKAHEAD_SEG`` segments past its end (its last rate held): the first
    sample and the traces, degC."""
    r = ctx.responses
    j_end = min(u_fixed.size + u_new.size + SCENARIO_LOOKAHEAD_SEG, max_seg)
    pad = j_end - u_fixed.size - u_new.size
    u = np.concatenate((u_fixed, u_new, np.full(max(pad, 0), u_new[-1] if u_new.size else 0.0)))
    u = u[:j_end]
    s_from, s_to = r.sample_of(u_fixed.size), r.sample_of(j_end)
    return s_from, [
        resp.a_t[s_from : s_to + 1, :j_end] @ u + resp.b_t[s_from : s_to + 1] for resp in r.resp
    ]


def edge_shortfall_c(
    ctx: Context, u_fixed: np.ndarray, u_new: np.ndarray, d: int, max_seg: int
) -> float:
    """How far short of a sweep's edges the scenario that falls shortest stays under the
    reference's solution ``u_new`` (0: every scenario gets beyond both), degC.

    The reference scenario turns round just beyond the edges; a scenario that lags it
    or sits lower in the box (a smaller dT0, a longer tau) may turn round before them.
    The reference placed that much further out turns them round beyond the edges too
    (to first order: the scenarios' traces shift alike).
    """
    _, traces = _scenario_traces(ctx, u_fixed, u_new, max_seg)
    e_start, e_end = _sweep_edges(ctx.spec, d)
    short = 0.0
    for t in traces:
        q = d * t  # increases along the sweep
        beyond = np.flatnonzero(q < d * e_start)
        if beyond.size == 0:  # never beyond the start edge: by how much
            short = max(short, float(q.min()) - d * e_start)
            continue
        short = max(short, d * e_end - float(q[beyond[0] :].max()))
    return short


def scenario_windows(
    ctx: Context, u_fixed: np.ndarray, u_new: np.ndarray, win: Window, max_seg: int
) -> tuple[Window, int] | None:
    """Per-scenario windows of a sweep placed for the reference scenario.

    Every scenario is simulated (affine responses) under the reference solution; its
    window starts at the last sample before it passes the starting edge, crosses each
    inner knot at the sample nearest to it and ends at the first sample beyond the far
    edge. Returns the window and the number of segments it needs, or None when some
    scenario does not make the sweep in the look-ahead.
    """
    r = ctx.responses
    s_from, traces = _scenario_traces(ctx, u_fixed, u_new, max_seg)
    d = win.direction
    e_start, e_end = _sweep_edges(ctx.spec, d)
    knots = [k for _, _, _, k in win.pieces() if k is not None]
    per, tol_all = [], []
    for t, off in zip(traces, ctx.offsets_c, strict=True):
        q = d * t  # increases along the sweep

        def first_past(level, after, q=q):
            idx = np.flatnonzero(q[after:] >= d * level)
            return None if idx.size == 0 else int(after + idx[0])

        # the scenario may begin the transition inside the region (the run's start, or a
        # lagging scenario still finishing the last sweep): its window starts where it
        # passes the start edge after it was last beyond it
        outside = np.flatnonzero(q < d * e_start)
        if outside.size == 0:
            return None  # never gets beyond the start edge
        c0 = first_past(e_start, int(outside[0]))
        if c0 is None:
            return None
        cuts, tols, after = [], [], c0
        for k in knots:
            k = k + off
            c = first_past(k, after)
            if c is None:
                return None
            if c - 1 > after and abs(t[c - 1] - k) < abs(t[c] - k):
                c -= 1
            cuts.append(c)
            tols.append(KNOT_TOL_C + abs(float(t[c]) - k))
            after = c + 1
        c1 = first_past(e_end, after)
        if c1 is None:
            return None
        per.append((s_from + c0 - 1, s_from + c1, tuple(s_from + c for c in cuts)))
        tol_all.append(tuple(tols))
    j_need = max(r.segments_to(p[1]) for p in per)
    if j_need > max_seg:
        return None
    ref = per[0]
    return replace(
        win,
        start_sample=ref[0],
        end_sample=ref[1],
        cut_samples=ref[2],
        per_scenario=tuple(per),
        knot_tol_c=tuple(tol_all),
    ), j_need


def return_to_end(ctx: Context, u_fixed: np.ndarray, max_seg: int) -> np.ndarray | None:
    """The fewest segments after ``u_fixed`` that bring the chamber to its end temperature."""
    j0 = u_fixed.size
    for n_r in range(1, max_seg - j0 + 1):
        lp = SubLP(ctx, u_fixed, j0 + n_r)
        lp.chamber()
        lp.device()
        lp.chamber_end(ctx.limits.end_c)
        x = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
        if x is not None:
            return np.concatenate((u_fixed, x))
    return None


def _place_sweep_once(
    ctx: Context,
    u_fixed: np.ndarray,
    d: int,
    band: Band,
    max_seg: int,
    slow: bool,
    every_sample: bool = False,
    pinned: bool = False,
) -> tuple[np.ndarray, Window] | None:
    """:func:`place_sweep`, searched once per synthesis for the same arguments.

    The slow retry runs a stuck candidate's greedy again, and its sweeps before the stuck
    one (and the stuck one's usual timings) are the same searches as before: the same
    fixed rates, band and segment limit give the same answer (the LPs are
    deterministic). A repeat returns the earlier answer and counts the earlier LP work
    again (:func:`~.lp.lp_nonzeros_solved`), so an effort limit cuts where it did.
    """
    key = (u_fixed.tobytes(), d, band, max_seg, slow, every_sample, pinned)
    hit = ctx.sweep_memo.get(key)
    if hit is not None:
        ctx.stats.sweeps_reused += 1
        count_work(hit[1])
        return hit[0]
    work0 = lp_nonzeros_solved()
    res = place_sweep(
        ctx, u_fixed, d, band, max_seg, slow=slow, every_sample=every_sample, pinned=pinned
    )
    ctx.sweep_memo[key] = (res, lp_nonzeros_solved() - work0)
    return res


def greedy(
    ctx: Context,
    directions: list[int],
    sweep_bands: list[Band],
    max_seg: int,
    progress: Progress,
    slow_retry: bool = False,
    pinned: bool = False,
) -> tuple[Structure | None, str]:
    """Place the sweeps one after another, each as early and as short as feasible.

    ``slow_retry``: a sweep that fits at none of its band's usual timings is tried once
    more timed near the bottom of the band.
    """
    limits = ctx.limits
    u_fixed = ctx.responses.fixed_rates.copy()
    windows: list[Window] = []
    for k, (d, band) in enumerate(zip(directions, sweep_bands, strict=True)):
        res = _place_sweep_once(ctx, u_fixed, d, band, max_seg, slow=False, pinned=pinned)
        if res is None and (slow_retry or pinned):
            # long segments cannot hold a sweep high in its band just after a turnaround
            # (the rate changes only every segment): time it near the bottom of the band
            res = _place_sweep_once(ctx, u_fixed, d, band, max_seg, slow=True, pinned=pinned)
        if res is None and slow_retry and ctx.spec.segment_min > PHASE_RETRY_MIN_SEGMENT_MIN:
            # long segments: the window at every phase of the segment grid, usual
            # timings first (the scan above tries one phase only)
            for slow in (False, True):
                res = _place_sweep_once(
                    ctx, u_fixed, d, band, max_seg, slow, every_sample=True, pinned=pinned
                )
                if res is not None:
                    break
        if res is None:
            where = "cooling" if d < 0 else "heating"
            horizon_min = float(ctx.responses.edges_min[max_seg])
            beyond = (
                f" (the search looks past the {limits.duration_max_min:g}-min limit for "
                "plans it can shorten)"
                if horizon_min > limits.duration_max_min + 1e-9
                else ""
            )
            return None, (
                f"sweep {k + 1} of {len(directions)} ({where}, gradient band {band.rank}) "
                f"does not fit before minute {horizon_min:g}{beyond}"
            )
        u_new, win = res
        u_fixed = np.concatenate(
            (u_fixed, np.clip(u_new, limits.rate_min_c_per_min, limits.rate_max_c_per_min))
        )
        windows.append(win)
        if progress:
            end_min = ctx.responses.edges_min[u_fixed.size]
            progress(f"sweep {k + 1}/{len(directions)} placed, ends at {end_min:g} min")
    u_all = return_to_end(ctx, u_fixed, max_seg)
    if u_all is None:
        return None, (
            f"no time is left within {ctx.responses.edges_min[max_seg]:g} min to bring the "
            f"chamber back to {limits.end_c:g} °C after the last sweep"
        )
    return Structure(windows, u_all.size, u_all), ""


@dataclass(slots=True)
class Search:
    """Result of :func:`synthesise`: the best structure that fits, or the reasons why not."""

    best: tuple[Structure, float] | None  # (structure, band separation) within the limit
    overrun: Structure | None  # shortest structure that does not fit
    ctx: Context
    reasons: list[str]
    #: the best structure repeats levels (the level-split family): levels per direction
    #: (+1 heating, -1 cooling) and the number of sweeps; None for the usual structures
    split: tuple[dict[int, int], int] | None = None
    #: candidates whose bands found no room for the levels at the separation asked (a
    #: robust search with a narrower slack spaces them closer: :mod:`.robust`)
    no_room: int = 0


def synthesise(
    spec: ExperimentSpec,
    params_list: list[ThermalParams],
    limits: Limits,
    models: Sequence[LinearThermalModel],
    progress: Progress,
    stats: LpStats,
    max_candidates: int | None = None,
    continuation: Continuation | None = None,
    n_sweeps: int | None = None,
    stop: Callable[[], bool] | None = None,
    robust_slack_c_per_min: float = ROBUST_SLACK_C_PER_MIN,
) -> Search:
    """Search structures (first direction, band separation, edge caps).

    For each candidate: bands -> greedy placement of the sweeps. ``shortest`` keeps the
    shortest structure that fits the duration limit; ``margin`` the one with the widest
    band separation that fits. ``n_sweeps`` (default ``levels_required``) sweeps are
    placed; with a ``continuation``, after its executed steps. ``stop()`` is asked before
    each candidate: True ends the search with what it has (an effort limit).
    ``robust_slack_c_per_min``: how far outside its band a scenario other than the
    reference may stray (robust plans; the bands are spaced twice that further apart).

    When no candidate fits (after the slow retry, at every separation), one plan with
    ``levels_required`` sweeps and not robust: the level-split family -- ``L + 1`` or
    ``L + 2`` sweeps, the levels shared unevenly between the directions
    (:func:`level_splits`, the squeezed direction getting fewer), each direction's
    surplus sweeps repeating a level in its transit band (:func:`~.bands.transit_band`);
    the first that fits is kept (``Search.split`` says which). Requests the usual
    structures plan are not affected. Still nothing: a near miss gets ``SECOND_CHANCE``,
    and last every design is tried with its sweeps' edge bins pinned (``PINNED``).
    """
    seg = spec.segment_min
    n_fixed = 0 if continuation is None else continuation.prefix.n_segments
    fixed_min = 0.0 if continuation is None else continuation.at_min
    max_new = int((limits.duration_max_min - fixed_min + 1e-9) // seg)
    max_seg = n_fixed + max_new
    ext_seg = n_fixed + int(math.ceil(max_new * OVERRUN_FACTOR))
    scenarios = [Scenario(p, m) for p, m in zip(params_list, models, strict=True)]
    responses = Responses(scenarios, ext_seg, seg, limits, continuation)
    ctx = Context(spec, limits, responses, stats, robust_slack_c_per_min=robust_slack_c_per_min)
    if progress is not None:
        heart = progress if isinstance(progress, Heartbeat) else Heartbeat(progress, time.monotonic)
        progress, ctx.beat = heart, heart.beat
    search = Search(None, None, ctx, [])
    start_t = None
    if continuation is not None:  # where the device is when the new steps begin
        ref, at = responses.resp[0], responses.sample_of(n_fixed)
        start_t = float(ref.a_t[at, :n_fixed] @ responses.fixed_rates + ref.b_t[at])
    base_sep = spec.delta_c_per_min + BAND_SAFETY_C_PER_MIN
    robust = len(params_list) > 1
    if robust:
        base_sep += 2 * robust_slack_c_per_min
    # "informative" starts from the shortest plan's sweeps (.informative runs them on)
    seps = [base_sep + x for x in MARGIN_SEPARATIONS] if spec.objective == "margin" else [base_sep]
    firsts = first_directions(spec, limits, start_t)

    def attempt(
        candidate: Guided | Classic,
        first: int,
        sep: float,
        slow_retry: bool,
        split: tuple[dict[int, int], int] | None = None,
    ) -> str:
        """One candidate's greedy: ``"fits"``, ``"over"`` (too long), ``"stuck"`` (some
        sweep did not fit) or ``"none"`` (no bands). ``split``: levels per direction and
        the number of sweeps (the level-split family); the sweeps beyond a direction's
        levels get its transit band."""
        directions = sweep_directions(spec, first, n_sweeps if split is None else split[1])
        ctx.where = (
            f"{type(candidate).__name__.lower()} bands, {'heating' if first > 0 else 'cooling'} "
            f"first, {len(directions)} sweeps" + (", slow timings" if slow_retry else "")
        )
        n_by_dir = {d: directions.count(d) for d in (+1, -1)}
        levels_by_dir = n_by_dir if split is None else split[0]
        # robust plans use the same bands: each scenario gets its own windows
        # and a slack (see scenario_windows and SubLP.window)
        bands = candidate_bands(candidate, spec, params_list, limits, levels_by_dir, sep)
        if bands is None:
            search.reasons.append(
                f"the gradients the chamber allows cannot hold the levels "
                f"{sep:.3f} °C/min apart (delta and a safety gap) with the "
                f"{type(candidate).__name__.lower()} band design"
                + (
                    ""
                    if split is None
                    else f" ({split[0][+1]} heating + {split[0][-1]} cooling levels)"
                )
            )
            search.no_room += 1
            return "none"
        if split is not None:  # sweeps that repeat a level: the fastest band, widened
            for d in (+1, -1):
                extra = n_by_dir[d] - levels_by_dir[d]
                bands[d] = list(bands[d]) + [transit_band(bands[d][-1], spec)] * extra
        order = order_bands(directions, bands, params_list[0], limits)
        # only a shorter structure can improve on what was found: prune
        limit = ext_seg
        if search.best is not None:
            limit = search.best[0].n_seg - 1
        elif search.overrun is not None:
            limit = min(limit, search.overrun.n_seg - 1)
        structure, why = greedy(
            ctx, directions, order, limit, progress, slow_retry, pinned=candidate.pinned
        )
        if structure is None:
            search.reasons.append(why)
            return "stuck"
        minutes = responses.edges_min[structure.n_seg]
        if structure.n_seg > max_seg:
            search.reasons.append(
                f"the sweeps need {minutes:g} min, more than the limit "
                f"{limits.duration_max_min:g} min"
            )
            if search.overrun is None or structure.n_seg < search.overrun.n_seg:
                search.overrun = structure
            return "over"
        if search.best is None or structure.n_seg < search.best[0].n_seg:
            search.best = (structure, sep)
            search.split = split
        if progress:
            progress(f"structure found: {minutes:g} min")
        return "fits"

    def split_structures(sep: float) -> list[tuple[tuple[dict[int, int], int], int]]:
        """The level-split family's ``((levels by direction, sweeps), first)``, in order:
        fewest sweeps, then each first direction's best splits."""
        rooms = {d: band_room(spec, params_list, limits, d, sep) for d in (+1, -1)}
        out = []
        for surplus in SPLIT_SURPLUS_SWEEPS:
            n_total = spec.levels_required + surplus
            for first in firsts:
                directions = sweep_directions(spec, first, n_total)
                n_by_dir = {d: directions.count(d) for d in (+1, -1)}
                for split in level_splits(spec.levels_required, n_by_dir, rooms, sep)[:SPLIT_TRIES]:
                    out.append(((split, n_total), first))
        return out

    for sep in seps:
        stuck: list[tuple[Guided | Classic, int]] = []
        for first in firsts:
            guided_found = False
            for candidate in CANDIDATES[:max_candidates]:
                if guided_found and isinstance(candidate, Classic):
                    break  # the classic designs were tuned as fallbacks: not worth the LPs
                if stop is not None and stop():
                    search.reasons.append(STOPPED)
                    return search
                outcome = attempt(candidate, first, sep, slow_retry=False)
                if outcome == "stuck":
                    stuck.append((candidate, first))
                guided_found = guided_found or (outcome == "fits" and isinstance(candidate, Guided))
        if search.best is None:
            # nothing fits: the candidates that got stuck on a sweep, once more with that
            # sweep timed near the bottom of its band (long segments need it)
            for candidate, first in stuck:
                if stop is not None and stop():
                    search.reasons.append(STOPPED)
                    return search
                attempt(candidate, first, sep, slow_retry=True)
        if search.best is not None:
            break  # margin: the widest separation that fits
    if search.best is None and n_sweeps is None and max_candidates is None and not robust:
        # still nothing, at any separation: more sweeps than levels, the squeezed
        # direction's levels shared with the other (issue 12); at the narrowest separation
        # only, and not for robust boxes (their fallbacks would wait for it)
        sep = seps[-1]
        for split, first in split_structures(sep):
            for candidate in CANDIDATES:
                if stop is not None and stop():
                    search.reasons.append(STOPPED)
                    return search
                attempt(candidate, first, sep, slow_retry=True, split=split)
                if search.best is not None:
                    return search
    near = search.overrun is not None and search.overrun.n_seg <= max_seg * (1 + NEAR_MISS_SHARE)
    # not for "margin": its plans are the robust ladder's nominal check, where a plan cut
    # at the limit from the usual structures was seen to hold on a box that a second
    # chance's plan did not (test_a_nominal_plan_that_holds_on_the_box_...)
    wanted = spec.objective != "margin" and not robust and max_candidates is None
    if search.best is None and near and wanted:
        # still nothing fits (level splits included), but nearly: other profiles of the
        # same levels
        for first in firsts:
            for candidate in SECOND_CHANCE:
                if stop is not None and stop():
                    search.reasons.append(STOPPED)
                    return search
                attempt(candidate, first, seps[-1], slow_retry=False)
    if search.best is None and not robust and max_candidates is None:
        # still nothing (near miss included): the edge bins held by their crossing times
        for first in firsts:
            guided_found = False
            for candidate in PINNED:
                if guided_found and isinstance(candidate, Classic):
                    break
                if stop is not None and stop():
                    search.reasons.append(STOPPED)
                    return search
                outcome = attempt(candidate, first, seps[-1], slow_retry=False)
                guided_found = guided_found or (outcome == "fits" and isinstance(candidate, Guided))
    return search


def truncate(ctx: Context, structure: Structure, max_seg: int) -> Structure | None:
    """Cut an over-long structure so that it returns to the end temperature in time;
    None when no cut does (the caller falls back to its other options)."""
    for n_r in range(1, max_seg - ctx.responses.n_fixed):
        cut = max_seg - n_r
        u_fixed = structure.u[:cut]
        lp = SubLP(ctx, u_fixed, max_seg)
        lp.chamber()
        lp.device()
        lp.chamber_end(ctx.limits.end_c)
        x = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
        if x is not None:
            end = ctx.responses.sample_of(cut)
            windows = [w for w in structure.windows if w.end_sample <= end]
            return Structure(windows, max_seg, np.concatenate((u_fixed, x)))
    return None


def _bound_cut(
    cut_spec: Callable[[str, int], ExperimentSpec],
    side: str,
    n_bins: int,
    params: ThermalParams,
    limits: Limits,
    share: float,
) -> int | None:
    """The fewest bins cut from ``side`` for which the proven lower bound of the
    sub-region is at most ``share`` of the duration limit (bisection: a narrower region
    never needs longer); None when not even one bin is left within it."""
    from .bound import duration_lower_bound

    target = share * limits.duration_max_min

    def fits(cut: int) -> bool:
        return duration_lower_bound(cut_spec(side, cut), params, limits).lower_bound_min <= target

    lo, hi = 0, n_bins - 1  # a cut of n_bins - 1 leaves one bin
    if not fits(hi):
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if fits(mid):
            hi = mid
        else:
            lo = mid
    return hi


def subregions(
    spec: ExperimentSpec,
    params_list: list[ThermalParams],
    limits: Limits,
    models: Sequence[LinearThermalModel],
    progress: Progress,
    stats: LpStats,
    stop: Callable[[], bool] | None = None,
    deep: Callable[[], bool] | None = None,
) -> Iterator[tuple[ExperimentSpec, Search]]:
    """The widest sub-regions (whole bins cut from the low, the high or both edges) for
    which a structure fits the duration limit: at most one per side, yielded as found.
    The bound-guided cuts (:data:`SUBREGION_BOUND_SHARES`) are tried only while ``deep()``
    says so (the caller: while it has nothing else to offer).

    ``stop()`` is asked before each search: the caller says when an option already
    covers the full region (sweeps designed for a narrower region often still cover the
    whole one: they pass the edges with margin), or its effort limit is spent, so the
    remaining searches are skipped.
    """
    n = spec.grid.n_bins

    def cut_spec(side: str, cut: int) -> ExperimentSpec:
        a = {"low": cut, "high": 0, "both": cut // 2}[side]
        return replace(
            spec, working_lo_c=spec.working_lo_c + a, working_hi_c=spec.working_hi_c - (cut - a)
        )

    for side in ("low", "high", "both"):
        wide = tuple(round(share * n) for share in SUBREGION_WIDE_SHARES)
        cuts = SUBREGION_CUTS if side != "both" else SUBREGION_CUTS_BOTH
        usual = sorted(set(cuts) | {c for c in wide if c > max(SUBREGION_CUTS)})
        usual = [c for c in usual if c < n - 1]

        def side_cuts(side: str = side, usual: list[int] = usual) -> Iterator[int]:
            yield from usual
            # none of those fitted: the widest sub-regions the bound leaves room for
            done = usual[-1] if usual else 0
            for share in SUBREGION_BOUND_SHARES:
                if deep is not None and not deep():
                    return
                cut = _bound_cut(cut_spec, side, n, params_list[0], limits, share)
                if cut is not None and cut > done:
                    yield cut
                    done = cut

        for cut in side_cuts():
            if stop is not None and stop():
                return
            sub = cut_spec(side, cut)
            search = synthesise(sub, params_list, limits, models, None, stats, max_candidates=1)
            if search.best is not None:
                if progress:
                    progress(f"sub-region [{sub.working_lo_c:g}, {sub.working_hi_c:g}] fits")
                yield sub, search
                break
