"""Synthesis of chamber programmes that cover a working region with distinct gradients.

The formulation (design note: ``docs/planner.md``)
--------------------------------------------------
Decision variables are the ramp rates ``u_j`` of fixed-length segments (``segment_min``).
By :func:`schedsyn.model.affine_response`, the internal temperature ``T_i`` and gradient
``g_i`` at every planner sample (every minute) are affine in ``u``, so every requirement
below is a linear constraint:

* rates within ``[rate_min, rate_max]``; chamber temperature at every boundary within
  the chamber limits; ``Tk(end) = end_c``; device temperature within its limits;
* **sweeps**: the programme is a sequence of ``levels_required`` monotone sweeps across
  the working region, alternating cooling and heating. Sweep ``k`` owns a time window
  ``[s_k, e_k]``; at its ends the device lies beyond the region's edges by
  ``edge_margin_c`` (``T(s_k) >= hi + m``, ``T(e_k) <= lo - m`` when cooling), and
  inside it the direction-signed gradient ``q = d * g`` lies in a **band** ``l_r(T) <=
  q_i <= v_r(T)``, piecewise linear in T: the sweep crosses each inner knot at a planned
  sample (+-0.25 degC), so each stretch is held to one affine piece -- linear because
  both ``q_i`` and ``T_i`` are affine in ``u``. The bands of one direction are disjoint
  by ``delta`` plus a safety gap at every temperature, and heating (``g > 0``) and
  cooling (``g < 0``) bands are apart by at least ``delta``; every pass of a bin is a
  mean of samples inside its sweep's band, so each bin gets ``levels_required`` passes
  pairwise ``delta`` apart.
* The bands follow the physics: ``g = (Tk + dT0 - T)/tau`` and the chamber limits bound
  the gradient available at each temperature (cooling near the floor, heating near the
  ceiling), the device must turn round before its own limits, and a sweep cannot change
  speed faster than the chamber rates allow; the bands are stacked below that top speed.

The combinatorial part -- where each sweep's window starts and ends -- is found by a
greedy search in time: sweep after sweep, the smallest transition and window lengths for
which the small LP over the next segments is feasible (Clarabel), for a few band designs
(``CANDIDATES``). A final LP over the
whole programme keeps those windows and maximises the margin (passes deeper inside their
bands and beyond the region edges), then a second LP keeps most of that margin and
minimises the number of rate changes so the step table stays short. The exported step
table (whole minutes, 0.1 degC) is re-simulated densely and its coverage recomputed by
:mod:`schedsyn.coverage`; a plan is called complete only on that independent check.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import cvxpy as cp
import numpy as np
import pandas as pd

from .coverage import CoverageReport, coverage_report
from .errors import InfeasiblePlanError, ParameterError, SolverFailedError
from .grid import BinGrid
from .model import FirstOrderLag, LinearThermalModel, affine_response
from .params import Limits, ThermalParams
from .programme import Programme
from .simulate import simulate

OBJECTIVES = ("shortest", "margin")

#: Planner samples every minute (segment boundaries are whole minutes).
SAMPLE_MIN = 1.0
#: Extra separation between neighbouring bands beyond delta, degC/min (sampling, rounding).
BAND_SAFETY_C_PER_MIN = 0.012
#: Longest transition (turnaround) searched before a sweep, min.
MAX_TRANSITION_MIN = 150.0
#: Distances of the inner band knots from the working edges, degC.
KNOT_INSETS_C = (1.5, 4.0)
#: A sweep crosses an inner knot at a planned sample within +- this plus half the
#: distance its band's top speed covers in one sample, degC.
KNOT_TOL_C = 0.25
#: Robust plans: how far outside its band a scenario other than the reference (box
#: centre) may pass, degC/min; the bands are spaced by twice this more than delta.
ROBUST_SLACK_C_PER_MIN = 0.05
#: Share of the full-rate acceleration of g (rate/tau) a turnaround is planned with.
TURN_ACCEL_FRACTION = 0.85
#: Preferred width of one gradient band, degC/min (room for the LP to manoeuvre).
BAND_WIDTH_C_PER_MIN = 0.05
#: Fraction of the gradient the chamber limits allow at T that the fastest band may use.
LIMIT_FRACTION = 0.92
#: LP solves in this process so far (``plan_experiment`` reports the ones it made).
_LP_COUNT = [0]


@dataclass(frozen=True, slots=True)
class ExperimentSpec:
    """One experiment: its working and approximation regions and the coverage target.

    Parameters
    ----------
    name : str
        Experiment name (used for output folders).
    working_lo_c, working_hi_c : float
        Working region, degC: every 1 degC bin in it must be covered.
    approx_lo_c, approx_hi_c : float
        Approximation region, degC: the device stays inside it from the first sweep on.
    levels_required : int
        Distinct gradient levels per bin (paper: 6), 2..12.
    delta_c_per_min : float
        Minimum difference between two levels, degC/min.
    segment_min : float
        Length of one decision segment, whole minutes, 2..30 (5-15 typical).
    objective : str
        ``"shortest"`` (shortest programme reaching the target) or ``"margin"`` (largest
        margin within ``duration_max_min``).
    max_steps : int
        Most steps the exported step table may have (after merging equal rates).
    edge_margin_c : float
        Each sweep passes the working edges by at least this, degC.
    max_cool_c_per_min, max_heat_c_per_min : float
        Fastest cooling / heating gradient the bands use, degC/min. Fast sweeps cost long
        turnarounds and overshoot: the chamber cools at only 1 degC/min, so a cooling
        gradient close to that takes long to build up.
    """

    name: str
    working_lo_c: float
    working_hi_c: float
    approx_lo_c: float
    approx_hi_c: float
    levels_required: int = 6
    delta_c_per_min: float = 0.05
    segment_min: float = 5.0
    objective: str = "shortest"
    max_steps: int = 80
    edge_margin_c: float = 0.5
    max_cool_c_per_min: float = 0.85
    max_heat_c_per_min: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise ParameterError("an experiment needs a non-empty name")
        for f in (
            "working_lo_c",
            "working_hi_c",
            "approx_lo_c",
            "approx_hi_c",
            "delta_c_per_min",
            "segment_min",
            "edge_margin_c",
            "max_cool_c_per_min",
            "max_heat_c_per_min",
        ):
            v = getattr(self, f)
            if not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{self.name}: {f} must be a finite number, got {v!r}")
        BinGrid(self.working_lo_c, self.working_hi_c)  # validates the working region
        if not (self.approx_lo_c <= self.working_lo_c and self.working_hi_c <= self.approx_hi_c):
            raise ParameterError(
                f"{self.name}: the approximation region [{self.approx_lo_c:g}, "
                f"{self.approx_hi_c:g}] degC must contain the working region "
                f"[{self.working_lo_c:g}, {self.working_hi_c:g}] degC"
            )
        if int(self.levels_required) != self.levels_required or not 2 <= self.levels_required <= 12:
            raise ParameterError(
                f"{self.name}: levels_required must be a whole number in 2..12, got "
                f"{self.levels_required!r}"
            )
        if not 0 < self.delta_c_per_min <= 1:
            raise ParameterError(
                f"{self.name}: delta_c_per_min must be in (0, 1] degC/min, got "
                f"{self.delta_c_per_min!r}"
            )
        if self.segment_min != int(self.segment_min) or not 2 <= self.segment_min <= 30:
            raise ParameterError(
                f"{self.name}: segment_min must be a whole number of minutes in 2..30, got "
                f"{self.segment_min!r}"
            )
        if self.objective not in OBJECTIVES:
            raise ParameterError(
                f"{self.name}: objective must be one of {OBJECTIVES}, got {self.objective!r}"
            )
        if int(self.max_steps) != self.max_steps or self.max_steps < 2:
            raise ParameterError(f"{self.name}: max_steps must be a whole number >= 2")
        if not 0 < self.edge_margin_c <= 10:
            raise ParameterError(f"{self.name}: edge_margin_c must be in (0, 10] degC")
        for f in ("max_cool_c_per_min", "max_heat_c_per_min"):
            if not 0.1 <= getattr(self, f) <= 3:
                raise ParameterError(f"{self.name}: {f} must be in 0.1..3 degC/min")

    @property
    def grid(self) -> BinGrid:
        return BinGrid(self.working_lo_c, self.working_hi_c)

    def to_dict(self) -> dict:
        return {f: getattr(self, f) for f in self.__dataclass_fields__}


# ----------------------------------------------------------------------------------
# Scenarios (nominal or a robust box) and their affine responses
# ----------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Scenario:
    """One (model, dT0) the plan must satisfy."""

    params: ThermalParams
    model: LinearThermalModel


def robust_scenarios(
    params: ThermalParams,
    tau_s_range: tuple[float, float] | None,
    dt0_c_range: tuple[float, float] | None,
    n_tau: int = 3,
) -> list[ThermalParams]:
    """Scenarios that cover a (tau, dT0) box.

    T and g are affine in dT0 for fixed rates (dT0 only enters the free response), so a
    band constraint that holds at both ends of the dT0 range holds in between: the two
    dT0 extremes are exact. In tau the response is nonlinear, so ``n_tau`` values spread
    over the range (both ends included) are used and the plan is verified afterwards on
    a dense grid.
    """
    taus = (
        [params.tau_s]
        if tau_s_range is None
        else list(np.linspace(tau_s_range[0], tau_s_range[1], n_tau))
    )
    dt0s = [params.dt0_c] if dt0_c_range is None else [dt0_c_range[0], dt0_c_range[1]]
    for name, rng in (("tau_s", tau_s_range), ("dt0_c", dt0_c_range)):
        if rng is not None and not rng[0] <= rng[1]:
            raise ParameterError(f"robust {name} range must be LO:HI with LO <= HI, got {rng}")
    return [replace(params, tau_s=float(t), dt0_c=float(d)) for t in taus for d in dt0s]


class _Responses:
    """Affine responses of all scenarios at the planner samples of a full-length grid."""

    def __init__(self, scenarios: Sequence[Scenario], n_seg: int, seg_min: float, limits: Limits):
        self.seg_min = seg_min
        self.scenarios = list(scenarios)
        self.durations = np.full(n_seg, float(seg_min))
        self.times = np.arange(0.0, n_seg * seg_min + 0.5 * SAMPLE_MIN, SAMPLE_MIN)
        self.resp = [
            affine_response(s.model, self.durations, self.times, limits.start_c, limits.t_init_c)
            for s in scenarios
        ]

    def sample_of(self, j_boundary: int) -> int:
        return int(round(j_boundary * self.seg_min / SAMPLE_MIN))


# ----------------------------------------------------------------------------------
# Bands: the gradient levels each sweep is confined to, piecewise linear in T
# ----------------------------------------------------------------------------------
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

    def bounds(self, temp_c):
        t = np.asarray(temp_c, dtype=float)
        return (
            np.interp(t, self.knots_c, self.lo_c_per_min),
            np.interp(t, self.knots_c, self.hi_c_per_min),
        )

    def piece(self, i: int) -> tuple[float, float, float, float, float]:
        """``(t_ref, lo0, lo1, hi0, hi1)`` of the affine piece between knots i and i+1."""
        t0, t1 = self.knots_c[i], self.knots_c[i + 1]
        lo0, lo_1 = self.lo_c_per_min[i], self.lo_c_per_min[i + 1]
        hi0, hi_1 = self.hi_c_per_min[i], self.hi_c_per_min[i + 1]
        return t0, lo0, (lo_1 - lo0) / (t1 - t0), hi0, (hi_1 - hi0) / (t1 - t0)

    def minutes(self, fraction: float = 0.5) -> np.ndarray:
        """Time to cross each piece at ``lo + fraction (hi - lo)`` (min per piece)."""
        out = []
        for i in range(len(self.knots_c) - 1):
            t = np.linspace(self.knots_c[i], self.knots_c[i + 1], 50)
            lo, hi = self.bounds(t)
            v = np.maximum(lo + fraction * (hi - lo), 1e-3)
            out.append(float(np.trapezoid(1.0 / v, t)))
        return np.array(out)


def _available_rate(
    direction: int, temp_c: float, params: ThermalParams, limits: Limits, cap: float
) -> float:
    """Largest |g| the chamber limits allow at T in this direction, capped (degC/min)."""
    tau = params.tau_min
    if direction < 0:
        limit_g = (temp_c - (limits.chamber_min_c + params.dt0_c)) / tau
        rate = -limits.rate_min_c_per_min
    else:
        limit_g = (limits.chamber_max_c + params.dt0_c - temp_c) / tau
        rate = limits.rate_max_c_per_min
    return min(cap, LIMIT_FRACTION * limit_g, LIMIT_FRACTION * rate)


def band_knots(spec: ExperimentSpec, insets_c: Sequence[float] | None = None) -> tuple[float, ...]:
    """Knots of the piecewise-linear bands: the extended edges and, inside each edge,
    knots at ``insets_c`` (default ``KNOT_INSETS_C``) where they fit (the device must
    slow down near the device limits to turn round, so the bands bend there)."""
    m = spec.edge_margin_c
    lo, hi = spec.working_lo_c, spec.working_hi_c
    insets_c = KNOT_INSETS_C if insets_c is None else insets_c
    inner = [k for k in insets_c if 2 * k + 2 <= hi - lo]
    return (lo - m, *(lo + k for k in inner), *(hi - k for k in reversed(inner)), hi + m)


def _invert_increasing(fun, target: float, hi: float) -> float:
    """Largest ``v`` in ``[0, hi]`` with ``fun(v) < target`` for increasing ``fun`` (bisection)."""
    lo_v, hi_v = 0.0, hi
    for _ in range(60):
        mid = 0.5 * (lo_v + hi_v)
        if fun(mid) < target:
            lo_v = mid
        else:
            hi_v = mid
    return lo_v


def _dynamic_tops(
    tops, knots, direction, tau_min, limits, turn_fraction: float = TURN_ACCEL_FRACTION
):
    """Lower the band tops so that a sweep can follow them.

    Along a sweep the speed ``v = |g|`` obeys ``dv/dt = (|U| - v)/tau`` at most when
    speeding up (``U`` the full chamber rate in the travel direction) and
    ``dv/dt = -(|U'| + v)/tau`` at most when slowing down (``U'`` the full rate the other
    way). With ``dT = v dt`` that is ``dv/dT <= (|U| - v)/(tau v)`` and
    ``dv/dT >= -(|U'| + v)/(tau v)``, integrated in closed form between the knots with a
    share ``turn_fraction`` of the rates.
    """
    up = limits.rate_max_c_per_min if direction > 0 else -limits.rate_min_c_per_min
    down = -limits.rate_min_c_per_min if direction > 0 else limits.rate_max_c_per_min
    k = turn_fraction
    a, b = k * up, k * down

    def f(v):  # distance (degC) to speed up from 0 to v: tau (-v - a ln(1 - v/a))
        return tau_min * (-v - a * math.log(max(1.0 - v / a, 1e-12)))

    def g(v):  # distance to slow down from v to 0: tau (v - b ln(1 + v/b))
        return tau_min * (v - b * math.log(1.0 + v / b))

    inverse = _invert_increasing
    order = list(range(len(knots))) if direction > 0 else list(range(len(knots)))[::-1]
    v = list(tops)
    for i, j in zip(order[:-1], order[1:], strict=True):  # speeding up, forwards
        dist = abs(knots[j] - knots[i])
        v[j] = min(v[j], inverse(f, f(min(v[i], 0.999 * a)) + dist, 0.999 * a))
    for i, j in zip(order[::-1][:-1], order[::-1][1:], strict=True):  # slowing, backwards
        dist = abs(knots[j] - knots[i])
        v[j] = min(v[j], inverse(g, g(v[i]) + dist, 10.0))
    return v


def turning_speed(
    room_c: float,
    reverse_rate_c_per_min: float,
    tau_min: float,
    turn_fraction: float = TURN_ACCEL_FRACTION,
) -> float:
    """Fastest speed |g| from which the device stops within ``room_c`` (degC/min).

    Reversing at a constant rate ``b`` (a share ``turn_fraction`` of the full reverse
    chamber rate), ``dv/dt = -(b + v)/tau``, so the distance to stop from ``v`` is
    ``tau (v - b ln(1 + v/b))`` (exact for the first-order lag); inverted by bisection.
    """
    if room_c <= 0:
        return 0.0
    b = turn_fraction * reverse_rate_c_per_min

    def dist(v):
        return tau_min * (v - b * math.log1p(v / b))

    return _invert_increasing(dist, room_c, 20.0)


@dataclass(frozen=True, slots=True)
class BandDesign:
    """How band tops are derived from the physics.

    ``room``: ``"sqrt"`` bounds the speed near a device limit by ``sqrt(a * room)`` (a
    conservative constant-deceleration estimate, a = share of rate/tau), ``"exact"`` by
    the exact first-order stopping distance (:func:`turning_speed`), which allows faster
    passes near the edges. ``knot_insets_c``: inner knots (more knots let the bands
    follow the curved speed limits). ``turn_fraction``: share of the full chamber rate
    assumed when speeding up or turning.
    """

    room: str = "sqrt"
    knot_insets_c: tuple[float, ...] = KNOT_INSETS_C
    turn_fraction: float = TURN_ACCEL_FRACTION


#: The band designs the search tries (see ``CANDIDATES``).
DESIGNS = {
    "sqrt": BandDesign(),
    "exact": BandDesign(room="exact", knot_insets_c=(1.5, 4.0, 8.0, 12.0), turn_fraction=0.9),
}


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
    gradient the chamber limits allow at T (``g = (Tk + dT0 - T)/tau``, for the least
    favourable scenario), and the speed from which the device can still turn round
    before its limit (``design.room``: ``sqrt(a * room)`` with ``a`` a share of the
    full-rate acceleration ``rate/tau``, or the exact stopping distance). Bands are
    ``width`` wide where there is room and narrower where a limit squeezes them, never
    closer than ``delta/2`` to zero, so heating and cooling passes stay ``delta`` apart.
    """
    design = DESIGNS["sqrt"] if design is None else design
    if knot_insets_c is None:
        knot_insets_c = design.knot_insets_c
    knots = band_knots(spec, knot_insets_c)
    v_min = spec.delta_c_per_min / 2 + BAND_SAFETY_C_PER_MIN
    cap0 = spec.max_cool_c_per_min if direction < 0 else spec.max_heat_c_per_min
    cap_lo, cap_hi = caps or (cap0, cap0)
    d_lo, d_hi = limits.device_min_c, limits.device_max_c
    tau_max = max(p.tau_min for p in params_list)
    tops = []
    for t in knots:
        f = (t - knots[0]) / (knots[-1] - knots[0])
        cap = cap_lo + f * (cap_hi - cap_lo)
        v_lim = min(_available_rate(direction, t, p, limits, cap) for p in params_list)
        # turning up near the floor of the device range uses the heating rate, turning
        # down near its ceiling the cooling rate
        room_lo, room_hi = t - d_lo, d_hi - t
        k = design.turn_fraction
        if design.room == "exact":
            v_room = min(
                turning_speed(room_lo, limits.rate_max_c_per_min, tau_max, k),
                turning_speed(room_hi, -limits.rate_min_c_per_min, tau_max, k),
            )
        else:
            a_lo = k * limits.rate_max_c_per_min / tau_max
            a_hi = k * -limits.rate_min_c_per_min / tau_max
            v_room = min(math.sqrt(max(a_lo * room_lo, 0.0)), math.sqrt(max(a_hi * room_hi, 0.0)))
        tops.append(min(v_lim, v_room))
    if dynamic:
        tops = _dynamic_tops(tops, knots, direction, tau_max, limits, design.turn_fraction)
    widths = [min(width_c_per_min, (v - v_min - (n_dir - 1) * sep_c_per_min) / n_dir) for v in tops]
    bands = []
    for r in range(1, n_dir + 1):  # rank 1 = slowest
        hi = tuple(v - (n_dir - r) * (w + sep_c_per_min) for v, w in zip(tops, widths, strict=True))
        lo = tuple(h - w for h, w in zip(hi, widths, strict=True))
        bands.append(Band(direction, r, tuple(knots), lo, hi, top=r == n_dir))
    return bands


def _band_feasibility(bands: Sequence[Band]) -> float:
    """Smallest band width at any knot (negative: the bands do not fit)."""
    return float(min(np.min(np.subtract(b.hi_c_per_min, b.lo_c_per_min)) for b in bands))


# ----------------------------------------------------------------------------------
# The LP pieces: every constraint is a row of  G @ [u, extra] <= h  built in numpy from
# the affine responses, handed to cvxpy as one matrix (fast to compile, easy to audit)
# ----------------------------------------------------------------------------------
@dataclass(slots=True)
class _Window:
    """Sweep ``direction`` owns samples ``start_s .. end_s`` (planner sample indices).

    ``cuts`` are the samples at which it crosses the band's inner knots, in travel order.
    """

    direction: int
    band: Band
    start_s: int
    end_s: int
    cuts: tuple[int, ...] = ()
    #: robust plans: ``(start_s, end_s, cuts)`` for each scenario (the scenarios lag one
    #: another, so each crosses the edges and knots at its own samples); None: shared
    per_scenario: tuple[tuple[int, int, tuple[int, ...]], ...] | None = None
    #: robust plans: knot tolerance (degC) of each scenario's cuts; a scenario that is
    #: not the reference crosses a knot between two samples wherever it happens to
    knot_tol_c: tuple[tuple[float, ...], ...] | None = None

    def bounds_of(self, scenario: int) -> tuple[int, int, tuple[int, ...]]:
        if self.per_scenario is None:
            return self.start_s, self.end_s, self.cuts
        return self.per_scenario[scenario]

    def pieces(self, scenario: int = 0):
        """``(first_sample, last_sample, piece_index, knot_at_last_or_None)`` in travel order."""
        n_piece = len(self.band.knots_c) - 1
        order = list(range(n_piece)) if self.direction > 0 else list(range(n_piece))[::-1]
        start_s, end_s, cuts = self.bounds_of(scenario)
        bounds = [start_s, *cuts, end_s]
        out = []
        for j, pi in enumerate(order):
            knot = None
            if j < n_piece - 1:
                knot = self.band.knots_c[pi + 1] if self.direction > 0 else self.band.knots_c[pi]
            out.append((bounds[j], bounds[j + 1], pi, knot))
        return out


class _SubLP:
    """An LP over the rates of segments ``[j0, j1)``, earlier rates fixed.

    Columns: the ``j1 - j0`` free rates, then ``extra`` scalar variables (margins, an
    epigraph variable). Rows are accumulated as ``G @ x <= h`` and ``E @ x == f``.
    """

    def __init__(
        self,
        planner: _Planner,
        u_fixed: np.ndarray,
        j1: int,
        extra: int = 0,
        scenarios: Sequence[int] | None = None,
    ):
        r = planner.responses
        self.planner = planner
        self.j0 = int(u_fixed.size)
        self.n = j1 - self.j0
        self.extra = extra
        self.s_from = r.sample_of(self.j0)
        self.s_to = r.sample_of(j1)
        rows = slice(self.s_from, self.s_to + 1)
        self.scen = []
        self.scen_idx = list(range(len(r.resp))) if scenarios is None else list(scenarios)
        for resp in (r.resp[i] for i in self.scen_idx):
            at = resp.a_t[rows, self.j0 : j1]
            ag = resp.a_g[rows, self.j0 : j1]
            bt = resp.b_t[rows] + resp.a_t[rows, : self.j0] @ u_fixed
            bg = resp.b_g[rows] + resp.a_g[rows, : self.j0] @ u_fixed
            self.scen.append((at, bt, ag, bg))
        seg = r.seg_min
        self.tk0 = planner.limits.start_c + seg * float(np.sum(u_fixed))
        self.tk_mat = seg * np.tril(np.ones((self.n, self.n)))
        self.g_rows: list[np.ndarray] = []
        self.h_rows: list[np.ndarray] = []
        self.e_rows: list[np.ndarray] = []
        self.f_rows: list[np.ndarray] = []

    def _pad(self, m: np.ndarray, extra_cols: dict[int, float] | None = None) -> np.ndarray:
        m = np.atleast_2d(m)
        out = np.zeros((m.shape[0], self.n + self.extra))
        out[:, : self.n] = m
        for k, coef in (extra_cols or {}).items():
            out[:, self.n + k] = coef
        return out

    def le(self, m, rhs, extra_cols=None) -> None:
        """``m @ u + sum(extra) <= rhs``."""
        rows = self._pad(m, extra_cols)
        self.g_rows.append(rows)
        self.h_rows.append(np.broadcast_to(np.asarray(rhs, dtype=float), rows.shape[:1]))

    def ge(self, m, rhs, extra_cols=None) -> None:
        """``m @ u - sum(extra) >= rhs`` written as ``-m @ u + extra <= -rhs``."""
        self.le(-np.atleast_2d(m), -np.asarray(rhs, dtype=float), extra_cols)

    def eq(self, m, rhs) -> None:
        self.e_rows.append(self._pad(m))
        self.f_rows.append(np.atleast_1d(np.asarray(rhs, dtype=float)))

    # -- constraint families -------------------------------------------------------
    def chamber(self) -> None:
        """Chamber air within its limits at every segment end (Tk is piecewise linear)."""
        lim = self.planner.limits
        self.le(self.tk_mat, lim.chamber_max_c - self.tk0)
        self.ge(self.tk_mat, lim.chamber_min_c - self.tk0)

    def chamber_end(self, value_c: float) -> None:
        self.eq(self.tk_mat[-1], value_c - self.tk0)

    def device(self) -> None:
        """The device stays within its limits at every sample.

        The approximation region is where the drift model is fitted, not a limit on the
        device: measurements outside it are simply not used (paper), and turning round
        outside it is often the fastest way to present a new gradient at the edge.
        """
        lim = self.planner.limits
        pad = self.planner.device_margin_c
        for at, bt, _, _ in self.scen:
            self.le(at, lim.device_max_c - pad - bt)
            self.ge(at, lim.device_min_c + pad - bt)

    def window(
        self, win: _Window, margin_g: int | None = None, margin_t: int | None = None
    ) -> None:
        """Band constraints inside the window and the edge conditions at its ends.

        ``margin_g`` / ``margin_t``: indices of extra columns that tighten the band and
        the edge conditions (maximised by the polish LP).
        """
        spec = self.planner.spec
        d, m = win.direction, spec.edge_margin_c
        mg = {margin_g: 1.0} if margin_g is not None else None
        mt = {margin_t: 1.0} if margin_t is not None else None
        for si, (at, bt, ag, bg) in zip(self.scen_idx, self.scen, strict=True):
            start_s, end_s, _ = win.bounds_of(si)
            s0, s1 = start_s - self.s_from, end_s - self.s_from
            pieces_done = 0
            for a, b_, pi, knot in win.pieces(si):
                w = slice(a - self.s_from, b_ - self.s_from + 1)
                t_ref, lo0, lo1, hi0, hi1 = win.band.piece(pi)
                # robust: a scenario's bands follow its own offset dT0 - dT0_ref (all its
                # sweeps shift alike, so its bands stay disjoint at every temperature)
                off = self.planner.offsets_c[si]
                t_ref += off
                if si != 0 and len(self.planner.responses.resp) > 1:
                    # robust: the other scenarios may stray ROBUST_SLACK outside the band
                    # (the bands are 2 ROBUST_SLACK further apart, so still disjoint)
                    lo0, hi0 = lo0 - ROBUST_SLACK_C_PER_MIN, hi0 + ROBUST_SLACK_C_PER_MIN
                # q = d g >= lo0 + lo1 (T - t_ref) + margin
                self.ge(d * ag[w] - lo1 * at[w], lo0 + lo1 * (bt[w] - t_ref) - d * bg[w], mg)
                # q <= hi0 + hi1 (T - t_ref) - margin (robust: not for the fastest band,
                # whose top bounds no other band; the scenarios spread most when fast)
                if not (win.band.top and len(self.planner.responses.resp) > 1):
                    self.le(d * ag[w] - hi1 * at[w], hi0 + hi1 * (bt[w] - t_ref) - d * bg[w], mg)
                if knot is not None:  # cross the knot at the planned sample
                    k = b_ - self.s_from
                    # a fast sweep moves far in one sample: half a sample's travel more
                    tol = KNOT_TOL_C + 0.5 * SAMPLE_MIN * float(win.band.bounds(knot)[1])
                    if win.knot_tol_c is not None:
                        tol = win.knot_tol_c[si][pieces_done]
                    pieces_done += 1
                    self.le(at[k], knot + off + tol - bt[k])
                    self.ge(at[k], knot + off - tol - bt[k])
            lo_edge, hi_edge = spec.working_lo_c - m, spec.working_hi_c + m
            if d < 0:  # starts above the region, ends below it
                self.ge(at[s0], hi_edge - bt[s0], mt)
                self.le(at[s1], lo_edge - bt[s1], mt)
            else:
                self.le(at[s0], lo_edge - bt[s0], mt)
                self.ge(at[s1], hi_edge - bt[s1], mt)

    def exit_speed(self, win: _Window, column: int) -> None:
        """Extra column ``column`` >= d * g at the window end, for every scenario."""
        for si, (_, _, ag, bg) in zip(self.scen_idx, self.scen, strict=True):
            s1 = win.bounds_of(si)[1] - self.s_from
            self.le(win.direction * ag[s1], -win.direction * bg[s1], {column: -1.0})

    # -- solving ---------------------------------------------------------------------
    def solve_direct(self, cost: np.ndarray, l1_weight: float = 0.0):
        """Minimise ``cost @ x + l1_weight * ||rates||_1`` by calling Clarabel directly.

        The search solves hundreds of these small feasibility LPs and cvxpy's compile
        step took longer than the solve itself, so they go to the same solver without the
        modelling layer (``scripts/bench_plan.py`` times one probe both ways). The
        whole-programme LPs (:func:`_polish`) are written in cvxpy. Returns the optimal
        ``x`` or None when the LP is infeasible.
        """
        import clarabel
        from scipy import sparse

        lim = self.planner.limits
        n, m = self.n, self.n + self.extra
        n_t = n if l1_weight > 0 else 0
        # the matrix is small (hundreds of rows, tens of columns): build it dense, convert
        # once (assembling it from sparse blocks cost more than the solve)
        eq = np.vstack(self.e_rows) if self.e_rows else np.zeros((0, m))
        g = np.vstack(self.g_rows)
        n_eq, n_g = eq.shape[0], g.shape[0]
        n_rows = n_eq + n_g + 2 * n + 2 * n_t
        a = np.zeros((n_rows, m + n_t))
        a[:n_eq, :m] = eq
        a[n_eq : n_eq + n_g, :m] = g
        r0 = n_eq + n_g
        idx = np.arange(n)
        a[r0 + idx, idx] = 1.0  # rate <= max
        a[r0 + n + idx, idx] = -1.0  # -rate <= -min
        b = np.concatenate(
            (
                np.concatenate(self.f_rows) if self.f_rows else np.zeros(0),
                np.concatenate(self.h_rows),
                np.full(n, lim.rate_max_c_per_min),
                np.full(n, -lim.rate_min_c_per_min),
                np.zeros(2 * n_t),
            )
        )
        if n_t:  # |rate| <= t
            r1 = r0 + 2 * n
            a[r1 + idx, idx] = 1.0
            a[r1 + idx, m + idx] = -1.0
            a[r1 + n + idx, idx] = -1.0
            a[r1 + n + idx, m + idx] = -1.0
        a = sparse.csc_matrix(a)
        q = np.concatenate((np.asarray(cost, dtype=float), np.full(n_t, float(l1_weight))))
        cones = ([clarabel.ZeroConeT(n_eq)] if n_eq else []) + [
            clarabel.NonnegativeConeT(a.shape[0] - n_eq)
        ]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        tic = time.perf_counter()
        try:
            sol = clarabel.DefaultSolver(
                sparse.csc_matrix((m + n_t, m + n_t)), q, a, b, cones, settings
            ).solve()
        finally:
            self.planner.lp_s += time.perf_counter() - tic
            self.planner.n_lp += 1
            _LP_COUNT[0] += 1
        self.last_size = {"variables": int(m + n_t), "constraints": int(a.shape[0])}
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            return None
        return np.asarray(sol.x[:m], dtype=float)

    def solve(
        self,
        objective: Callable[[cp.Variable], cp.Expression],
        extra_bounds: Sequence[tuple[float | None, float | None]] = (),
        extra_constraints: Callable[[cp.Variable], list] | None = None,
    ):
        lim = self.planner.limits
        x = cp.Variable(self.n + self.extra)
        g = np.vstack(self.g_rows)
        h = np.concatenate(self.h_rows)
        cons = [
            g @ x <= h,
            x[: self.n] >= lim.rate_min_c_per_min,
            x[: self.n] <= lim.rate_max_c_per_min,
        ]
        if self.e_rows:
            cons.append(np.vstack(self.e_rows) @ x == np.concatenate(self.f_rows))
        for k, (lo, hi) in enumerate(extra_bounds):
            if lo is not None:
                cons.append(x[self.n + k] >= lo)
            if hi is not None:
                cons.append(x[self.n + k] <= hi)
        if extra_constraints is not None:
            cons += extra_constraints(x)
        prob = cp.Problem(cp.Minimize(objective(x)), cons)
        ok = self.planner.solve(prob)
        self.last_size = {"variables": int(x.size), "constraints": int(h.size + 2 * self.n)}
        if not ok or x.value is None:
            return None
        return np.asarray(x.value, dtype=float)


class _Planner:
    """Shared state of one synthesis: spec, limits, responses, solver statistics."""

    def __init__(self, spec: ExperimentSpec, limits: Limits, responses: _Responses):
        self.spec, self.limits, self.responses = spec, limits, responses
        self.n_lp = 0
        self.lp_s = 0.0
        #: the device limits are tightened by this in the LPs (raised when rounding the
        #: step table for the operator pushes the device a hair past a limit)
        self.device_margin_c = 0.0
        ref = responses.scenarios[0].params
        self.offsets_c = [sc.params.dt0_c - ref.dt0_c for sc in responses.scenarios]
        self.size = {"variables": 0, "constraints": 0}

    def solve(self, problem: cp.Problem) -> bool:
        """Solve an LP with Clarabel (HiGHS if Clarabel fails); True when solved.

        An ``optimal_inaccurate`` answer is accepted: every plan is verified afterwards
        by dense re-simulation of its exported step table, so a slightly inaccurate LP
        can never make a plan look better than it is.
        """
        tic = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Solution may be inaccurate")
                try:
                    problem.solve(solver=cp.CLARABEL)
                except cp.error.SolverError:
                    problem.solve(solver=cp.HIGHS)
        except cp.error.SolverError as exc:  # pragma: no cover - both solvers broken
            raise SolverFailedError(f"LP solvers failed: {exc}") from None
        finally:
            self.lp_s += time.perf_counter() - tic
            self.n_lp += 1
            _LP_COUNT[0] += 1
        return problem.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def _sweep_directions(spec: ExperimentSpec, first: int) -> list[int]:
    return [first * (-1) ** k for k in range(spec.levels_required)]


def _first_directions(spec: ExperimentSpec, limits: Limits) -> list[int]:
    if spec.working_hi_c + spec.edge_margin_c <= limits.t_init_c:
        return [-1]
    if spec.working_lo_c - spec.edge_margin_c >= limits.t_init_c:
        return [+1]
    return [-1, +1]


def planning_effort(spec: ExperimentSpec, limits: Limits) -> float:
    """Rough relative cost of planning ``spec`` (for scheduling a campaign, longest first).

    A region that contains the start temperature is searched starting both ways (twice
    the structures), and wider regions need longer sweeps.
    """
    return len(_first_directions(spec, limits)) * (spec.working_hi_c - spec.working_lo_c)


def _turnaround_minutes(
    v_from: float, d_to: int, v_to: float, params: ThermalParams, limits: Limits
) -> float:
    """Time for g to go from ``-d_to * v_from`` to ``d_to * v_to`` at the full chamber rate.

    ``g(t) = U + (g0 - U) exp(-t/tau)`` under a constant rate U.
    """
    u = limits.rate_max_c_per_min if d_to > 0 else limits.rate_min_c_per_min
    g0, g1 = -d_to * v_from, d_to * v_to
    ratio = (g0 - u) / (g1 - u)
    return params.tau_min * math.log(ratio) if ratio > 1 else 0.0


def _order_bands(directions, bands_by_dir, spec, params, limits):
    """Assign bands to sweeps so that the estimated total time is smallest.

    Estimated time = sum of sweep times (region span / band centre) + turnarounds (the
    first-order response to the full chamber rate), over every assignment of the bands
    of each direction to that direction's sweeps.
    """
    from itertools import permutations

    idx = {d: [k for k, dd in enumerate(directions) if dd == d] for d in (+1, -1)}
    best: tuple[float, list[Band]] | None = None
    perms_h = list(permutations(bands_by_dir[+1])) or [()]
    perms_c = list(permutations(bands_by_dir[-1])) or [()]
    for ph in perms_h:
        for pc in perms_c:
            placed = dict(zip(idx[+1], ph, strict=True)) | dict(zip(idx[-1], pc, strict=True))
            seq = [placed[k] for k in range(len(directions))]
            total = 0.0
            prev = 0.0
            for d, b in zip(directions, seq, strict=True):
                lo, _ = b.bounds(np.array(b.knots_c))
                v_in, v_out = (lo[-1], lo[0]) if d < 0 else (lo[0], lo[-1])
                total += float(b.minutes().sum()) + _turnaround_minutes(
                    prev, d, v_in, params, limits
                )
                prev = v_out
            if best is None or total < best[0]:
                best = (total, seq)
    assert best is not None  # at least one assignment is tried
    return best[1]


@dataclass(slots=True)
class _Structure:
    windows: list[_Window]
    n_seg: int
    u: np.ndarray


def _place_sweep(planner: _Planner, u_fixed, d, band, max_seg):
    """Shortest transition + window for one sweep.

    The window may start at any planner sample after the fixed segments; its length is
    tried from the band's top speed to its centre speed. The transition length is found
    by doubling then bisection (feasibility is close to monotone in it: waiting longer
    beyond the edge is always possible while the device limits allow).
    """
    spec, r = planner.spec, planner.responses
    seg = spec.segment_min
    j0 = u_fixed.size
    s_start = r.sample_of(j0)
    s_max = r.sample_of(max_seg)
    # piece durations (samples) in travel order, from the band's top speed down
    options = []
    for fraction in (1.0, 0.75, 0.5, 0.25):
        minutes = band.minutes(fraction)
        if d < 0:
            minutes = minutes[::-1]
        # round the planned knot times, not each piece (rounded pieces drift)
        at = np.round(np.cumsum(minutes) / SAMPLE_MIN)
        options.append(np.maximum(1, np.diff(np.concatenate(([0.0], at)))).astype(int))
    d_fast = int(options[0].sum())

    robust = len(r.resp) > 1

    def solve_window(win, j1, scenarios):
        lp = _SubLP(planner, u_fixed, j1, extra=1, scenarios=scenarios)
        lp.chamber()
        lp.device()
        lp.window(win)
        lp.exit_speed(win, 0)
        # leave the window slowly: the next turnaround is then shorter
        cost = np.zeros(lp.n + 1)
        cost[-1] = 1.0
        sol = lp.solve_direct(cost, l1_weight=1e-4)
        return None if sol is None else sol[:-1]

    def attempt(x: int):
        for steps in options:
            s0 = s_start + x
            bounds = s0 + np.concatenate(([0], np.cumsum(steps)))
            s1 = int(bounds[-1])
            if s1 > s_max:
                return None
            j1 = min(int(math.ceil(s1 * SAMPLE_MIN / seg - 1e-9)), max_seg)
            win = _Window(d, band, s0, s1, tuple(int(c) for c in bounds[1:-1]))
            if not robust:
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
            found = _scenario_windows(planner, u_fixed, sol, win, max_seg)
            if found is None:
                continue
            win_all, j1_all = found
            sol_all = solve_window(win_all, j1_all, None)
            if sol_all is not None:
                return sol_all, win_all
        return None

    hi_x = min(s_max - s_start - d_fast, int(MAX_TRANSITION_MIN / SAMPLE_MIN))
    if hi_x < 0:
        return None
    # earliest feasible transition: scan in segment steps (feasibility is not monotone
    # enough for bisection over the whole range), then refine to the minute
    step = max(1, int(round(seg / SAMPLE_MIN)))
    prev, found = -1, None
    for x in range(0, hi_x + 1, step):
        res = attempt(x)
        if res is not None:
            found = (x, res)
            break
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


#: Robust plans: segments simulated past a sweep's planned end to find where the lagging
#: scenarios leave the region (the last rate is held).
SCENARIO_LOOKAHEAD_SEG = 6


def _scenario_windows(
    planner: _Planner, u_fixed: np.ndarray, u_new: np.ndarray, win: _Window, max_seg: int
) -> tuple[_Window, int] | None:
    """Per-scenario windows of a sweep placed for the reference scenario.

    Every scenario is simulated (affine responses) under the reference solution; its
    window starts at the last sample before it passes the starting edge, crosses each
    inner knot at the sample nearest to it and ends at the first sample beyond the far
    edge. Returns the window and the number of segments it needs, or None when some
    scenario does not make the sweep in the look-ahead.
    """
    r, spec = planner.responses, planner.spec
    seg_min = r.seg_min
    j_end = min(u_fixed.size + u_new.size + SCENARIO_LOOKAHEAD_SEG, max_seg)
    pad = j_end - u_fixed.size - u_new.size
    u = np.concatenate((u_fixed, u_new, np.full(max(pad, 0), u_new[-1] if u_new.size else 0.0)))
    u = u[:j_end]
    s_from = r.sample_of(u_fixed.size)
    s_to = r.sample_of(j_end)
    d, m = win.direction, spec.edge_margin_c
    e_start = spec.working_hi_c + m if d < 0 else spec.working_lo_c - m
    e_end = spec.working_lo_c - m if d < 0 else spec.working_hi_c + m
    knots = [k for _, _, _, k in win.pieces() if k is not None]
    per, tol_all = [], []
    for resp, off in zip(r.resp, planner.offsets_c, strict=True):
        t = resp.a_t[s_from : s_to + 1, :j_end] @ u + resp.b_t[s_from : s_to + 1]
        q = d * t  # increases along the sweep

        def first_past(level, after, q=q):
            idx = np.flatnonzero(q[after:] >= d * level)
            return None if idx.size == 0 else int(after + idx[0])

        c0 = first_past(e_start, 0)
        if c0 is None or c0 == 0:
            return None  # never reaches the region, or already inside it at the start
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
    j_need = max(int(math.ceil(p[1] * SAMPLE_MIN / seg_min - 1e-9)) for p in per)
    if j_need > max_seg:
        return None
    ref = per[0]
    return replace(
        win,
        start_s=ref[0],
        end_s=ref[1],
        cuts=ref[2],
        per_scenario=tuple(per),
        knot_tol_c=tuple(tol_all),
    ), j_need


def _greedy(
    planner: _Planner, directions, sweep_bands, max_seg, progress: Callable[[str], None] | None
) -> tuple[_Structure | None, str]:
    """Place the sweeps one after another, each as early and as short as feasible."""
    spec, limits = planner.spec, planner.limits
    seg = spec.segment_min
    u_fixed = np.zeros(0)
    windows: list[_Window] = []
    for k, (d, band) in enumerate(zip(directions, sweep_bands, strict=True)):
        res = _place_sweep(planner, u_fixed, d, band, max_seg)
        if res is None:
            where = "cooling" if d < 0 else "heating"
            return None, (
                f"sweep {k + 1} of {len(directions)} ({where}, gradient band {band.rank}) "
                f"does not fit within {max_seg * seg:g} min"
            )
        u_new, win = res
        u_fixed = np.concatenate(
            (u_fixed, np.clip(u_new, limits.rate_min_c_per_min, limits.rate_max_c_per_min))
        )
        windows.append(win)
        if progress:
            progress(f"sweep {k + 1}/{len(directions)} placed, ends at {u_fixed.size * seg:g} min")
    # return the chamber to its end temperature as soon as possible
    j0 = u_fixed.size
    for n_r in range(1, max_seg - j0 + 1):
        lp = _SubLP(planner, u_fixed, j0 + n_r)
        lp.chamber()
        lp.device()
        lp.chamber_end(limits.end_c)
        x = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
        if x is not None:
            u_fixed = np.concatenate((u_fixed, x))
            return _Structure(windows, u_fixed.size, u_fixed), ""
    return None, (
        f"no time is left within {max_seg * seg:g} min to bring the chamber back "
        f"to {limits.end_c:g} degC after the last sweep"
    )


def _whole_lp(planner: _Planner, windows: Sequence[_Window], n_seg: int, extra: int = 0):
    """The LP over the whole programme with the given sweep windows (margins optional)."""
    lp = _SubLP(planner, np.zeros(0), n_seg, extra=extra)
    lp.chamber()
    lp.chamber_end(planner.limits.end_c)
    lp.device()
    for w in windows:
        if extra:
            lp.window(w, margin_g=0, margin_t=1)
        else:
            lp.window(w)
    return lp


def _polish(planner: _Planner, structure: _Structure):
    """Whole-programme LPs with the windows fixed: maximise margin, then fewest changes.

    Margins: ``margin_g`` shrinks every band from both sides (passes further apart than
    delta), ``margin_t`` pushes every sweep further beyond the region edges. They are
    capped (0.03 degC/min, 1 degC): beyond that they would only slow the programme.
    """
    lp = _whole_lp(planner, structure.windows, structure.n_seg, extra=2)
    bounds = [(0.0, 0.03), (0.0, 1.0)]
    x = lp.solve(lambda x: -(x[-2] / 0.03 + 0.5 * x[-1] / 1.0), bounds)
    planner.size = lp.last_size
    if x is None:
        return structure.u, 0.0, 0.0
    best_g, best_t = x[-2], x[-1]
    bounds2 = [(0.8 * best_g, 0.03), (0.8 * best_t, 1.0)]
    n = lp.n
    x2 = lp.solve(lambda x: cp.norm1(cp.diff(x[:n])), bounds2)
    if x2 is not None:
        x = x2
    return x[:n], float(x[-2]), float(x[-1])


# ----------------------------------------------------------------------------------
# Results
# ----------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Plan:
    """A planned experiment, checked on its exported (rounded) step table.

    ``coverage`` and ``coverage_0p1`` come from an independent dense re-simulation of
    ``programme`` (what the operator types), never from the optimiser's variables.
    """

    spec: ExperimentSpec
    params: ThermalParams
    limits: Limits
    programme: Programme
    coverage: CoverageReport
    coverage_0p1: CoverageReport
    complete: bool
    status: str
    solve_s: float
    margin_g_c_per_min: float
    margin_t_c: float
    n_lp: int
    problem_size: dict
    scenarios: tuple[ThermalParams, ...]
    violations: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())
    t_min_c: float = float("nan")
    t_max_c: float = float("nan")
    box_check: dict | None = None

    @property
    def duration_min(self) -> float:
        return self.programme.total_min

    @property
    def steps(self) -> int:
        return self.programme.n_segments

    def to_frame(self) -> pd.DataFrame:
        """The step table."""
        return self.programme.to_frame()

    def to_summary_dict(self) -> dict:
        return {
            "experiment": self.spec.name,
            "working_min_c": self.spec.working_lo_c,
            "working_max_c": self.spec.working_hi_c,
            "duration_min": self.duration_min,
            "steps": self.steps,
            "coverage": self.coverage.coverage,
            "min_levels": self.coverage.min_levels,
            "coverage_delta_0p1": self.coverage_0p1.coverage,
            "complete": self.complete,
            "margin_g_c_per_min": self.margin_g_c_per_min,
            "margin_t_c": self.margin_t_c,
            "solve_s": self.solve_s,
        }

    def to_json_dict(self) -> dict:
        return {
            "experiment": self.spec.name,
            "tau_s": self.params.tau_s,
            "dt0_c": self.params.dt0_c,
            "spec": self.spec.to_dict(),
            "limits": self.limits.to_dict(),
            "robust_scenarios": [p.to_dict() for p in self.scenarios]
            if len(self.scenarios) > 1
            else [],
            "status": self.status,
            "complete": self.complete,
            "coverage": self.coverage.coverage,
            "coverage_delta_0p1": self.coverage_0p1.coverage,
            "min_levels": self.coverage.min_levels,
            "short_bins": [list(b) for b in self.coverage.short_bins()],
            "duration_min": self.duration_min,
            "steps": self.steps,
            "device_min_c": self.t_min_c,
            "device_max_c": self.t_max_c,
            "margin_g_c_per_min": self.margin_g_c_per_min,
            "margin_t_c": self.margin_t_c,
            "solve_s": self.solve_s,
            "lp_solves": self.n_lp,
            "problem_size": self.problem_size,
            "solver": "Clarabel (LP) via cvxpy",
            "violations": list(self.violations),
            "notes": list(self.notes),
            "robust_box_check": self.box_check,
        }


