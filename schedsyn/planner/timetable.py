"""Timetable SLP: complete plans from crossing times, with automatic starting profiles.

A stage beside the band search (session 35, issue 12). The structure is fixed: ``L =
levels_required`` monotone sweeps across the working region, alternating direction, each
with a rank within its direction (1 = slowest). Decision variables: the segment rates
``u`` (the request's segment grid), the *timetable* ``t[k, p]`` (when sweep ``k`` crosses
its ``p``-th bin boundary) and the end time.

With the crossings fixed, a pass's time-mean gradient over a bin is ``1 / (t[k, p+1] -
t[k, p])``, so the levels are conditions on the timetable alone: per bin the ranks of a
direction are ``delta + safety`` apart and the slowest cooling plus the slowest heating
speed is at least that. ``T(u, t)`` is affine in ``u`` and smooth in ``t``
(:func:`~schedsyn.model.affine_response` at any time), so everything is linearised in
``(u, t)`` and solved by a sequential LP (HiGHS via :func:`scipy.optimize.linprog`):
trust regions, l1 penalties on violations, the end time (plus a small l1 term on rate
changes, for fewer steps) as objective, and after every LP the timetable replaced by the
trajectory's actual crossings.

The start comes from a tracking simulation of per-sweep target speed profiles (entry,
cruise, exit speed per sweep) derived from the physics (:mod:`.physics`): rank speeds
spaced ``delta + safety`` apart, cruise speeds under the bands' caps and the chamber's
(``(Tk_max + dT0 - T)/tau`` heating, ``(T - Tk_min - dT0)/tau`` cooling), edge speeds
small where reversing is slow. A few orders of the ranks and two speed scalings are
tried, best start first, within a budget of LP solves (``max_lps``: the same answer on
any machine and under any load; an optional wall-clock ``deadline_s`` on top).

Every returned programme is the rounded step table (whole minutes, 0.1 degC) and has
passed :func:`~.check.check_programme` (complete, no limit broken) and
:func:`~.check.step_limit_problems`. The method is a local optimiser: ``None`` proves
nothing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from ..coverage import CoverageReport, level_separation, passes
from ..errors import ParameterError, SchedsynError
from ..model import FirstOrderLag, LinearThermalModel, affine_response
from ..params import Limits, ThermalParams
from ..programme import Programme
from ..simulate import simulate
from .bound import duration_lower_bound
from .check import FINE_CHECK_DT_MIN, check_programme, step_limit_problems
from .physics import LIMIT_FRACTION, invert_increasing, stop_distance
from .request import ExperimentSpec, check_request, first_directions

#: Separation the timetable keeps between ranks above ``delta``, degC/min.
SAFETY_C_PER_MIN = 0.012
#: A near miss (no complete plan, but an SLP ended within ``NEAR_MISS_MIN`` of the
#: budget) is searched again from that SLP's start only, with this smaller separation
#: above ``delta``, within ``NEAR_MISS_LPS`` more LP solves: the band search's plans keep
#: 0.0005-0.005 degC/min; ``10-30-levels4-240`` ended 0.8 min over with 0.012 and is
#: complete at 240 with 0.006 (51 LPs), ``m45-m35-floor-m52`` 5 min over, complete at
#: 533 (350 LPs; 200 LPs spread over every start found nothing).
NEAR_MISS_SAFETY_C_PER_MIN = 0.006
NEAR_MISS_MIN = 10.0
NEAR_MISS_LPS = 350
#: The LP asks this much more separation than the merit (second-order error of 1/D).
LP_EXTRA_C_PER_MIN = 0.003
#: Smallest gradient (in the sweep direction) inside a sweep's window, degC/min.
MONO_EPS = 0.003
#: Turns go this much further past the edges than ``edge_margin_c``, degC.
DEPTH_PAD_C = 0.02
#: Weight of sum |u[j+1] - u[j]| in the objective (fewer steps).
L1_WEIGHT = 0.5
#: Share of ``end_tol_c`` the LP keeps in reserve on the chamber's end temperature.
END_EXTRA_C = 0.2
#: Times the penalty weights are raised tenfold when the SLP stalls with violations left.
PENALTY_RAISES = 2
#: Lower weights tried when a structure converged just over the budget.
L1_LOWER = (0.1, 0.02)
#: Rounded tables are checked when the end time improved by this much, min.
CHECK_EVERY_MIN = 1.0
#: Share of the chamber rates the tracking start accelerates and brakes with.
TRACK_SHARE = 0.9
#: Speed scalings of the cruise speeds tried.
SCALINGS = (1.0, 0.7)
#: Levels the structure generator handles.
LEVELS_RANGE = (2, 10)
#: Steps per sweep the stage's tables need at least (a speed-up and a braking rate; the
#: benchmark's have 6-10): a lower step limit is refused at once.
MIN_STEPS_PER_SWEEP = 2
#: LP solves the search may spend (every candidate's together; 0.3-0.7 s each on one core
#: of the 2-core machine): the benchmark's plans were found within 125-573.
MAX_LPS = 500

Progress = Callable[[str], None] | None


@dataclass(frozen=True)
class TimetableResult:
    """A complete plan of the timetable stage and what was tried.

    ``programme`` is the rounded step table; ``coverage`` its check
    (:func:`~.check.check_programme`); ``order`` the structure (e.g. ``C1H1C2H2C3H3``),
    ``speeds`` the starting profile's (entry, cruise, exit) per sweep, ``scale`` its cruise
    scaling; ``tried`` one dict per candidate (order, scale, speeds, start end, LPs,
    seconds, best end, found). ``min_separation_c_per_min``: the worst bin's level
    separation (:func:`~schedsyn.coverage.level_separation`) at the check's fine sampling;
    ``safety_c_per_min`` the separation above ``delta`` it was planned with
    (:data:`NEAR_MISS_SAFETY_C_PER_MIN` where a near miss was searched again).
    """

    programme: Programme
    coverage: CoverageReport
    order: str
    scale: float
    speeds: tuple[tuple[float, float, float], ...]
    min_separation_c_per_min: float
    n_lp: int
    seconds: float
    tried: tuple[dict, ...] = field(default=())
    safety_c_per_min: float = SAFETY_C_PER_MIN

    @property
    def duration_min(self) -> float:
        return self.programme.total_min

    @property
    def steps(self) -> int:
        return self.programme.n_segments


# -- the request, flattened ---------------------------------------------------------
@dataclass
class _Setup:
    spec: ExperimentSpec
    params: ThermalParams
    limits: Limits
    model: LinearThermalModel
    edges: np.ndarray  # bin boundaries, degC
    sep: float
    depth: float

    @property
    def lo(self) -> float:
        return float(self.edges[0])

    @property
    def hi(self) -> float:
        return float(self.edges[-1])

    @property
    def nb(self) -> int:
        return self.edges.size - 1

    @property
    def tau(self) -> float:
        return self.params.tau_min

    @property
    def seg(self) -> float:
        return float(self.spec.segment_min)


@dataclass(frozen=True)
class _Structure:
    dirs: tuple[int, ...]  # +1 heating, -1 cooling
    ranks: tuple[int, ...]  # rank within the direction, 1 = slowest

    @property
    def name(self) -> str:
        return "".join(
            f"{'H' if d > 0 else 'C'}{r}" for d, r in zip(self.dirs, self.ranks, strict=True)
        )


def structures(levels: int, first: int, split: tuple[int, int] | None = None) -> list[_Structure]:
    """Alternating structures starting in direction ``first``.

    ``split``: ranked sweeps (first direction, other direction); default the first
    direction ``ceil(levels / 2)``. An uneven split (one direction holds fewer levels,
    e.g. where a chamber limit caps its speed near an edge) adds unranked sweeps (rank 0,
    "free": they only bring the device back) so that the directions still alternate.
    Orders: slow ranks first, fast ranks first, and the first direction slow-first with
    the other fast-first; free sweeps last in their direction.
    """
    n_first, n_other = split if split is not None else ((levels + 1) // 2, levels // 2)
    sweeps_first = max(n_first, n_other)  # the first direction has as many as the other
    sweeps_other = max(n_other, sweeps_first - 1)
    n_sweeps = sweeps_first + sweeps_other
    dirs = tuple(first * (-1) ** k for k in range(n_sweeps))
    out = []
    for a_up, b_up in ((True, True), (False, False), (True, False)):
        ra = list(range(1, n_first + 1)) if a_up else list(range(n_first, 0, -1))
        rb = list(range(1, n_other + 1)) if b_up else list(range(n_other, 0, -1))
        ra += [0] * (sweeps_first - n_first)
        rb += [0] * (sweeps_other - n_other)
        ranks = [ra[k // 2] if k % 2 == 0 else rb[k // 2] for k in range(n_sweeps)]
        st = _Structure(dirs, tuple(ranks))
        if st not in out:
            out.append(st)
    return out


def ranks_at_edges(su: _Setup, d: int) -> int:
    """How many ranks direction ``d`` can hold in the edge bins under the chamber's limit:
    the fastest time-mean speed there (the cap at the bin's inner side, LIMIT_FRACTION of
    it), the slowest rank at least sep/2, the others sep apart."""
    caps = [float(_chamber_cap(su, d, t)) for t in (su.lo + 1.0, su.hi - 1.0)]
    top = min(caps)
    return max(1, int(math.floor((top - 0.5 * su.sep) / su.sep)) + 1)


# -- the starting profiles ------------------------------------------------------------
def _rates(su: _Setup, d: int) -> tuple[float, float]:
    """(forward, reverse) chamber rate magnitudes for a sweep in direction ``d``."""
    lim = su.limits
    up, down = lim.rate_max_c_per_min, -lim.rate_min_c_per_min
    return (up, down) if d > 0 else (down, up)


def _chamber_cap(su: _Setup, d: int, temp_c):
    """Speed the chamber limits allow at ``temp_c`` in direction ``d`` (LIMIT_FRACTION of it)."""
    lim, dt0 = su.limits, su.params.dt0_c
    if d > 0:
        g = (lim.chamber_max_c + dt0 - np.asarray(temp_c, float)) / su.tau
    else:
        g = (np.asarray(temp_c, float) - lim.chamber_min_c - dt0) / su.tau
    return LIMIT_FRACTION * np.maximum(g, 0.0)


def _turn_room(su: _Setup, edge_hi: bool) -> float:
    """Room beyond an edge for a turn (to the device limit or the chamber's turning
    point ``Tk + dT0``), less the turn depth, degC."""
    lim, dt0 = su.limits, su.params.dt0_c
    if edge_hi:
        far = min(lim.device_max_c, lim.chamber_max_c + dt0)
        return far - su.hi - su.depth
    far = max(lim.device_min_c, lim.chamber_min_c + dt0)
    return su.lo - far - su.depth


def edge_speeds(su: _Setup, edge_hi: bool, n: int) -> list[float]:
    """Speeds of ranks 1..n at an edge: small where reversing is slow (the reversing
    chamber rate is small, the turn has little room, the chamber limit is near)."""
    lim = su.limits
    # a sweep leaving/entering the hot edge reverses by cooling, the cold edge by heating
    r_rev = -lim.rate_min_c_per_min if edge_hi else lim.rate_max_c_per_min
    base = min(max(0.05 * r_rev, 0.5 * su.sep), 0.3)
    step = max(1.15 * su.sep, 0.5 * base)
    room = _turn_room(su, edge_hi)
    v_room = invert_increasing(
        lambda v: stop_distance(v, TRACK_SHARE * r_rev, su.tau), max(room, 0.0), 20.0
    )
    edge = su.hi if edge_hi else su.lo
    if edge_hi:  # heating sweeps arrive at the hot edge, limited by the ceiling there
        cap = float(_chamber_cap(su, +1, edge))
    else:
        cap = float(_chamber_cap(su, -1, edge))
    top = min(v_room, cap)  # the fastest rank should turn within the room, under the cap
    out = []
    for r in range(n):
        v = min(base + r * step, top - (n - 1 - r) * su.sep)
        out.append(max(v, 0.5 * su.sep + r * su.sep))  # never closer than sep
    return out


def cruise_speeds(su: _Setup, d: int, n: int, scale: float) -> list[float]:
    """Cruise speeds of ranks 1..n: the fastest under the bands' cap, the chamber rate and
    the chamber limit in the middle of the region, the others ``max(1.6 sep, 0.1)`` below."""
    spec = su.spec
    band = spec.max_heat_c_per_min if d > 0 else spec.max_cool_c_per_min
    fwd, _ = _rates(su, d)
    mid = 0.5 * (su.lo + su.hi)
    top = min(band, LIMIT_FRACTION * fwd, float(_chamber_cap(su, d, mid))) * scale
    top = max(top, su.sep * n + 0.05)
    step = max(1.6 * su.sep, 0.1)
    if n > 1 and top - (n - 1) * step < 0.25:
        # a low cap (chamber limit near the region): ranks closer, still sep apart, so
        # that the slowest does not crawl (only its sum with the other direction's
        # slowest must reach sep)
        step = max(1.15 * su.sep, min(step, (top - 0.25) / (n - 1)))
    return [max(top - (n - 1 - r) * step, 0.5 * su.sep + r * su.sep) for r in range(n)]


def starting_speeds(su: _Setup, st: _Structure, scale: float) -> list[tuple[float, float, float]]:
    """(entry, cruise, exit) per sweep of the structure."""
    n = {
        d: sum(1 for x, r in zip(st.dirs, st.ranks, strict=True) if x == d and r > 0)
        for d in (-1, +1)
    }
    hot = {d: edge_speeds(su, True, max(n[d], 1)) for d in (-1, +1)}
    cold = {d: edge_speeds(su, False, max(n[d], 1)) for d in (-1, +1)}
    out = []
    for d, r in zip(st.dirs, st.ranks, strict=True):
        r = r if r > 0 else max(n[d], 1)  # a free sweep: as fast as the fastest rank
        c = cruise_speeds(su, d, max(n[d], 1), scale)[r - 1]
        if d < 0:  # cooling: enters at the hot edge, leaves at the cold edge
            e, f = hot[d][r - 1], cold[d][r - 1]
        else:
            e, f = cold[d][r - 1], hot[d][r - 1]
        out.append((min(e, c), c, min(f, c)))
    return out


def _profile(su: _Setup, d: int, e: float, c: float, f: float, n: int = 601):
    """Target speed over the distance from the entry edge: from ``e`` speeding up, at most
    ``c`` and the chamber's cap, braking to ``f`` at the far edge."""
    fwd, rev = _rates(su, d)
    r_acc, r_brk = TRACK_SHARE * fwd, TRACK_SHARE * rev
    width = su.hi - su.lo
    x = np.linspace(0.0, width, n)
    temps = (su.lo + x) if d > 0 else (su.hi - x)
    cap = np.minimum(c, np.maximum(_chamber_cap(su, d, temps), 0.5 * e))
    h = x[1] - x[0]
    tau = su.tau
    up = np.empty(n)
    up[0] = e
    for i in range(1, n):
        v = up[i - 1]
        up[i] = min(cap[i], v + h * (r_acc - v) / (tau * max(v, 0.02)))
    dn = np.empty(n)
    dn[-1] = f
    for i in range(n - 2, -1, -1):
        v = dn[i + 1]
        dn[i] = v + h * (r_brk + v) / (tau * max(v, 0.02))
    return x, np.minimum(np.minimum(up, dn), cap)


