"""Stage 8b: robust ramp programmes, by generate and verify.

The band search (:mod:`.robust`) holds every scenario of a robust box to bands placed
from the box centre: shifted by dT0, not scaled by tau. Where tau varies widely that is
stricter than the coverage target, and the search falls back where simple programmes
cover the whole box (red team: long ramps at the rate limits, turning 10-35 degC beyond
the region; data/robust_hand/).

This rung searches that family directly. A programme is ``K`` legs of constant chamber
rate, alternating direction: each approaches at the chamber's limit rate, passes at a
share of it, turns beyond (or inside) the region and holds there; a last leg runs to the
end temperature (:class:`_Family`, 4 parameters per leg). A candidate is simulated exactly
(:func:`_lag_samples`) for the box's 3 x 3 corner, edge and centre scenarios, every device
also shifted ``T_MARGIN_C`` up and down, and scored by a penalty objective:

* per bin and scenario, the passes (:func:`pass_gradients`, as the coverage metric finds
  them) must hold ``levels_required`` levels at least ``delta + SAFETY_C_PER_MIN`` apart
  (:func:`separation`: the widest spacing at which they do, vectorised);
* the device stays within its limits, the programme within the duration limit;
* a small term on the duration shortens what meets all that.

The optimiser is SciPy's differential evolution, its population seeded with starts built
from the lag (:func:`_starts`), fixed seeds and a budget of evaluations (the same answer
on any machine), for ``K`` = levels, levels + 1, levels + 2. A candidate is rounded to
the step table an operator types and accepted only when the dense box check
(:func:`~.robust.verify_robust`, 25 x 19 points) holds and
:func:`~.check.check_programme` finds it complete within every limit; where the box check
fails, its worst point joins the screening set and a Nelder-Mead run repairs the
candidate (a cutting-plane loop). Finding nothing proves nothing; :func:`box_spread_proof`
proves some boxes uncoverable.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import differential_evolution, minimize

from ..errors import StepTableError
from ..params import Limits, ThermalParams
from ..programme import Programme
from .check import check_programme, step_limit_problems
from .request import ExperimentSpec, first_directions
from .robust import box_scenarios, verify_robust

Range = tuple[float, float] | None
Progress = Callable[[str], None] | None

#: Separation the screening asks above ``delta``, degC/min (the dense check at 0.1 min
#: and the rounding to whole minutes and 0.1 degC move the passes' gradients a little).
SAFETY_C_PER_MIN = 0.006
#: The screening asks coverage of every device shifted this much up and down, degC.
T_MARGIN_C = 0.5
#: Screening simulation step, min (the dense check uses 0.1 min).
SCREEN_DT_MIN = 0.25
#: Slowest leg, as a share of the chamber's rate limit in its direction.
MIN_SHARE = 0.03
#: Farthest a leg's fast approach may end before the region's near edge, degC.
APPROACH_C = 40.0
#: Farthest a leg may turn beyond the region's far edge, degC (less the region's width:
#: a turn may also lie inside the region, the device's offset carrying it out).
OVERSHOOT_C = 60.0
#: Longest hold at a turn, min.
MAX_HOLD_MIN = 150.0
#: Objective evaluations the whole search may spend, per level required (about 0.5-2 ms
#: each): a count, so the same answer on any machine and under any load.
EVALS_PER_LEVEL = 13000
#: Evaluations of a Nelder-Mead repair run (a point the dense check added), per
#: parameter.
RUN_EVALS_PER_PARAM = 100
#: Differential evolution: population per parameter, generations.
POPSIZE = 15
GENERATIONS = 100
#: Differential evolution stops when its best improved by less than this share over this
#: many generations.
STALL_SHARE = 0.005
STALL_GENERATIONS = 25
#: Starting points per leg count and first direction (:func:`_starts`), in the population.
STARTS = 6
#: Times the dense box check may send a candidate back with its worst point added.
MAX_CUTS = 4

# weights of the penalty objective (each term 0 when its requirement is met)
_W_SEP = 100.0  # per degC/min of the worst (scenario, bin) separation below target
_W_SEP_MEAN = 20.0  # per degC/min of the mean shortfall (a gradient off the worst bin)
_W_DEVICE = 1.0  # per degC past a device limit
_W_OVER = 0.05  # per min over the duration limit
_W_DURATION = 0.2  # per duration limit of length (shortens what meets the rest)


@dataclass(frozen=True)
class RampResult:
    """A programme of the ramp rung that holds on the whole box (dense check).

    ``programme``: the rounded step table; ``legs``: the sweeps across the region;
    ``box_check``: :func:`~.robust.verify_robust`'s result; ``evals``: objective
    evaluations spent; ``screened``: the (tau_s, dt0_c) points the search scored on;
    ``min_separation_c_per_min``: the screening's worst level separation.
    """

    programme: Programme
    legs: int
    box_check: dict
    evals: int
    screened: tuple[tuple[float, float], ...]
    min_separation_c_per_min: float


class _Budget(Exception):
    """The search's budget of objective evaluations is spent."""


