"""After the check (``objective = "informative"``): spend the rest of the budget on the drift fit.

The shortest complete plan stacks its gradient bands close under the fastest gradients the
chamber allows and crosses the region at nearly constant speed: it meets the coverage
target, but leaves the slow gradients in the middle of the region unvisited, and the
drift fit (:mod:`schedsyn.design`) is only as good as the spread of its samples over the
(T, g) plane. This stage keeps the shortest plan's sweep windows (so every band, hence
every level of every bin, stays as planned) and lets the programme run on to the whole
budget, choosing all the rates to maximise the total information of the samples in the
approximation region::

    D(u) = log det  sum_k x(T_k(u), g_k(u)) x(T_k(u), g_k(u))'

(the drift polynomial's terms ``x`` in coded variables, 1-min samples). ``T_k`` and
``g_k`` are affine in the rates ``u``, the terms are polynomials of them, so ``D`` is
smooth but not concave in ``u``: it is raised by sequential linear programming -- each
step maximises the first-order model of ``D`` (its gradient through the affine responses)
minus ``L1_WEIGHT`` times the total rate change (few steps in the table) within a trust
region around the current rates, subject to the same whole-programme constraints as the
planner's own LPs (chamber and device limits, every sweep window, the end at the end
setpoint) and with the gradients near the approximation region kept within the design
space's envelope of reachable gradients (what the fit is coded over: faster sweeps would
buy leverage from gradients the device never sees in use). A step is kept only when the
exact merit rises; the trust region halves otherwise.

Samples outside the approximation region carry no information and no gradient of ``D``:
on their own they would stay outside. In a region far from the 20 degC end the minutes
the programme runs on begin as holds at the end temperature, where they would be wasted,
so the merit is ``D`` less a pull, ``PULL_SAMPLES_PER_C`` average samples' worth of
``log det`` (``p / n_inside`` each) per degC each sample is outside the region (exact and
convex in the LP: a sum of ``pos`` terms). On the paper's W1 the pull took the
informative plan from 381 to 461 of its 540 minutes in the region and its information
from 1.02 to 1.57 times the shortest plan's (docs/drift-fit.md). A run that ends in a
region far from the end temperature needs a long soak to settle; when the table will end
with one (``end_soak``), the device must end no farther from settled than the shortest
plan run on with holds does, and every degC beyond the end tolerance (less
``END_MARGIN_C``) costs ``END_PRICE_PER_C`` of ``log det`` per term, so that it ends
settled wherever the programme can.

The result is re-checked like every plan (rounded table, dense re-simulation): it is
used only when it is complete and within every limit, otherwise the shortest plan stands
and a note says why. The plan reports the price (minutes over the shortest plan) and the
gain (``log det`` per term, D-efficiency per sample) in ``Plan.informative``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from ..design import DesignSpace
from ..terms import monomials, parse_terms
from .lp import Context
from .polish import whole_lp
from .search import Structure

#: Sequential-LP iterations (each one LP) and the trust region on the rates, degC/min.
SLP_ITERATIONS = 20
TRUST_START_C_PER_MIN = 0.4
TRUST_MIN_C_PER_MIN = 0.01
#: Weight of the total rate change against the normalised information gain (fewer steps),
#: and the heavier weights tried when the table has more steps than ``max_steps``.
L1_WEIGHT = 0.01
L1_WEIGHT_LADDER = (0.01, 0.04, 0.16)
#: Step-size of the central differences of the coded terms (exact for polynomials
#: up to rounding).
CODED_H = 1e-4
#: Samples this close to the approximation region keep their gradients in its envelope, degC.
NEAR_C = 2.0
#: Stop when a step raises log det by less than this.
GAIN_TOL = 1e-4
#: The pull into the approximation region: a sample 1 degC outside it costs as much as this
#: many average samples inside are worth (``p / n_inside`` of log det each).
PULL_SAMPLES_PER_C = 10.0
#: With ``end_settled``: the margin kept inside the end tolerance for the rounded table, degC
#: (the timetable stage's own, ``min(0.1, 0.4 end_tol_c)``).
END_MARGIN_C = 0.1
#: ... and the price of every degC the device ends beyond that, in ``log det`` per term: so
#: steep that ending settled comes before any information (a whole run-on gains a few).
END_PRICE_PER_C = 10.0


@dataclass(frozen=True, slots=True)
class InformativeResult:
    """Rates of the informative programme and what they gained (module docstring)."""

    u: np.ndarray
    log_det_start: float
    log_det_end: float
    iterations: int
    n_segments: int


def _log_det_and_gradient(
    t: np.ndarray, g: np.ndarray, space: DesignSpace, terms: tuple[str, ...]
) -> tuple[float, np.ndarray, np.ndarray]:
    """``D`` of samples (T, g) and its gradient with respect to each sample's T and g."""
    inside = (t >= space.approx_lo_c) & (t <= space.approx_hi_c)
    u, v = space.code(t[inside], g[inside])
    x = monomials(u, v, terms)
    m = x.T @ x
    sign, logdet = np.linalg.slogdet(m)
    d_t = np.zeros_like(t)
    d_g = np.zeros_like(g)
    if sign <= 0:
        return -math.inf, d_t, d_g
    m_inv = np.linalg.inv(m)
    xu = (monomials(u + CODED_H, v, terms) - monomials(u - CODED_H, v, terms)) / (2 * CODED_H)
    xv = (monomials(u, v + CODED_H, terms) - monomials(u, v - CODED_H, terms)) / (2 * CODED_H)
    xm = x @ m_inv
    # d log det(sum x x') / d u_k = 2 x_k' M^-1 dx_k/du_k; then the chain rule to degC
    g_lo, g_hi = space.gradient_range_c_per_min
    du_dt = 1.0 / (0.5 * (space.approx_hi_c - space.approx_lo_c))
    dv_dg = 1.0 / (0.5 * (g_hi - g_lo))
    d_t[inside] = 2.0 * np.einsum("ij,ij->i", xm, xu) * du_dt
    d_g[inside] = 2.0 * np.einsum("ij,ij->i", xm, xv) * dv_dg
    return float(logdet), d_t, d_g