def check_programme(
    programme: Programme,
    spec: ExperimentSpec,
    limits: Limits,
    scenarios: Sequence[ThermalParams],
    model: LinearThermalModel | None = None,
) -> tuple[CoverageReport, CoverageReport, list[str], float, float]:
    """Independent check of a step table: dense simulation (0.1 min) for every scenario.

    Returns the worst-scenario coverage at ``delta`` and at 0.1 degC/min, every limit the
    programme breaks, and the device's min/max temperature.
    """
    grid = spec.grid
    worst = worst01 = None
    problems = list(programme.violations(limits))
    t_lo, t_hi = np.inf, -np.inf
    for p in scenarios:
        traj = simulate(
            programme,
            p,
            model=model if len(scenarios) == 1 else None,
            dt_min=0.1,
            t0_c=limits.t_init_c,
        )
        rep = coverage_report(
            traj.t_c, traj.g_c_per_min, grid, spec.levels_required, spec.delta_c_per_min
        )
        rep01 = coverage_report(traj.t_c, traj.g_c_per_min, grid, spec.levels_required, 0.1)
        if (
            worst is None
            or rep.coverage < worst.coverage
            or (rep.coverage == worst.coverage and rep.min_levels < worst.min_levels)
        ):
            worst = rep
        if worst01 is None or rep01.coverage < worst01.coverage:
            worst01 = rep01
        t_lo, t_hi = min(t_lo, traj.t_c.min()), max(t_hi, traj.t_c.max())
    if t_lo < limits.device_min_c - 1e-6 or t_hi > limits.device_max_c + 1e-6:
        where = (
            ""
            if len(scenarios) == 1
            else (f" (over the {len(scenarios)} design scenarios of the robust box)")
        )
        problems.append(
            f"the device reaches {t_lo:.2f} .. {t_hi:.2f} degC{where}, outside its limits "
            f"{limits.device_min_c:g} .. {limits.device_max_c:g} degC"
        )
    if worst is None or worst01 is None:
        raise ParameterError("check_programme needs at least one scenario")
    return worst, worst01, problems, float(t_lo), float(t_hi)


