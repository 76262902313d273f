"""Stage 4: the linear programmes -- constraint rows from the affine responses, and solving.

Decision variables are the ramp rates ``u_j`` of fixed-length segments. By
:func:`schedsyn.model.affine_response` the internal temperature ``T_i``, gradient ``g_i``
and chamber ``Tk`` at every planner sample are affine in ``u`` (``x = A u + b``), so every
requirement is a row of ``G @ [u, extra] <= h`` or ``E @ [u, extra] == f``, built in numpy
(fast to assemble, easy to audit):

* chamber within its limits at every segment end (Tk is piecewise linear);
* device within its limits at every sample;
* inside a sweep's window, the direction-signed gradient ``q = d g`` within the sweep's
  band, one affine piece per stretch between the knots the sweep crosses at planned
  samples (so ``lo(T_i)`` is affine in ``u`` too); beyond the edges at the window's ends.

The search solves hundreds of small probes straight with Clarabel (cvxpy's compile step
cost more than the solve), falling back to HiGHS when Clarabel fails numerically; the
whole-programme LPs go through cvxpy. Every outcome is counted in :class:`LpStats`, so a
solver failure is never mistaken for infeasibility.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np

from ..errors import SolverFailedError
from ..model import affine_response
from ..params import Limits
from .bands import Band
from .request import Continuation, ExperimentSpec, Scenario

#: Planner samples every minute (segment boundaries are whole minutes).
SAMPLE_MIN = 1.0
#: A sweep crosses an inner knot at a planned sample within +- this plus half the
#: distance its band's top speed covers in one sample, degC.
KNOT_TOL_C = 0.25
#: Robust plans: how far outside its band a scenario other than the reference (box
#: centre) may pass, degC/min; the bands are spaced by twice this more than delta.
ROBUST_SLACK_C_PER_MIN = 0.05

#: Clarabel's settings beyond its defaults, for every LP (directly and through cvxpy): its
#: KKT systems factorised by qdldl, single-threaded. Its default ("auto") chose the
#: multi-threaded faer for the whole-programme LPs, which took 3-4x longer on a 2-core
#: machine (``scripts/bench_lp.py``), and threads would fight the campaign's processes.
#: Its presolve only drops rows with an infinite right-hand side, which these LPs never
#: have: off, the answers are bit for bit the same and a probe ~10 % faster.
CLARABEL_SETTINGS: dict[str, Any] = {"direct_solve_method": "qdldl", "presolve_enable": False}
#: Clarabel's answers, by what they mean for the planner.
_CLARABEL_OK = {"Solved": "optimal", "AlmostSolved": "inaccurate"}
_CLARABEL_INFEASIBLE = ("PrimalInfeasible", "AlmostPrimalInfeasible")
#: How many solver-failure messages a plan keeps (the count is kept in full).
MAX_FAILURE_MESSAGES = 5

#: Constraint-matrix nonzeros of the LPs solved so far, per thread (a plan runs in one).
_work = threading.local()


def lp_nonzeros_solved() -> int:
    """Constraint-matrix nonzeros of every LP this thread has solved so far.

    The planner's measure of search effort (:class:`schedsyn.planner.core._Effort`): it
    counts work rather than time, so where an effort limit cuts a search does not depend
    on the machine's speed or on what else shares its cores. It tracks CPU time closely
    (each LP's solve costs in proportion to its nonzeros, and the LPs dominate a search).
    """
    return int(getattr(_work, "nonzeros", 0))


def count_work(nonzeros: int) -> None:
    _work.nonzeros = lp_nonzeros_solved() + int(nonzeros)


@contextlib.contextmanager
def quiet_stdout_fd() -> Iterator[None]:
    """Send file descriptor 1 to the null device for the duration (Python's and C's output).

    HiGHS (through highspy) prints its banner from C++ the first time a process uses it,
    whatever its output options; the planner's output must stay the progress lines the
    user asked for (``--quiet`` means quiet).
    """
    try:
        sys.stdout.flush()
    except (AttributeError, OSError, ValueError):
        pass
    try:
        saved = os.dup(1)
    except OSError:  # no stdout at all
        yield
        return
    try:
        with open(os.devnull, "w", encoding="utf-8") as null:
            os.dup2(null.fileno(), 1)
            try:
                yield
            finally:
                os.dup2(saved, 1)
    finally:
        os.close(saved)


@dataclass(slots=True)
class LpStats:
    """What the LP solves of one plan did: counts by outcome and time spent.

    ``optimal``/``inaccurate``: solved (an inaccurate answer is used: every plan is
    checked by dense re-simulation of its exported table afterwards); ``infeasible``: the
    solver proved the LP has no solution; ``failed``: every solver tried gave up
    (numerical trouble, iteration limit) -- not evidence of infeasibility.
    """

    solves: int = 0
    seconds: float = 0.0
    optimal: int = 0
    inaccurate: int = 0
    infeasible: int = 0
    #: of the infeasible: proven by one row and the rate bounds, without a solver
    infeasible_by_bounds: int = 0
    #: sweep placements answered from an earlier identical placement (the slow retry
    #: re-places the sweeps before the one that got stuck): no LP solved for them
    sweeps_reused: int = 0
    failed: int = 0
    fallbacks: int = 0
    messages: list[str] = field(default_factory=list)

    def record(self, outcome: str, seconds: float, message: str | None = None) -> None:
        self.solves += 1
        self.seconds += seconds
        setattr(self, outcome, getattr(self, outcome) + 1)
        if message and len(self.messages) < MAX_FAILURE_MESSAGES:
            self.messages.append(message)

    def to_dict(self) -> dict[str, Any]:
        return {
            "lp_solves": self.solves,
            "optimal": self.optimal,
            "inaccurate": self.inaccurate,
            "infeasible": self.infeasible,
            "infeasible_by_bounds": self.infeasible_by_bounds,
            "sweeps_reused": self.sweeps_reused,
            "solver_failures": self.failed,
            "highs_fallbacks": self.fallbacks,
            "lp_seconds": round(self.seconds, 3),
            "failure_messages": list(self.messages),
        }


class Responses:
    """Affine responses of all scenarios at the planner samples of the whole segment grid.

    The grid is ``n_seg`` segments of ``seg_min`` from t = 0, or, continuing a run, the
    executed steps (fixed, any lengths) followed by segments of ``seg_min``; samples every
    ``SAMPLE_MIN`` minute from t = 0. A continuation's ``start_correction_c`` (measured
    minus modelled T at the end of the executed steps, ``M``) is added to the free response
    from ``M`` on as ``c exp(-(t - M)/tau)`` (and ``-c/tau exp(..)`` to g): the decay of an
    initial offset through the first-order lag (``tau`` of each scenario; for augmented
    models that is their first-order equivalent).
    """

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        n_seg: int,
        seg_min: float,
        limits: Limits,
        continuation: Continuation | None = None,
    ):
        self.seg_min = seg_min
        self.scenarios = list(scenarios)
        prefix = continuation.prefix if continuation is not None else None
        fixed = prefix.durations_min if prefix is not None else np.zeros(0)
        #: segments of the executed steps (their rates are fixed)
        self.n_fixed = int(fixed.size)
        self.fixed_rates = prefix.rates_c_per_min if prefix is not None else np.zeros(0)
        self.durations = np.concatenate((fixed, np.full(n_seg - fixed.size, float(seg_min))))
        self.edges_min = np.concatenate(([0.0], np.cumsum(self.durations)))
        self.times = np.arange(0.0, self.edges_min[-1] + 0.5 * SAMPLE_MIN, SAMPLE_MIN)
        t0 = limits.t_init_c
        if continuation is not None and continuation.t0_c is not None:
            t0 = continuation.t0_c
        self._start_c, self._t0_c, self._continuation = limits.start_c, t0, continuation
        self.resp = [self._response(s, self.times) for s in scenarios]
        #: T rows at times between the samples, by (scenario, time): see :meth:`t_rows_at`
        self._t_rows: dict[tuple[int, float], tuple[np.ndarray, float]] = {}

    def _response(self, scenario: Scenario, times: np.ndarray):
        resp = affine_response(scenario.model, self.durations, times, self._start_c, self._t0_c)
        cont = self._continuation
        if cont is not None and cont.start_correction_c:
            at, tau = cont.at_min, scenario.params.tau_min
            decay = np.where(times >= at, np.exp(-np.maximum(times - at, 0.0) / tau), 0.0)
            c = cont.start_correction_c
            resp.b_t[:] = resp.b_t + c * decay
            resp.b_g[:] = resp.b_g - c / tau * decay
        return resp

    def t_rows_at(self, scenario: int, times_min: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """``(a_t, b_t)``: T at any times (between the planner samples too), affine in the
        rates of every segment of the grid, exactly as at the samples (cached by time)."""
        missing = [t for t in times_min if (scenario, float(t)) not in self._t_rows]
        if missing and len(self._t_rows) + len(missing) > T_ROWS_CACHE_MAX:
            self._t_rows.clear()  # a long pinned search asks for many times: bounded memory
            missing = list(times_min)  # the ones that were kept are gone too
        if missing:
            resp = self._response(self.scenarios[scenario], np.asarray(missing, dtype=float))
            for i, t in enumerate(missing):
                self._t_rows[(scenario, float(t))] = (resp.a_t[i], float(resp.b_t[i]))
        rows = [self._t_rows[(scenario, float(t))] for t in times_min]
        return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])

    def sample_of(self, j_boundary: int) -> int:
        """Planner sample index at the boundary before segment ``j_boundary``."""
        return int(round(self.edges_min[j_boundary] / SAMPLE_MIN))

    def segments_to(self, sample: int) -> int:
        """Fewest segments from t = 0 that reach planner sample ``sample``."""
        return int(np.searchsorted(self.edges_min, sample * SAMPLE_MIN - 1e-9, side="left"))

    def max_segments(self, duration_max_min: float) -> int:
        """Segments of the grid that fit in ``duration_max_min`` from t = 0."""
        fixed_end = self.edges_min[self.n_fixed]
        return self.n_fixed + int((duration_max_min - fixed_end + 1e-9) // self.seg_min)


#: Rows of T between the samples kept by :meth:`Responses.t_rows_at` (a row per time
#: holds every segment's coefficient: 20,000 rows of a 12-h grid of 3-min segments take
#: about 50 MB).
T_ROWS_CACHE_MAX = 20_000
#: Pinned edge bins: a crossing of a bin's boundary is pinned to within this, min.
PIN_MIN = 0.1
#: Pinned edge bins: a sweep ends at least this far beyond the region's edge, degC (its
#: pass of the edge bin must end before the next sweep's begins).
PIN_EXIT_C = 0.05
#: Pinned edge bins: the crossing times are kept this much inside the band's, min. None
#: needed: the bands' safety gap (``BAND_SAFETY_C_PER_MIN``) already covers counting a
#: pass's mean gradient on samples 0.1 min apart.
PIN_TIME_SAFETY_MIN = 0.0


@dataclass(frozen=True, slots=True)
class EdgePins:
    """A sweep's two edge bins held by their crossing times (issue 12).

    Held pointwise to its band, a sweep must enter and leave the region at band speed and
    turn round outside it. Held by crossing times, it may speed up inside the entry bin
    and brake inside the exit bin, as long as it crosses each within ``[min, max]``
    minutes -- its mean gradient there, the level the bin is counted at, stays within the
    band: it enters the entry bin within ``[entry_min, entry_min + PIN_MIN]`` and leaves
    it within ``[entry_min + PIN_MIN + entry_min_min, entry_min + entry_max_min]``; the
    same for the exit bin from ``exit_min``. Every time is in minutes from t = 0.
    """

    entry_min: float
    entry_min_min: float
    entry_max_min: float
    exit_min: float
    exit_min_min: float
    exit_max_min: float

    @property
    def end_min(self) -> float:
        """Latest time the sweep leaves its exit bin."""
        return self.exit_min + self.exit_max_min


@dataclass(slots=True)
class Window:
    """Sweep ``direction`` owns planner samples ``start_sample .. end_sample``.

    ``cut_samples`` are the samples at which it crosses the band's inner knots, in travel
    order (sample indices, not seconds: sample ``i`` is at ``i * SAMPLE_MIN`` minutes).
    """

    direction: int
    band: Band
    start_sample: int
    end_sample: int
    cut_samples: tuple[int, ...] = ()
    #: robust plans: ``(start, end, cuts)`` samples for each scenario (the scenarios lag
    #: one another, so each crosses the edges and knots at its own samples); None: shared
    per_scenario: tuple[tuple[int, int, tuple[int, ...]], ...] | None = None
    #: robust plans: knot tolerance (degC) of each scenario's cuts; a scenario that is
    #: not the reference crosses a knot between two samples wherever it happens to
    knot_tol_c: tuple[tuple[float, ...], ...] | None = None
    #: edge bins held by their crossing times (:class:`EdgePins`) instead of pointwise
    pins: EdgePins | None = None

    def banded_range(self, scenario: int = 0) -> tuple[int, int]:
        """First and last sample held pointwise to the band (all of the window, unless
        its edge bins are pinned: then from the entry bin's latest exit to the exit
        bin's earliest entry)."""
        start, end, _ = self.bounds_of(scenario)
        if self.pins is None:
            return start, end
        p = self.pins
        return int(math.ceil(p.entry_min + p.entry_max_min - 1e-9)), int(
            math.floor(p.exit_min + 1e-9)
        )

    def bounds_of(self, scenario: int) -> tuple[int, int, tuple[int, ...]]:
        if self.per_scenario is None:
            return self.start_sample, self.end_sample, self.cut_samples
        return self.per_scenario[scenario]

    def pieces(self, scenario: int = 0):
        """``(first_sample, last_sample, piece_index, knot_at_last_or_None)`` in travel order."""
        n_piece = len(self.band.knots_c) - 1
        order = list(range(n_piece)) if self.direction > 0 else list(range(n_piece))[::-1]
        first, last = self.banded_range(scenario)
        bounds = [first, *self.bounds_of(scenario)[2], last]
        out = []
        for j, pi in enumerate(order):
            knot = None
            if j < n_piece - 1:
                knot = self.band.knots_c[pi + 1] if self.direction > 0 else self.band.knots_c[pi]
            out.append((bounds[j], bounds[j + 1], pi, knot))
        return out


class Context:
    """Shared state of one synthesis: spec, limits, responses and the LP statistics.

    ``device_margin_c`` tightens the device limits in the LPs (a re-polish uses it when
    rounding the step table for the operator pushed the device a hair past a limit; see
    :meth:`tightened`).
    """

    def __init__(
        self,
        spec: ExperimentSpec,
        limits: Limits,
        responses: Responses,
        stats: LpStats,
        device_margin_c: float = 0.0,
        robust_slack_c_per_min: float = ROBUST_SLACK_C_PER_MIN,
    ):
        self.spec, self.limits, self.responses, self.stats = spec, limits, responses, stats
        self.device_margin_c = device_margin_c
        #: robust: how far outside a band the scenarios other than the reference may stray
        self.robust_slack_c_per_min = robust_slack_c_per_min
        ref = responses.scenarios[0].params
        self.offsets_c = [sc.params.dt0_c - ref.dt0_c for sc in responses.scenarios]
        self.size = {"variables": 0, "constraints": 0}
        #: placements of single sweeps already searched (see :func:`.search.greedy`)
        self.sweep_memo: dict[tuple, tuple[Any, int]] = {}
        #: where the search is, for :attr:`beat` (set by :func:`.search.synthesise`)
        self.where = ""
        #: ``beat(text)``: a progress line saying the search is still at work, when the
        #: last one is long ago (:class:`.search.Heartbeat`); None without progress
        self.beat: Callable[[Callable[[], str]], None] | None = None

    @property
    def robust(self) -> bool:
        return len(self.responses.resp) > 1

    def tightened(self, device_margin_c: float) -> Context:
        """The same synthesis with the device limits tightened by ``device_margin_c``."""
        return Context(
            self.spec,
            self.limits,
            self.responses,
            self.stats,
            device_margin_c,
            self.robust_slack_c_per_min,
        )

    def solve_cvxpy(self, problem: cp.Problem) -> bool:
        """Solve an LP with Clarabel, HiGHS if Clarabel fails; True when solved.

        An ``optimal_inaccurate`` answer is accepted (and counted): every plan is verified
        afterwards by dense re-simulation of its exported step table, so a slightly
        inaccurate LP can never make a plan look better than it is.
        """
        tic = time.perf_counter()
        status, message = None, None
        for solver in (cp.CLARABEL, cp.HIGHS):
            try:
                quiet = quiet_stdout_fd() if solver == cp.HIGHS else contextlib.nullcontext()
                with warnings.catch_warnings(), quiet:
                    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
                    opts = CLARABEL_SETTINGS if solver == cp.CLARABEL else {}
                    problem.solve(solver=solver, **opts)
                status = problem.status
            except cp.error.SolverError as exc:
                status, message = None, f"{solver}: {exc}"
            if status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE, cp.INFEASIBLE):
                break
            if solver == cp.CLARABEL:
                self.stats.fallbacks += 1
        seconds = time.perf_counter() - tic
        if status == cp.OPTIMAL:
            self.stats.record("optimal", seconds)
        elif status == cp.OPTIMAL_INACCURATE:
            self.stats.record("inaccurate", seconds)
        elif status in (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE):
            self.stats.record("infeasible", seconds)
        else:
            self.stats.record("failed", seconds, message or f"LP status {status}")
        return status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