def _step_rows(
    n: int,
    centre: np.ndarray,
    radius: float,
    ag_near: np.ndarray,
    bg_near: np.ndarray,
    g_range: tuple[float, float],
    end_rows: tuple[np.ndarray, float, float, float] | None = None,
) -> Callable[[cp.Variable], list]:
    """Constraints of one step: the trust region, the gradient envelope at the samples
    near the approximation region, and (``end_rows``: the last sample's row and offset,
    the settled temperature, the bound) how far from settled the device ends."""

    def rows(x: cp.Variable) -> list:
        out = [cp.abs(x[:n] - centre) <= radius]
        if ag_near.shape[0]:
            g_near = ag_near @ x[:n] + bg_near
            out += [g_near >= g_range[0], g_near <= g_range[1]]
        if end_rows is not None:
            a_end, b_end, settle_c, bound_c = end_rows
            out.append(cp.abs(a_end @ x[:n] + b_end - settle_c) <= bound_c)
        return out

    return rows


def _outside_c(t: np.ndarray, space: DesignSpace) -> float:
    """Sum over the samples of how far each is outside the approximation region, degC."""
    return float(
        np.maximum(space.approx_lo_c - t, 0.0).sum() + np.maximum(t - space.approx_hi_c, 0.0).sum()
    )