def _verify_robust(programme, spec, params, tau_range, dt0_range, limits) -> dict:
    """Dense check of a robust plan over its whole box (9 x 7 grid, ends included)."""
    from .sweep import verify_box

    res = verify_box(
        programme,
        (spec.working_lo_c, spec.working_hi_c),
        tau_range if tau_range is not None else (params.tau_s, params.tau_s),
        dt0_range if dt0_range is not None else (params.dt0_c, params.dt0_c),
        levels_required=spec.levels_required,
        deltas_c_per_min=(spec.delta_c_per_min, 0.1),
        t0_c=limits.t_init_c,
    )
    return {
        "holds": res.holds(),
        "full_share": res.full_share,
        "worst": res.worst(),
        "min_levels": int(res.min_levels_grid.min()),
        "covered_box": res.covered_box(),
        "grid_points": int(np.prod(res.shape)),
    }


def robustness_price(
    nominal: Plan,
    robust: Plan,
    tau_s_range: tuple[float, float] | None,
    dt0_c_range: tuple[float, float] | None,
) -> pd.DataFrame:
    """The price of robustness: a nominal and a robust plan side by side.

    Both plans are checked on the same dense grid over the box (:func:`_verify_robust`,
    at least 9 x 7 points); one row per plan with its duration, steps, coverage at
    delta and at 0.1 degC/min (worst design scenario), and over the box the worst
    coverage, the fewest levels and the share of grid points fully covered. The extra
    duration of the robust plan is in ``extra_min``.
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
            box = _verify_robust(
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
                "box_worst_coverage": box["worst"]["coverage"],
                "box_min_levels": box["min_levels"],
                "box_full_share": box["full_share"],
                "complete_over_box": bool(box["holds"]),
            }
        )
    return pd.DataFrame(rows)


def explain_shortfall(spec: ExperimentSpec, params: ThermalParams, limits: Limits) -> list[str]:
    """Which limit makes the region's edges hard to cover, in words with numbers."""
    notes = []
    tau = params.tau_min
    n_cool = spec.levels_required // 2
    n_heat = spec.levels_required - n_cool
    need = lambda n: n * spec.delta_c_per_min  # noqa: E731 - n levels delta apart, from ~0
    g_cool = (spec.working_lo_c - (limits.chamber_min_c + params.dt0_c)) / tau
    if g_cool <= 0:
        floor_t = limits.chamber_min_c + params.dt0_c
        notes.append(
            f"the chamber floor {limits.chamber_min_c:g} degC cannot bring the device below "
            f"{floor_t:g} degC (floor + dT0), so the bins below it are unreachable; a floor "
            f"of at most {spec.working_lo_c - spec.edge_margin_c - params.dt0_c - 1:g} degC "
            "is needed"
        )
    elif g_cool < need(n_cool) + 0.1:
        notes.append(
            f"at {spec.working_lo_c:g} degC the chamber floor {limits.chamber_min_c:g} degC "
            f"allows cooling gradients of at most {g_cool:.3f} degC/min "
            f"(g = (Tk_min + dT0 - T)/tau); {n_cool} cooling levels {spec.delta_c_per_min:g} "
            "degC/min apart need clearly more: lower the floor or the level count"
        )
    g_heat = (limits.chamber_max_c + params.dt0_c - spec.working_hi_c) / tau
    if g_heat <= 0:
        notes.append(
            f"the chamber ceiling {limits.chamber_max_c:g} degC cannot bring the device above "
            f"{limits.chamber_max_c + params.dt0_c:g} degC"
        )
    elif g_heat < need(n_heat) + 0.1:
        notes.append(
            f"at {spec.working_hi_c:g} degC the chamber ceiling {limits.chamber_max_c:g} degC "
            f"allows heating gradients of at most {g_heat:.3f} degC/min; {n_heat} heating "
            "levels need clearly more: raise the ceiling or lower the level count"
        )
    # turning room between the working edges and the device limits
    tau_s_min = params.tau_min
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
        v_room = math.sqrt(max(2 * TURN_ACCEL_FRACTION * rate / tau_s_min * room, 0.0))
        n_dir = max(n_cool, n_heat)
        if v_room < 2 * n_dir * (spec.delta_c_per_min + BAND_SAFETY_C_PER_MIN):
            notes.append(
                f"at {edge:g} degC the device limit leaves {room:g} degC to turn round; with "
                f"the chamber {word} at {rate:g} degC/min the passes there cannot be faster "
                f"than about {v_room:.2f} degC/min, so {n_dir} levels per direction there "
                "need slow, long passes: widen the device limits, lower the level count or "
                "lengthen the experiment"
            )
    if spec.approx_lo_c < limits.device_min_c or spec.approx_hi_c > limits.device_max_c:
        notes.append(
            f"the approximation region [{spec.approx_lo_c:g}, {spec.approx_hi_c:g}] degC "
            f"exceeds the device limits {limits.device_min_c:g} .. {limits.device_max_c:g} degC"
        )
    return notes