#: A row proves an LP infeasible when its least value over the rate bounds exceeds its
#: right-hand side by more than this, relative to ``max(1, |rhs|)`` (the solvers' own
#: feasibility tolerance is 1e-8).
BOUNDS_INFEASIBLE_TOL = 1e-6


def bounds_prove_infeasible(
    a: np.ndarray, b: np.ndarray, n_eq: int, n_rates: int, limits: Limits
) -> bool:
    """True when one row of ``A[:n_eq] x = b``, ``A[n_eq:] x <= b`` cannot hold for any
    rates within the chamber's rate limits (the first ``n_rates`` columns; the others
    are free).

    A necessary condition only, so it proves infeasibility, never feasibility: a knot the
    device cannot reach in time even at full rate, the bulk of the probes that scan a
    transition's length, is caught without a solver.
    """
    rates = a[:, :n_rates]
    up, down = np.maximum(rates, 0.0).sum(axis=1), np.minimum(rates, 0.0).sum(axis=1)
    lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
    least, most = lo * up + hi * down, hi * up + lo * down
    tol = BOUNDS_INFEASIBLE_TOL * np.maximum(1.0, np.abs(b))
    over = least - b > tol
    over[:n_eq] |= b[:n_eq] - most[:n_eq] > tol[:n_eq]
    if a.shape[1] > n_rates:  # a row with a free column can take any value
        over &= ~np.any(a[:, n_rates:] != 0.0, axis=1)
    return bool(over.any())