def informative_rates(
    ctx: Context,
    structure: Structure,
    u_start: np.ndarray,
    space: DesignSpace,
    n_segments: int,
    terms: str | tuple = "full",
    progress: Callable[[str], None] | None = None,
    margins: tuple[float, float] = (0.0, 0.0),
    l1_weight: float = L1_WEIGHT,
    pull: float | None = None,
    end_settled: tuple[float, float] | None = None,
) -> InformativeResult | None:
    """Rates of ``n_segments`` segments keeping ``structure``'s sweep windows and
    maximising the samples' information (module docstring); None when no LP solved.

    ``u_start`` are the shortest plan's rates (its segments; the rest start as holds);
    ``margins`` (band margin degC/min, edge margin degC) are kept as that plan's are;
    ``l1_weight`` prices the total rate change (more weight, fewer steps); ``pull`` prices
    each degC a sample is outside the approximation region (default
    :data:`PULL_SAMPLES_PER_C`; 0 for none); ``end_settled`` = (settled temperature,
    tolerance), degC, keeps the device's end no farther from settled than the start's
    end, or than the tolerance less :data:`END_MARGIN_C` if that is larger.
    """
    terms_t = parse_terms(terms)
    n_seg_short = structure.n_seg
    if n_segments < n_seg_short or ctx.responses.n_fixed:
        return None
    lp = whole_lp(ctx, structure.windows, n_segments, extra=2)
    fixed_margins = [(margins[0], margins[0]), (margins[1], margins[1])]
    at, bt, ag, bg = lp.scen[0]
    n = lp.n
    x0 = np.zeros(n)
    x0[: min(n, u_start.size)] = u_start[:n]

    def samples(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return at @ x + bt, ag @ x + bg

    d0, d_t, d_g = _log_det_and_gradient(*samples(x0), space, terms_t)
    if not math.isfinite(d0):
        return None
    start = d0
    # the pull's price of a degC outside the region, per sample, in average samples inside
    # (each worth p / n_inside of log det)
    t_start = samples(x0)[0]
    n_in = int(((t_start >= space.approx_lo_c) & (t_start <= space.approx_hi_c)).sum())
    pull = PULL_SAMPLES_PER_C if pull is None else pull
    price = pull * len(terms_t) / max(n_in, 1)

    end_rows = None
    end_target_c = math.inf
    end_price = 0.0
    if end_settled is not None:
        settle_c, within_c = end_settled
        # the device should end within the tolerance less a margin for the table's rounding
        # (then no soak at all): a steep price on every degC beyond, and a hard bound of no
        # farther than the start ends (the shortest plan run on with holds)
        end_target_c = within_c - min(END_MARGIN_C, 0.4 * within_c)
        end_price = END_PRICE_PER_C * len(terms_t)
        end_bound = max(end_target_c, abs(float(t_start[-1]) - settle_c))
        end_rows = (at[-1], float(bt[-1]), settle_c, end_bound)

    def merit(d: float, t: np.ndarray) -> float:
        out = d - price * _outside_c(t, space) if price else d
        if end_rows is not None:
            out -= end_price * max(abs(float(t[-1]) - end_rows[2]) - end_target_c, 0.0)
        return out

    m0 = merit(d0, t_start)
    g_env = space.gradient_range_c_per_min
    rho = TRUST_START_C_PER_MIN
    iterations = 0
    for _ in range(SLP_ITERATIONS):
        c = at.T @ d_t + ag.T @ d_g
        scale = float(np.abs(c).sum()) or 1.0
        cn = c / scale * n  # a gain of order one per unit mean rate change
        pull_n = price / scale * n
        end_n = end_price / scale * n

        def objective(
            x: cp.Variable, cn: np.ndarray = cn, pull_n: float = pull_n, end_n: float = end_n
        ) -> cp.Expression:
            out = -(cn @ x[:n]) + l1_weight * cp.norm1(cp.diff(x[:n]))
            if pull_n:
                t = at @ x[:n] + bt
                out += pull_n * cp.sum(
                    cp.pos(space.approx_lo_c - t) + cp.pos(t - space.approx_hi_c)
                )
            if end_rows is not None:
                a_end, b_end, settle_c, _ = end_rows
                out += end_n * cp.pos(cp.abs(a_end @ x[:n] + b_end - settle_c) - end_target_c)
            return out

        # gradients near the approximation region stay within the design space's envelope
        # (the reachable gradients the fit is coded over; no worse than the start's): a
        # D-criterion alone would buy leverage with ever faster sweeps
        t_now, g_now = samples(x0)
        near = (t_now >= space.approx_lo_c - NEAR_C) & (t_now <= space.approx_hi_c + NEAR_C)
        g_lo = min(g_env[0], float(g_now[near].min(initial=0.0)))
        g_hi = max(g_env[1], float(g_now[near].max(initial=0.0)))

        trust = _step_rows(n, x0.copy(), rho, ag[near], bg[near], (g_lo, g_hi), end_rows)

        x = lp.solve(objective, fixed_margins, trust)
        iterations += 1
        if x is None:
            rho *= 0.5
            if rho < TRUST_MIN_C_PER_MIN:
                break
            continue
        t1, g1 = samples(x[:n])
        d1, d_t1, d_g1 = _log_det_and_gradient(t1, g1, space, terms_t)
        m1 = merit(d1, t1)
        if m1 > m0 + GAIN_TOL:
            x0, d0, m0, d_t, d_g = x[:n], d1, m1, d_t1, d_g1
            if progress is not None:
                progress(f"informative: log det {d0:.2f} (start {start:.2f})")
        else:
            rho *= 0.5
            if rho < TRUST_MIN_C_PER_MIN:
                break
    if m0 <= merit(start, t_start) + GAIN_TOL:
        return None
    return InformativeResult(x0, start, d0, iterations, n)