#: Structures tried by the search: edge caps (cooling at lo, cooling at hi, heating at
#: lo, heating at hi) as fractions of ``max_cool_c_per_min`` / ``max_heat_c_per_min``, and
#: whether the band tops are lowered to what the sweep dynamics can follow, and the band
#: design (``DESIGNS``: how the turning room near the device limits is modelled). Heating ->
#: cooling turnarounds happen at the upper edge and are slow (the chamber cools at only
#: 1 degC/min), so sweeps are slower there; cooling -> heating turnarounds at the lower
#: edge are quick (3 degC/min). The list was tuned on the paper's four regions (see
#: docs/planner.md); every candidate yields a valid plan or none.
CANDIDATES = (
    ((1.0, 0.7, 1.0, 0.9), True, "sqrt"),
    ((1.0, 0.7, 1.0, 0.9), False, "sqrt"),
    ((1.0, 0.7, 1.4, 0.9), False, "sqrt"),
    ((0.7, 0.7, 1.0, 0.9), True, "sqrt"),
    # exact turning room and more knots: faster passes near a device limit (W4's hot
    # edge has 2 degC of room below +62 degC and a chamber that cools at 1 degC/min)
    ((1.0, 0.7, 1.0, 0.9), True, "exact"),
    ((1.0, 1.0, 1.0, 1.0), True, "exact"),
)
#: The greedy may run past the duration limit by this factor; such a structure is only
#: used (cut at the limit) when nothing fits, to give the best reachable coverage.
OVERRUN_FACTOR = 1.3


