"""Gradient estimation from a measured log: Kalman filter + Rauch-Tung-Striebel smoother.

Two state-space models share one filter. Time runs in minutes, temperatures in degC, the
gradient ``g = dT/dt`` in degC/min; ``y_k`` is the internal sensor at time ``t_k``.

**Kinematic** (no model, any log): state ``x = (T, g)``, the gradient a random walk
(white-noise acceleration, an integrated random walk)::

    dT/dt = g,   dg/dt = w(t),   E[w(t) w(s)] = q delta(t - s)      q: (degC/min^2)^2/min
    y_k = T(t_k) + v_k,          var v_k = r                        r: degC^2

exact over a step ``h = t_{k+1} - t_k`` of any length (irregular sampling, gaps)::

    F = [[1, h], [0, 1]],   Q = q [[h^3/3, h^2/2], [h^2/2, h]]

**Model-based** (the chamber temperature ``Tk`` logged): the thermal model of
:mod:`schedsyn.model` drives ``T``, and a random-walk correction ``d`` (degC/min) absorbs
what the model misses::

    dT/dt = (Tk(t) + dT0 - T)/tau + d,   dd/dt = w(t),   g = (Tk + dT0 - T)/tau + d

with ``Tk`` linear between samples. The model (:class:`schedsyn.model.FirstOrderLag`)
gives its step response ``S(h) = 1 - e``, ``e = exp(-h/tau)``, and its unit-ramp
response ``R(h) = h - tau S(h)``; exactly::

    T' = e T + tau S(h) d + u,   u = S(h)(Tk_k + dT0) + s R(h)      (s: Tk slope)
    Q11 = q tau^3 (R/tau - S^2/2),  Q12 = q tau R(h),  Q22 = q h

Both have ``F = [[a, b], [0, 1]]`` and measure the first state, so one filter serves
both: :func:`predict`, :func:`update` and :func:`rts_step` are the only place the
recursions are written. Every path calls them: the row-by-row loop with floats, and the
steady-state fast path (constant step, converged covariance) with numpy arrays, where the
mean recursions become linear time-invariant and are solved vectorised (:func:`_lti`).

Long logs are filtered and smoothed in chunks of :data:`CHUNK_ROWS` rows: a forward pass
keeps only the filter's state at each chunk start (a checkpoint); the backward pass
re-filters one chunk from its checkpoint and smooths it, so the working memory does not
grow with the log (the results are the same as one pass over the whole log).

The noise levels ``(q, r)`` maximise the likelihood of the innovations (``r`` is at least
the quantisation floor ``step^2/12``); a user may fix either. A NaN reading only skips
the measurement update: the row still gets an estimate.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import minimize
from scipy.signal import lfilter

from .errors import LogFormatError, ParameterError
from .logs import MeasuredLog
from .model import FirstOrderLag
from .params import ThermalParams

#: Initial (diffuse) standard deviations of the state: T (degC) and g or d (degC/min).
PRIOR_T_STD_C = 10.0
PRIOR_G_STD_C_PER_MIN = 3.0
#: The first finite measurements mostly fix the diffuse prior; they are left out of the
#: likelihood (their terms would depend on the prior, not on q and r).
N_DIFFUSE = 2
#: The noise search runs at full rate on logs up to this many rows (a 9 h log at 10 s)...
FULL_RATE_ML_ROWS = 4000
#: ... and on an evenly strided copy of about this many rows of longer logs (the strided
#: search fits q, r within ~10 % of the full-rate search; see tests and the benchmark).
MAX_ML_ROWS = 1500
#: Bounds of the search, in natural log of q ((degC/min^2)^2/min) and of r (degC^2).
LOG_Q_BOUNDS = (math.log(1e-14), math.log(1e4))
LOG_R_BOUNDS = (math.log(1e-12), math.log(1e2))
#: Rows per chunk of the filter and smoother: the working memory (about 0.5 kB per chunk
#: row) does not grow with the log.
CHUNK_ROWS = 65_536
#: The quantisation step of logs with more readings than this is detected on an evenly
#: strided subset of about this many (every grid level a slow signal crosses is still seen).
QUANT_SAMPLE_ROWS = 262_144
#: Relative change of the filtered covariance below which the filter counts as steady.
STEADY_RTOL = 1e-11
#: Shortest run of equal steps with readings worth the vectorised steady-state path.
MIN_STEADY_ROWS = 32

#: ``progress(stage, done, total)``; stages "noise levels" (evaluations, total 0: open),
#: "filter" and "smoother" (rows).
Progress = Callable[[str, int, int], None]


# -- discretisation (pure, vectorised) --------------------------------------------------
def kinematic_transition(h_min: np.ndarray, q: float):
    """``(a, b, q11, q12, q22)`` of the integrated random walk over steps ``h_min``.

    ``F = [[1, h], [0, 1]]``, ``Q = q [[h^3/3, h^2/2], [h^2/2, h]]``.
    """
    h = np.asarray(h_min, dtype=float)
    return np.ones_like(h), h, q * h**3 / 3.0, q * h**2 / 2.0, q * h


def lag_transition(h_min: np.ndarray, model: FirstOrderLag, q: float):
    """``(a, b, q11, q12, q22)`` of the first-order lag with a random-walk correction.

    ``a = e = 1 - S(h)``, ``b = tau S(h)`` with the model's step response ``S`` and ramp
    response ``R`` (:class:`~schedsyn.model.FirstOrderLag`); the noise integrals
    ``Q11 = q tau^3 (R/tau - S^2/2)`` (a series ``x^3/3 - x^4/4 + 7 x^5/60`` at small
    ``x = h/tau``, where the difference cancels), ``Q12 = q tau R``, ``Q22 = q h``.
    """
    h = np.asarray(h_min, dtype=float)
    tau = model.tau_min
    s = model.step(h)  # S(h) = 1 - e
    ramp = model.ramp(h)  # R(h) = h - tau S(h)
    x = h / tau
    # (x - 2(1 - e) + (1 - e^2)/2) = x - S - S^2/2 = R/tau - S^2/2
    closed = ramp / tau - 0.5 * s * s
    series = x**3 / 3.0 - x**4 / 4.0 + 7.0 * x**5 / 60.0
    q11 = q * tau**3 * np.where(x < 1e-2, series, closed)
    return 1.0 - s, tau * s, q11, q * tau * ramp, q * h


def lag_input(
    h_min: np.ndarray, tk_start_c: np.ndarray, tk_end_c: np.ndarray, model: FirstOrderLag
) -> np.ndarray:
    """Chamber-driven part ``u`` of ``T'`` over each step (``Tk`` linear within a step).

    ``u = (1 - e)(Tk_k + dT0) + s R(h)``, ``s = (Tk_{k+1} - Tk_k)/h``: the model's free
    response from ``T = 0`` plus its ramp response (one copy of the model maths).
    """
    h = np.asarray(h_min, dtype=float)
    free_t, _ = model.free(h, np.asarray(tk_start_c, dtype=float), 0.0)
    slope = (np.asarray(tk_end_c, dtype=float) - tk_start_c) / h
    return free_t + model.gain * slope * model.ramp(h)


# -- one step of the filter and of the smoother ------------------------------------------
# The only place the recursions are written. Plain arithmetic, so the same functions run
# on floats (row by row, ~1.5 us per row in CPython, far less than numpy's per-call cost
# on 2x2 arrays) and on numpy arrays (the vectorised steady-state path). ``F = [[a, b],
# [0, 1]]``; states are ``(x1, x2)`` and covariances ``(p11, p12, p22)`` (symmetric).
def predict(x1, x2, p11, p12, p22, a, b, u, q11, q12, q22):
    """Time update over one step: ``x- = F x + (u, 0)``, ``P- = F P F^T + Q``.

    Returns ``(x1-, x2-, P11-, P12-, P22-)``.
    """
    # x1- = a x1 + b x2 + u          P11- = a^2 P11 + 2ab P12 + b^2 P22 + Q11
    # x2- = x2                       P12- = a P12 + b P22 + Q12
    #                                P22- = P22 + Q22
    t = a * p12 + b * p22
    return a * x1 + b * x2 + u, x2, a * (a * p11 + b * p12) + b * t + q11, t + q12, p22 + q22


def update(x1, x2, p11, p12, p22, y, r):
    """Measurement update with reading ``y = x1 + v``, ``var v = r``.

    Returns ``(x1+, x2+, P11+, P12+, P22+, e, S)``: the filtered state, the innovation
    ``e`` and its variance ``S``.
    """
    # e = y - x1-,  S = P11- + r,  K = (P11-, P12-) / S
    # x+ = x- + K e,  P+ = P- - K K^T S  (K K^T S = (P11 P11, P11 P12, P12 P12) / S)
    s = p11 + r
    e = y - x1
    k1 = p11 / s
    k2 = p12 / s
    return x1 + k1 * e, x2 + k2 * e, p11 - k1 * p11, p12 - k1 * p12, p22 - k2 * p12, e, s


def rts_step(fx1, fx2, f11, f12, f22, px1, px2, p11, p12, p22, sx1, sx2, s11, s12, s22, a, b):
    """One Rauch-Tung-Striebel step backwards, from row ``k+1`` to row ``k``.

    ``f``: filtered ``x_k|k, P_k|k``; ``p``: predicted ``x_k+1|k, P_k+1|k``; ``s``:
    smoothed ``x_k+1|N, P_k+1|N``; ``a, b``: ``F`` of the step ``k -> k+1``. Returns the
    smoothed ``(x1, x2, P11, P12, P22)`` of row ``k``.
    """
    # C = P_k|k F^T (P_k+1|k)^-1,  P_k|k F^T = [[f11 a + f12 b, f12], [f12 a + f22 b, f22]]
    m11 = f11 * a + f12 * b
    m21 = f12 * a + f22 * b
    det = p11 * p22 - p12 * p12
    c11 = (m11 * p22 - f12 * p12) / det
    c12 = (f12 * p11 - m11 * p12) / det
    c21 = (m21 * p22 - f22 * p12) / det
    c22 = (f22 * p11 - m21 * p12) / det
    # x_k|N = x_k|k + C (x_k+1|N - x_k+1|k)
    d1 = sx1 - px1
    d2 = sx2 - px2
    # P_k|N = P_k|k + C (P_k+1|N - P_k+1|k) C^T
    e11, e12, e22 = s11 - p11, s12 - p12, s22 - p22
    t11 = c11 * e11 + c12 * e12
    t12 = c11 * e12 + c12 * e22
    t21 = c21 * e11 + c22 * e12
    t22 = c21 * e12 + c22 * e22
    return (
        fx1 + c11 * d1 + c12 * d2,
        fx2 + c21 * d1 + c22 * d2,
        f11 + t11 * c11 + t12 * c12,
        f12 + t11 * c21 + t12 * c22,
        f22 + t21 * c21 + t22 * c22,
    )


# -- the recursions over rows ------------------------------------------------------------
def _lti(m, w1, w2, x_init):
    """``x_j = M x_{j-1} + w_j`` for ``j = 0..n-1`` from ``x_{-1} = x_init``, vectorised.

    ``(I - M z^-1)^-1 = adj(I - M z^-1) / det``: each state is a sum of second-order IIR
    filters (``scipy.signal.lfilter``) with denominator ``1 - tr(M) z^-1 + det(M) z^-2``;
    the initial state enters as ``M x_init`` added to ``w_0``.
    """
    (m11, m12), (m21, m22) = m
    w1 = np.array(w1, dtype=float)
    w2 = np.array(w2, dtype=float)
    w1[0] += m11 * x_init[0] + m12 * x_init[1]
    w2[0] += m21 * x_init[0] + m22 * x_init[1]
    den = [1.0, -(m11 + m22), m11 * m22 - m12 * m21]
    x1 = lfilter([1.0, -m22], den, w1) + lfilter([0.0, m12], den, w2)
    x2 = lfilter([0.0, m21], den, w1) + lfilter([1.0, -m11], den, w2)
    return x1, x2


def _filter_map(p, a, b, u, q11, q12, q22, y, r):
    """``(M, w)`` of the filtered mean ``x_j = update(predict(x_j-1))`` at a fixed
    covariance ``p``: ``x_j = M x_j-1 + w_j``, ``M`` the step with no input and no reading,
    ``w`` the step from ``x = 0`` with the inputs ``u`` and readings ``y`` (arrays)."""
    p11, p12, p22 = p

    def step(x1, x2, uu, yy):
        xp1, xp2, pp11, pp12, pp22 = predict(x1, x2, p11, p12, p22, a, b, uu, q11, q12, q22)
        return update(xp1, xp2, pp11, pp12, pp22, yy, r)[:2]

    c1, c2 = step(1.0, 0.0, 0.0, 0.0), step(0.0, 1.0, 0.0, 0.0)
    return ((c1[0], c2[0]), (c1[1], c2[1])), step(0.0, 0.0, u, y)


def _smoother_map(fa, pa, f_cov, p_cov, a, b):
    """``(M, w)`` of the smoothed mean ``x_k|N = rts_step(x_k+1|N)`` at fixed covariances,
    ``x_k|N = C x_k+1|N + (x_k|k - C x_k+1|k)``: ``M = C`` from the step with zero
    filtered and predicted means, ``w`` from ``x_k+1|N = 0`` with the means ``fa``, ``pa``
    (filtered and predicted, (2, n): one column per step)."""
    f11, f12, f22 = f_cov
    p11, p12, p22 = p_cov

    def step(s1, s2, fx1, fx2, px1, px2):
        return rts_step(fx1, fx2, f11, f12, f22, px1, px2, p11, p12, p22, s1, s2, 0, 0, 0, a, b)[:2]

    c1, c2 = step(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), step(0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    w = step(0.0, 0.0, fa[0], fa[1], pa[0], pa[1])
    return ((c1[0], c2[0]), (c1[1], c2[1])), w


def _same_step(b: np.ndarray) -> np.ndarray:
    """``same[k]``: row ``k``'s transition equals row ``k-1``'s (``b`` monotone in the step)."""
    same = np.zeros(b.size, dtype=bool)
    same[1:] = np.abs(b[1:] - b[:-1]) <= 1e-9 * np.abs(b[1:])
    return same


def _run_ends(same: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """``end[k]``: last row of the run starting at ``k`` in which every row has a reading
    and the same transition as the row before."""
    n = same.size
    ok = finite & same
    bad = np.flatnonzero(~ok)
    if bad.size == 0:
        return np.full(n, n - 1)
    pos = np.searchsorted(bad, np.arange(n), side="left")
    nxt = np.where(pos < bad.size, bad[np.minimum(pos, bad.size - 1)], n)
    return nxt - 1


def _nan_columns(m: int) -> list[array]:
    """Five arrays of ``m`` doubles, NaN."""
    return [array("d", [math.nan]) * m for _ in range(5)]


@dataclass(frozen=True, slots=True)
class _Carry:
    """The forward pass between two rows; restarting from it repeats the pass exactly."""

    state: tuple[float, float, float, float, float]  # filtered (x1, x2, P11, P12, P22)
    seen: int = 0  # finite readings so far (the first N_DIFFUSE are not in the likelihood)
    steady: bool = False  # the filtered covariance has converged under the current step
    last_p: tuple[float, float, float] = (math.nan, math.nan, math.nan)  # previous row's P


@dataclass(frozen=True, slots=True)
class _Forward:
    """Output of :func:`_forward` over ``m`` rows."""

    filt: np.ndarray | None  # (5, m) filtered x1, x2, P11, P12, P22; None if not stored
    pred: np.ndarray | None  # (5, m) predicted
    innov: np.ndarray  # (m,) innovations, NaN without a reading
    svar: np.ndarray  # (m,) their variances
    m2ll: float  # -2 log L of these rows
    stretches: tuple[tuple[int, int], ...]  # (first, last) rows solved in steady state
    carry: _Carry  # the state after the last row
    # the same as Python floats for the smoother's row-by-row steps: (filt, pred) as five
    # lists each, filled on the rows stepped one by one, at each stretch's first (pred)
    # and last (filt) row; and the lists of a and b
    lists: tuple[list[array], list[array], list[float], list[float]] | None = None


def _forward(
    carry: _Carry, rows: _Rows, r: float, *, offset: int, store: bool, fast: bool
) -> _Forward:
    """Kalman filter over ``m`` rows: :func:`predict` then :func:`update` on each.

    Row ``k``'s ``a, b, u, q..`` is the transition from row ``k-1`` (the row before the
    chunk for ``k = 0``); at the log's first row (``offset == 0``) ``carry.state`` is the
    prior and there is no prediction. A NaN ``y`` skips the update. With ``fast``, runs
    of at least ``MIN_STEADY_ROWS`` rows with readings and an unchanged step, once the
    covariance has converged (relative change < ``STEADY_RTOL``), are solved vectorised.
    ``-2 log L`` sums ``log(2 pi S) + e^2/S`` over readings after the first ``N_DIFFUSE``.
    """
    y, u = rows.y, rows.u
    m = len(y)
    yl, al, bl, ul = y.tolist(), rows.a.tolist(), rows.b.tolist(), u.tolist()
    q11l, q12l, q22l = rows.q11.tolist(), rows.q12.tolist(), rows.q22.tolist()
    samel = rows.same.tolist()
    end: list[int] = _run_ends(rows.same, np.isfinite(y)).tolist() if fast else []
    x1, x2, p11, p12, p22 = carry.state
    seen, steady = carry.seen, carry.steady
    o11, o12, o22 = carry.last_p
    # stored states: one preallocated array of doubles per component (no Python float kept
    # per value, and numpy reads it without a copy)
    fcols = _nan_columns(m if store else 0)
    pcols = _nan_columns(m if store else 0)
    f0, f1, f2, f3, f4 = fcols
    g0, g1, g2, g3, g4 = pcols
    stretch_states = []
    # innovations and their variances (NaN: no reading), row by row into the doubles,
    # stretches through numpy views of the same memory
    innov_d, svar_d = array("d", [math.nan]) * m, array("d", [math.nan]) * m
    innov, svar = np.frombuffer(innov_d), np.frombuffer(svar_d)
    m2ll = 0.0
    log2pi = math.log(2.0 * math.pi)
    log = math.log
    stretches = []
    k = 0
    while k < m:
        if fast and steady and seen >= N_DIFFUSE and end[k] - k + 1 >= MIN_STEADY_ROWS:
            # steady state: P-, S, K and P+ are those of row k on every row to k1, so the
            # means follow x_j = M x_j-1 + w_j with M and w from the same predict/update
            k1 = end[k]
            ak, bk, qa, qb, qc = al[k], bl[k], q11l[k], q12l[k], q22l[k]
            ys, us = y[k : k1 + 1], u[k : k1 + 1]
            mm, w = _filter_map((p11, p12, p22), ak, bk, us, qa, qb, qc, ys, r)
            xf1, xf2 = _lti(mm, w[0], w[1], (x1, x2))
            prev1 = np.concatenate(([x1], xf1[:-1]))
            prev2 = np.concatenate(([x2], xf2[:-1]))
            xp1, xp2, pp11, pp12, pp22 = predict(
                prev1, prev2, p11, p12, p22, ak, bk, us, qa, qb, qc
            )
            _, _, p11, p12, p22, e, s = update(xp1, xp2, pp11, pp12, pp22, ys, r)
            innov[k : k1 + 1] = e
            svar[k : k1 + 1] = s
            m2ll += float(np.sum(e * e)) / s + e.size * (log2pi + log(s))
            seen += e.size
            x1, x2 = float(xf1[-1]), float(xf2[-1])
            if store:
                stretch_states.append(
                    (k, k1, (xp1, xp2, pp11, pp12, pp22), (xf1, xf2, p11, p12, p22))
                )
                for col, v in zip(
                    pcols, (float(xp1[0]), float(xp2[0]), pp11, pp12, pp22), strict=True
                ):
                    col[k] = v
                for col, v in zip(fcols, (x1, x2, p11, p12, p22), strict=True):
                    col[k1] = v
            o11, o12, o22 = p11, p12, p22
            stretches.append((k, k1))
            k = k1 + 1
            continue
        if k or offset:
            x1, x2, p11, p12, p22 = predict(
                x1, x2, p11, p12, p22, al[k], bl[k], ul[k], q11l[k], q12l[k], q22l[k]
            )
        if store:
            g0[k], g1[k], g2[k], g3[k], g4[k] = x1, x2, p11, p12, p22
        yk = yl[k]
        if yk == yk:  # not NaN
            x1, x2, p11, p12, p22, e, s = update(x1, x2, p11, p12, p22, yk, r)
            innov_d[k] = e
            svar_d[k] = s
            if seen >= N_DIFFUSE:
                m2ll += log2pi + log(s) + e * e / s
            seen += 1
            if not samel[k]:
                steady = False
            elif not (offset + k) & 15:  # test convergence every 16th row (<= 16 rows late)
                scale = STEADY_RTOL * (abs(p11) + abs(p22))
                steady = (
                    abs(p11 - o11) <= scale and abs(p12 - o12) <= scale and abs(p22 - o22) <= scale
                )
            o11, o12, o22 = p11, p12, p22
        else:
            steady = False
            o11 = o12 = o22 = math.nan
        if store:
            f0[k], f1[k], f2[k], f3[k], f4[k] = x1, x2, p11, p12, p22
        k += 1
    out = _Carry((x1, x2, p11, p12, p22), seen, steady, (o11, o12, o22))
    if not store:
        return _Forward(None, None, innov, svar, m2ll, tuple(stretches), out)
    filt = np.vstack([np.frombuffer(c) for c in fcols])
    pred = np.vstack([np.frombuffer(c) for c in pcols])
    for k, k1, ps, fs in stretch_states:
        for i in range(5):
            pred[i, k : k1 + 1] = ps[i]
            filt[i, k : k1 + 1] = fs[i]
    lists = (fcols, pcols, al, bl)
    return _Forward(filt, pred, innov, svar, m2ll, tuple(stretches), out, lists)


def _backward(filt, pred, lists, stretches, nxt, *, fast) -> np.ndarray:
    """RTS smoother over ``m`` rows: :func:`rts_step` from the last row back to the first.

    ``filt``, ``pred`` (5, m) and ``lists`` come from :func:`_forward` (``lists``: the
    same as Python floats where the rows are stepped one by one, with ``a`` and ``b``:
    row ``k`` the step into row ``k``). ``nxt`` is None when the rows end the log (the
    last row's smoothed state is its filtered one), else ``(smoothed, predicted, a, b)``
    of the row after them. With ``fast``, the rows of a steady stretch share ``P_k|k``,
    ``P_k+1|k`` and ``F``, hence the gain ``C``: their means are solved vectorised, their
    covariance iterated only until it stops changing. Returns (5, m) smoothed states.
    """
    m = filt.shape[1]
    (f0, f1, f2, f3, f4), (g0, g1, g2, g3, g4), al, bl = lists
    ocols = _nan_columns(m)
    o0, o1, o2, o3, o4 = ocols
    stretch_out = []
    k = m - 1
    if nxt is None:
        cur = (f0[k], f1[k], f2[k], f3[k], f4[k])
    else:  # the last row of a chunk is never inside a stretch's shared-gain range
        s_next, p, a_next, b_next = nxt
        cur = rts_step(
            f0[k], f1[k], f2[k], f3[k], f4[k], p[0], p[1], p[2], p[3], p[4],
            s_next[0], s_next[1], s_next[2], s_next[3], s_next[4], a_next, b_next,
        )  # fmt: skip
    o0[k], o1[k], o2[k], o3[k], o4[k] = cur
    k -= 1
    starts = {k1: k0 for k0, k1 in stretches} if fast else {}
    while k >= 0:
        k0 = starts.get(k + 1)
        if k0 is None or k0 >= k:  # a plain row
            j = k + 1
            cur = rts_step(
                f0[k], f1[k], f2[k], f3[k], f4[k], g0[j], g1[j], g2[j], g3[j], g4[j],
                cur[0], cur[1], cur[2], cur[3], cur[4], al[j], bl[j],
            )  # fmt: skip
            o0[k], o1[k], o2[k], o3[k], o4[k] = cur
            k -= 1
            continue
        # rows k0..k of a steady stretch: x_j|N = C x_j+1|N + (x_j|j - C x_j+1|j)
        lo = k0
        f11, f12, f22 = filt[2:, k].tolist()
        p11, p12, p22 = pred[2:, k + 1].tolist()
        ak, bk = al[k + 1], bl[k + 1]
        fa = filt[:2, lo : k + 1][:, ::-1]  # rows k, k-1, ..., lo
        pa = pred[:2, lo + 1 : k + 2][:, ::-1]  # rows k+1, ..., lo+1 (ends in its chunk)
        mm, w = _smoother_map(fa, pa, (f11, f12, f22), (p11, p12, p22), ak, bk)
        s1, s2 = _lti(mm, w[0], w[1], cur[:2])
        # covariance: P_j|N = P_j|j + C (P_j+1|N - P_j+1|j) C^T, constant once it settles
        s11, s12, s22 = cur[2:]
        covs = []
        j = k
        while j >= lo:
            _, _, n11, n12, n22 = rts_step(
                0.0, 0.0, f11, f12, f22, 0.0, 0.0, p11, p12, p22, 0.0, 0.0, s11, s12, s22, ak, bk
            )
            scale = 1e-14 * (abs(n11) + abs(n22))
            fixed = abs(n11 - s11) <= scale and abs(n12 - s12) <= scale and abs(n22 - s22) <= scale
            s11, s12, s22 = n11, n12, n22
            covs.append((n11, n12, n22))
            j -= 1
            if fixed:
                break
        stretch_out.append((lo, k, s1[::-1], s2[::-1], j, covs[::-1], (s11, s12, s22)))
        cur = (float(s1[-1]), float(s2[-1]), s11, s12, s22)
        k = lo - 1
    out = np.vstack([np.frombuffer(c) for c in ocols])
    for lo, k, x1, x2, j, covs, settled in stretch_out:
        out[0, lo : k + 1] = x1
        out[1, lo : k + 1] = x2
        out[2:, j + 1 : k + 1] = np.array(covs).T  # rows j+1..k stepped one by one
        if j >= lo:
            out[2:, lo : j + 1] = np.array(settled)[:, None]  # the rest at the settled value
    return out


def _prior_carry(x0) -> _Carry:
    return _Carry((float(x0[0]), float(x0[1]), PRIOR_T_STD_C**2, 0.0, PRIOR_G_STD_C_PER_MIN**2))


def kalman_filter(y, a, b, u, q11, q12, q22, r, x0, p0, *, store=True):
    """Kalman filter for ``x' = [[a, b], [0, 1]] x + [u, 0] + w``, ``y = x[0] + v``.

    The plain row-by-row path (:func:`predict`, :func:`update` on every row). Row ``k``
    of ``a, b, u, q..`` is the transition from row ``k-1`` to ``k`` (row 0 is unused).
    ``x0 = (T, d)`` and ``p0 = (p11, p12, p22)`` are the prior at row 0. A NaN ``y``
    skips the update. Returns ``(filtered, predicted, innovations, innovation variances,
    -2 log-likelihood)``; ``filtered``/``predicted`` are ``(n, 5)`` arrays of ``(x1, x2,
    p11, p12, p22)`` per row (None when ``store`` is False: likelihood only).
    """
    yy, aa, bb, uu, qa, qb, qc = (np.asarray(v, dtype=float) for v in (y, a, b, u, q11, q12, q22))
    carry = _Carry((float(x0[0]), float(x0[1]), float(p0[0]), float(p0[1]), float(p0[2])))
    rows = _Rows(yy, _same_step(bb), aa, bb, uu, qa, qb, qc)
    fwd = _forward(carry, rows, r, offset=0, store=store, fast=False)
    if fwd.filt is None or fwd.pred is None:
        return None, None, fwd.innov, fwd.svar, fwd.m2ll
    return fwd.filt.T.copy(), fwd.pred.T.copy(), fwd.innov, fwd.svar, fwd.m2ll


def rts_smoother(filtered, predicted, a, b):
    """Rauch-Tung-Striebel smoother over the output of :func:`kalman_filter`.

    The plain path (:func:`rts_step` on every row). Returns arrays ``(x1, x2, p11, p12,
    p22)`` of the smoothed states and covariances.
    """
    filt = np.asarray(filtered, dtype=float).T
    pred = np.asarray(predicted, dtype=float).T
    lists = (filt.tolist(), pred.tolist(), np.asarray(a).tolist(), np.asarray(b).tolist())
    out = _backward(filt, pred, lists, (), None, fast=False)
    return tuple(out[i].copy() for i in range(5))


def filter_smooth(y, a, b, u, q11, q12, q22, r, x0, p0, *, smooth=True):
    """:func:`kalman_filter` then :func:`rts_smoother`, with the steady-state fast path.

    Where the sampling step stays constant and every row has a reading, the filter's
    covariance converges; once its relative change is below ``STEADY_RTOL`` the gain,
    the covariances and the smoother gain ``C`` stay constant and the mean recursions are
    linear time-invariant, solved vectorised by :func:`_lti` (with the same
    :func:`predict`/:func:`update`/:func:`rts_step` evaluated on arrays). Elsewhere
    (start-up, NaN rows, gaps, irregular steps) the rows are stepped one by one. Results
    equal the plain path to ~1e-8 relative (tested).

    Arguments are numpy arrays (``y`` NaN where there is no reading). Returns
    ``(x1, x2, p11, p12, p22, innovations, innovation variances, -2 log L)`` as arrays
    (the first five None when ``smooth`` is False: the filter's likelihood only).
    """
    yy, aa, bb, uu, qa, qb, qc = (np.asarray(v, dtype=float) for v in (y, a, b, u, q11, q12, q22))
    carry = _Carry((float(x0[0]), float(x0[1]), float(p0[0]), float(p0[1]), float(p0[2])))
    rows = _Rows(yy, _same_step(bb), aa, bb, uu, qa, qb, qc)
    fwd = _forward(carry, rows, r, offset=0, store=smooth, fast=True)
    if not smooth:
        return None, None, None, None, None, fwd.innov, fwd.svar, fwd.m2ll
    out = _backward(fwd.filt, fwd.pred, fwd.lists, fwd.stretches, None, fast=True)
    return (*(out[i].copy() for i in range(5)), fwd.innov, fwd.svar, fwd.m2ll)


# -- quantisation and noise levels ---------------------------------------------------------
def quantisation_step(values_c: np.ndarray) -> float:
    """The sensor's resolution if the readings lie on a grid, else 0.

    The step is the 5th percentile of the spacings of the distinct readings (robust to
    a stray off-grid value); the readings count as
    quantised when at least 90 % of those spacings are within 10 % of a whole multiple of
    it (a real ADC grid, e.g. TCLab's ~0.32 degC, is not perfectly even).
    """
    v = np.asarray(values_c, dtype=float)
    v = np.unique(np.round(v[np.isfinite(v)], 9))
    if v.size < 3:
        return 0.0
    d = np.diff(v)
    step = float(np.percentile(d, 5))
    if step <= 0:
        return 0.0
    ratio = d / step
    near = np.abs(ratio - np.round(ratio)) <= 0.1
    return step if near.mean() >= 0.9 else 0.0


@dataclass(frozen=True, slots=True)
class NoiseLevels:
    """Process and measurement noise of the filter.

    ``q``: spectral density of the gradient's random walk, (degC/min^2)^2/min;
    ``r``: measurement variance, degC^2 (includes the quantisation floor ``quant_c^2/12``);
    ``quant_c``: sensor resolution used for the floor, degC; ``fitted``: names of the
    levels chosen by maximum likelihood (the others were given by the user).
    """

    q: float
    r: float
    quant_c: float
    fitted: tuple[str, ...]

    def __post_init__(self) -> None:
        for name in ("q", "r"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ParameterError(f"{name} must be a finite number > 0, got {v!r}")


def _check_level(name: str, value: float | None, unit: str) -> float | None:
    if value is None:
        return None
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ParameterError(f"{name} must be > 0 {unit}, got {value!r}")
    return v


# -- the models as row sources --------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Rows:
    """Filter inputs of rows ``lo..hi-1`` (row ``k``: the step into it)."""

    y: np.ndarray
    same: np.ndarray
    a: np.ndarray
    b: np.ndarray
    u: np.ndarray
    q11: np.ndarray
    q12: np.ndarray
    q22: np.ndarray


@dataclass(frozen=True, slots=True)
class _Setup:
    """Everything the filter needs except the noise levels, computed chunk by chunk.

    ``time_s``, ``y`` and ``chamber_c`` are the log's arrays (not copied); ``model`` is
    None for the kinematic model; ``u_merged`` replaces the chamber input of a strided
    copy (the exact input over each merged step).
    """

    time_s: np.ndarray
    y: np.ndarray
    model: FirstOrderLag | None
    chamber_c: np.ndarray | None = None
    u_merged: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.y.size)

    @property
    def x0(self) -> tuple[float, float]:
        return float(self.y[int(np.argmax(np.isfinite(self.y)))]), 0.0

    def steps(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(h_min, same, u)`` of rows ``lo..hi-1`` (``h = 0``, ``u = 0`` at row 0).

        ``same[k]``: the step into row ``k`` equals the step into row ``k-1`` up to the
        rounding of the logged times (the steady-state path may then share one transition).
        """
        a0 = max(lo - 1, 0)  # the steps of rows a0..hi-1 are needed for `same`
        t = self.time_s[max(a0 - 1, 0) : hi] / 60.0
        h_ext = np.diff(t) if a0 > 0 else np.concatenate(([0.0], np.diff(t)))
        t_rows = self.time_s[a0 + 1 : hi] / 60.0
        tol = 1e-9 * h_ext[1:] + 8.0 * np.finfo(float).eps * np.abs(t_rows)
        same_ext = np.concatenate(([False], np.abs(np.diff(h_ext)) <= tol))
        h, same = (h_ext[1:], same_ext[1:]) if lo > 0 else (h_ext, same_ext)
        u = np.zeros(h.size)
        if self.u_merged is not None:
            u = self.u_merged[lo:hi].copy()
        elif self.model is not None:
            assert self.chamber_c is not None  # set with the model
            first = 1 if lo == 0 else 0
            tk = self.chamber_c
            u[first:] = lag_input(
                h[first:], tk[lo - 1 + first : hi - 1], tk[lo + first : hi], self.model
            )
        return h, same, u

    def rows(self, lo: int, hi: int, q: float) -> _Rows:
        h, same, u = self.steps(lo, hi)
        if self.model is None:
            a, b, q11, q12, q22 = kinematic_transition(h, q)
        else:
            a, b, q11, q12, q22 = lag_transition(h, self.model, q)
        return _Rows(self.y[lo:hi], same, a, b, u, q11, q12, q22)

    def stride(self, step: int) -> _Setup:
        """Every ``step``-th row, with exact transitions over the merged steps."""
        if step <= 1:
            return self
        idx = np.arange(0, self.n, step)
        u = None
        if self.model is not None:
            # compose T' = e T + u over the fine steps of each coarse step:
            # u_c = sum_j u_j prod_{i > j} e_i  (exact for the chamber-driven part)
            u = np.zeros(idx.size)
            group = max(1, CHUNK_ROWS // step) * step  # whole coarse steps per chunk
            for lo in range(1, int(idx[-1]) + 1, group):
                hi = min(lo + group, int(idx[-1]) + 1)
                h, _, uf = self.steps(lo, hi)
                log_e = np.log1p(-self.model.step(h))  # log e_i
                cum = np.cumsum(log_e)
                rows = np.arange(lo, hi)
                coarse = (rows + step - 1) // step  # coarse step of each fine row
                last = coarse * step - lo  # its last fine row, local
                w = uf * np.exp(cum[last] - cum[rows - lo])
                u += np.bincount(coarse, weights=w, minlength=idx.size)[: idx.size]
        return _Setup(self.time_s[idx], self.y[idx], self.model, None, u)


def _chunks(n: int) -> list[tuple[int, int]]:
    return [(lo, min(lo + CHUNK_ROWS, n)) for lo in range(0, n, CHUNK_ROWS)]


def _likelihood(setup: _Setup, q: float, r: float) -> float:
    """``-2 log L`` of the innovations (the filter only, chunk by chunk)."""
    carry = _prior_carry(setup.x0)
    m2ll = 0.0
    for lo, hi in _chunks(setup.n):
        fwd = _forward(carry, setup.rows(lo, hi, q), r, offset=lo, store=False, fast=True)
        m2ll += fwd.m2ll
        carry = fwd.carry
    return m2ll


def _smooth(setup: _Setup, q: float, r: float, keep: np.ndarray | None, emit, progress):
    """Filter and smooth ``setup`` in chunks; ``emit(rows, smoothed, innov, svar)`` gets
    the kept rows (global indices or a slice) of each chunk, last chunk first. Returns
    -2 log L.

    Forward: the filter over every chunk, keeping its state at each chunk start.
    Backward: each chunk re-filtered from its checkpoint (kept outright when the log is
    one chunk), then smoothed from the next chunk's first smoothed row.
    """
    bounds = _chunks(setup.n)
    single = len(bounds) == 1
    carry = _prior_carry(setup.x0)
    checkpoints = []
    kept_fwd: tuple[_Rows, _Forward] | None = None
    innov_parts = []
    m2ll = 0.0
    for lo, hi in bounds:
        rw = setup.rows(lo, hi, q)
        checkpoints.append(carry)
        fwd = _forward(carry, rw, r, offset=lo, store=single, fast=True)
        if single:
            kept_fwd = (rw, fwd)
        sel = _kept(keep, lo, hi)
        innov_parts.append((fwd.innov[sel], fwd.svar[sel]))
        m2ll += fwd.m2ll
        carry = fwd.carry
        if progress is not None:
            progress("filter", hi, setup.n)
    nxt = None
    for (lo, hi), cp, (inn, sv) in zip(
        reversed(bounds), reversed(checkpoints), reversed(innov_parts), strict=True
    ):
        if kept_fwd is not None:
            rw, fwd = kept_fwd
        else:
            rw = setup.rows(lo, hi, q)
            fwd = _forward(cp, rw, r, offset=lo, store=True, fast=True)
        assert fwd.filt is not None and fwd.pred is not None  # stored
        sm = _backward(fwd.filt, fwd.pred, fwd.lists, fwd.stretches, nxt, fast=True)
        nxt = (tuple(sm[:, 0].tolist()), tuple(fwd.pred[:, 0].tolist()), rw.a[0], rw.b[0])
        sel = _kept(keep, lo, hi)
        emit(_global(sel, lo), sm[:, sel], inn, sv)
        if progress is not None:
            progress("smoother", setup.n - lo, setup.n)
    return m2ll


def _kept(keep: np.ndarray | None, lo: int, hi: int) -> np.ndarray | slice:
    """Local indices (within rows ``lo..hi-1``) of the kept rows; a slice when all are."""
    if keep is None:
        return slice(0, hi - lo)
    return keep[np.searchsorted(keep, lo) : np.searchsorted(keep, hi)] - lo


def _global(sel: np.ndarray | slice, lo: int) -> np.ndarray | slice:
    if isinstance(sel, slice):
        return slice(lo + sel.start, lo + sel.stop)
    return sel + lo


def _second_difference_var(y: np.ndarray) -> tuple[float, int]:
    """Variance and count of the second differences of the finite readings (chunked)."""
    tail = np.zeros(0)
    n = 0
    s1 = s2 = 0.0
    for lo, hi in _chunks(y.size):
        yf = y[lo:hi]
        yf = np.concatenate((tail, yf[np.isfinite(yf)]))
        d2 = np.diff(yf, 2)
        n += d2.size
        s1 += float(d2.sum())
        s2 += float(np.sum(d2 * d2))
        tail = yf[-2:]
    if n == 0:
        return 0.0, 0
    mean = s1 / n
    return max(s2 / n - mean * mean, 0.0), n


def _fit_noise(
    setup: _Setup, q: float | None, r: float | None, quant_c: float, progress=None
) -> NoiseLevels:
    """Maximum likelihood of the innovations over the free levels (log-parametrised)."""
    floor = quant_c**2 / 12.0
    fitted = tuple(n for n, v in (("q", q), ("r", r)) if v is None)
    if q is not None and r is not None:
        return NoiseLevels(q, r, quant_c, ())
    n = setup.n
    step = 1 if n <= FULL_RATE_ML_ROWS else int(math.ceil(n / MAX_ML_ROWS))
    coarse = setup.stride(step)
    if int(np.isfinite(coarse.y).sum()) < max(20, N_DIFFUSE + 3):
        coarse = setup
    # starting point: white noise dominates second differences, var(d2 y) ~ 6 r
    var_d2, n_d2 = _second_difference_var(setup.y)
    r_start = max(var_d2 / 6.0, 1e-8) if n_d2 > 1 else 1e-4
    r_extra_start = max(r_start - floor, 1e-3 * r_start)
    calls = [0]

    def levels(theta):
        # clipped to the bounds: Nelder-Mead is unbounded, the filter needs r > 0
        i = 0
        qq = q
        if q is None:
            qq = math.exp(min(max(theta[i], LOG_Q_BOUNDS[0]), LOG_Q_BOUNDS[1]))
            i += 1
        if r is None:
            rr = floor + math.exp(min(max(theta[i], LOG_R_BOUNDS[0]), LOG_R_BOUNDS[1]))
        else:
            rr = r
        return qq, rr

    def cost(theta):
        qq, rr = levels(theta)
        m2ll = _likelihood(coarse, qq, rr)
        calls[0] += 1
        if progress is not None:
            progress("noise levels", calls[0], 0)
        return m2ll if math.isfinite(m2ll) else 1e300

    if q is None:
        # coarse scan of q (the likelihood is often flat far from the optimum)
        grid = np.arange(-12.0, 3.0, 2.0) * math.log(10.0)
        best: tuple[float, float] | None = None
        for lq in grid:
            theta = [lq] + ([] if r is not None else [math.log(r_extra_start)])
            c = cost(theta)
            if best is None or c < best[0]:
                best = (c, lq)
        assert best is not None  # the grid is not empty
        start = [best[1]]
    else:
        start = []
    if r is None:
        start.append(math.log(r_extra_start))
    # initial simplex one unit (a factor e) along each log level: scipy's default (5 % of
    # the coordinate) is degenerate at log q = 0
    x0 = np.array(start)
    simplex = np.vstack([x0, x0 + np.eye(x0.size)])
    res = minimize(
        cost,
        x0,
        method="Nelder-Mead",
        options={"xatol": 0.05, "fatol": 0.05, "maxiter": 400, "initial_simplex": simplex},
    )
    qq, rr = levels(res.x)
    return NoiseLevels(qq, rr, quant_c, fitted)


# -- results --------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class GradientEstimate:
    """Smoothed internal temperature and gradient, one row per log row (or per kept row
    when the estimate was decimated with ``every_s``).

    Attributes
    ----------
    time_s : array
        Log times, s.
    t_est_c, t_std_c : array
        Smoothed internal temperature and its standard deviation, degC.
    g_est_c_per_min, g_std_c_per_min : array
        Smoothed gradient dT/dt and its standard deviation, degC/min.
    innovation_c, innovation_std_c : array
        Filter innovations ``y_k - T_k|k-1`` and their predicted standard deviations
        ``sqrt(S_k)``, degC (NaN on rows without a reading).
    noise : NoiseLevels
        ``q``, ``r`` and which of them were fitted.
    minus2_log_likelihood : float
        ``-2 log L`` of the innovations at the chosen noise levels (full-rate pass over
        every row, decimated or not).
    method : str
        ``"kinematic"`` or ``"model"`` (thermal model with the chamber as input).
    params : ThermalParams or None
        The thermal model of the model-based variant.
    every_s : float or None
        The decimation: one row every ``every_s`` seconds (None: every log row).
    """

    time_s: np.ndarray
    t_est_c: np.ndarray
    t_std_c: np.ndarray
    g_est_c_per_min: np.ndarray
    g_std_c_per_min: np.ndarray
    innovation_c: np.ndarray
    innovation_std_c: np.ndarray
    noise: NoiseLevels
    minus2_log_likelihood: float
    method: str
    params: ThermalParams | None = None
    every_s: float | None = None

    @property
    def q(self) -> float:
        return self.noise.q

    @property
    def r(self) -> float:
        return self.noise.r

    @property
    def log_likelihood(self) -> float:
        return -0.5 * self.minus2_log_likelihood

    @property
    def n_rows(self) -> int:
        return int(self.time_s.size)

    @property
    def time_min(self) -> np.ndarray:
        return self.time_s / 60.0

    @property
    def normalised_innovations(self) -> np.ndarray:
        """``e_k / sqrt(S_k)``: about N(0, 1) when the model and noise levels are right."""
        return self.innovation_c / self.innovation_std_c

    def take(self, rows: np.ndarray | slice) -> GradientEstimate:
        """The estimate at a subset of its rows (e.g. ``slice(0, None, 10)`` for plots)."""
        arrays = {
            name: getattr(self, name)[rows]
            for name in (
                "time_s",
                "t_est_c",
                "t_std_c",
                "g_est_c_per_min",
                "g_std_c_per_min",
                "innovation_c",
                "innovation_std_c",
            )
        }
        return GradientEstimate(
            **arrays,
            noise=self.noise,
            minus2_log_likelihood=self.minus2_log_likelihood,
            method=self.method,
            params=self.params,
            every_s=self.every_s,
        )

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame(
            {
                "time_s": self.time_s,
                "t_est_c": self.t_est_c,
                "g_est_c_per_min": self.g_est_c_per_min,
                "g_std_c_per_min": self.g_std_c_per_min,
                "t_std_c": self.t_std_c,
                "innovation_c": self.innovation_c,
                "innovation_std_c": self.innovation_std_c,
            }
        )

    def summary(self) -> str:
        fitted = ", ".join(self.noise.fitted) or "none"
        z = self.normalised_innovations
        z = z[np.isfinite(z)]
        every = "" if self.every_s is None else f"; one row every {self.every_s:g} s"
        return (
            f"{self.method} Kalman smoother: q = {self.q:.3g} (degC/min^2)^2/min, "
            f"r = {self.r:.3g} degC^2 (sigma {math.sqrt(self.r):.3g} degC; quantisation "
            f"{self.noise.quant_c:g} degC; fitted by ML: {fitted}); median gradient std "
            f"{np.nanmedian(self.g_std_c_per_min):.3g} degC/min; normalised innovations "
            f"std {np.std(z):.2f} (1 if consistent){every}"
        )


def decimation_rows(time_s: np.ndarray, every_s: float) -> np.ndarray:
    """Rows kept when a log is decimated to one row every ``every_s`` seconds.

    The first row of each ``every_s``-wide time bin counted from the first row
    (``floor((t - t_0) / every_s)`` changes), so irregular logs and gaps keep at most one
    row per bin and every bin with a row keeps one.
    """
    if not (isinstance(every_s, int | float) and math.isfinite(every_s) and every_s > 0):
        raise ParameterError(f"every_s must be a number of seconds > 0, got {every_s!r}")
    t = np.asarray(time_s, dtype=float)
    parts = []
    prev = -1.0
    for lo, hi in _chunks(t.size):
        bins = np.floor((t[lo:hi] - t[0]) / every_s)
        new = np.flatnonzero(np.diff(np.concatenate(([prev], bins))) > 0) + lo
        parts.append(new)
        prev = float(bins[-1])
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def _resolve_quant(log: MeasuredLog, quant_c: float | None) -> float:
    if quant_c is None:
        y = log.t_int_c
        stride = max(1, int(math.ceil(y.size / QUANT_SAMPLE_ROWS)))
        return quantisation_step(y[::stride])
    v = float(quant_c)
    if not (math.isfinite(v) and v >= 0):
        raise ParameterError(f"quant_c must be >= 0 degC, got {quant_c!r}")
    return v


def _estimate(
    log: MeasuredLog,
    setup: _Setup,
    q: float | None,
    r: float | None,
    quant_c: float | None,
    every_s: float | None,
    grad,
    method: str,
    params: ThermalParams | None,
    progress: Progress | None,
) -> GradientEstimate:
    """Noise levels, then the chunked smoother; the kept rows go straight to the output."""
    q, r = _check_level("q", q, "(degC/min^2)^2/min"), _check_level("r", r, "degC^2")
    keep = None if every_s is None else decimation_rows(log.time_s, every_s)
    noise = _fit_noise(setup, q, r, _resolve_quant(log, quant_c), progress)
    n_out = setup.n if keep is None else keep.size
    cols = {n: np.empty(n_out) for n in ("t", "t_std", "g", "g_std", "innov", "innov_std")}

    def emit(rows, sm, innov, svar):
        # rows: global rows (a slice when every row is kept); i: their output positions
        i = rows if keep is None else np.searchsorted(keep, rows)
        g, g_var = grad(rows, sm[0], sm[1], sm[2], sm[3], sm[4])
        cols["t"][i] = sm[0]
        cols["t_std"][i] = np.sqrt(np.maximum(sm[2], 0.0))
        cols["g"][i] = g
        cols["g_std"][i] = np.sqrt(np.maximum(g_var, 0.0))
        cols["innov"][i] = innov
        cols["innov_std"][i] = np.sqrt(svar)

    m2ll = _smooth(setup, noise.q, noise.r, keep, emit, progress)
    return GradientEstimate(
        time_s=log.time_s if keep is None else log.time_s[keep],
        t_est_c=cols["t"],
        t_std_c=cols["t_std"],
        g_est_c_per_min=cols["g"],
        g_std_c_per_min=cols["g_std"],
        innovation_c=cols["innov"],
        innovation_std_c=cols["innov_std"],
        noise=noise,
        minus2_log_likelihood=float(m2ll),
        method=method,
        params=params,
        every_s=None if every_s is None else float(every_s),
    )


def estimate_gradient(
    log: MeasuredLog,
    *,
    q: float | None = None,
    r: float | None = None,
    quant_c: float | None = None,
    every_s: float | None = None,
    progress: Progress | None = None,
) -> GradientEstimate:
    """Kinematic Kalman smoother: ``(T, g)`` with the gradient a random walk.

    Parameters
    ----------
    log : MeasuredLog
        The run (NaN readings are skipped, gaps handled exactly).
    q : float, optional
        Gradient random-walk density, (degC/min^2)^2/min; fitted by ML when None.
    r : float, optional
        Measurement variance, degC^2 (total, including quantisation); ML when None.
    quant_c : float, optional
        Sensor resolution, degC, for the floor ``r >= quant_c^2/12`` of the ML search;
        detected from the readings when None (see :func:`quantisation_step`).
    every_s : float, optional
        Keep one row every ``every_s`` seconds (:func:`decimation_rows`); every row is
        still filtered, only the output is thinned (and its memory with it).
    progress : callable(stage, done, total), optional
        Told how far the noise search, the filter and the smoother are.
    """
    setup = _Setup(log.time_s, np.asarray(log.t_int_c, dtype=float), None)

    def grad(rows, x1, x2, p11, p12, p22):
        return x2, p22

    return _estimate(log, setup, q, r, quant_c, every_s, grad, "kinematic", None, progress)


def estimate_gradient_model(
    log: MeasuredLog,
    params: ThermalParams | None = None,
    *,
    chamber: str = "tk_set_c",
    q: float | None = None,
    r: float | None = None,
    quant_c: float | None = None,
    every_s: float | None = None,
    progress: Progress | None = None,
) -> GradientEstimate:
    """Model-based Kalman smoother: the thermal model driven by the logged chamber.

    State ``(T, d)``; the gradient is ``g = (Tk + dT0 - T)/tau + d`` where ``d`` is a
    random-walk correction for what the model misses (see the module docstring). With a
    correct model, ``d`` stays near 0 and the gradient follows the chamber without lag.

    Parameters
    ----------
    params : ThermalParams, optional
        ``tau_s`` and ``dt0_c`` of the device (default :class:`ThermalParams`).
    chamber : {"tk_set_c", "tk_air_c"}
        Which logged chamber temperature drives the model (it must have no NaN).
    q, r, quant_c, every_s, progress
        As in :func:`estimate_gradient`; ``q`` is the density of the correction ``d``.
    """
    params = ThermalParams() if params is None else params
    if chamber not in ("tk_set_c", "tk_air_c"):
        raise ParameterError(f"chamber must be 'tk_set_c' or 'tk_air_c', got {chamber!r}")
    tk = getattr(log, chamber)
    if tk is None:
        raise LogFormatError(
            f"{log.source}: the model-based estimate needs the chamber column {chamber}, "
            "which the log does not have; use the kinematic estimate instead"
        )
    if np.isnan(tk).any():
        rows = np.flatnonzero(np.isnan(tk))
        raise LogFormatError(
            f"{log.source}: column {chamber} has {rows.size} NaN row(s) (first: row "
            f"{rows[0] + 1}); the model needs the chamber temperature on every row"
        )
    model = FirstOrderLag(params)
    setup = _Setup(log.time_s, np.asarray(log.t_int_c, dtype=float), model, tk)
    tau = params.tau_min

    def grad(rows, x1, x2, p11, p12, p22):
        # g = (Tk + dT0 - T)/tau + d ;  var g = P11/tau^2 - 2 P12/tau + P22
        g = (tk[rows] + params.dt0_c - x1) / tau + x2
        return g, p11 / tau**2 - 2.0 * p12 / tau + p22

    return _estimate(log, setup, q, r, quant_c, every_s, grad, "model", params, progress)


def finite_difference_gradient(time_s: np.ndarray, t_c: np.ndarray) -> np.ndarray:
    """Plain central finite difference of the samples, degC/min (the baseline).

    ``g_k = (y_{k+1} - y_{k-1}) / (t_{k+1} - t_{k-1})`` (one-sided at the ends, via
    ``numpy.gradient``); NaN readings propagate.
    """
    return np.gradient(np.asarray(t_c, dtype=float), np.asarray(time_s, dtype=float) / 60.0)