def _lag_samples(
    durations_min: np.ndarray,
    rates_c_per_min: np.ndarray,
    start_c: float,
    t0_c: float,
    tau_min: np.ndarray,
    dt0_c: np.ndarray,
    times_min: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact T and g of ``tau dT/dt + T = Tk + dT0`` under a piecewise-linear ``Tk``, at
    ``times_min`` for every scenario (rows): per segment ``T = Tk + dT0 - U tau + c
    e^(-t/tau)`` with ``c`` from the segment's start. (The simulator's
    :func:`~schedsyn.model.affine_response` builds a matrix per scenario for any linear
    model; the objective needs only this lag, for 18 scenarios at once, tens of thousands
    of times.)"""
    edges = np.concatenate(([0.0], np.cumsum(durations_min)))
    tk_edges = start_c + np.concatenate(([0.0], np.cumsum(durations_min * rates_c_per_min)))
    seg = np.clip(np.searchsorted(edges, times_min, side="right") - 1, 0, durations_min.size - 1)
    tau = tau_min[:, None]
    dt0 = dt0_c[:, None]
    # T at every segment start, per scenario
    n = durations_min.size
    t_start = np.empty((tau_min.size, n))
    temp = np.full(tau_min.size, float(t0_c))
    for j in range(n):
        t_start[:, j] = temp
        u, d = rates_c_per_min[j], durations_min[j]
        c = temp - tk_edges[j] - dt0_c + u * tau_min
        temp = tk_edges[j] + u * d + dt0_c - u * tau_min + c * np.exp(-d / tau_min)
    s = times_min - edges[seg]
    u = rates_c_per_min[seg][None, :]
    c = t_start[:, seg] - tk_edges[seg][None, :] - dt0 + u * tau
    e = np.exp(-s[None, :] / tau)
    temp = tk_edges[seg][None, :] + u * s[None, :] + dt0 - u * tau + c * e
    grad = u - c * e / tau
    return temp, grad


def separation(grads: np.ndarray, levels: int) -> np.ndarray:
    """Per row of ``grads`` (NaN: no pass), the widest spacing ``d`` at which its values
    hold ``levels`` levels pairwise ``>= d`` apart (greedy from the smallest, as
    :func:`~schedsyn.coverage.distinct_levels` counts them); 0 where fewer values than
    ``levels``. Bisection to 1e-4 degC/min, vectorised over the rows."""
    g = np.sort(np.where(np.isfinite(grads), grads, np.inf), axis=1)
    finite = np.isfinite(g)
    lo = np.zeros(g.shape[0])
    hi = np.full(g.shape[0], 8.0)
    enough = finite.sum(axis=1) >= levels
    for _ in range(17):
        mid = 0.5 * (lo + hi)
        count = np.zeros(g.shape[0], dtype=int)
        last = np.full(g.shape[0], -np.inf)
        for k in range(g.shape[1]):
            take = finite[:, k] & (g[:, k] - last >= mid - 1e-12)
            count += take
            last = np.where(take, g[:, k], last)
        ok = count >= levels
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return np.where(enough, lo, 0.0)


def pass_gradients(temps_c: np.ndarray, grads_c_per_min: np.ndarray, lo_c: float, n_bins: int):
    """The passes of every scenario (rows of ``temps_c``) through every 1 degC bin from
    ``lo_c``, as :func:`~schedsyn.coverage.passes` finds them (maximal runs of samples in
    one bin, their mean gradient): an array ``(n_scenarios * n_bins, most passes)``, row
    ``s * n_bins + b``, NaN-padded."""
    n_s, n_t = temps_c.shape
    k = np.floor(temps_c - lo_c)
    k = np.where((k >= 0) & (k < n_bins), k, -1).astype(np.int64)
    # a sentinel column keeps one scenario's last run from joining the next one's first
    flat = np.concatenate((k, np.full((n_s, 1), -2)), axis=1).ravel()
    g = np.concatenate((grads_c_per_min, np.zeros((n_s, 1))), axis=1).ravel()
    change = np.flatnonzero(np.diff(flat) != 0) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [flat.size]))
    keep = flat[starts] >= 0
    starts, ends = starts[keep], ends[keep]
    cs = np.concatenate(([0.0], np.cumsum(g)))
    mean = (cs[ends] - cs[starts]) / (ends - starts)
    group = (starts // (n_t + 1)) * n_bins + flat[starts]
    order = np.argsort(group, kind="stable")
    group, mean = group[order], mean[order]
    first = np.searchsorted(group, group, side="left")
    pos = np.arange(group.size) - first
    out = np.full((n_s * n_bins, max(int(pos.max()) + 1 if pos.size else 1, 1)), np.nan)
    out[group, pos] = mean
    return out


class _Family:
    """The ramp family for one request: parameters in, programme and score out.

    Leg ``k`` (direction ``d``, alternating from ``first``) has four parameters, each
    mapped from the real line through a logistic: where its fast approach at the chamber's
    limit rate ends (``APPROACH_C`` before the near edge .. the far edge), the share of
    the limit rate it passes the region at, how far beyond the far edge it turns (up to
    ``OVERSHOOT_C``, within the chamber's limits; negative: the device's offset carries it
    out), and the hold there. The last leg runs to the end temperature at a share of the
    limit rate.
    """

    def __init__(
        self,
        spec: ExperimentSpec,
        limits: Limits,
        legs: int,
        first: int,
        tau_range_s: tuple[float, float],
        dt0_range_c: tuple[float, float],
    ) -> None:
        self.spec, self.limits, self.legs, self.first = spec, limits, legs, first
        self.lo, self.hi = spec.working_lo_c, spec.working_hi_c
        self.tau_range_s, self.dt0_range_c = tau_range_s, dt0_range_c
        self.max_hold_min = min(MAX_HOLD_MIN, 0.3 * limits.duration_max_min)
        self.width = self.hi - self.lo
        self.n = 4 * legs + 1

    def direction(self, k: int) -> int:
        return self.first * (1 if k % 2 == 0 else -1)

    def edges(self, d: int) -> tuple[float, float]:
        """(near, far) edge of the region for a leg in direction ``d``."""
        return (self.lo, self.hi) if d > 0 else (self.hi, self.lo)

    def decode(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Parameters to the programme's segment durations and rates."""
        y = 1.0 / (1.0 + np.exp(-np.clip(x, -30, 30)))
        lim = self.limits
        tk = lim.start_c
        durations: list[float] = []
        rates: list[float] = []

        def ramp(to_c: float, rate: float) -> None:
            nonlocal tk
            if (to_c - tk) * rate > 1e-6:
                durations.append((to_c - tk) / rate)
                rates.append(rate)
                tk = to_c

        for k in range(self.legs):
            d = self.direction(k)
            near, far = self.edges(d)
            full = lim.rate_max_c_per_min if d > 0 else lim.rate_min_c_per_min
            bound = lim.chamber_max_c if d > 0 else lim.chamber_min_c
            turn = far + d * (OVERSHOOT_C * y[4 * k + 2] - self.width)
            turn = min(turn, bound) if d > 0 else max(turn, bound)
            approach = near - d * APPROACH_C + d * y[4 * k] * (APPROACH_C + self.width)
            approach = min(approach, turn) if d > 0 else max(approach, turn)
            ramp(approach, full)
            ramp(turn, (MIN_SHARE + (1 - MIN_SHARE) * y[4 * k + 1]) * full)
            hold = y[4 * k + 3] * self.max_hold_min
            if hold > 0.5:
                durations.append(hold)
                rates.append(0.0)
        share = MIN_SHARE + (1 - MIN_SHARE) * y[4 * self.legs]
        gap = lim.end_c - tk
        ramp(lim.end_c, share * (lim.rate_max_c_per_min if gap > 0 else lim.rate_min_c_per_min))
        if not durations:  # (every turn behind the chamber, no hold: nothing to run)
            durations, rates = [1.0], [0.0]
        return np.array(durations), np.array(rates)

    def encode(self, legs: list[tuple[float, float, float, float]], last_share: float):
        """Parameters for per-leg (approach before the near edge degC, share, overshoot
        beyond the far edge degC, hold min) and the last leg's share: the inverse of
        :meth:`decode`'s mapping (clipped into its ranges)."""
        x = np.empty(self.n)
        for k, (before, share, over, hold) in enumerate(legs):
            x[4 * k] = _logit((APPROACH_C - before) / (APPROACH_C + self.width))
            x[4 * k + 1] = _logit((share - MIN_SHARE) / (1 - MIN_SHARE))
            x[4 * k + 2] = _logit((over + self.width) / OVERSHOOT_C)
            x[4 * k + 3] = _logit(hold / self.max_hold_min)
        x[4 * self.legs] = _logit((last_share - MIN_SHARE) / (1 - MIN_SHARE))
        return x

    def programme(self, x: np.ndarray) -> Programme:
        d, u = self.decode(x)
        return Programme(d, u, self.limits.start_c)