#: The tracking start keeps the chamber this far inside its limits, degC, ...
TRACK_CHAMBER_MARGIN_C = 1.0


def _track_margins(su: _Setup) -> tuple[float, float]:
    """(floor, ceiling) margins of the tracking start's chamber: ``TRACK_CHAMBER_MARGIN_C``,
    or half the room beyond a turn where the chamber limit is closer (red team q13: a
    ceiling 1 degC past the region's top with dT0 0; 1 degC inside it the device never
    turned past the edge and no start finished)."""
    lim, dt0 = su.limits, su.params.dt0_c
    room_hi = lim.chamber_max_c + dt0 - (su.hi + su.depth)
    room_lo = (su.lo - su.depth) - (lim.chamber_min_c + dt0)
    return tuple(  # type: ignore[return-value]
        min(TRACK_CHAMBER_MARGIN_C, max(0.05, 0.5 * room)) for room in (room_lo, room_hi)
    )


def track(su: _Setup, st: _Structure, speeds, n_seg: int):
    """Segment rates following the structure's target profiles, and the segment index
    where the last sweep ended (None if it did not within ``n_seg``)."""
    lim, p = su.limits, su.params
    tau, seg = su.tau, su.seg
    a = math.exp(-seg / tau)
    T, Tk = lim.t_init_c, lim.start_c
    g = (Tk + p.dt0_c - T) / tau
    u = np.zeros(n_seg)
    profs = [_profile(su, d, *sp_) for d, sp_ in zip(st.dirs, speeds, strict=True)]
    k, phase, end_at = 0, "pre", None
    depth = su.depth + 0.05
    d0 = st.dirs[0]
    edge0 = su.hi if d0 < 0 else su.lo
    b0 = -d0  # beyond the first entry edge
    fwd_pre, rev_pre = _rates(su, b0)
    v_pre = 0.6 * min(
        TRACK_SHARE * fwd_pre, su.spec.max_heat_c_per_min if b0 > 0 else su.spec.max_cool_c_per_min
    )

    def approach(d, e, pos):
        """Speed before the entry edge (pos < 0) that brakes to ``e`` at the edge."""
        _, rev = _rates(su, d)
        rb = TRACK_SHARE * rev
        target = float(stop_distance(e, rb, tau)) - pos
        return invert_increasing(lambda v: stop_distance(v, rb, tau), target, 5.0)

    m_lo, m_hi = _track_margins(su)
    for j in range(n_seg):
        if phase == "pre":
            moving = max(b0 * g, 0.0)
            t_stop = T + b0 * float(stop_distance(moving, TRACK_SHARE * rev_pre, tau))
            if b0 * (t_stop - edge0) >= depth:
                phase = "sweep"
            else:
                gs = b0 * v_pre
        if phase == "sweep":
            d = st.dirs[k]
            x_edge = su.hi if d < 0 else su.lo
            x_exit = su.lo if d < 0 else su.hi
            xx, vv = profs[k]
            pos = d * (T - x_edge) + 0.5 * seg * abs(g)
            if pos < 0:  # still before the entry edge: as fast as it can brake to e
                fwd, _ = _rates(su, d)
                band = su.spec.max_heat_c_per_min if d > 0 else su.spec.max_cool_c_per_min
                v = min(
                    approach(d, vv[0], pos),
                    band,
                    LIMIT_FRACTION * fwd,
                    max(float(_chamber_cap(su, d, T)), vv[0]),
                )
            else:
                v = float(np.interp(pos, xx, vv))
            gs = d * v
            if d * (T - x_exit) > depth:
                k += 1
                if k == len(st.dirs):
                    phase = "end"
                else:
                    gs = st.dirs[k] * profs[k][1][0]
        if phase == "end":
            if end_at is None:
                end_at = j
            uj = (lim.end_c - Tk) / seg
        else:
            uj = (gs - g * a) / (1 - a)
        uj = min(max(uj, lim.rate_min_c_per_min), lim.rate_max_c_per_min)
        uj = min(
            max(uj, (lim.chamber_min_c + m_lo - Tk) / seg), (lim.chamber_max_c - m_hi - Tk) / seg
        )
        u[j] = uj
        Tk1 = Tk + uj * seg
        gn = uj + (g - uj) * a
        T = T + uj * seg - tau * (gn - g)
        g, Tk = gn, Tk1
    return u, end_at


