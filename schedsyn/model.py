"""Exact discrete-time solution of the thermal model, affine in the segment ramp rates.

The chamber follows a piecewise-linear programme: segment ``i`` starts at ``t_i`` (min),
lasts ``h_i`` and ramps at ``u_i`` degC/min, so::

    Tk(t) = Tk0 + sum_i u_i * r_i(t),   r_i(t) = clip(t - t_i, 0, h_i)

For a linear, time-invariant device model with unit-ramp response ``R(x)`` (``R = 0`` for
``x <= 0``), step response ``S = R'`` and static gain ``K``, superposition gives, exactly::

    T(t) = T_free(t) + K * sum_i u_i * [R(t - t_i) - R(t - t_{i+1})]
    g(t) = g_free(t) + K * sum_i u_i * [S(t - t_i) - S(t - t_{i+1})]

where ``T_free`` is the response to the constant chamber ``Tk0`` from the initial state.
So the internal temperature ``T``, its gradient ``g = dT/dt`` and the chamber ``Tk`` at any
set of sample times are affine in the rates: ``x = A @ u + b``. This is the one copy of the
model maths used by the simulator, the planner, the sweeps and the estimator.

For the first-order lag ``tau dT/dt + T = Tk + dT0`` (tau in minutes here)::

    S(x) = 1 - exp(-x/tau)
    R(x) = x - tau * (1 - exp(-x/tau))
    T_free(t) = e T0 + (1 - e) (Tk0 + dT0),   g_free(t) = e (Tk0 + dT0 - T0) / tau,
    e = exp(-t/tau)

These are the pure functions :func:`lag_step`, :func:`lag_ramp` and :func:`lag_free`, the
one copy of the first-order lag: :class:`FirstOrderLag` is made of them, and so is the
one-pole case of :class:`schedsyn.effects.LinearEffectModel`. :func:`lag_foh` is the same
lag on a uniform grid for an input linear between grid points (first-order hold), used by
the nonlinear effects and the diagnosis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.signal import lfilter

from .params import ThermalParams


# --------------------------------------------------------------------------------------
# the first-order lag: tau dT/dt + T = v(t)   (times in minutes)
# --------------------------------------------------------------------------------------
def lag_step(x_min: np.ndarray, tau_min: float) -> np.ndarray:
    """Unit-step response of the lag, ``S(x) = 1 - e^{-x/tau}`` (0 for ``x <= 0``)."""
    x = np.maximum(np.asarray(x_min, dtype=float), 0.0)
    return -np.expm1(-x / tau_min)


def lag_ramp(x_min: np.ndarray, tau_min: float) -> np.ndarray:
    """Unit-ramp response of the lag, ``R(x) = x - tau (1 - e^{-x/tau})`` (0 for ``x <= 0``).

    ``R`` is the integral of :func:`lag_step`; written with ``expm1`` so that small ``x``
    (where ``R ~ x^2 / (2 tau)``) keeps its precision.
    """
    x = np.maximum(np.asarray(x_min, dtype=float), 0.0)
    return x + tau_min * np.expm1(-x / tau_min)


def lag_free(
    t_min: np.ndarray, target_c: float | np.ndarray, t0_c: float, tau_min: float
) -> tuple[np.ndarray, np.ndarray]:
    """Lag from ``T(0) = t0_c`` towards a constant ``target_c``: temperature and gradient.

    ``T = e T0 + (1 - e) target``, ``g = dT/dt = e (target - T0) / tau``, ``e = e^{-t/tau}``.
    """
    e = np.exp(-np.asarray(t_min, dtype=float) / tau_min)
    return e * t0_c + (1.0 - e) * target_c, e * (target_c - t0_c) / tau_min


def lag_foh(v_c: np.ndarray, t0_c: float, tau_min: float, h_min: float) -> np.ndarray:
    """Exact lag of an input linear between the points of a uniform grid (first-order hold).

    ``T[k+1] = a T[k] + (1-a) v[k] + (v[k+1] - v[k]) (1 - tau (1-a)/h)``, ``a = e^{-h/tau}``
    (the step of :func:`lag_free` plus the ramp response ``R(h)/h`` of the input's slope).

    Parameters
    ----------
    v_c : array (n,)
        Input (the right-hand side ``v`` of ``tau dT/dt + T = v``) at ``0, h, 2h, ...``, degC.
    t0_c : float
        ``T`` at the first grid point, degC.
    tau_min, h_min : float
        Time constant and grid step, min, both > 0.

    Returns
    -------
    array (n,)
        ``T`` at the grid points (the first is ``t0_c``).
    """
    v = np.asarray(v_c, dtype=float)
    a = math.exp(-h_min / tau_min)
    beta = 1.0 - tau_min * (1.0 - a) / h_min
    c = (1.0 - a) * v[:-1] + beta * np.diff(v)
    y, _ = lfilter([1.0], [1.0, -a], c, zi=[a * t0_c])
    return np.concatenate(([t0_c], y))


class LinearThermalModel(Protocol):
    """What the affine machinery needs from a linear time-invariant device model.

    Times are in minutes. ``ramp`` and ``step`` must return 0 for ``x <= 0``.
    """

    @property
    def gain(self) -> float: ...

    def ramp(self, x_min: np.ndarray) -> np.ndarray: ...

    def step(self, x_min: np.ndarray) -> np.ndarray: ...

    def free(
        self, t_min: np.ndarray, tk0_c: float | np.ndarray, t0_c: float
    ) -> tuple[np.ndarray, np.ndarray]: ...


@dataclass(frozen=True, slots=True)
class FirstOrderLag:
    """The paper's planning model ``tau_s dT/dt + T = Tk + dt0_c`` (see :func:`lag_step`)."""

    params: ThermalParams = ThermalParams()

    @property
    def gain(self) -> float:
        return 1.0

    @property
    def tau_min(self) -> float:
        return self.params.tau_min

    def step(self, x_min: np.ndarray) -> np.ndarray:
        # S(x) = 1 - exp(-x/tau) for x > 0
        return lag_step(x_min, self.tau_min)

    def ramp(self, x_min: np.ndarray) -> np.ndarray:
        # R(x) = x - tau (1 - exp(-x/tau)) for x > 0
        return lag_ramp(x_min, self.tau_min)

    def free(
        self, t_min: np.ndarray, tk0_c: float | np.ndarray, t0_c: float
    ) -> tuple[np.ndarray, np.ndarray]:
        # T_free = e T0 + (1 - e)(Tk0 + dT0); g_free = e (Tk0 + dT0 - T0)/tau
        return lag_free(t_min, tk0_c + self.params.dt0_c, t0_c, self.tau_min)


@dataclass(frozen=True, slots=True)
class AffineResponse:
    """``T = A_t @ u + b_t``, ``g = A_g @ u + b_g``, ``Tk = A_tk @ u + b_tk`` at sample times.

    Units: temperatures degC, gradients degC/min, rates ``u`` degC/min, times min.
    """

    times_min: np.ndarray
    a_t: np.ndarray
    b_t: np.ndarray
    a_g: np.ndarray
    b_g: np.ndarray
    a_tk: np.ndarray
    b_tk: np.ndarray

    def evaluate(self, rates_c_per_min: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(T, g, Tk)`` for concrete rates."""
        u = np.asarray(rates_c_per_min, dtype=float)
        return self.a_t @ u + self.b_t, self.a_g @ u + self.b_g, self.a_tk @ u + self.b_tk


def segment_starts(durations_min: np.ndarray) -> np.ndarray:
    """Start times (min) of segments with the given durations; length ``n + 1`` (last = end)."""
    d = np.asarray(durations_min, dtype=float)
    return np.concatenate(([0.0], np.cumsum(d)))


def affine_response(
    model: LinearThermalModel,
    durations_min: np.ndarray,
    times_min: np.ndarray,
    tk0_c: float = 20.0,
    t0_c: float = 20.0,
) -> AffineResponse:
    """Exact ``T``, ``g`` and ``Tk`` at ``times_min`` as affine functions of segment rates.

    Parameters
    ----------
    model : LinearThermalModel
        Device model (e.g. :class:`FirstOrderLag`).
    durations_min : array (n,)
        Segment durations, min, each > 0.
    times_min : array (m,)
        Sample times, min, any order, may lie inside segments or past the end (the chamber
        then holds its last temperature).
    tk0_c, t0_c : float
        Chamber and internal temperature at t = 0, degC.
    """
    d = np.asarray(durations_min, dtype=float)
    t = np.asarray(times_min, dtype=float)
    lag_start, lag_end = _segment_lags(d, t)
    k = model.gain
    a_t = k * (model.ramp(lag_start) - model.ramp(lag_end))
    a_g = k * (model.step(lag_start) - model.step(lag_end))
    a_tk = np.clip(lag_start, 0.0, d[None, :])
    b_t, b_g = model.free(t, tk0_c, t0_c)
    return AffineResponse(
        times_min=t, a_t=a_t, b_t=b_t, a_g=a_g, b_g=b_g, a_tk=a_tk, b_tk=np.full(t.shape, tk0_c)
    )


def _segment_lags(d: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``t_k - t_i`` and ``t_k - t_{i+1}`` for every sample k and segment i (start, end)."""
    edges = segment_starts(d)
    return t[:, None] - edges[None, :-1], t[:, None] - edges[None, 1:]


def affine_temperature(
    model: LinearThermalModel,
    durations_min: np.ndarray,
    times_min: np.ndarray,
    tk0_c: float = 20.0,
    t0_c: float = 20.0,
) -> tuple[np.ndarray, np.ndarray]:
    """``(A_t, b_t)`` of :func:`affine_response` alone (the same numbers), for callers that
    need only the temperature: the diagnosis fits evaluate it thousands of times."""
    d = np.asarray(durations_min, dtype=float)
    t = np.asarray(times_min, dtype=float)
    lag_start, lag_end = _segment_lags(d, t)
    a_t = model.gain * (model.ramp(lag_start) - model.ramp(lag_end))
    return a_t, model.free(t, tk0_c, t0_c)[0]