class _Scorer:
    """The penalty objective over a screening set of scenarios (see the module doc)."""

    def __init__(self, family: _Family, points: list[tuple[float, float]], counter: list[int]):
        self.f = family
        self.tau_min = np.array([p[0] for p in points]) / 60.0
        self.dt0_c = np.array([p[1] for p in points])
        self.counter = counter
        spec = family.spec
        self.nb = int(round(spec.working_hi_c - spec.working_lo_c))
        self.target = spec.delta_c_per_min + SAFETY_C_PER_MIN
        #: the best parameters seen that meet every requirement, and their objective
        self.best_x: np.ndarray | None = None
        self.best_value = math.inf
        self.lowest = math.inf  # the lowest objective seen, requirements met or not

    def parts(self, x: np.ndarray) -> dict:
        d, u = self.f.decode(x)
        return self.parts_of(d, u)

    def parts_of(self, d: np.ndarray, u: np.ndarray, dt_min: float = SCREEN_DT_MIN) -> dict:
        """The objective's terms for segment durations ``d`` and rates ``u``."""
        lim, spec = self.f.limits, self.f.spec
        total = float(d.sum())
        times = np.arange(0.0, total + 1e-9, dt_min)
        temp, grad = _lag_samples(d, u, lim.start_c, lim.t_init_c, self.tau_min, self.dt0_c, times)
        # coverage must hold with every device a little warmer and a little colder: the
        # rounding of the table moves the turns (a turn that just reached an edge bin
        # lost it to the rounding)
        shifted = np.concatenate((temp - T_MARGIN_C, temp + T_MARGIN_C))
        sep = separation(
            pass_gradients(shifted, np.concatenate((grad, grad)), spec.working_lo_c, self.nb),
            spec.levels_required,
        )
        short = np.maximum(0.0, self.target - sep)
        device = float(
            np.maximum(0.0, lim.device_min_c - temp.min(axis=1)).sum()
            + np.maximum(0.0, temp.max(axis=1) - lim.device_max_c).sum()
        )
        over = max(0.0, total - lim.duration_max_min)
        return {
            "sep_min": float(sep.min()),
            "short_max": float(short.max()),
            "short_mean": float(short.mean()),
            "device_c": device,
            "over_min": over,
            "total_min": total,
        }

    def __call__(self, x: np.ndarray) -> float:
        self.counter[0] += 1
        if self.counter[0] > self.counter[1]:
            raise _Budget
        p = self.parts(x)
        penalty = (
            _W_SEP * p["short_max"]
            + _W_SEP_MEAN * p["short_mean"]
            + _W_DEVICE * p["device_c"]
            + _W_OVER * p["over_min"]
        )
        value = penalty + _W_DURATION * p["total_min"] / self.f.limits.duration_max_min
        self.lowest = min(self.lowest, value)
        if _met(p) and value < self.best_value:  # (kept when the budget ends a run)
            self.best_value, self.best_x = value, np.array(x, copy=True)
        return value


