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

with ``Tk`` linear between samples; exactly, with ``e = exp(-h/tau)``::

    T' = e T + tau (1 - e) d + u,   u = (1 - e)(Tk_k + dT0) + s R(h)   (s: Tk slope)
    Q11 = q tau^3 (x - 2(1 - e) + (1 - e^2)/2),  Q12 = q tau R(h),  Q22 = q h,  x = h/tau

where ``R(h) = h - tau (1 - e)`` is the model's unit-ramp response
(:meth:`schedsyn.model.FirstOrderLag.ramp`; ``u`` comes from the same model object).

Both have ``F = [[a, b], [0, 1]]`` and measure the first state, so one scalar filter
serves both. The noise levels ``(q, r)`` maximise the likelihood of the innovations
(``r`` is at least the quantisation floor ``step^2/12``); a user may fix either. A NaN
reading only skips the measurement update: the row still gets an estimate.
"""

from __future__ import annotations

import math
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


# -- discretisation (pure, vectorised) --------------------------------------------------
def kinematic_transition(h_min: np.ndarray, q: float):
    """``(a, b, q11, q12, q22)`` of the integrated random walk over steps ``h_min``.

    ``F = [[1, h], [0, 1]]``, ``Q = q [[h^3/3, h^2/2], [h^2/2, h]]``.
    """
    h = np.asarray(h_min, dtype=float)
    return np.ones_like(h), h, q * h**3 / 3.0, q * h**2 / 2.0, q * h


def lag_transition(h_min: np.ndarray, tau_min: float, q: float):
    """``(a, b, q11, q12, q22)`` of the first-order lag with a random-walk correction.

    ``a = e = exp(-h/tau)``, ``b = tau (1 - e)``; ``Q`` as in the module docstring, with a
    series for ``Q11`` at small ``x = h/tau`` (``x^3/3 - x^4/4 + 7 x^5/60``) where the
    closed form cancels.
    """
    h = np.asarray(h_min, dtype=float)
    x = h / tau_min
    one_minus_e = -np.expm1(-x)
    closed = x - 2.0 * one_minus_e - 0.5 * np.expm1(-2.0 * x)
    series = x**3 / 3.0 - x**4 / 4.0 + 7.0 * x**5 / 60.0
    q11 = q * tau_min**3 * np.where(x < 1e-2, series, closed)
    ramp = h - tau_min * one_minus_e  # R(h)
    return 1.0 - one_minus_e, tau_min * one_minus_e, q11, q * tau_min * ramp, q * h


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


# -- the filter and the smoother (scalar 2x2 maths; fast in plain Python) ----------------
def kalman_filter(y, a, b, u, q11, q12, q22, r, x0, p0, *, store=True):
    """Kalman filter for ``x' = [[a, b], [0, 1]] x + [u, 0] + w``, ``y = x[0] + v``.

    Row ``k`` of ``a, b, u, q..`` (lists of floats) is the transition from row ``k-1`` to
    ``k`` (row 0 is unused). ``x0 = (T, d)`` and ``p0 = (p11, p12, p22)`` are the prior at
    row 0. A NaN ``y`` skips the update. Returns ``(filtered, predicted, innovations,
    innovation variances, -2 log-likelihood)``; ``filtered``/``predicted`` are lists of
    ``(x1, x2, p11, p12, p22)`` per row (empty when ``store`` is False: likelihood only).

    Equations (``P`` symmetric)::

        predict  x1- = a x1 + b x2 + u          P11- = a^2 P11 + 2ab P12 + b^2 P22 + Q11
                 x2- = x2                       P12- = a P12 + b P22 + Q12
                                                P22- = P22 + Q22
        update   e = y - x1-,  S = P11- + r,  K = (P11-, P12-)/S
                 x+ = x- + K e,  P+ = P- - K K^T S
        -2 log L = sum over finite y (after the first N_DIFFUSE) of log(2 pi S) + e^2/S

    Written with scalar floats over Python lists: a 2x2 step costs ~2 us, far less than
    numpy's per-call overhead on 2x2 arrays.
    """
    n = len(y)
    x1, x2 = float(x0[0]), float(x0[1])
    p11, p12, p22 = (float(v) for v in p0)
    filt: list[tuple[float, float, float, float, float]] = []
    pred: list[tuple[float, float, float, float, float]] = []
    innov = [math.nan] * n
    svar = [math.nan] * n
    m2ll = 0.0
    seen = 0
    log2pi = math.log(2.0 * math.pi)
    log = math.log
    keep_f, keep_p = filt.append, pred.append
    for k in range(n):
        if k:
            ak, bk = a[k], b[k]
            x1 = ak * x1 + bk * x2 + u[k]
            t = ak * p12 + bk * p22
            p11 = ak * (ak * p11 + bk * p12) + bk * t + q11[k]
            p12 = t + q12[k]
            p22 = p22 + q22[k]
        if store:
            keep_p((x1, x2, p11, p12, p22))
        yk = y[k]
        if yk == yk:  # not NaN
            s = p11 + r
            e = yk - x1
            k1 = p11 / s
            k2 = p12 / s
            x1 += k1 * e
            x2 += k2 * e
            p22 -= k2 * p12
            p12 -= k1 * p12
            p11 -= k1 * p11
            innov[k] = e
            svar[k] = s
            if seen >= N_DIFFUSE:
                m2ll += log2pi + log(s) + e * e / s
            seen += 1
        if store:
            keep_f((x1, x2, p11, p12, p22))
    return filt, pred, innov, svar, m2ll


def rts_smoother(filtered, predicted, a, b):
    """Rauch-Tung-Striebel smoother over the output of :func:`kalman_filter`.

    Backwards from the last row, with ``F = [[a, b], [0, 1]]`` of the step ``k -> k+1``::

        C_k = P_k|k F^T (P_k+1|k)^-1
        x_k|N = x_k|k + C_k (x_k+1|N - x_k+1|k)
        P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k^T

    Returns arrays ``(x1, x2, p11, p12, p22)`` of the smoothed states and covariances.
    """
    n = len(filtered)
    out = [filtered[-1]] * n
    x1, x2, p11, p12, p22 = filtered[-1]
    for k in range(n - 2, -1, -1):
        ak, bk = a[k + 1], b[k + 1]
        fx1, fx2, f11, f12, f22 = filtered[k]
        px1, px2, q11_, q12_, q22_ = predicted[k + 1]
        # M = P_k|k F^T
        m11 = f11 * ak + f12 * bk
        m21 = f12 * ak + f22 * bk
        # C = M (P_k+1|k)^-1
        det = q11_ * q22_ - q12_ * q12_
        c11 = (m11 * q22_ - f12 * q12_) / det
        c12 = (f12 * q11_ - m11 * q12_) / det
        c21 = (m21 * q22_ - f22 * q12_) / det
        c22 = (f22 * q11_ - m21 * q12_) / det
        d1 = x1 - px1
        d2 = x2 - px2
        x1 = fx1 + c11 * d1 + c12 * d2
        x2 = fx2 + c21 * d1 + c22 * d2
        e11 = p11 - q11_
        e12 = p12 - q12_
        e22 = p22 - q22_
        # P = P_k|k + C E C^T
        t11 = c11 * e11 + c12 * e12
        t12 = c11 * e12 + c12 * e22
        t21 = c21 * e11 + c22 * e12
        t22 = c21 * e12 + c22 * e22
        p11 = f11 + t11 * c11 + t12 * c12
        p12 = f12 + t11 * c21 + t12 * c22
        p22 = f22 + t21 * c21 + t22 * c22
        out[k] = (x1, x2, p11, p12, p22)
    arr = np.array(out, dtype=float)
    return tuple(arr[:, i].copy() for i in range(5))


# -- steady-state fast path (same results as kalman_filter + rts_smoother) ---------------
#: Relative change of the filtered covariance below which the filter counts as steady.
STEADY_RTOL = 1e-11
#: Shortest run of equal steps with readings worth the vectorised steady-state path.
MIN_STEADY_ROWS = 32


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


def _run_ends(b: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """``end[k]``: last row of the run starting at ``k`` in which every row has a reading
    and the same transition as the row before (``b`` is monotone in the step)."""
    n = b.size
    ok = finite.copy()
    ok[0] = False
    ok[1:] &= np.abs(b[1:] - b[:-1]) <= 1e-9 * np.abs(b[1:])
    bad = np.flatnonzero(~ok)
    pos = np.searchsorted(bad, np.arange(n), side="left")
    nxt = np.where(pos < bad.size, bad[np.minimum(pos, bad.size - 1)], n)
    return nxt - 1


def filter_smooth(y, a, b, u, q11, q12, q22, r, x0, p0, *, smooth=True):
    """:func:`kalman_filter` then :func:`rts_smoother`, with a steady-state fast path.

    Where the sampling step stays constant and every row has a reading, the filter's
    covariance converges; once its relative change is below ``STEADY_RTOL`` the gain,
    the covariances and the smoother gain ``C`` stay constant and the mean recursions are
    linear time-invariant (forwards ``x_k = (I - K H) F x_k-1 + (I - K H)[u_k, 0] +
    K y_k``, backwards ``x_k|N = C x_k+1|N + x_k|k - C x_k+1|k``), solved vectorised by
    :func:`_lti`. Elsewhere (start-up, NaN rows, gaps, irregular steps) the plain scalar
    recursions run. Results equal the plain path to ~1e-8 relative (tested).

    Arguments are numpy arrays (``y`` NaN where there is no reading). Returns
    ``(x1, x2, p11, p12, p22, innovations, innovation variances, -2 log L)`` as arrays
    (the first five None when ``smooth`` is False: the filter's likelihood only).
    """
    y = np.asarray(y, dtype=float)
    b = np.asarray(b, dtype=float)
    n = y.size
    end = _run_ends(b, np.isfinite(y)).tolist()
    same = np.zeros(n, dtype=bool)
    same[1:] = np.abs(b[1:] - b[:-1]) <= 1e-9 * np.abs(b[1:])
    samel = same.tolist()
    yl, al, bl, ul = y.tolist(), a.tolist(), b.tolist(), u.tolist()
    q11l, q12l, q22l = q11.tolist(), q12.tolist(), q22.tolist()
    x1, x2 = float(x0[0]), float(x0[1])
    p11, p12, p22 = (float(v) for v in p0)
    filt = np.empty((n, 5))
    pred = np.empty((n, 5))
    # plain rows are collected in lists and written into the arrays in bulk
    rows_l: list[int] = []
    filt_l: list[tuple] = []
    pred_l: list[tuple] = []
    innov_l: list[tuple] = []
    innov = np.full(n, np.nan)
    svar = np.full(n, np.nan)
    m2ll = 0.0
    seen = 0
    log2pi = math.log(2.0 * math.pi)
    steady = False  # the filtered covariance has converged under the current step
    o11 = o12 = o22 = math.nan  # the previous row's filtered covariance
    stretches = []  # (first_row, last_row) run in steady state
    k = 0
    while k < n:
        if steady and end[k] - k + 1 >= MIN_STEADY_ROWS and seen >= N_DIFFUSE:
            k1 = end[k]
            ak, bk = al[k], bl[k]
            t = ak * p12 + bk * p22
            pp11 = ak * (ak * p11 + bk * p12) + bk * t + q11l[k]
            pp12 = t + q12l[k]
            pp22 = p22 + q22l[k]
            s = pp11 + r
            g1, g2 = pp11 / s, pp12 / s
            m = ((1.0 - g1) * ak, (1.0 - g1) * bk), (-g2 * ak, 1.0 - g2 * bk)
            ys, us = y[k : k1 + 1], u[k : k1 + 1]
            # filtered means of the stretch: x_j = M x_j-1 + (I - K H)[u_j, 0] + K y_j
            xf1, xf2 = _lti(m, (1.0 - g1) * us + g1 * ys, g2 * (ys - us), (x1, x2))
            prev1 = np.concatenate(([x1], xf1[:-1]))
            prev2 = np.concatenate(([x2], xf2[:-1]))
            xp1 = ak * prev1 + bk * prev2 + us
            e = ys - xp1
            innov[k : k1 + 1] = e
            svar[k : k1 + 1] = s
            m2ll += float(np.sum(e * e)) / s + e.size * (log2pi + math.log(s))
            seen += e.size
            p11, p12, p22 = pp11 - g1 * pp11, pp12 - g1 * pp12, pp22 - g2 * pp12
            if smooth:
                pred[k : k1 + 1, 0] = xp1
                pred[k : k1 + 1, 1] = prev2
                pred[k : k1 + 1, 2:] = (pp11, pp12, pp22)
                filt[k : k1 + 1, 0] = xf1
                filt[k : k1 + 1, 1] = xf2
                filt[k : k1 + 1, 2:] = (p11, p12, p22)
            x1, x2 = float(xf1[-1]), float(xf2[-1])
            o11, o12, o22 = p11, p12, p22
            stretches.append((k, k1))
            k = k1 + 1
            continue
        if k:
            ak, bk = al[k], bl[k]
            x1 = ak * x1 + bk * x2 + ul[k]
            t = ak * p12 + bk * p22
            p11 = ak * (ak * p11 + bk * p12) + bk * t + q11l[k]
            p12 = t + q12l[k]
            p22 = p22 + q22l[k]
        if smooth:
            pred_l.append((x1, x2, p11, p12, p22))
        yk = yl[k]
        if yk == yk:
            s = p11 + r
            e = yk - x1
            g1 = p11 / s
            g2 = p12 / s
            x1 += g1 * e
            x2 += g2 * e
            p22 -= g2 * p12
            p12 -= g1 * p12
            p11 -= g1 * p11
            innov_l.append((k, e, s))
            if seen >= N_DIFFUSE:
                m2ll += log2pi + math.log(s) + e * e / s
            seen += 1
            if not samel[k]:
                steady = False
            elif not k & 15:  # test convergence every 16th row (cheap, <= 16 rows late)
                scale = STEADY_RTOL * (abs(p11) + abs(p22))
                steady = (
                    abs(p11 - o11) <= scale and abs(p12 - o12) <= scale and abs(p22 - o22) <= scale
                )
            o11, o12, o22 = p11, p12, p22
        else:
            steady = False
            o11 = o12 = o22 = math.nan
        if smooth:
            filt_l.append((x1, x2, p11, p12, p22))
            rows_l.append(k)
        k += 1
    if rows_l:
        filt[rows_l] = filt_l
        pred[rows_l] = pred_l
    if innov_l:
        ik, ie, isv = zip(*innov_l, strict=True)
        innov[list(ik)] = ie
        svar[list(ik)] = isv
    if not smooth:
        return None, None, None, None, None, innov, svar, m2ll
    # -- backwards: rows k0 .. k1-1 of a stretch share P_k|k, P_k+1|k, F, hence C -------
    starts = {k1: k0 for k0, k1 in stretches}
    out = np.empty((n, 5))
    out[-1] = filt[-1]
    pos = np.full(n, -1, dtype=np.int64)
    pos[rows_l] = np.arange(len(rows_l))
    posl = pos.tolist()  # where a plain row sits in filt_l / pred_l (-1: a stretch row)
    done_rows: list[int] = []
    done_vals: list[tuple] = []
    x1, x2, p11, p12, p22 = filt[-1].tolist()
    k = n - 2
    while k >= 0:
        ak, bk = al[k + 1], bl[k + 1]
        i = posl[k]
        fx1, fx2, f11, f12, f22 = filt_l[i] if i >= 0 else filt[k].tolist()
        i = posl[k + 1]
        px1, px2, q11_, q12_, q22_ = pred_l[i] if i >= 0 else pred[k + 1].tolist()
        m11 = f11 * ak + f12 * bk
        m21 = f12 * ak + f22 * bk
        det = q11_ * q22_ - q12_ * q12_
        c11 = (m11 * q22_ - f12 * q12_) / det
        c12 = (f12 * q11_ - m11 * q12_) / det
        c21 = (m21 * q22_ - f22 * q12_) / det
        c22 = (f22 * q11_ - m21 * q12_) / det
        k0 = starts.get(k + 1)
        lo = k if k0 is None or k0 > k else k0  # rows lo..k use this C
        if lo < k:
            fa = filt[lo : k + 1][::-1]  # rows k, k-1, ..., lo
            pa = pred[lo + 1 : k + 2][::-1]  # rows k+1, ..., lo+1
            r1 = fa[:, 0] - c11 * pa[:, 0] - c12 * pa[:, 1]
            r2 = fa[:, 1] - c21 * pa[:, 0] - c22 * pa[:, 1]
            s1, s2 = _lti(((c11, c12), (c21, c22)), r1, r2, (x1, x2))
            out[lo : k + 1, 0] = s1[::-1]
            out[lo : k + 1, 1] = s2[::-1]
            x1, x2 = float(s1[-1]), float(s2[-1])
        if lo == k:  # a plain row
            e11, e12, e22 = p11 - q11_, p12 - q12_, p22 - q22_
            t11 = c11 * e11 + c12 * e12
            t12 = c11 * e12 + c12 * e22
            t21 = c21 * e11 + c22 * e12
            t22 = c21 * e12 + c22 * e22
            p11 = f11 + t11 * c11 + t12 * c12
            p12 = f12 + t11 * c21 + t12 * c22
            p22 = f22 + t21 * c21 + t22 * c22
            d1 = x1 - px1
            d2 = x2 - px2
            x1 = fx1 + c11 * d1 + c12 * d2
            x2 = fx2 + c21 * d1 + c22 * d2
            done_rows.append(k)
            done_vals.append((x1, x2, p11, p12, p22))
            k -= 1
            continue
        # covariance: P_j|N = P_f + C (P_j+1|N - P_p) C^T, constant once it stops changing
        j = k
        while j >= lo:
            e11, e12, e22 = p11 - q11_, p12 - q12_, p22 - q22_
            t11 = c11 * e11 + c12 * e12
            t12 = c11 * e12 + c12 * e22
            t21 = c21 * e11 + c22 * e12
            t22 = c21 * e12 + c22 * e22
            n11 = f11 + t11 * c11 + t12 * c12
            n12 = f12 + t11 * c21 + t12 * c22
            n22 = f22 + t21 * c21 + t22 * c22
            scale = 1e-14 * (abs(n11) + abs(n22))
            fixed = abs(n11 - p11) <= scale and abs(n12 - p12) <= scale and abs(n22 - p22) <= scale
            p11, p12, p22 = n11, n12, n22
            if fixed:
                out[lo : j + 1, 2:] = (p11, p12, p22)
                break
            out[j, 2:] = (p11, p12, p22)
            j -= 1
        k = lo - 1
    if done_rows:
        out[done_rows] = done_vals
    return (
        out[:, 0].copy(),
        out[:, 1].copy(),
        out[:, 2].copy(),
        out[:, 3].copy(),
        out[:, 4].copy(),
        innov,
        svar,
        m2ll,
    )


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


# -- the models as transition builders -----------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Setup:
    """Everything the filter needs except the noise levels (time in minutes)."""

    t_min: np.ndarray
    y: np.ndarray
    h_min: np.ndarray  # h[k] = t[k] - t[k-1], h[0] = 0 (unused)
    u: np.ndarray
    tau_min: float | None  # None: kinematic model
    x0: tuple[float, float]

    def transition(self, q: float):
        if self.tau_min is None:
            return kinematic_transition(self.h_min, q)
        return lag_transition(self.h_min, self.tau_min, q)

    def stride(self, step: int) -> _Setup:
        """Every ``step``-th row, with exact transitions over the merged steps."""
        if step <= 1:
            return self
        idx = np.arange(0, self.t_min.size, step)
        t = self.t_min[idx]
        h = np.concatenate(([0.0], np.diff(t)))
        u = np.zeros_like(t)
        if self.tau_min is not None:
            # compose T' = e T + u over the fine steps in each coarse step:
            # u_c = sum_j u_j prod_{i > j} e_i  (exact for the chamber-driven part)
            cum = np.cumsum(-self.h_min / self.tau_min)  # log prod e_i
            fine = np.arange(1, idx[-1] + 1)
            chunk = np.searchsorted(idx, fine, side="left")  # coarse step of each fine one
            w = self.u[fine] * np.exp(cum[idx[chunk]] - cum[fine])
            u = np.bincount(chunk, weights=w, minlength=idx.size)
        return _Setup(t, self.y[idx], h, u, self.tau_min, self.x0)


def _prior(x0):
    return x0, (PRIOR_T_STD_C**2, 0.0, PRIOR_G_STD_C_PER_MIN**2)


def _run(setup: _Setup, q: float, r: float, smooth: bool):
    """:func:`filter_smooth` of ``setup`` at noise levels ``(q, r)``."""
    a, b, q11, q12, q22 = setup.transition(q)
    x0, p0 = _prior(setup.x0)
    return filter_smooth(setup.y, a, b, setup.u, q11, q12, q22, r, x0, p0, smooth=smooth)


def _fit_noise(setup: _Setup, q: float | None, r: float | None, quant_c: float) -> NoiseLevels:
    """Maximum likelihood of the innovations over the free levels (log-parametrised)."""
    floor = quant_c**2 / 12.0
    fitted = tuple(n for n, v in (("q", q), ("r", r)) if v is None)
    if q is not None and r is not None:
        return NoiseLevels(q, r, quant_c, ())
    n_fin = int(np.isfinite(setup.y).sum())
    n = setup.y.size
    step = 1 if n <= FULL_RATE_ML_ROWS else int(math.ceil(n / MAX_ML_ROWS))
    coarse = setup.stride(step)
    if int(np.isfinite(coarse.y).sum()) < max(20, N_DIFFUSE + 3):
        coarse = setup
    # starting point: white noise dominates second differences, var(d2 y) ~ 6 r
    yf = setup.y[np.isfinite(setup.y)]
    r_start = max(float(np.var(np.diff(yf, 2))) / 6.0, 1e-8) if n_fin > 3 else 1e-4
    r_extra_start = max(r_start - floor, 1e-3 * r_start)

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
        m2ll = _run(coarse, qq, rr, smooth=False)[-1]
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
    """Smoothed internal temperature and gradient, one row per log row.

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
        ``-2 log L`` of the innovations at the chosen noise levels (full-rate pass).
    method : str
        ``"kinematic"`` or ``"model"`` (thermal model with the chamber as input).
    params : ThermalParams or None
        The thermal model of the model-based variant.
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
    def time_min(self) -> np.ndarray:
        return self.time_s / 60.0

    @property
    def normalised_innovations(self) -> np.ndarray:
        """``e_k / sqrt(S_k)``: about N(0, 1) when the model and noise levels are right."""
        return self.innovation_c / self.innovation_std_c

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
        return (
            f"{self.method} Kalman smoother: q = {self.q:.3g} (degC/min^2)^2/min, "
            f"r = {self.r:.3g} degC^2 (sigma {math.sqrt(self.r):.3g} degC; quantisation "
            f"{self.noise.quant_c:g} degC; fitted by ML: {fitted}); median gradient std "
            f"{np.nanmedian(self.g_std_c_per_min):.3g} degC/min; normalised innovations "
            f"std {np.std(z):.2f} (1 if consistent)"
        )


def _setup_time(log: MeasuredLog) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(log.time_s, dtype=float) / 60.0
    return t, np.concatenate(([0.0], np.diff(t)))


def _first_finite(y: np.ndarray) -> float:
    return float(y[np.flatnonzero(np.isfinite(y))[0]])


def _finish(
    setup: _Setup, noise: NoiseLevels, method: str, grad, params, time_s: np.ndarray
) -> GradientEstimate:
    x1, x2, p11, p12, p22, innov, svar, m2ll = _run(setup, noise.q, noise.r, smooth=True)
    g, g_var = grad(x1, x2, p11, p12, p22)
    return GradientEstimate(
        time_s=np.array(time_s, dtype=float),
        t_est_c=x1,
        t_std_c=np.sqrt(np.maximum(p11, 0.0)),
        g_est_c_per_min=g,
        g_std_c_per_min=np.sqrt(np.maximum(g_var, 0.0)),
        innovation_c=innov,
        innovation_std_c=np.sqrt(np.asarray(svar)),
        noise=noise,
        minus2_log_likelihood=float(m2ll),
        method=method,
        params=params,
    )


def _resolve_quant(log: MeasuredLog, quant_c: float | None) -> float:
    if quant_c is None:
        return quantisation_step(log.t_int_c)
    v = float(quant_c)
    if not (math.isfinite(v) and v >= 0):
        raise ParameterError(f"quant_c must be >= 0 degC, got {quant_c!r}")
    return v


def estimate_gradient(
    log: MeasuredLog,
    *,
    q: float | None = None,
    r: float | None = None,
    quant_c: float | None = None,
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
    """
    q, r = _check_level("q", q, "(degC/min^2)^2/min"), _check_level("r", r, "degC^2")
    t, h = _setup_time(log)
    y = np.asarray(log.t_int_c, dtype=float)
    setup = _Setup(t, y, h, np.zeros_like(t), None, (_first_finite(y), 0.0))
    noise = _fit_noise(setup, q, r, _resolve_quant(log, quant_c))

    def grad(x1, x2, p11, p12, p22):
        return x2, p22

    return _finish(setup, noise, "kinematic", grad, None, log.time_s)


def estimate_gradient_model(
    log: MeasuredLog,
    params: ThermalParams | None = None,
    *,
    chamber: str = "tk_set_c",
    q: float | None = None,
    r: float | None = None,
    quant_c: float | None = None,
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
    q, r, quant_c
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
    q, r = _check_level("q", q, "(degC/min^2)^2/min"), _check_level("r", r, "degC^2")
    model = FirstOrderLag(params)
    t, h = _setup_time(log)
    u = np.zeros_like(t)
    if t.size > 1:
        u[1:] = lag_input(h[1:], tk[:-1], tk[1:], model)
    y = np.asarray(log.t_int_c, dtype=float)
    setup = _Setup(t, y, h, u, params.tau_min, (_first_finite(y), 0.0))
    noise = _fit_noise(setup, q, r, _resolve_quant(log, quant_c))
    tau, offset = params.tau_min, (tk + params.dt0_c) / params.tau_min

    def grad(x1, x2, p11, p12, p22):
        # g = (Tk + dT0 - T)/tau + d ;  var g = P11/tau^2 - 2 P12/tau + P22
        return offset - x1 / tau + x2, p11 / tau**2 - 2.0 * p12 / tau + p22

    return _finish(setup, noise, "model", grad, params, log.time_s)


def finite_difference_gradient(time_s: np.ndarray, t_c: np.ndarray) -> np.ndarray:
    """Plain central finite difference of the samples, degC/min (the baseline).

    ``g_k = (y_{k+1} - y_{k-1}) / (t_{k+1} - t_{k-1})`` (one-sided at the ends, via
    ``numpy.gradient``); NaN readings propagate.
    """
    return np.gradient(np.asarray(t_c, dtype=float), np.asarray(time_s, dtype=float) / 60.0)