def dense_to_csc(a: np.ndarray):
    """``scipy.sparse.csc_matrix(a)`` for a dense ``a``, the same arrays, ~3x faster (the
    generic constructor goes through COO; a probe's matrix has hundreds of rows)."""
    from scipy import sparse

    at = a.T
    nz = at != 0.0
    _, rows = np.nonzero(nz)  # row-major over a.T: column by column of a
    indptr = np.concatenate(([0], np.cumsum(nz.sum(axis=1))))
    return sparse.csc_matrix(
        (at[nz], rows.astype(np.int32), indptr.astype(np.int32)), shape=a.shape
    )


class SubLP:
    """An LP over the rates of segments ``[j0, j1)``, earlier rates fixed.

    Columns: the ``j1 - j0`` free rates, then ``extra`` scalar variables (margins, an
    epigraph variable). Rows are accumulated as ``G @ x <= h`` and ``E @ x == f``.
    """

    def __init__(
        self,
        ctx: Context,
        u_fixed: np.ndarray,
        j1: int,
        extra: int = 0,
        scenarios: Sequence[int] | None = None,
    ):
        r = ctx.responses
        self.ctx = ctx
        self.j0 = int(u_fixed.size)
        self.j1 = int(j1)
        self.u_fixed = np.asarray(u_fixed, dtype=float)
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
        # Tk at the segment ends: start + sum of duration x rate (the free segments' part
        # is tk_mat @ u)
        self.tk0 = ctx.limits.start_c + float(r.durations[: self.j0] @ u_fixed)
        self.tk_mat = np.tril(np.ones((self.n, self.n))) * r.durations[self.j0 : j1][None, :]
        # row blocks ``(sign, m, rhs, extra_cols)``: ``sign * m @ u + extra <= sign * rhs``
        # (equalities: ``m @ u == rhs``), kept as given and written once into the LP's
        # matrix by :meth:`_rows`: padding each block on arrival and stacking the padded
        # copies cost more than the bounds check that ends most probes
        self._g: list[tuple[float, np.ndarray, Any, dict[int, float] | None]] = []
        self._e: list[tuple[float, np.ndarray, Any, dict[int, float] | None]] = []
        self.last_size = {"variables": 0, "constraints": 0}

    def le(self, m, rhs, extra_cols=None) -> None:
        """``m @ u + sum(extra) <= rhs``."""
        self._g.append((1.0, np.atleast_2d(m), rhs, extra_cols))

    def ge(self, m, rhs, extra_cols=None) -> None:
        """``m @ u - sum(extra) >= rhs`` written as ``-m @ u + extra <= -rhs``."""
        self._g.append((-1.0, np.atleast_2d(m), rhs, extra_cols))

    def eq(self, m, rhs) -> None:
        self._e.append((1.0, np.atleast_2d(m), rhs, None))

    def _rows(self, blocks, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The blocks as ``(A, b)``, ``A`` with the ``n + extra`` columns (into ``out``'s
        first rows when given)."""
        n_rows = sum(m.shape[0] for _, m, _, _ in blocks)
        a = np.zeros((n_rows, self.n + self.extra)) if out is None else out[:n_rows]
        b = np.empty(n_rows)
        r = 0
        for sign, m, rhs, extra_cols in blocks:
            k = m.shape[0]
            if sign > 0:
                a[r : r + k, : self.n] = m
                b[r : r + k] = rhs
            else:
                np.negative(m, out=a[r : r + k, : self.n])
                b[r : r + k] = -np.asarray(rhs, dtype=float)
            for j, coef in (extra_cols or {}).items():
                a[r : r + k, self.n + j] = coef
            r += k
        return a, b

    # -- constraint families -------------------------------------------------------
    def chamber(self) -> None:
        """Chamber air within its limits at every segment end (Tk is piecewise linear)."""
        lim = self.ctx.limits
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
        lim = self.ctx.limits
        pad = self.ctx.device_margin_c
        for at, bt, _, _ in self.scen:
            self.le(at, lim.device_max_c - pad - bt)
            self.ge(at, lim.device_min_c + pad - bt)

    def window(
        self,
        win: Window,
        margin_g: int | None = None,
        margin_t: int | None = None,
        extra_edge_c: float = 0.0,
    ) -> None:
        """Band constraints inside the window and the edge conditions at its ends.

        ``margin_g`` / ``margin_t``: indices of extra columns that tighten the band and
        the edge conditions (maximised by the polish LP). ``extra_edge_c``: the window
        starts and ends that much further beyond the edges (a robust sweep's reference
        placed far enough out for the scenarios that fall short of it).
        """
        spec = self.ctx.spec
        d, m = win.direction, spec.edge_margin_c
        mg = {margin_g: 1.0} if margin_g is not None else None
        mt = {margin_t: 1.0} if margin_t is not None else None
        for si, (at, bt, ag, bg) in zip(self.scen_idx, self.scen, strict=True):
            start, end, _ = win.bounds_of(si)
            s0, s1 = start - self.s_from, end - self.s_from
            pieces_done = 0
            for a, b_, pi, knot in win.pieces(si):
                w = slice(a - self.s_from, b_ - self.s_from + 1)
                t_ref, lo0, lo1, hi0, hi1 = win.band.piece(pi)
                # robust: a scenario's bands follow its own offset dT0 - dT0_ref (all its
                # sweeps shift alike, so its bands stay disjoint at every temperature)
                off = self.ctx.offsets_c[si]
                t_ref += off
                if si != 0 and self.ctx.robust:
                    # robust: the other scenarios may stray the slack outside the band
                    # (the bands are twice the slack further apart, so still disjoint)
                    slack = self.ctx.robust_slack_c_per_min
                    lo0, hi0 = lo0 - slack, hi0 + slack
                # q = d g >= lo0 + lo1 (T - t_ref) + margin
                self.ge(d * ag[w] - lo1 * at[w], lo0 + lo1 * (bt[w] - t_ref) - d * bg[w], mg)
                # q <= hi0 + hi1 (T - t_ref) - margin (robust: not for the fastest band,
                # whose top bounds no other band; the scenarios spread most when fast)
                if not (win.band.top and self.ctx.robust):
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
            if win.pins is not None:
                self._pins(win, si, at, bt, ag, bg, mt)
                continue
            lo_edge = spec.working_lo_c - m - extra_edge_c
            hi_edge = spec.working_hi_c + m + extra_edge_c
            if d < 0:  # starts above the region, ends below it
                self.ge(at[s0], hi_edge - bt[s0], mt)
                self.le(at[s1], lo_edge - bt[s1], mt)
            else:
                self.le(at[s0], lo_edge - bt[s0], mt)
                self.ge(at[s1], hi_edge - bt[s1], mt)

    def t_at(self, scenario: int, times_min: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` with T at ``times_min`` = ``A @ free rates + b`` (earlier rates fixed)."""
        a_full, b_full = self.ctx.responses.t_rows_at(scenario, times_min)
        return a_full[:, self.j0 : self.j1], b_full + a_full[:, : self.j0] @ self.u_fixed

    def _pins(self, win: Window, si: int, at, bt, ag, bg, mt) -> None:
        """A pinned sweep's edge bins: their crossing times and, inside them, its direction.

        With ``y = d T`` rising along the sweep and ``e`` a bin's boundary crossed first,
        ``e'`` the one crossed last: ``y(t0) <= d e`` and ``y(t0 + PIN) >= d e`` (it enters
        within the pin), ``y(t0 + PIN + min) <= d e'`` and ``y(t0 + max) >= d e'`` (it
        leaves after ``min`` and before ``max``: its mean gradient over the bin is
        between ``w / max`` and ``w / min``). Inside a bin the gradient is free -- the
        sweep may speed up or brake there -- but it moves forward at every sample from
        the pin to the earliest exit (one pass, not two). It ends ``PIN_EXIT_C`` beyond
        the region (``mt``: further, the polish's edge margin).
        """
        spec, p, d = self.ctx.spec, win.pins, win.direction
        assert p is not None
        if self.ctx.robust:  # the scenarios' offsets and own crossings are not modelled
            raise ValueError("pinned edge bins are for plans of one model, not robust boxes")
        w = spec.grid.bin_c
        lo, hi = spec.working_lo_c, spec.working_hi_c
        e_in, e_out = (hi, lo) if d < 0 else (lo, hi)
        eps = PIN_MIN
        bins = (
            (p.entry_min, p.entry_min_min, p.entry_max_min, e_in, e_in + d * w),
            (p.exit_min, p.exit_min_min, p.exit_max_min, e_out - d * w, e_out),
        )
        for k, (t0, dmin, dmax, first, last) in enumerate(bins):
            times = (t0, t0 + eps, t0 + eps + dmin, t0 + dmax)
            a, b = self.t_at(si, times)
            self.le(d * a[0], d * first - d * b[0])  # not yet in at t0
            self.ge(d * a[1], d * first - d * b[1])  # in by t0 + PIN
            self.le(d * a[2], d * last - d * b[2])  # not out before t0 + PIN + min
            # out by t0 + max (and, leaving the region, a little beyond it)
            beyond, extra = (PIN_EXIT_C, mt) if k == 1 else (0.0, None)
            self.ge(d * a[3], d * last + beyond - d * b[3], extra)
            # forward at every sample from the pin to the earliest exit: one pass
            i0 = int(math.ceil(t0 / SAMPLE_MIN - 1e-9)) - self.s_from
            i1 = int(math.floor((t0 + eps + dmin) / SAMPLE_MIN + 1e-9)) - self.s_from
            if i1 >= i0:
                self.ge(d * ag[i0 : i1 + 1], -d * bg[i0 : i1 + 1])

    def exit_speed(self, win: Window, column: int) -> None:
        """Extra column ``column`` >= d * g at the window end, for every scenario."""
        for si, (_, _, ag, bg) in zip(self.scen_idx, self.scen, strict=True):
            s1 = win.bounds_of(si)[1] - self.s_from
            self.le(win.direction * ag[s1], -win.direction * bg[s1], {column: -1.0})

    # -- solving ---------------------------------------------------------------------
    def _matrices(self, l1_weight: float):
        """``(q, A, b, n_eq)`` of ``min q x s.t. A[:n_eq] x = b[:n_eq], A[n_eq:] x <= b``.

        Rate bounds are rows; with ``l1_weight > 0`` auxiliary columns ``t >= |rate|``
        carry the weight. The matrix is small (hundreds of rows, tens of columns): built
        dense (assembling it from sparse blocks cost more than the solve).
        """
        lim = self.ctx.limits
        n, m = self.n, self.n + self.extra
        n_t = n if l1_weight > 0 else 0
        n_eq = sum(rows.shape[0] for _, rows, _, _ in self._e)
        n_g = sum(rows.shape[0] for _, rows, _, _ in self._g)
        a = np.zeros((n_eq + n_g + 2 * n + 2 * n_t, m + n_t))
        _, f = self._rows(self._e, a[:n_eq])
        _, h = self._rows(self._g, a[n_eq : n_eq + n_g])
        r0 = n_eq + n_g
        idx = np.arange(n)
        a[r0 + idx, idx] = 1.0  # rate <= max
        a[r0 + n + idx, idx] = -1.0  # -rate <= -min
        b = np.concatenate(
            (
                f,
                h,
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
        return n_t, a, b, n_eq

    def solve_direct(self, cost: np.ndarray, l1_weight: float = 0.0) -> np.ndarray | None:
        """Minimise ``cost @ x + l1_weight * ||rates||_1``: Clarabel directly, HiGHS if it fails.

        The search solves hundreds of these small LPs, so they skip the modelling layer
        (``scripts/bench_plan.py`` times one probe both ways). Returns the optimal ``x``,
        or None when the LP is infeasible -- or when both solvers failed, which is counted
        apart in the plan's :class:`LpStats` (and raised when it leaves nothing to plan).
        """
        import clarabel
        from scipy import optimize, sparse

        m = self.n + self.extra
        n_t, a, b, n_eq = self._matrices(l1_weight)
        q = np.concatenate((np.asarray(cost, dtype=float), np.full(n_t, float(l1_weight))))
        self.last_size = {"variables": int(m + n_t), "constraints": int(a.shape[0])}
        # counted as solved either way: the effort limit cuts where it did, only sooner
        count_work(int(np.count_nonzero(a)))
        if bounds_prove_infeasible(a, b, n_eq, self.n, self.ctx.limits):
            # most probes of a transition too short to reach the window in time end here
            self.ctx.stats.record("infeasible", 0.0)
            self.ctx.stats.infeasible_by_bounds += 1
            return None
        a_sparse = dense_to_csc(a)
        cones = ([clarabel.ZeroConeT(n_eq)] if n_eq else []) + [
            clarabel.NonnegativeConeT(a.shape[0] - n_eq)
        ]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        for name, value in CLARABEL_SETTINGS.items():
            setattr(settings, name, value)
        tic = time.perf_counter()
        p_zero = sparse.csc_matrix(
            (np.zeros(0), np.zeros(0, np.int32), np.zeros(m + n_t + 1, np.int32)),
            shape=(m + n_t, m + n_t),
        )
        sol = clarabel.DefaultSolver(p_zero, q, a_sparse, b, cones, settings).solve()
        status = str(sol.status)
        if status in _CLARABEL_OK:
            self.ctx.stats.record(_CLARABEL_OK[status], time.perf_counter() - tic)
            return np.asarray(sol.x[:m], dtype=float)
        if status in _CLARABEL_INFEASIBLE:
            self.ctx.stats.record("infeasible", time.perf_counter() - tic)
            return None
        # numerical trouble: the same LP to HiGHS (free variables, rate bounds as rows)
        self.ctx.stats.fallbacks += 1
        res = optimize.linprog(
            q,
            A_ub=a[n_eq:],
            b_ub=b[n_eq:],
            A_eq=a[:n_eq] if n_eq else None,
            b_eq=b[:n_eq] if n_eq else None,
            bounds=(None, None),
            method="highs",
        )
        seconds = time.perf_counter() - tic
        if res.status == 0:
            self.ctx.stats.record("optimal", seconds)
            return np.asarray(res.x[:m], dtype=float)
        if res.status == 2:
            self.ctx.stats.record("infeasible", seconds)
            return None
        self.ctx.stats.record("failed", seconds, f"Clarabel {status}; HiGHS: {res.message}")
        return None

    def solve(
        self,
        objective: Callable[[cp.Variable], cp.Expression],
        extra_bounds: Sequence[tuple[float | None, float | None]] = (),
        extra_constraints: Callable[[cp.Variable], list] | None = None,
    ) -> np.ndarray | None:
        """Solve through cvxpy (the whole-programme LPs); None when not solved."""
        lim = self.ctx.limits
        x = cp.Variable(self.n + self.extra)
        g, h = self._rows(self._g)
        e, f = self._rows(self._e)
        cons = [
            g @ x <= h,
            x[: self.n] >= lim.rate_min_c_per_min,
            x[: self.n] <= lim.rate_max_c_per_min,
        ]
        if self._e:
            cons.append(e @ x == f)
        for k, (lo, hi) in enumerate(extra_bounds):
            if lo is not None:
                cons.append(x[self.n + k] >= lo)
            if hi is not None:
                cons.append(x[self.n + k] <= hi)
        if extra_constraints is not None:
            cons += extra_constraints(x)
        prob = cp.Problem(cp.Minimize(objective(x)), cons)
        count_work(int(np.count_nonzero(g)) + int(np.count_nonzero(e)))
        ok = self.ctx.solve_cvxpy(prob)
        self.last_size = {"variables": int(x.size), "constraints": int(h.size + 2 * self.n)}
        if not ok or x.value is None:
            return None
        return np.asarray(x.value, dtype=float)


def require_solvable(stats: LpStats, what: str) -> None:
    """Raise :class:`SolverFailedError` when failed solves, not infeasibility, left nothing.

    Called when a search found no structure: if the solvers failed on probes and never
    once proved one infeasible, "infeasible" would be a guess.
    """
    # the solvers' proofs: one row and the rate bounds prove only the plainly impossible
    if stats.failed and stats.infeasible == stats.infeasible_by_bounds:
        raise SolverFailedError(
            f"{what}: the LP solvers failed on {stats.failed} of "
            f"{stats.solves - stats.infeasible_by_bounds} problems "
            f"and proved none infeasible ({'; '.join(stats.messages[:2])}); this is a "
            "numerical failure, not evidence that the request is impossible"
        )