def _met(parts: dict) -> bool:
    """Every requirement of the screening met (the objective's terms, :meth:`_Scorer.parts`)."""
    return parts["short_max"] <= 0 and parts["device_c"] <= 0 and parts["over_min"] <= 0


def _logit(y: float) -> float:
    y = min(max(y, 1e-3), 1 - 1e-3)
    return math.log(y / (1 - y))


def _starts(family: _Family, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Starting points: the legs of each direction at shares spread from the limit down
    (fastest first, slowest first, shuffled), each approaching fast to a lag before the
    region and turning a lag plus the dT0 spread beyond it with a short hold; and once
    turning where every device ends a degree beyond it, within the chamber's and the
    device's limits, held longer where those cut the turn short (a region near the
    chamber's floor)."""
    lim, spec = family.limits, family.spec
    tau_min = 0.5 * (family.tau_range_s[0] + family.tau_range_s[1]) / 60.0
    dt0_lo, dt0_hi = family.dt0_range_c
    out = []
    for variant in range(n):
        per_dir: dict[int, list[int]] = {1: [], -1: []}
        for k in range(family.legs):
            per_dir[family.direction(k)].append(k)
        legs: list[tuple[float, float, float, float]] = [(0.0, 1.0, 0.0, 0.0)] * family.legs
        for d, ks in per_dir.items():
            shares = np.geomspace(1.0, 0.1, max(len(ks), 1))[: len(ks)]
            if variant == 1:
                shares = shares[::-1]
            if variant >= 3:
                shares = rng.permutation(shares)
            full = lim.rate_max_c_per_min if d > 0 else -lim.rate_min_c_per_min
            for k, share in zip(ks, shares, strict=True):
                lag = share * full * tau_min
                # variant 2 turns in device terms: every dT0 carried a degree out, within
                # the chamber's and the device's limits (then held for it to get there)
                if d > 0:
                    want = spec.working_hi_c - dt0_lo + 1.0 + 0.5 * lag
                    turn = min(want, lim.chamber_max_c, lim.device_max_c - dt0_hi - 0.2)
                else:
                    want = spec.working_lo_c - dt0_hi - 1.0 - 0.5 * lag
                    turn = max(want, lim.chamber_min_c, lim.device_min_c - dt0_lo + 0.2)
                if variant == 2:
                    over = d * (turn - family.edges(d)[1])
                    hold = 0.2 * tau_min if turn == want else 0.6 * tau_min
                else:  # turning a lag plus the dT0 spread beyond, short holds
                    over, hold = lag + dt0_hi - dt0_lo + 1, 5.0
                legs[k] = (min(lag, APPROACH_C), float(share), over, hold)
        x = family.encode(legs, 0.95)
        if variant >= 3:
            x = x + rng.normal(0.0, 0.3, x.size)
        out.append(x)
    return out


def _grid_point(box: dict) -> tuple[float, float] | None:
    worst = box.get("worst") or {}
    if "tau_s" not in worst:
        return None
    return (float(worst["tau_s"]), float(worst["dt0_c"]))


def ramp_search(
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    tau_s: Range,
    dt0_c: Range,
    progress: Progress = None,
    max_evals: int | None = None,
) -> RampResult | None:
    """A ramp programme that covers the whole robust box, or None (see the module doc).

    ``max_evals`` bounds the objective evaluations (default :data:`EVALS_PER_LEVEL` per
    level required).
    """
    tau_range = (float(tau_s[0]), float(tau_s[1])) if tau_s else (params.tau_s, params.tau_s)
    dt0_range = (float(dt0_c[0]), float(dt0_c[1])) if dt0_c else (params.dt0_c, params.dt0_c)
    taus = sorted({tau_range[0], 0.5 * (tau_range[0] + tau_range[1]), tau_range[1]})
    dt0s = sorted({dt0_range[0], 0.5 * (dt0_range[0] + dt0_range[1]), dt0_range[1]})
    points = [(t, d) for t in taus for d in dt0s]
    budget = EVALS_PER_LEVEL * spec.levels_required if max_evals is None else max_evals
    counter = [0, int(budget)]
    rng = np.random.default_rng(20261204)
    levels = spec.levels_required
    scenarios = box_scenarios(params, tau_s, dt0_c)
    for legs in (levels, levels + 1, levels + 2):
        for first in first_directions(spec, limits):
            if counter[0] >= counter[1]:
                return None
            family = _Family(spec, limits, legs, first, tau_range, dt0_range)
            found = _evolve(family, points, counter, rng)
            if found is None:
                continue
            try:
                result = _verified(
                    family, found, points, counter, spec, params, limits, tau_s, dt0_c, scenarios
                )
            except _Budget:
                return None
            if result is not None:
                if progress:
                    progress(
                        f"{spec.name}: ramp rung: {legs} legs cover the whole box in "
                        f"{result.programme.total_min:g} min ({counter[0]} evaluations)"
                    )
                return result  # more legs take longer: the fewest that work
    return None


def _evolve(
    family: _Family,
    points: list[tuple[float, float]],
    counter: list[int],
    rng: np.random.Generator,
) -> np.ndarray | None:
    """Differential evolution over the family's parameters (in [0, 1] before the logit),
    its population seeded with :func:`_starts`: the best parameters that meet every
    requirement of the screening, or None. (Nelder-Mead from a few starts found 3-4 of the
    red team's 8 boxes, depending on the seed; this 6, scripts/bench_ramps.py.)"""
    scorer = _Scorer(family, points, counter)

    def objective(y: np.ndarray) -> float:
        y = np.clip(y, 1e-6, 1 - 1e-6)
        return scorer(np.log(y / (1 - y)))

    size = POPSIZE * family.n
    population = rng.random((size, family.n))
    for i, x in enumerate(_starts(family, rng, STARTS)):
        population[i] = 1.0 / (1.0 + np.exp(-x))
    history: list[float] = []

    def stalled(*_args, **_kwargs) -> bool:
        """After each generation: stop when the best has improved by less than
        :data:`STALL_SHARE` over the last :data:`STALL_GENERATIONS` (a family that cannot
        meet the target plateaus early; r04 and r13 of data/robust_hand/)."""
        history.append(scorer.lowest)
        if len(history) <= STALL_GENERATIONS:
            return False
        before = history[-1 - STALL_GENERATIONS]
        return before - history[-1] <= STALL_SHARE * abs(before)

    try:
        differential_evolution(
            objective,
            [(0.0, 1.0)] * family.n,
            callback=stalled,
            init=population,
            maxiter=GENERATIONS,
            seed=int(rng.integers(2**31)),
            polish=False,
            tol=0.0,
            mutation=(0.5, 1.0),
            recombination=0.7,
        )
    except _Budget:
        pass
    return scorer.best_x


def _run(
    family: _Family, x0: np.ndarray, points: list[tuple[float, float]], counter: list[int]
) -> np.ndarray | None:
    """A Nelder-Mead repair run from ``x0`` once the dense check added a point: the best
    parameters that meet every requirement of the screening, or None."""
    scorer = _Scorer(family, points, counter)
    minimize(
        scorer,
        x0,
        method="Nelder-Mead",
        options={
            "maxfev": RUN_EVALS_PER_PARAM * family.n,
            "xatol": 1e-3,
            "fatol": 1e-6,
            "adaptive": True,
        },
    )
    return scorer.best_x


def _verified(
    family: _Family,
    x: np.ndarray,
    points: list[tuple[float, float]],
    counter: list[int],
    spec: ExperimentSpec,
    params: ThermalParams,
    limits: Limits,
    tau_s: Range,
    dt0_c: Range,
    scenarios: list[ThermalParams],
) -> RampResult | None:
    """The rounded table of ``x`` when the dense box check holds; else the worst grid point
    joins ``points`` and the search goes on from ``x`` (at most :data:`MAX_CUTS` times)."""
    for _ in range(MAX_CUTS + 1):
        try:
            programme = family.programme(x).rounded(limits).ending_at(limits.end_c, limits)
        except StepTableError:  # (a degenerate candidate: not a plan)
            return None
        box = verify_robust(programme, spec, params, tau_s, dt0_c, limits)
        if box["holds"]:
            cov, _, problems, _, _ = check_programme(programme, spec, limits, scenarios)
            problems = [*problems, *step_limit_problems(programme, spec)]
            if cov.complete and not problems:
                scorer = _Scorer(family, points, counter)
                return RampResult(
                    programme=programme,
                    legs=family.legs,
                    box_check=box,
                    evals=counter[0],
                    screened=tuple(points),
                    min_separation_c_per_min=scorer.parts(x)["sep_min"],
                )
            return None
        point = _grid_point(box)
        if point is None or point in points:
            return None
        points.append(point)
        again = _run(family, x, points, counter)
        if again is None:
            return None
        x = again
    return None


#: How the box-spread proof's note begins.
NO_PROGRAMME_COVERS_BOX = "no programme covers the whole robust box"
#: Sampling of the fastest paths the box-spread proof follows, min.
PROOF_STEP_MIN = 0.05
#: tau values of the box the proof tries (its ends and evenly between).
PROOF_N_TAU = 9


def _first_time_past(
    edge_c: float, up: bool, params: ThermalParams, limits: Limits
) -> float | None:
    """The latest sample time before the device (``params``) can first pass ``edge_c``
    (below it when not ``up``): on the chamber's fastest path that way (the full rate to
    the chamber's limit, then held), which takes the device there first of all programmes
    (the lag is monotone in the chamber's path). A lower bound on when any programme gets
    it there; None when none does within the duration limit."""
    rate = limits.rate_max_c_per_min if up else limits.rate_min_c_per_min
    bound = limits.chamber_max_c if up else limits.chamber_min_c
    total = limits.duration_max_min
    ramp = min(total, (bound - limits.start_c) / rate) if rate else 0.0
    durations = [d for d in (ramp, total - ramp) if d > 0]
    rates = [rate, 0.0][: len(durations)] if ramp > 0 else [0.0]
    times = np.arange(0.0, total + 1e-9, PROOF_STEP_MIN)
    temp, _ = _lag_samples(
        np.array(durations),
        np.array(rates),
        limits.start_c,
        limits.t_init_c,
        np.array([params.tau_s / 60.0]),
        np.array([params.dt0_c]),
        times,
    )
    past = temp[0] >= edge_c if up else temp[0] < edge_c
    if not past.any():
        return None
    k = int(np.argmax(past))
    return float(times[max(k - 1, 0)])


def box_spread_proof(
    spec: ExperimentSpec, params: ThermalParams, limits: Limits, tau_s: Range, dt0_c: Range
) -> str | None:
    """A proof that no programme covers the whole robust box, or None (not a proof that one
    does).

    Two devices of the box with the same tau and offsets ``a < b`` differ by ``(b - a)(1 -
    e^(-t/tau))`` at time ``t`` whatever the chamber does (the lag is linear; both start at
    ``t_init_c``). The warmer must reach the region's bottom bin, ``T < lo + 1``, which no
    programme brings about before ``t_b`` (its fastest cooling path); then the colder is
    below ``lo + 1 - (b - a)(1 - e^(-t_b/tau))``. Where that is below ``device_min_c``,
    every programme that covers the bottom bin for the warmer takes the colder past its
    limit. Likewise at the top bin for the colder device and ``device_max_c``. Tried for
    :data:`PROOF_N_TAU` tau values of the box; the strongest is reported with what would
    not rule the box out.
    """
    if dt0_c is None or dt0_c[1] <= dt0_c[0]:
        return None
    a, b = float(dt0_c[0]), float(dt0_c[1])
    taus = np.linspace(*tau_s, PROOF_N_TAU) if tau_s is not None else [params.tau_s]
    lo, hi = spec.working_lo_c, spec.working_hi_c
    best: tuple[float, str] | None = None
    for tau in taus:
        for bottom in (True, False):
            mover = replace(params, tau_s=float(tau), dt0_c=b if bottom else a)
            edge = lo + 1.0 if bottom else hi - 1.0
            t = _first_time_past(edge, not bottom, mover, limits)
            if t is None:
                continue
            share = 1.0 - math.exp(-t * 60.0 / float(tau))
            apart = (b - a) * share
            if bottom:
                other, limit, key = edge - apart, limits.device_min_c, "device_min_c"
                excess = limit - other
            else:
                other, limit, key = edge + apart, limits.device_max_c, "device_max_c"
                excess = other - limit
            if excess <= 1e-6 or (best is not None and excess <= best[0]):
                continue
            room = abs(edge - limit)
            width = room / share if share > 0 else math.inf
            warm, cold = ("warmer", "colder") if bottom else ("colder", "warmer")
            best = (
                excess,
                f"{NO_PROGRAMME_COVERS_BOX}: its devices at tau {tau:g} s with "
                f"dT0 {a:g} and {b:g} °C differ by {b - a:g} x (1 - e^(-t/tau)) °C at time t "
                f"whatever the chamber does; the {warm} can be in the region's "
                f"{'bottom' if bottom else 'top'} bin ({'below' if bottom else 'from'} "
                f"{edge:g} °C) {t:.0f} min into the run at the earliest (the chamber's "
                f"fastest path), when they differ by {apart:.2f} °C or more, so the {cold} is "
                f"then {'below' if bottom else 'above'} {other:.2f} °C, past {key} = "
                f"{limit:g} °C by {excess:.2f} °C. This argument does not rule out a dT0 "
                f"range under about {width:.2f} °C wide at this tau, or {key} at "
                f"{other:.2f} °C",
            )
    return None if best is None else best[1]