@dataclass(slots=True)
class _Search:
    best: tuple | None  # (structure, sep) that fits the duration limit
    overrun: _Structure | None  # shortest structure that does not fit
    planner: _Planner
    reasons: list[str]


def _synthesise(spec, params_list, limits, models, progress, max_candidates=None) -> _Search:
    """Search structures (first direction, band separation, edge caps).

    For each candidate: bands -> greedy placement of the sweeps. ``shortest`` keeps the
    shortest structure that fits the duration limit; ``margin`` the one with the widest
    band separation that fits.
    """
    seg = spec.segment_min
    max_seg = int(limits.duration_max_min // seg)
    ext_seg = int(math.ceil(max_seg * OVERRUN_FACTOR))
    scenarios = [Scenario(p, m) for p, m in zip(params_list, models, strict=True)]
    planner = _Planner(spec, limits, _Responses(scenarios, ext_seg, seg, limits))
    search = _Search(None, None, planner, [])
    base_sep = spec.delta_c_per_min + BAND_SAFETY_C_PER_MIN
    if len(params_list) > 1:
        base_sep += 2 * ROBUST_SLACK_C_PER_MIN
    seps = [base_sep] if spec.objective == "shortest" else [base_sep + x for x in (0.04, 0.02, 0.0)]
    for sep in seps:
        for first in _first_directions(spec, limits):
            directions = _sweep_directions(spec, first)
            n_by_dir = {d: directions.count(d) for d in (+1, -1)}
            for caps, dynamic, design in CANDIDATES[:max_candidates]:
                cap_by_dir = {
                    -1: (caps[0] * spec.max_cool_c_per_min, caps[1] * spec.max_cool_c_per_min),
                    +1: (caps[2] * spec.max_heat_c_per_min, caps[3] * spec.max_heat_c_per_min),
                }
                # robust plans use the same bands: each scenario gets its own windows
                # and a slack (see _scenario_windows and _SubLP.window)
                bands = {
                    d: make_bands(
                        spec,
                        n_by_dir[d],
                        d,
                        sep,
                        params_list,
                        limits,
                        caps=cap_by_dir[d],
                        dynamic=dynamic,
                        design=DESIGNS[design],
                    )
                    if n_by_dir[d]
                    else []
                    for d in (+1, -1)
                }
                narrow = [d for d in (+1, -1) if bands[d] and _band_feasibility(bands[d]) <= 0]
                if narrow:
                    search.reasons.append(
                        f"the {'heating' if narrow[0] > 0 else 'cooling'} gradients the chamber "
                        f"allows near the region's edges cannot hold {n_by_dir[narrow[0]]} "
                        f"levels {sep:.3f} degC/min apart"
                    )
                    continue
                order = _order_bands(directions, bands, spec, params_list[0], limits)
                # only a shorter structure can improve on what was found: prune
                limit = ext_seg
                if search.best is not None:
                    limit = search.best[0].n_seg - 1
                elif search.overrun is not None:
                    limit = min(limit, search.overrun.n_seg - 1)
                structure, why = _greedy(planner, directions, order, limit, progress)
                if structure is None:
                    search.reasons.append(why)
                    continue
                minutes = structure.n_seg * seg
                if structure.n_seg > max_seg:
                    search.reasons.append(
                        f"the sweeps need {minutes:g} min, more than the limit "
                        f"{limits.duration_max_min:g} min"
                    )
                    if search.overrun is None or structure.n_seg < search.overrun.n_seg:
                        search.overrun = structure
                    continue
                if search.best is None or structure.n_seg < search.best[0].n_seg:
                    search.best = (structure, sep)
                if progress:
                    progress(f"structure found: {minutes:g} min")
        if search.best is not None:
            break  # margin: the widest separation that fits
    return search


def _truncate(planner: _Planner, structure: _Structure, max_seg: int) -> _Structure:
    """Cut an over-long structure so that it returns to the end temperature in time."""
    limits = planner.limits
    for n_r in range(1, max_seg):
        cut = max_seg - n_r
        u_fixed = structure.u[:cut]
        lp = _SubLP(planner, u_fixed, max_seg)
        lp.chamber()
        lp.device()
        lp.chamber_end(limits.end_c)
        x = lp.solve_direct(np.zeros(lp.n), l1_weight=1.0)
        if x is not None:
            end_s = planner.responses.sample_of(cut)
            windows = [w for w in structure.windows if w.end_s <= end_s]
            return _Structure(windows, max_seg, np.concatenate((u_fixed, x)))
    raise SolverFailedError("could not bring the chamber back to its end temperature")


def plan_experiment(
    spec: ExperimentSpec,
    params: ThermalParams | None = None,
    limits: Limits | None = None,
    *,
    model: LinearThermalModel | None = None,
    robust_tau_s: tuple[float, float] | None = None,
    robust_dt0_c: tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    require_complete: bool = False,
) -> Plan:
    """Synthesise a chamber programme for ``spec`` (see the module doc for the method).

    Parameters
    ----------
    spec : ExperimentSpec
    params : ThermalParams
        Nominal model parameters (default tau 2400 s, dT0 3 degC).
    limits : Limits
        Chamber, device and duration limits.
    model : LinearThermalModel, optional
        A linear device model to plan with instead of the first-order lag of ``params``
        (e.g. an augmented model from ``schedsyn diagnose``); ``params`` then only shapes
        the gradient bands.
    robust_tau_s, robust_dt0_c : (lo, hi), optional
        Plan one programme for every (tau, dT0) in the box (see :func:`robust_scenarios`).
    progress : callable(str), optional
        Receives short progress messages.
    require_complete : bool
        Raise :class:`InfeasiblePlanError` instead of returning an incomplete plan.

    Returns
    -------
    Plan
        Always checked by dense re-simulation of the rounded step table. When the target
        cannot be met, the plan covers the largest part of the region it can and
        ``notes`` say which bins fall short and which limit binds.
    """
    params = ThermalParams() if params is None else params
    limits = Limits() if limits is None else limits
    tic = time.perf_counter()
    robust = robust_tau_s is not None or robust_dt0_c is not None
    if robust and model is not None:
        raise ParameterError(
            "robust planning uses the first-order model of each scenario; "
            "give either a model or a robust box, not both"
        )
    params_list = robust_scenarios(params, robust_tau_s, robust_dt0_c)
    if robust:
        # the reference scenario (first) is the centre of the box: sweeps are placed for
        # it and every scenario's windows are read off its simulation
        params_list = [
            replace(
                params,
                tau_s=float(np.mean(robust_tau_s)) if robust_tau_s else params.tau_s,
                dt0_c=float(np.mean(robust_dt0_c)) if robust_dt0_c else params.dt0_c,
            ),
            *params_list,
        ]
    models = [model if model is not None else FirstOrderLag(p) for p in params_list]

    lp_count0 = _LP_COUNT[0]
    search = _synthesise(spec, params_list, limits, models, progress)
    notes: list[str] = []
    if robust and search.best is None:
        # no one programme fits the whole box: plan for its inner half (half of each
        # range, same centre), then its inner quarter, else for the nominal point with the
        # widest band separation that fits; the box check below says which part of the
        # whole box the result covers
        def inner(rng, share):
            if rng is None:
                return None
            mid, half = 0.5 * (rng[0] + rng[1]), 0.5 * share * (rng[1] - rng[0])
            return (mid - half, mid + half)

        for share, word in ((0.5, "half"), (0.25, "quarter")):
            in_tau, in_dt0 = inner(robust_tau_s, share), inner(robust_dt0_c, share)
            if progress:
                progress(f"no programme fits the robust box; trying its inner {word}")
            inner_list = [params_list[0], *robust_scenarios(params, in_tau, in_dt0)]
            search = _synthesise(
                spec, inner_list, limits, [FirstOrderLag(p) for p in inner_list], progress
            )
            if search.best is not None:
                box = " x ".join(
                    f"{name} {r[0]:g}..{r[1]:g} {unit}"
                    for name, r, unit in (("tau", in_tau, "s"), ("dT0", in_dt0, "degC"))
                    if r is not None
                )
                notes.append(
                    "no single programme meeting the target for every scenario of "
                    f"the robust box was found; planned robustly for its inner {word} "
                    f"({box})"
                )
                break
        else:
            notes.append(
                "no single programme meeting the target for every scenario of the "
                "robust box (or its inner half or quarter) was found; planned at the "
                "nominal point with the widest margins that fit"
            )
            spec_margin = replace(spec, objective="margin")
            search = _synthesise(spec_margin, [params], limits, [FirstOrderLag(params)], progress)
    max_seg = int(limits.duration_max_min // spec.segment_min)
    if search.best is not None:
        structure, _ = search.best
        u, margin_g, margin_t = _polish(search.planner, structure)
    else:
        # nothing fits in time: try the over-long structure cut at the limit, and the
        # widest sub-regions that fit; keep whichever covers most of the region
        notes += explain_shortfall(spec, params, limits)
        options = []
        if search.overrun is not None:
            structure = _truncate(search.planner, search.overrun, max_seg)
            options.append(
                (
                    f"all {spec.levels_required} sweeps need "
                    f"{search.overrun.n_seg * spec.segment_min:g} min, more than the "
                    f"limit {limits.duration_max_min:g} min; the programme is cut at "
                    "the limit",
                    structure.u,
                    0.0,
                    0.0,
                    search,
                )
            )

        checked: dict[int, float] = {}

        def verified(option):
            key = id(option[1])
            if key not in checked:
                prog = (
                    Programme(
                        np.full(option[1].size, float(spec.segment_min)), option[1], limits.start_c
                    )
                    .merged(1e-6)
                    .rounded(limits)
                )
                checked[key] = check_programme(prog, spec, limits, params_list, model)[0].coverage
            return checked[key]

        def full_coverage_found():
            return any(verified(o) >= 1.0 for o in options[-1:])

        for sub_spec, sub_search in _subregions(
            spec, params_list, limits, models, progress, stop=full_coverage_found
        ):
            u_sub, mg, mt = _polish(sub_search.planner, sub_search.best[0])
            options.append(
                (
                    f"sweeps designed for the sub-region [{sub_spec.working_lo_c:g}, "
                    f"{sub_spec.working_hi_c:g}] degC (the full region did not fit "
                    "in time)",
                    u_sub,
                    mg,
                    mt,
                    sub_search,
                )
            )
        if not options:
            msg = (
                f"{spec.name}: no programme covers any part of [{spec.working_lo_c:g}, "
                f"{spec.working_hi_c:g}] degC with {spec.levels_required} gradient levels "
                f"{spec.delta_c_per_min:g} degC/min apart within "
                f"{limits.duration_max_min:g} min ({'; '.join(search.reasons[:2])}); "
                "best reachable coverage is 0%. "
                "Lengthen the duration, narrow the region or lower the level count."
            )
            raise InfeasiblePlanError(msg, best_coverage=0.0)

        note, u, margin_g, margin_t, search = max(options, key=verified)
        notes.append(note)
    planner = search.planner
    raw = Programme(np.full(u.size, float(spec.segment_min)), u, limits.start_c)
    programme = raw.merged(rate_tol_c_per_min=1e-6).rounded(limits)
    cov, cov01, problems, t_lo, t_hi = check_programme(programme, spec, limits, params_list, model)
    # rounding to whole minutes and 0.1 degC can push the device a hair past a limit the
    # LP met at its samples: polish again with the limits tightened by that much
    for _ in range(2):
        excess = max(limits.device_min_c - t_lo, t_hi - limits.device_max_c)
        if excess <= 1e-6 or search.best is None:
            break
        planner.device_margin_c += excess + 0.05
        u2, mg2, mt2 = _polish(planner, search.best[0])
        prog2 = (
            Programme(np.full(u2.size, float(spec.segment_min)), u2, limits.start_c)
            .merged(rate_tol_c_per_min=1e-6)
            .rounded(limits)
        )
        check2 = check_programme(prog2, spec, limits, params_list, model)
        excess2 = max(limits.device_min_c - check2[3], check2[4] - limits.device_max_c)
        if check2[0].coverage < cov.coverage or excess2 >= excess:
            break
        programme, (cov, cov01, problems, t_lo, t_hi) = prog2, check2
        u, margin_g, margin_t = u2, mg2, mt2
    if programme.n_segments > spec.max_steps:
        problems.append(
            f"the step table has {programme.n_segments} steps, more than "
            f"max_steps = {spec.max_steps}"
        )
    complete = cov.complete and not problems
    if not cov.complete:
        short = cov.short_bins()
        notes.append(
            f"{len(short)} of {spec.grid.n_bins} bins have fewer than {spec.levels_required} "
            f"distinct levels: " + ", ".join(f"[{a:g},{b:g}) {n}" for a, b, n in short[:10])
        )
        notes += [n for n in explain_shortfall(spec, params, limits) if n not in notes]
    box_check = None
    if robust:
        box_check = _verify_robust(programme, spec, params, robust_tau_s, robust_dt0_c, limits)
        if not box_check["holds"]:
            complete = False
            part = box_check["covered_box"]
            notes.append(
                "coverage does not hold everywhere in the robust box (worst point tau "
                f"{box_check['worst']['tau_s']:g} s, dT0 {box_check['worst']['dt0_c']:g} degC: "
                f"{box_check['worst']['coverage']:.0%}); "
                + (
                    f"it holds for tau {part['tau_s_range'][0]:g}..{part['tau_s_range'][1]:g} s "
                    f"x dT0 {part['dt0_c_range'][0]:g}..{part['dt0_c_range'][1]:g} degC"
                    if part
                    else "no grid point is fully covered"
                )
            )
    status = "complete" if complete else ("incomplete" if not problems else "limits violated")
    plan = Plan(
        spec=spec,
        params=params,
        limits=limits,
        programme=programme,
        coverage=cov,
        coverage_0p1=cov01,
        complete=complete,
        status=status,
        solve_s=time.perf_counter() - tic,
        margin_g_c_per_min=margin_g,
        margin_t_c=margin_t,
        n_lp=_LP_COUNT[0] - lp_count0,
        problem_size=planner.size,
        scenarios=tuple(params_list),
        violations=tuple(problems),
        notes=tuple(notes),
        t_min_c=t_lo,
        t_max_c=t_hi,
        box_check=box_check,
    )
    if require_complete and not complete:
        raise InfeasiblePlanError(
            f"{spec.name}: the target cannot be met: {'; '.join(notes + problems)}; best "
            f"reachable coverage is {cov.coverage:.0%}",
            best_coverage=cov.coverage,
        )
    return plan


def _subregions(spec, params_list, limits, models, progress, stop=None):
    """The widest sub-regions (whole bins cut from the low, the high or both edges) for
    which a structure fits the duration limit: at most one per side, yielded as found.

    ``stop()`` is asked before each further side: the caller says when an option already
    covers the full region (sweeps designed for a narrower region often still cover the
    whole one: they pass the edges with margin), so the remaining searches are skipped.
    """
    n = spec.grid.n_bins
    for side in ("low", "high", "both"):
        wide = (round(0.3 * n), round(0.45 * n))  # regions far too wide for the time
        cuts = (2, 4, 7) if side != "both" else (4, 7)
        for cut in sorted(set(cuts) | {c for c in wide if c > 7}):
            if cut >= n - 1:
                break
            a = {"low": cut, "high": 0, "both": cut // 2}[side]
            b = cut - a
            sub = replace(
                spec, working_lo_c=spec.working_lo_c + a, working_hi_c=spec.working_hi_c - b
            )
            search = _synthesise(sub, params_list, limits, models, None, max_candidates=1)
            if search.best is not None:
                if progress:
                    progress(f"sub-region [{sub.working_lo_c:g}, {sub.working_hi_c:g}] fits")
                yield sub, search
                if stop is not None and stop():
                    return
                break