def crossings(su: _Setup, st: _Structure, times, T):
    """Each sweep's crossings of the boundaries in turn, read off a trajectory (None if
    some are missing)."""
    P = su.nb + 1
    tt = np.zeros((len(st.dirs), P))
    i = 0
    n = len(T)
    for k, d in enumerate(st.dirs):
        B = su.edges if d > 0 else su.edges[::-1]
        for p, bnd in enumerate(B):
            while i + 1 < n and not (d * (T[i + 1] - bnd) >= 0 and d * (T[i] - bnd) < 0):
                i += 1
            if i + 1 >= n:
                return None
            f = (bnd - T[i]) / (T[i + 1] - T[i])
            tt[k, p] = times[i] + f * (times[i + 1] - times[i])
            i += 1
    return tt


# -- the SLP ------------------------------------------------------------------------------
@dataclass
class _Clock:
    """The search's clock, in LP solves (deterministic), with an optional wall deadline
    (``time.monotonic()`` value) on top."""

    max_lps: int
    deadline: float | None = None
    lps: int = 0

    def over(self, stop_lps: float) -> bool:
        """``stop_lps`` solves done, or the wall deadline passed."""
        late = self.deadline is not None and time.monotonic() > self.deadline
        return self.lps >= stop_lps or late


class _Timetable:
    """Variables, LP rows and the exact merit for one structure."""

    def __init__(self, su: _Setup, st: _Structure, n_seg: int, clock: _Clock | None = None):
        self.clock = _Clock(max_lps=10**9) if clock is None else clock
        self.su, self.st = su, st
        lim = su.limits
        self.nu = n_seg
        self.dur = np.full(n_seg, su.seg)
        self.S = len(st.dirs)
        self.P = su.nb + 1
        self.B = np.array([su.edges if d > 0 else su.edges[::-1] for d in st.dirs], float)
        self.it = self.nu
        self.nt = self.S * self.P
        self.iend = self.nu + self.nt
        self.nx = self.iend + 1
        self.end_margin = min(0.1, 0.4 * lim.end_tol_c)
        self.weights = dict(
            cross=60.0, level=3000.0, mono=300.0, turn=60.0, end=60.0, outside=60.0, device=60.0
        )
        self.n_lp = 0
        self.l1 = L1_WEIGHT
        # level rows: ("diff", bin, k_fast, p, k_slow, p) / ("sum", bin, k_cool, p, k_heat, p)
        pos = {}
        for k, d in enumerate(st.dirs):
            for p in range(self.P - 1):
                j = p if d > 0 else su.nb - 1 - p
                pos[(j, k)] = p
        cool = sorted(
            [k for k in range(self.S) if st.dirs[k] < 0 and st.ranks[k] > 0],
            key=lambda k: st.ranks[k],
        )
        heat = sorted(
            [k for k in range(self.S) if st.dirs[k] > 0 and st.ranks[k] > 0],
            key=lambda k: st.ranks[k],
        )
        rows = []
        for j in range(su.nb):
            for grp in (cool, heat):
                for a, b in zip(grp[1:], grp[:-1], strict=False):
                    rows.append((1.0, pos[(j, a)] + a * self.P, -1.0, pos[(j, b)] + b * self.P))
            if cool and heat:
                rows.append(
                    (
                        1.0,
                        pos[(j, cool[0])] + cool[0] * self.P,
                        1.0,
                        pos[(j, heat[0])] + heat[0] * self.P,
                    )
                )
        self.level_rows = np.array(rows, float)  # (sign_a, flat index a, sign_b, flat index b)
        # hard rows that do not change: chamber limits at segment ends, crossing order
        L = np.tril(np.ones((self.nu, self.nu))) * su.seg
        Z = np.zeros((self.nu, self.nx))
        Z[:, : self.nu] = L
        ch_hi, ch_lo = Z, -Z
        order = []
        for k in range(self.S):
            for p in range(self.P - 1):
                order.append((self.it + k * self.P + p, self.it + k * self.P + p + 1, -0.3))
            if k + 1 < self.S:
                order.append((self.it + k * self.P + self.P - 1, self.it + (k + 1) * self.P, -2.0))
        order.append((self.it + self.nt - 1, self.iend, -2.0))
        rows_o = np.zeros((len(order), self.nx))
        for i, (a, b, _) in enumerate(order):
            rows_o[i, a], rows_o[i, b] = 1.0, -1.0
        self.A_fixed = np.vstack([ch_hi, ch_lo, rows_o])
        self.b_fixed = np.concatenate(
            [
                np.full(self.nu, lim.chamber_max_c - lim.start_c),
                np.full(self.nu, -(lim.chamber_min_c - lim.start_c)),
                [o[2] for o in order],
            ]
        )
        td = np.arange(1.0, self.nu * su.seg, 2.0)
        rd = self.resp(td)
        Ad = np.zeros((td.size, self.nx))
        Ad[:, : self.nu] = rd.a_t
        self.dev_rows = (self.A_fixed.shape[0], self.A_fixed.shape[0] + 2 * td.size)
        self.A_dev = np.vstack([Ad, -Ad])
        self.b_dev = np.concatenate(
            [lim.device_max_c - 0.1 - rd.b_t, -(lim.device_min_c + 0.1 - rd.b_t)]
        )
        self.A_fixed = np.vstack([self.A_fixed, self.A_dev])
        self.b_fixed = np.concatenate([self.b_fixed, self.b_dev])
        self.A_fixed = sp.csr_matrix(self.A_fixed)
        self.t_fine = np.arange(0.0, self.nu * su.seg, 0.1)
        r_fine = self.resp(self.t_fine)  # only T is needed on the fine grid (memory)
        self.fine_a_t, self.fine_b_t = r_fine.a_t, r_fine.b_t

    def resp(self, times):
        lim = self.su.limits
        return affine_response(
            self.su.model, self.dur, np.asarray(times, float), lim.start_c, lim.t_init_c
        )

    # -- exact violations ---------------------------------------------------------
    def _speeds(self, t):
        lr = self.level_rows
        ia, ib = lr[:, 1].astype(int), lr[:, 3].astype(int)
        sa = 1.0 / np.maximum(t[ia + 1] - t[ia], 1e-6)
        sb = 1.0 / np.maximum(t[ib + 1] - t[ib], 1e-6)
        return lr[:, 0] * sa + lr[:, 2] * sb

    def mono_samples(self, tt, ext):
        ks, ts = [], []
        for k in range(self.S):
            x = np.arange(tt[k, 0] - ext, tt[k, -1] + ext + 1e-9, 0.5)
            ks.append(np.full(x.size, k))
            ts.append(x)
        return np.concatenate(ks), np.concatenate(ts)

    def turn_intervals(self, tt):
        su = self.su
        d0 = self.st.dirs[0]
        out = [(su.hi if d0 < 0 else su.lo, -d0, 0.0, tt[0, 0], False)]
        for k in range(self.S - 1):
            d = self.st.dirs[k]
            out.append((su.lo if d < 0 else su.hi, d, tt[k, -1], tt[k + 1, 0], True))
        return out

    def evaluate(self, x):
        su, lim = self.su, self.su.limits
        u, t, t_end = x[: self.nu], x[self.it : self.iend], x[self.iend]
        tt = t.reshape(self.S, self.P)
        T, _, _ = self.resp(t).evaluate(u)
        cross = np.abs(T - self.B.ravel())
        lev = np.maximum(0.0, su.sep - self._speeds(t))
        ks, tm = self.mono_samples(tt, 0.0)
        dm = np.array(self.st.dirs, float)[ks]
        _, gm, _ = self.resp(tm).evaluate(u)
        mono = np.maximum(0.0, MONO_EPS - dm * gm)
        turn, outside = [], []
        Tf = self.fine_a_t @ u + self.fine_b_t
        for edge, db, a, b, between in self.turn_intervals(tt):
            m = (self.t_fine >= a) & (self.t_fine < b)
            if not m.any():
                turn.append(su.depth)
                continue
            beyond = db * (Tf[m] - edge)
            turn.append(max(0.0, su.depth - beyond.max()))
            if between:
                inner = (self.t_fine[m] > a + 0.3) & (self.t_fine[m] < b - 0.3)
                outside.append(float(np.maximum(0.0, -beyond[inner]).sum()) * 0.4)
        _, _, tke = self.resp([t_end]).evaluate(u)
        end = max(0.0, abs(tke[0] - lim.end_c) - (lim.end_tol_c - self.end_margin))
        # beyond the device limits (less 0.1 degC) at the LP's device samples: the LP keeps
        # these rows hard only where the iterate is inside, so a start that overshoots
        # (the tracked start at a device limit 0.3 degC past the edge: 45.0 against 44.3)
        # must be steered back by the merit, or the SLP converges outside and every
        # rounded table fails the check
        device = np.maximum(0.0, self.A_dev[:, : self.nu] @ u - self.b_dev)
        return dict(
            cross=cross,
            level=lev,
            mono=mono,
            turn=np.array(turn),
            outside=np.array(outside),
            end=np.array([end]),
            device=device,
        )

    def merit(self, x):
        v = self.evaluate(x)
        pen = sum(self.weights[k] * float(np.sum(v[k])) for k in v)
        pen += self.l1 * float(np.abs(np.diff(x[: self.nu])).sum())
        return x[self.iend] + pen, v

    def project(self, x):
        """The timetable replaced by the trajectory's actual crossings (None if missing)."""
        u = x[: self.nu]
        T = self.fine_a_t @ u + self.fine_b_t
        tt = crossings(self.su, self.st, self.t_fine, T)
        if tt is None:
            return None
        for _ in range(2):
            Tc, gc, _ = self.resp(tt.ravel()).evaluate(u)
            gs = np.where(np.abs(gc) > 1e-4, gc, np.where(gc >= 0, 1e-4, -1e-4))
            tt = tt - np.clip((Tc - self.B.ravel()) / gs, -0.1, 0.1).reshape(tt.shape)
        y = x.copy()
        y[self.it : self.iend] = tt.ravel()
        return y

    # -- one LP ---------------------------------------------------------------------
    def lp(self, x0, rho_t, rho_u):
        su, lim, nx, nu = self.su, self.su.limits, self.nx, self.nu
        u0, t0, te0 = x0[:nu], x0[self.it : self.iend], x0[self.iend]
        tt0 = t0.reshape(self.S, self.P)
        W = self.weights
        blocks, rhs, pen = [], [], []

        def soft(A, b, w):
            A = np.atleast_2d(A)
            blocks.append(A)
            rhs.append(np.atleast_1d(b))
            pen.append(np.full(A.shape[0], w))

        # crossings |T_lin - B| <= s
        r = self.resp(t0)
        _, g0, _ = r.evaluate(u0)
        A = np.zeros((self.nt, nx))
        A[:, :nu] = r.a_t
        A[np.arange(self.nt), self.it + np.arange(self.nt)] = g0
        const = r.b_t - g0 * t0
        B = self.B.ravel()
        soft(A, B - const, W["cross"])
        soft(-A, -(B - const), W["cross"])
        # levels: 1/D ~ 2/D0 - D/D0^2
        lr = self.level_rows
        A = np.zeros((lr.shape[0], nx))
        const = np.zeros(lr.shape[0])
        for col_s, col_i in ((0, 1), (2, 3)):
            sgn, idx = lr[:, col_s], lr[:, col_i].astype(int)
            D0 = np.maximum(t0[idx + 1] - t0[idx], 0.05)
            const += sgn * 2.0 / D0
            rows = np.arange(lr.shape[0])
            np.add.at(A, (rows, self.it + idx + 1), -sgn / D0**2)
            np.add.at(A, (rows, self.it + idx), sgn / D0**2)
        soft(-A, const - su.sep - LP_EXTRA_C_PER_MIN, W["level"])
        # monotone sweeps
        ks, tm = self.mono_samples(tt0, min(rho_t, 1.0))
        rm = self.resp(tm)
        dm = np.array(self.st.dirs, float)[ks]
        A = np.zeros((tm.size, nx))
        A[:, :nu] = -dm[:, None] * rm.a_g
        soft(A, dm * rm.b_g - MONO_EPS, W["mono"])
        # turns: depth at the current extreme, outside elsewhere
        for edge, db, a, b, between in self.turn_intervals(tt0):
            ts = np.arange(a, b, 0.25)
            if ts.size == 0:
                ts = np.array([0.5 * (a + b)])
            rt = self.resp(ts)
            T, _, _ = rt.evaluate(u0)
            i = int(np.argmax(db * (T - edge)))
            row = np.zeros(nx)
            row[:nu] = -db * rt.a_t[i]
            soft(row, db * (rt.b_t[i] - edge) - su.depth, W["turn"])
            if between:
                inner = np.flatnonzero((ts > a + rho_t + 0.3) & (ts < b - rho_t - 0.3))[::2]
                if inner.size:
                    A = np.zeros((inner.size, nx))
                    A[:, :nu] = -db * rt.a_t[inner]
                    soft(A, db * (rt.b_t[inner] - edge), W["outside"])
        # end: chamber within end_tol - margin of end_c
        re = self.resp([te0])
        seg_i = min(int(te0 // su.seg), nu - 1)
        row = np.zeros(nx)
        row[:nu] = re.a_tk[0]
        row[self.iend] = u0[seg_i]
        const = re.b_tk[0] - u0[seg_i] * te0
        # the LP asks a little more than the merit: the linearisation in t_end is rough
        # where the end time crosses a segment boundary
        tol = lim.end_tol_c - self.end_margin - END_EXTRA_C * lim.end_tol_c
        soft(row, lim.end_c + tol - const, W["end"])
        soft(-row, -(lim.end_c - tol - const), W["end"])
        # device limits: soft at the limit (the hard rows below stop at the iterate)
        A = np.zeros((self.A_dev.shape[0], nx))
        A[:, :nu] = self.A_dev[:, :nu]
        soft(A, self.b_dev, W["device"])
        # fewer steps: |u[j+1] - u[j]|
        A = np.zeros((nu - 1, nx))
        A[np.arange(nu - 1), np.arange(1, nu)] = 1.0
        A[np.arange(nu - 1), np.arange(nu - 1)] = -1.0
        soft(A, np.zeros(nu - 1), self.l1)
        soft(-A, np.zeros(nu - 1), self.l1)
        # assemble: soft rows with one slack each, then the hard rows
        As = sp.csr_matrix(np.vstack(blocks))
        ns = As.shape[0]
        A1 = sp.hstack([As, -sp.identity(ns, format="csr")])
        A2 = sp.hstack([self.A_fixed, sp.csr_matrix((self.A_fixed.shape[0], ns))])
        A = sp.vstack([A1, A2]).tocsc()
        # device limits: hard, but never tighter than where the iterate already is
        b_fixed = self.b_fixed.copy()
        a, z = self.dev_rows
        now = self.A_fixed[a:z, :nu] @ u0
        b_fixed[a:z] = np.maximum(b_fixed[a:z], now + 1e-6)
        b = np.concatenate(rhs + [b_fixed])
        c = np.zeros(nx + ns)
        c[self.iend] = 1.0
        c[nx:] = np.concatenate(pen)
        lb, ub = np.empty(nx), np.empty(nx)
        lb[:nu] = np.maximum(lim.rate_min_c_per_min, u0 - rho_u)
        ub[:nu] = np.minimum(lim.rate_max_c_per_min, u0 + rho_u)
        lb[self.it : self.iend] = t0 - rho_t
        ub[self.it : self.iend] = t0 + rho_t
        lb[self.iend] = te0 - rho_t
        ub[self.iend] = min(te0 + rho_t, nu * su.seg)
        bounds = np.concatenate([np.c_[lb, ub], np.c_[np.zeros(ns), np.full(ns, np.inf)]])
        self.n_lp += 1
        self.clock.lps += 1
        try:
            res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
        except ValueError:
            return None, None
        if res.status != 0:
            return None, None
        return res.x[:nx], res.fun


# -- rounding and checking ---------------------------------------------------------------
def _programme(su: _Setup, x, nu: int, end_min: int) -> Programme | None:
    """The iterate's rates cut at ``end_min`` (whole minutes), rounded like every plan."""
    lim = su.limits
    u = x[:nu]
    full = int(end_min // su.seg)
    d = [su.seg] * full
    r = list(u[:full])
    rest = end_min - full * su.seg
    if rest > 1e-9:
        d.append(rest)
        r.append(u[min(full, nu - 1)])
    try:
        prog = Programme(np.array(d, float), np.array(r), lim.start_c).rounded(lim)
    except (SchedsynError, ValueError):
        return None
    # the SLP ends anywhere within end_tol_c of end_c; the table says end_c itself
    # (fuzzing: a table ending at 20.1 degC); _verify checks the steered ramp
    return prog.ending_at(lim.end_c, lim)


def _verify(su: _Setup, prog: Programme) -> tuple[bool, CoverageReport | None]:
    spec, lim = su.spec, su.limits
    if prog.total_min > lim.duration_max_min + 1e-9:
        return False, None
    cov, _, problems, _, _ = check_programme(prog, spec, lim, [su.params], su.model)
    problems = list(problems) + step_limit_problems(prog, spec)
    return bool(cov.complete and not problems), cov


def min_separation(
    prog: Programme,
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    model: LinearThermalModel | None = None,
) -> float:
    """The worst bin's level separation of the table (simulated every 0.02 min), degC/min."""
    traj = simulate(prog, params, model=model, dt_min=FINE_CHECK_DT_MIN, t0_c=limits.t_init_c)
    bins, means, _, _ = passes(traj.t_c, traj.g_c_per_min, spec.grid)
    seps = [
        level_separation(means[bins == j], spec.levels_required) for j in range(spec.grid.n_bins)
    ]
    return float(np.nanmin(seps)) if np.any(np.isfinite(seps)) else float("nan")


# -- the search ----------------------------------------------------------------------------
def _refusal(spec: ExperimentSpec, params: ThermalParams, limits: Limits) -> str | None:
    try:
        check_request(spec, limits)
    except ParameterError as err:
        return str(err)
    if not LEVELS_RANGE[0] <= spec.levels_required <= LEVELS_RANGE[1]:
        return f"levels_required {spec.levels_required} outside {LEVELS_RANGE}"
    if spec.objective != "shortest":
        return f"objective {spec.objective!r}: the timetable stage plans the shortest only"
    if spec.max_steps < MIN_STEPS_PER_SWEEP * spec.levels_required + 1:
        # it does not plan a step limit, only checks it: below this every table it
        # found broke the limit and the search ran to the end of its LPs (45 s)
        return (
            f"max_steps {spec.max_steps} is below the {MIN_STEPS_PER_SWEEP} steps per sweep "
            f"and one more its {spec.levels_required} sweeps need "
            f"({MIN_STEPS_PER_SWEEP * spec.levels_required + 1}); it does not plan step limits"
        )
    n_seg = limits.duration_max_min / spec.segment_min
    if n_seg > 400:
        return f"{n_seg:.0f} segments: too many for the timetable LPs"
    bound = duration_lower_bound(spec, params, limits).lower_bound_min
    if bound > limits.duration_max_min:
        return (
            f"the proven lower bound {bound:.0f} min exceeds the budget "
            f"{limits.duration_max_min:g} min"
        )
    return None


#: The SLP says where it is at least this often on a long search, s.
HEARTBEAT_S = 20.0


def _slp(
    tp: _Timetable,
    x,
    stop_lps: float,
    on_better: Callable[[np.ndarray], None],
    max_iters: int = 400,
    rho_t: float = 3.0,
    rho_u: float = 0.5,
    say: Callable[[str], None] | None = None,
    label: str = "",
):
    m, v = tp.merit(x)
    stall = 0
    last_said = time.monotonic()
    for it in range(max_iters):
        if tp.clock.over(stop_lps):
            break
        if say is not None and time.monotonic() - last_said > HEARTBEAT_S:
            # a long SLP step was silent for minutes (red team: 5 min 16 s, 300 steps)
            last_said = time.monotonic()
            say(f"timetable: {label}: step {it}, {tp.n_lp} LPs, merit {m:.1f}")
        xn, pred = tp.lp(x, rho_t, rho_u)
        if xn is None:
            rho_t *= 0.5
            rho_u *= 0.5
            if rho_t < 0.01:
                break
            continue
        xp = tp.project(xn)
        if xp is None:
            rho_t *= 0.4
            rho_u *= 0.4
            if rho_t < 0.01:
                break
            continue
        mn, vn = tp.merit(xp)
        dpred = m - pred
        ratio = (m - mn) / dpred if dpred > 1e-9 else 0.0
        if mn < m:
            gain = m - mn
            x, m, v = xp, mn, vn
            stall = stall + 1 if gain < 0.05 else 0
            if ratio > 0.4:
                rho_t, rho_u = min(rho_t * 1.6, 6.0), min(rho_u * 1.6, 2.0)
            elif ratio < 0.1:
                rho_t, rho_u = rho_t * 0.5, rho_u * 0.5
            viol = sum(float(np.sum(vn[k])) for k in vn)
            if viol < 1e-3:
                on_better(x)
        else:
            rho_t, rho_u = rho_t * 0.4, rho_u * 0.4
            stall += 1
        if (rho_t < 0.01 and rho_u < 0.002) or stall >= 25:
            break
    return x, m, v


def timetable_search(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    *,
    model: LinearThermalModel | None = None,
    max_lps: int = MAX_LPS,
    deadline_s: float | None = None,
    first_found: bool = False,
    progress: Progress = None,
) -> TimetableResult | None:
    """A complete plan by the timetable SLP, or None when none was found within
    ``max_lps`` LP solves (and ``deadline_s`` wall seconds, if given). ``first_found``:
    stop at the first candidate that gives a complete plan (else once a plan is in hand
    and half the LPs are spent, keeping the shortest).

    Tries alternating structures (first direction from where the device starts relative
    to the region; both splits of an odd level count; slow ranks first, fast first, mixed)
    and two cruise-speed scalings, best start first, each from a tracking simulation of
    profiles derived from the physics. Returns the shortest verified plan found: the
    rounded step table, complete by :func:`~.check.check_programme`, within every limit,
    ``duration_max_min`` and the step limits. Refuses (None, at once) requests it does not
    handle: an invalid request, a level count outside ``LEVELS_RANGE``, an objective other
    than "shortest", more than 400 segments.
    """
    tic = time.monotonic()

    def say(msg: str) -> None:
        if progress is not None:
            progress(msg)

    try:
        why = _refusal(spec, params, limits)
        if why is not None:
            say(f"timetable: refused: {why}")
            return None
        deadline = None if deadline_s is None else tic + deadline_s
        clock = _Clock(max_lps=int(max_lps), deadline=deadline)
        ends: list[tuple[float, str, float]] = []
        found = _search(spec, params, limits, model, tic, clock, say, first_found, ends=ends)
        budget = limits.duration_max_min
        if found is not None or not ends or min(ends)[0] > budget + NEAR_MISS_MIN:
            return found
        end, order, scale = min(ends)
        say(
            f"timetable: near miss ({order} x{scale:g} ended at {end:.1f} min, budget "
            f"{budget:g}): again from its start with {NEAR_MISS_SAFETY_C_PER_MIN:g} °C/min "
            f"above delta instead of {SAFETY_C_PER_MIN:g}"
        )
        again = _Clock(max_lps=NEAR_MISS_LPS, deadline=deadline)
        found = _search(
            spec,
            params,
            limits,
            model,
            tic,
            again,
            say,
            first_found,
            NEAR_MISS_SAFETY_C_PER_MIN,
            only=(order, scale),
        )
        if found is None:
            return None
        return replace(found, n_lp=found.n_lp + clock.lps)
    except (
        ValueError,
        ArithmeticError,
        np.linalg.LinAlgError,
        SchedsynError,
        MemoryError,
    ) as err:  # a request it cannot handle: no plan rather than a crash
        say(f"timetable: gave up: {type(err).__name__}: {err}")
        return None


def _search(
    spec,
    params,
    limits,
    model,
    tic,
    clock: _Clock,
    say,
    first_found: bool = False,
    safety_c_per_min: float = SAFETY_C_PER_MIN,
    ends: list[tuple[float, str, float]] | None = None,
    only: tuple[str, float] | None = None,
) -> TimetableResult | None:
    """The search; ``ends`` (if given) receives every SLP's final end time (min), order
    and scale; ``only`` (order, scale) runs that start alone."""
    lp_stop = clock.max_lps
    model = FirstOrderLag(params) if model is None else model
    su = _Setup(
        spec,
        params,
        limits,
        model,
        spec.grid.edges_c.astype(float),
        spec.delta_c_per_min + safety_c_per_min,
        spec.edge_margin_c + DEPTH_PAD_C,
    )
    budget = limits.duration_max_min
    # candidates: structure x scaling, with their tracked start
    cands = []
    kinds: dict[_Structure, tuple[int, int]] = {}
    n_track = int(math.ceil(1.5 * budget / su.seg))
    t0 = limits.t_init_c

    def reach_min(first: int) -> float:  # time to get beyond the first sweep's entry edge
        if first < 0:
            return max(su.hi - t0, 0.0) / limits.rate_max_c_per_min
        return max(t0 - su.lo, 0.0) / -limits.rate_min_c_per_min

    firsts = sorted(first_directions(spec, limits), key=reach_min)
    L = spec.levels_required
    fit = {d: ranks_at_edges(su, d) for d in (-1, +1)}
    splits = []  # (ranked sweeps first direction, other), per first direction
    for first in firsts:
        even = ((L + 1) // 2, L // 2)
        options = [even] + ([(L // 2, (L + 1) // 2)] if L % 2 else [])
        ok = [s for s in options if s[0] <= fit[first] and s[1] <= fit[-first]]
        if not ok:  # a chamber limit caps one direction near an edge: shift levels over
            n_f = min(fit[first], L - 1)
            n_o = L - n_f
            if n_o > fit[-first]:
                n_o = min(fit[-first], L - 1)
                n_f = L - n_o
            ok = [(n_f, n_o)]
            # and one more level away from the capped direction: its ranks under the cap
            # closer to its slowest (red team q13: 8 levels, 3 heating ranks fit; 3/5 found
            # nothing, 2/6 is complete in 305 min)
            if fit[first] < fit[-first] and n_f > 1 and n_o + 1 <= fit[-first]:
                ok.append((n_f - 1, n_o + 1))
            elif fit[-first] < fit[first] and n_o > 1 and n_f + 1 <= fit[first]:
                ok.append((n_f + 1, n_o - 1))
            say(
                f"timetable: first {'heating' if first > 0 else 'cooling'}: the edge bins "
                f"hold {fit[-1]} cooling / {fit[1]} heating ranks: split "
                + " or ".join(f"{a}/{b}" for a, b in ok)
            )
        splits.append((first, ok))
    todo = [
        (st, (i_kind, i_first + i_split))
        for i_first, (first, ok) in enumerate(splits)
        for i_split, split in enumerate(ok)
        for i_kind, st in enumerate(structures(L, first, split))
    ]
    for st, kind in todo:
        kinds[st] = kind
        for scale in SCALINGS:
            if clock.over(lp_stop):
                break
            speeds = starting_speeds(su, st, scale)
            u, end_at = track(su, st, speeds, n_track)
            if end_at is None:
                say(f"timetable: {st.name} x{scale}: the tracked start does not finish")
                continue
            cands.append((st, scale, speeds, u, end_at))
    if not cands:
        return None
    starts = []
    for st, scale, speeds, u, end_at in cands:
        if clock.over(lp_stop):
            break
        n_seg = min(n_track, max(end_at + 12, int(math.ceil(1.1 * budget / su.seg))))
        n_seg = min(n_seg, int(math.ceil(1.25 * budget / su.seg)))
        uu = u[:n_seg].copy()
        tp = _Timetable(su, st, n_seg, clock)
        T = tp.fine_a_t @ uu + tp.fine_b_t
        tt = crossings(su, st, tp.t_fine, T)
        if tt is None:
            say(
                f"timetable: {st.name} x{scale}: the start misses crossings within "
                f"{n_seg * su.seg:.0f} min"
            )
            continue
        tk = limits.start_c + np.concatenate(([0.0], np.cumsum(uu * su.seg)))
        j = int(math.ceil(tt[-1, -1] / su.seg))
        while j < n_seg and abs(tk[j] - limits.end_c) > limits.end_tol_c - tp.end_margin:
            j += 1
        x0 = np.concatenate([uu, tt.ravel(), [min(j, n_seg) * su.seg]])
        m0, _ = tp.merit(x0)
        starts.append((m0, st, scale, speeds, n_seg, x0))  # tp rebuilt when run (memory)
        del tp
        say(f"timetable: start {st.name} x{scale}: end {x0[-1]:.0f} min, merit {m0:.0f}")
    # slow ranks first before the other orders, the quicker first direction first,
    # then the better start
    starts.sort(key=lambda s: (kinds[s[1]], s[0]))
    if only is not None:
        starts = [s for s in starts if (s[1].name, s[2]) == only]
    best: dict | None = None
    tried = []
    n_lp = 0
    for i, (_, st, scale, speeds, n_seg, x0) in enumerate(starts):
        now, wall = clock.lps, time.monotonic()
        if clock.over(lp_stop - 2):
            break
        tp = _Timetable(su, st, n_seg, clock)
        left = len(starts) - i
        room = lp_stop - now
        slice_lps = room if left == 1 else max(room * 0.6, room / left)
        c_stop = now + slice_lps
        state: dict[str, Any] = {"checked_end": np.inf, "found": None}

        def on_better(x, tp=tp, state=state):
            end = float(x[-1])
            if end > budget + 1.0 or end > state["checked_end"] - CHECK_EVERY_MIN:
                return
            state["checked_end"] = end
            # the end on whole minutes: the minute before the SLP's end time (the chamber
            # may already be within end_tol_c of end_c), else the one after
            for end_min in sorted({math.floor(end + 1e-6), math.ceil(end - 1e-6)}):
                if end_min < x[tp.iend - 1] + 1.0 or end_min > tp.nu * su.seg:
                    continue  # not after the last crossing, or past the horizon
                if state["found"] is not None and end_min >= state["found"][0].total_min:
                    break
                prog = _programme(su, x, tp.nu, end_min)
                if prog is None:
                    continue
                ok, cov = _verify(su, prog)
                if ok:
                    state["found"] = (prog, cov)
                    break

        say(f"timetable: SLP {st.name} x{scale} (up to {slice_lps:.0f} LPs)")
        name = f"SLP {st.name} x{scale}"
        x, m, v = _slp(tp, x0, c_stop, on_better, say=say, label=name)
        for _ in range(PENALTY_RAISES):  # stuck with violations left: weigh them more
            resid = sum(float(np.sum(v[k])) for k in v)
            if state["found"] is not None or resid < 1e-3 or float(x[-1]) > budget + 30.0:
                break
            if clock.over(c_stop - 1):
                break
            for k in tp.weights:
                tp.weights[k] *= 10.0
            say(
                f"timetable: {st.name} x{scale}: end {x[-1]:.1f} min, violations "
                f"{resid:.3g}: penalties x10"
            )
            x, m, v = _slp(tp, x, c_stop, on_better, rho_t=1.0, rho_u=0.2, say=say, label=name)
        for weight in L1_LOWER:  # converged just over the budget: trade steps for minutes
            if state["found"] is not None or float(x[-1]) > budget + 15.0:
                break
            if clock.over(c_stop - 1):
                break
            tp.l1 = weight
            say(f"timetable: {st.name} x{scale}: end {x[-1]:.1f} min, l1 weight {weight:g}")
            x, m, v = _slp(tp, x, c_stop, on_better, rho_t=1.0, rho_u=0.2, say=say, label=name)
        if state["found"] is None or float(x[-1]) < state["found"][0].total_min - 0.5:
            state["checked_end"] = np.inf
            on_better(x)
        n_lp += tp.n_lp
        if ends is not None:
            ends.append((float(x[-1]), st.name, scale))
        found = state["found"]
        row = dict(
            order=st.name,
            scale=scale,
            speeds=[tuple(round(s, 3) for s in sp_) for sp_ in speeds],
            start_end_min=float(x0[-1]),
            end_min=float(x[-1]),
            lps=tp.n_lp,
            seconds=round(time.monotonic() - wall, 1),
            found_min=None if found is None else found[0].total_min,
        )
        tried.append(row)
        what = f"complete {found[0].total_min:g} min" if found else "no complete plan"
        say(f"timetable: {st.name} x{scale}: end {x[-1]:.1f} min after {tp.n_lp} LPs, {what}")
        if found is not None and (best is None or found[0].total_min < best["prog"].total_min):
            best = dict(prog=found[0], cov=found[1], st=st, scale=scale, speeds=speeds)
        if best is not None and (first_found or clock.over(0.5 * lp_stop)):
            break  # a plan in hand (and half the LPs spent): stop here
    if best is None:
        return None
    prog = best["prog"]
    return TimetableResult(
        programme=prog,
        coverage=best["cov"],
        order=best["st"].name,
        scale=best["scale"],
        speeds=tuple((float(e), float(c), float(f)) for e, c, f in best["speeds"]),
        min_separation_c_per_min=min_separation(prog, spec, params, limits, model),
        n_lp=n_lp,
        seconds=time.monotonic() - tic,
        tried=tuple(tried),
        safety_c_per_min=safety_c_per_min,
    )
