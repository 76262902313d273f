"""A library of candidate effects the planning model leaves out, and the augmented models.

The planning model is ``tau dT/dt + T = Tk + dT0`` with the chamber air ``Tk`` equal to
its setpoint programme. Each :class:`Effect` here is one named, physically meaningful
augmentation with its own parameters (units in the names), bounds and starting guesses;
``effect.augment(base, values)`` returns a new :class:`ModelSpec` (the base is untouched).

Linear effects keep the model linear and time invariant, so they are
:class:`LinearEffectModel` objects (``gain``, ``ramp``, ``step``, ``free``) and go through
:func:`schedsyn.model.affine_response`, the exact machinery the planner optimises over:

- ``chamber_lag``: ``tau_c dA/dt + A = Tk_set``; ``tau dT/dt + T = A + dT0``.
- ``second_time_constant``: ``tau2 dM/dt + M = Tk``; ``tau dT/dt + T = M + dT0``.
  Both give the two-pole unit-ramp response (times in min, ``a = tau``, ``b = tau2``)::

      S(x) = 1 - (a e^{-x/a} - b e^{-x/b}) / (a - b)
      R(x) = x - (a + b) + (a^2 e^{-x/a} - b^2 e^{-x/b}) / (a - b)

  and, as the extra state starts at the chamber temperature ``Tk0``, the same free
  response as the first-order lag. They differ only in the chamber air, so they cannot
  be told apart when the air is not logged.
- ``dead_time``: ``tau dT/dt + T = Tk(t - d) + dT0``: ``R(x - d)``, ``S(x - d)``.
- ``selfheat_slope``: ``dT0 = dt0 + s (T - 20)`` gives
  ``tau/(1-s) dT/dt + T = (Tk + dt0 - 20 s)/(1-s)``: gain ``1/(1-s)``, ``tau_eff =
  tau/(1-s)``.
- ``dt0_drift``: ``dT0 = dt0 + r t`` (``t`` from the programme's start: the device warms
  up or its dissipation changes over the run). The extra input ``r t`` goes through the
  device lag only, so it adds ``r R(t)`` to ``T`` and ``r S(t)`` to ``g`` (``R``, ``S`` the
  lag's ramp and step responses), which is part of the free response: the rates' matrix
  is unchanged and the planner's LP is exact.

Nonlinear effects are simulated by an exact per-step update on a uniform grid (the
chamber air is linear within a step; first-order hold, :func:`schedsyn.model.lag_foh`)::

    T[k+1] = a T[k] + (1-a) v[k] + (v[k+1] - v[k]) (1 - tau (1-a)/h),  a = exp(-h/tau)

with ``v = A + dT0``:

- ``chamber_rate_limit``: ``A[k+1] = A[k] + clip(S[k+1] - A[k], -c h, r h)``;
- ``chamber_cycling``: ``A = S + amp sin(2 pi t / P + phi)``;
- ``asymmetric_tau``: ``tau = tau_heat`` while ``v > T`` (heating), else ``tau_cool``;
- ``tau_temperature``: ``tau(T) = tau max(1 + k (T - 20), 0.1)`` (the device's heat
  capacity and conductances change with temperature), each step with ``tau`` at its
  midpoint temperature (predicted with the step's starting ``tau``, then corrected once).

They expose the limits they imply for the planner through
:meth:`ModelSpec.planner_limits`.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from .errors import ParameterError
from .model import affine_response, affine_temperature, lag_foh, lag_free, lag_ramp, lag_step
from .params import DT0_ABS_MAX_C, Limits, ThermalParams
from .programme import Programme

#: Reference temperature of the self-heating slope, degC (the paper's start temperature).
SLOPE_REF_C = 20.0
#: Relative separation below which the two poles of a two-pole model are nudged apart.
_POLE_SEP = 1e-4
#: Largest drift of the self-heating offset a model accepts, degC/h.
DT0_DRIFT_MAX_C_PER_H = 10.0
#: Largest relative change of the time constant per degC (``tau_temperature``), 1/degC.
TAU_SLOPE_MAX_PER_C = 0.015
#: Least ``tau(T) / tau`` of ``tau_temperature`` (the line is held there, never <= 0).
TAU_FACTOR_MIN = 0.1
#: Minute of the run at which a drifting self-heating offset is taken for the planner's
#: first-order heuristics (the middle of the paper's 9-hour run; the exact model keeps
#: the drift).
DRIFT_PLANNER_AT_MIN = 270.0


# --------------------------------------------------------------------------------------
# linear augmented model (goes through affine_response)
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class LinearEffectModel:
    """Linear device model with optional second pole, dead time and self-heating slope.

    ``tau_s dT/dt + T = M(t - delay_s) + dt0_c + s (T - 20)``, ``tau2_s dM/dt + M = Tk``
    (``M = Tk`` when ``tau2_s == 0``). Satisfies :class:`schedsyn.model.LinearThermalModel`
    (times in minutes), so the planner and :func:`schedsyn.simulate.simulate` accept it.

    Parameters
    ----------
    tau_s : float
        Device time constant, s, > 0.
    dt0_c : float
        Self-heating offset at 20 degC, degC.
    tau2_s : float
        Second pole (chamber lag or second thermal mass), s, >= 0 (0 = none).
    delay_s : float
        Transport delay from chamber to device, s, >= 0.
    dt0_slope_c_per_c : float
        Change of the self-heating offset per degC of device temperature, in (-0.5, 0.5).
    dt0_drift_c_per_h : float
        Change of the self-heating offset per hour from the programme's start, degC/h,
        within +-DT0_DRIFT_MAX_C_PER_H.
    """

    tau_s: float = 2400.0
    dt0_c: float = 3.0
    tau2_s: float = 0.0
    delay_s: float = 0.0
    dt0_slope_c_per_c: float = 0.0
    dt0_drift_c_per_h: float = 0.0

    def __post_init__(self) -> None:
        ThermalParams(self.tau_s, self.dt0_c)  # validates tau_s and dt0_c
        for name in ("tau2_s", "delay_s"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and 0.0 <= v <= 1e6):
                raise ParameterError(f"{name} must be within 0 .. 1e6 s, got {v!r}")
        s = float(self.dt0_slope_c_per_c)
        if not (math.isfinite(s) and abs(s) < 0.5):
            raise ParameterError(f"dt0_slope_c_per_c must be within -0.5 .. 0.5, got {s!r}")
        r = float(self.dt0_drift_c_per_h)
        if not (math.isfinite(r) and abs(r) <= DT0_DRIFT_MAX_C_PER_H):
            raise ParameterError(
                f"dt0_drift_c_per_h must be within -{DT0_DRIFT_MAX_C_PER_H:g} .. "
                f"{DT0_DRIFT_MAX_C_PER_H:g} degC/h, got {r!r}"
            )

    @property
    def gain(self) -> float:
        # K = 1/(1 - s)
        return 1.0 / (1.0 - self.dt0_slope_c_per_c)

    @property
    def tau_eff_min(self) -> float:
        # tau_eff = tau/(1 - s), in minutes
        return self.tau_s / 60.0 / (1.0 - self.dt0_slope_c_per_c)

    def _poles(self) -> tuple[float, float]:
        a, b = self.tau_eff_min, self.tau2_s / 60.0
        if b > 0 and abs(a - b) < _POLE_SEP * a:
            b = a * (1.0 - _POLE_SEP)  # the double pole as the limit of two close ones
        return a, b

    def _shift(self, x_min: np.ndarray) -> np.ndarray:
        return np.maximum(np.asarray(x_min, dtype=float) - self.delay_s / 60.0, 0.0)

    def step(self, x_min: np.ndarray) -> np.ndarray:
        x = self._shift(x_min)
        a, b = self._poles()
        if b == 0.0:
            return lag_step(x, a)  # one pole: S = 1 - e^{-x/a}, the first-order lag's
        # S = 1 - (a e^{-x/a} - b e^{-x/b})/(a - b)
        return 1.0 - (a * np.exp(-x / a) - b * np.exp(-x / b)) / (a - b)

    def ramp(self, x_min: np.ndarray) -> np.ndarray:
        x = self._shift(x_min)
        a, b = self._poles()
        if b == 0.0:
            return lag_ramp(x, a)  # one pole: R = x - a (1 - e^{-x/a}), the first-order lag's
        # R = x - (a + b) + (a^2 e^{-x/a} - b^2 e^{-x/b})/(a - b), written to avoid
        # cancellation at small x: (a^2 (e^{-x/a} - 1) - b^2 (e^{-x/b} - 1))/(a - b) + x
        return x + (a * a * np.expm1(-x / a) - b * b * np.expm1(-x / b)) / (a - b)

    def free(
        self, t_min: np.ndarray, tk0_c: float | np.ndarray, t0_c: float
    ) -> tuple[np.ndarray, np.ndarray]:
        # constant chamber Tk0 (second state starts and stays at Tk0): the first-order lag
        # towards target = K (Tk0 + dt0 - 20 s) with tau_eff
        target = self.gain * (tk0_c + self.dt0_c - SLOPE_REF_C * self.dt0_slope_c_per_c)
        temp, grad = lag_free(t_min, target, t0_c, self.tau_eff_min)
        if self.dt0_drift_c_per_h != 0.0:
            # the drift r t (t from the start) through the device lag: r R(t), r S(t)
            r = self.gain * self.dt0_drift_c_per_h / 60.0
            temp = temp + r * lag_ramp(t_min, self.tau_eff_min)
            grad = grad + r * lag_step(t_min, self.tau_eff_min)
        return temp, grad


# --------------------------------------------------------------------------------------
# nonlinear simulation on a uniform grid
# --------------------------------------------------------------------------------------
def uniform_grid_min(end_min: float, step_min: float) -> np.ndarray:
    """``0, h, 2h, ...`` covering ``end_min`` (the last point is >= end_min)."""
    n = max(1, int(math.ceil(end_min / step_min - 1e-9)))
    return step_min * np.arange(n + 1)


def _simulation_grid(
    programme: Programme, times_min: np.ndarray, grid_min: float | None
) -> tuple[np.ndarray, float]:
    """The uniform grid a nonlinear model is simulated on for samples at ``times_min``,
    and its step: ``grid_min``, or 1/6 min (finer for short logs), to the later of the
    last sample and the programme's end."""
    end = max(float(np.max(times_min)), programme.total_min)
    h = grid_min if grid_min is not None else min(1.0 / 6.0, end / 2000.0)
    return uniform_grid_min(end, h), h


def lag_foh_asymmetric(
    v_c: np.ndarray, t0_c: float, tau_heat_min: float, tau_cool_min: float, h_min: float
) -> np.ndarray:
    """First-order hold lag whose time constant is ``tau_heat`` while the target is above T.

    The direction is decided per step from the mean target ``(v[k] + v[k+1])/2`` against
    ``T[k]`` (exact when the direction does not change inside a step). Vectorised by
    runs: the whole rest is filtered with the current direction's time constant, and the
    run ends at the first step whose direction differs (a few runs per programme segment).
    """
    v = np.asarray(v_c, dtype=float)
    n = v.size
    out = np.empty(n)
    out[0] = t0_c
    mid = 0.5 * (v[:-1] + v[1:])
    k = 0
    while k < n - 1:
        heat = bool(mid[k] > out[k])
        y = lag_foh(v[k:], out[k], tau_heat_min if heat else tau_cool_min, h_min)
        # direction of each later step with this run's temperatures
        flip = np.flatnonzero((mid[k:] > y[:-1]) != heat)
        end = k + (int(flip[0]) if flip.size else n - 1 - k)  # first step of the next run
        out[k + 1 : end + 1] = y[1 : end - k + 1]
        k = end
    return out


def lag_foh_tau_of_t(
    v_c: np.ndarray, t0_c: float, tau_min: float, slope_per_c: float, h_min: float
) -> np.ndarray:
    """First-order hold lag whose time constant is ``tau max(1 + k (T - 20), 0.1)``.

    Each step is the exact first-order-hold update of :func:`schedsyn.model.lag_foh` with
    ``tau`` at the step's midpoint temperature, predicted with the ``tau`` of the step's
    start and corrected once (second order in the step; ``tau`` changes by ``k dT`` over
    a step of ``dT``).
    """
    v = np.asarray(v_c, dtype=float)
    n = v.size
    out = np.empty(n)
    out[0] = t0_c
    if slope_per_c == 0.0:
        return lag_foh(v, t0_c, tau_min, h_min)
    h, k, ref = float(h_min), float(slope_per_c), SLOPE_REF_C
    exp, temp, fmin = math.exp, float(t0_c), TAU_FACTOR_MIN
    for i in range(n - 1):
        v0, dv = float(v[i]), float(v[i + 1] - v[i])
        tau = tau_min * max(1.0 + k * (temp - ref), fmin)
        a = exp(-h / tau)
        pred = a * temp + (1.0 - a) * v0 + dv * (1.0 - tau * (1.0 - a) / h)
        tau = tau_min * max(1.0 + k * (0.5 * (temp + pred) - ref), fmin)
        a = exp(-h / tau)
        temp = a * temp + (1.0 - a) * v0 + dv * (1.0 - tau * (1.0 - a) / h)
        out[i + 1] = temp
    return out


def _rate_limited_step(a: float, s0: float, s1: float, h: float, c: float, r: float) -> float:
    """One exact step of the limiter from air ``a`` with the setpoint linear s0 -> s1."""
    sig = (s1 - s0) / h  # setpoint slope in this step
    d0 = a - s0
    if abs(d0) <= 1e-12:
        return s0 + min(max(sig, -c), r) * h
    if d0 > 0:  # above the setpoint: cool at the limit until meeting it at t*
        a1 = a - c * h
        if a1 >= s1:
            return a1
        ts = d0 / (c + sig)  # c + sig > 0 here
        return s1 if sig <= r else s0 + sig * ts + r * (h - ts)
    a1 = a + r * h  # below: heat at the limit until meeting it
    if a1 <= s1:
        return a1
    ts = -d0 / (r - sig)
    return s1 if sig >= -c else s0 + sig * ts - c * (h - ts)


def rate_limited(
    setpoint_c: np.ndarray,
    h_min: float | np.ndarray,
    max_cool_c_per_min: float,
    max_heat_c_per_min: float,
) -> np.ndarray:
    """Chamber air that follows the setpoint at bounded rates, exactly for a setpoint
    linear between grid points.

    ``dA/dt = clip(dS/dt, -c, r)`` while ``A = S``; otherwise ``A`` moves towards ``S`` at
    the limiting rate (``-c`` above, ``+r`` below) and, on meeting ``S`` at ``t*`` inside a
    step, tracks it (or moves on at the limit if ``S`` is faster than the limit).
    Vectorised by runs (tracking / cooling at the limit / heating at the limit).
    ``h_min``: the step, or each step's length (a grid with the setpoint's corners on it:
    a corner between grid points would cut its peak off, and the limited air would carry
    the cut through the whole run at the limit).
    """
    s = np.asarray(setpoint_c, dtype=float)
    c, r = float(max_cool_c_per_min), float(max_heat_c_per_min)
    n = s.size
    h = np.broadcast_to(np.asarray(h_min, dtype=float), (max(n - 1, 0),))
    tt = np.concatenate(([0.0], np.cumsum(h)))
    out = np.empty(n)
    out[0] = s[0]
    slope = np.diff(s) / h
    k = 0
    while k < n - 1:
        a = out[k]
        if abs(a - s[k]) <= 1e-12:  # tracking until the setpoint outruns a limit
            fast = np.flatnonzero((slope[k:] > r) | (slope[k:] < -c))
            j = k + (int(fast[0]) if fast.size else n - 1 - k)
            out[k + 1 : j + 1] = s[k + 1 : j + 1]
            if j < n - 1:
                out[j + 1] = _rate_limited_step(out[j], s[j], s[j + 1], float(h[j]), c, r)
            k = j + 1
            continue
        rate = -c if a > s[k] else r
        line = a + rate * (tt[k + 1 :] - tt[k])  # at k+1, k+2, ...
        met = np.flatnonzero(line < s[k + 1 :]) if rate < 0 else np.flatnonzero(line > s[k + 1 :])
        m = int(met[0]) if met.size else n - 1 - k  # the step k+m meets the setpoint
        out[k + 1 : k + m + 1] = line[:m]
        j = k + m
        if j < n - 1:
            out[j + 1] = _rate_limited_step(out[j], s[j], s[j + 1], float(h[j]), c, r)
        k = j + 1
    return out


#: The last few rate-limited air paths (:func:`_rate_limited_air`), newest last: a fit
#: of the device's parameters with the limits held, and a finite-difference Jacobian's
#: columns for them, ask for the same air again and again.
_LIMITED_AIR_CACHE: OrderedDict[tuple, tuple[np.ndarray, np.ndarray | None]] = OrderedDict()
_LIMITED_AIR_CACHE_SIZE = 8
_LIMITED_AIR_LOCK = threading.Lock()


def _rate_limited_air(
    programme: Programme,
    grid: np.ndarray,
    h: float,
    sample_min: np.ndarray | None,
    max_cool_c_per_min: float,
    max_heat_c_per_min: float,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The rate-limited air on ``grid`` and at ``sample_min`` (None: not asked).

    The limiter runs on the grid with the setpoint's corners (and the samples) added:
    exact there; a corner between grid points would cut off its peak. The answer depends
    on nothing else than the arguments, so the last few are kept (keyed by their bytes)
    and handed out as copies.
    """
    c, r = float(max_cool_c_per_min), float(max_heat_c_per_min)
    samples = None if sample_min is None else np.ravel(np.asarray(sample_min, dtype=float))
    key = (
        np.asarray(programme.durations_min, dtype=float).tobytes(),
        np.asarray(programme.boundary_temps_c, dtype=float).tobytes(),
        np.asarray(grid, dtype=float).tobytes(),
        float(h),
        None if samples is None else samples.tobytes(),
        c,
        r,
    )
    with _LIMITED_AIR_LOCK:
        hit = _LIMITED_AIR_CACHE.get(key)
        if hit is not None:
            _LIMITED_AIR_CACHE.move_to_end(key)
    if hit is None:
        corners = np.cumsum(programme.durations_min)
        extra = [corners] if samples is None else [corners, samples]
        fine = np.union1d(grid, np.concatenate(extra))
        fine = fine[fine >= grid[0]]
        fine = fine[np.concatenate(([True], np.diff(fine) > 1e-9 * max(h, 1.0)))]
        air_fine = rate_limited(programme.chamber_at(fine), np.diff(fine), c, r)
        air = np.interp(grid, fine, air_fine)
        at = None if sample_min is None else np.interp(sample_min, fine, air_fine)
        hit = (air, at)
        with _LIMITED_AIR_LOCK:
            _LIMITED_AIR_CACHE[key] = hit
            while len(_LIMITED_AIR_CACHE) > _LIMITED_AIR_CACHE_SIZE:
                _LIMITED_AIR_CACHE.popitem(last=False)
    air, at = hit
    return air.copy(), None if at is None else at.copy()


# --------------------------------------------------------------------------------------
# the model specification (base + at most one effect), as written to model files
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Prediction:
    """Model prediction at sample times: internal ``t_c``, gradient and chamber air, degC."""

    time_min: np.ndarray
    t_c: np.ndarray
    g_c_per_min: np.ndarray
    tk_air_c: np.ndarray


@dataclass(frozen=True, slots=True)
class ModelSpec:
    """The base model ``(tau_s, dt0_c)`` augmented with at most one named effect.

    ``parameters`` maps the effect's parameter names (units in the names) to values.
    """

    tau_s: float = 2400.0
    dt0_c: float = 3.0
    effect: str = "none"
    parameters: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        ThermalParams(self.tau_s, self.dt0_c)
        if self.effect not in EFFECTS and self.effect != "none":
            raise ParameterError(
                f"unknown effect {self.effect!r}; known: none, {', '.join(EFFECTS)}"
            )
        params = {k: float(v) for k, v in dict(self.parameters).items()}
        if self.effect != "none":
            eff = EFFECTS[self.effect]
            missing = [n for n in eff.param_names if n not in params]
            extra = [n for n in params if n not in eff.param_names]
            if missing or extra:
                raise ParameterError(
                    f"effect {self.effect} needs parameters {', '.join(eff.param_names)}; "
                    f"missing {missing or 'none'}, unexpected {extra or 'none'}"
                )
            eff.check(params)
        elif params:
            raise ParameterError(f"effect 'none' takes no parameters, got {sorted(params)}")
        object.__setattr__(self, "tau_s", float(self.tau_s))
        object.__setattr__(self, "dt0_c", float(self.dt0_c))
        object.__setattr__(self, "parameters", MappingProxyType(params))

    @classmethod
    def unchecked(
        cls, tau_s: float, dt0_c: float, effect: str, parameters: dict[str, float]
    ) -> ModelSpec:
        """The model without the checks of its values: for a fit whose optimiser keeps
        them within the effect's bounds and evaluates thousands of them (the checks cost
        as much as a linear model's prediction). ``parameters`` is taken as is (floats,
        exactly the effect's names)."""
        spec = object.__new__(cls)
        object.__setattr__(spec, "tau_s", float(tau_s))
        object.__setattr__(spec, "dt0_c", float(dt0_c))
        object.__setattr__(spec, "effect", effect)
        object.__setattr__(spec, "parameters", MappingProxyType(parameters))
        return spec

    def __reduce__(self):
        # the read-only parameters (a mappingproxy) do not pickle: rebuild from a dict, so
        # that a model crosses to process-pool workers (sweeps, re-plan sweeps)
        return (ModelSpec.unchecked, (self.tau_s, self.dt0_c, self.effect, dict(self.parameters)))

    # -- kinds ---------------------------------------------------------------------------
    @property
    def is_linear(self) -> bool:
        return self.effect == "none" or EFFECTS[self.effect].linear

    def linear_model(self, around_c: float | None = None) -> LinearEffectModel:
        """The :class:`LinearEffectModel` for the planner (linear effects only).

        For a nonlinear effect this is the linear base part; use :meth:`planner_limits`
        with it and :meth:`predict` to check a plan. ``around_c``: the temperature the
        plan works around (the working region's middle); ``tau_temperature`` is then
        linearised with ``tau`` there (default: at 20 degC, its ``tau_s``).
        """
        p = self.parameters
        if self.effect == "tau_temperature" and around_c is not None:
            return LinearEffectModel(self.tau_at(around_c), self.dt0_c)
        kw: dict[str, float] = {}
        if self.effect == "chamber_lag":
            kw["tau2_s"] = p["tau_chamber_s"]
        elif self.effect == "second_time_constant":
            kw["tau2_s"] = p["tau2_s"]
        elif self.effect == "dead_time":
            kw["delay_s"] = p["delay_s"]
        elif self.effect == "selfheat_slope":
            kw["dt0_slope_c_per_c"] = p["dt0_slope_c_per_c"]
        elif self.effect == "dt0_drift":
            kw["dt0_drift_c_per_h"] = p["dt0_drift_c_per_h"]
        elif self.effect == "asymmetric_tau":
            # the linear part: the mean of the two time constants
            return LinearEffectModel(0.5 * (p["tau_heat_s"] + p["tau_cool_s"]), self.dt0_c)
        return LinearEffectModel(self.tau_s, self.dt0_c, **kw)

    def tau_at(self, t_c: float) -> float:
        """The device's time constant at ``t_c`` degC, s (``tau_s`` but for
        ``tau_temperature``)."""
        if self.effect != "tau_temperature":
            return self.tau_s
        factor = 1.0 + self.parameters["tau_slope_per_c"] * (float(t_c) - SLOPE_REF_C)
        return self.tau_s * max(factor, TAU_FACTOR_MIN)

    def planner_params(self, around_c: float | None = None) -> ThermalParams:
        """First-order equivalent for the planner's heuristics (bands, reachability).

        ``tau`` is the model's mean delay: ``tau/(1-s) + tau2 + delay`` (first moment of
        the impulse response); for ``asymmetric_tau`` the mean of the two; for
        ``dt0_drift`` the offset at minute ``DRIFT_PLANNER_AT_MIN`` (kept within the
        model's range); for ``tau_temperature`` ``tau`` at ``around_c`` (see
        :meth:`linear_model`). The exact response is :meth:`linear_model`; this only sizes
        heuristic bounds.
        """
        p = self.parameters
        if self.effect == "asymmetric_tau":
            return ThermalParams(0.5 * (p["tau_heat_s"] + p["tau_cool_s"]), self.dt0_c)
        if self.effect == "dt0_drift":
            mid = self.dt0_c + p["dt0_drift_c_per_h"] * DRIFT_PLANNER_AT_MIN / 60.0
            return ThermalParams(self.tau_s, min(max(mid, -DT0_ABS_MAX_C), DT0_ABS_MAX_C))
        m = self.linear_model(around_c)
        return ThermalParams(m.tau_eff_min * 60.0 + m.tau2_s + m.delay_s, self.dt0_c)

    def planner_limits(self, limits: Limits | None = None) -> Limits:
        """Chamber limits the effect implies (a rate limit lowers the usable rates)."""
        limits = Limits() if limits is None else limits
        if self.effect != "chamber_rate_limit":
            return limits
        p = self.parameters
        lo = max(limits.rate_min_c_per_min, -p["max_cool_rate_c_per_min"])
        hi = min(limits.rate_max_c_per_min, p["max_heat_rate_c_per_min"])
        return dataclasses.replace(limits, rate_min_c_per_min=lo, rate_max_c_per_min=hi)

    # -- prediction ----------------------------------------------------------------------
    def predict(
        self,
        programme: Programme,
        times_min: np.ndarray,
        t0_c: float = 20.0,
        grid_min: float | None = None,
    ) -> Prediction:
        """Internal temperature, gradient and chamber air at ``times_min``.

        Linear models are evaluated exactly (:func:`affine_response`); nonlinear ones on a
        uniform grid of ``grid_min`` (default: 1/6 min, or finer for short logs) and
        interpolated linearly.
        """
        t = np.asarray(times_min, dtype=float)
        if self.is_linear:
            resp = affine_response(
                self.linear_model(), programme.durations_min, t, programme.start_c, t0_c
            )
            temp, grad, tk = resp.evaluate(programme.rates_c_per_min)
            if self.effect == "chamber_lag":
                air_resp = affine_response(
                    LinearEffectModel(self.parameters["tau_chamber_s"], 0.0),
                    programme.durations_min,
                    t,
                    programme.start_c,
                    programme.start_c,
                )
                tk = air_resp.evaluate(programme.rates_c_per_min)[0]
            return Prediction(t, temp, grad, tk)
        grid, h = _simulation_grid(programme, t, grid_min)
        air, temp, limited_at = self._simulate_grid(programme, grid, h, t0_c, t)
        v = air + self.dt0_c
        tau = self._tau_grid_min(v, temp)
        grad = (v - temp) / tau
        air_t = self._air_at(programme, t, limited_at)
        return Prediction(t, np.interp(t, grid, temp), np.interp(t, grid, grad), air_t)

    def predict_channels(
        self,
        programme: Programme,
        t_times_min: np.ndarray,
        air_times_min: np.ndarray | None,
        t0_c: float = 20.0,
        grid_min: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Internal temperature at ``t_times_min`` and chamber air at ``air_times_min``.

        The same maths as :meth:`predict`, evaluating each channel only where it is
        needed (used by the fits, which call it thousands of times).
        """
        if not self.is_linear:
            # predict's grid and simulation (the rate limiter's knots include every sample
            # time, so the same times go in), without the gradient and the air it would
            # also interpolate
            t = np.asarray(t_times_min, dtype=float)
            n = t.size
            times = t if air_times_min is None else np.concatenate((t, air_times_min))
            grid, h = _simulation_grid(programme, times, grid_min)
            _, temp, limited_at = self._simulate_grid(programme, grid, h, t0_c, times)
            temp_t = np.interp(t, grid, temp)
            if air_times_min is None:
                return temp_t, None
            return temp_t, self._air_at(programme, times, limited_at)[n:]
        a_t, b_t = affine_temperature(
            self.linear_model(), programme.durations_min, t_times_min, programme.start_c, t0_c
        )
        temp = a_t @ programme.rates_c_per_min + b_t
        if air_times_min is None:
            return temp, None
        if self.effect == "chamber_lag":
            a_air, b_air = affine_temperature(
                LinearEffectModel(self.parameters["tau_chamber_s"], 0.0),
                programme.durations_min,
                air_times_min,
                programme.start_c,
                programme.start_c,
            )
            return temp, a_air @ programme.rates_c_per_min + b_air
        return temp, programme.chamber_at(air_times_min)

    def _air_at(
        self, programme: Programme, t: np.ndarray, limited_at: np.ndarray | None
    ) -> np.ndarray:
        """The chamber air at the sample times ``t`` of a nonlinear model's simulation
        (``limited_at``: the rate-limited air there, from :meth:`_simulate_grid`)."""
        if self.effect == "chamber_cycling":  # the air exactly, not interpolated
            p = self.parameters
            return programme.chamber_at(t) + p["amplitude_c"] * np.sin(
                2.0 * np.pi * t * 60.0 / p["period_s"] + p["phase_rad"]
            )
        if limited_at is not None:  # the limited air at the samples, exactly
            return limited_at
        return programme.chamber_at(t)  # the chamber follows its setpoint

    def _tau_grid_min(self, v: np.ndarray, temp: np.ndarray) -> np.ndarray:
        if self.effect == "asymmetric_tau":
            p = self.parameters
            return np.where(v > temp, p["tau_heat_s"], p["tau_cool_s"]) / 60.0
        if self.effect == "tau_temperature":
            k = self.parameters["tau_slope_per_c"]
            return self.tau_s / 60.0 * np.maximum(1.0 + k * (temp - SLOPE_REF_C), TAU_FACTOR_MIN)
        return np.full(v.shape, self.tau_s / 60.0)

    def _simulate_grid(
        self,
        programme: Programme,
        grid: np.ndarray,
        h: float,
        t0_c: float,
        sample_min: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Air and internal temperature on the uniform ``grid``; the rate-limited air also
        at ``sample_min`` (else None)."""
        p = self.parameters
        limited_at = None
        if self.effect == "chamber_rate_limit":
            air, limited_at = _rate_limited_air(
                programme,
                grid,
                h,
                sample_min,
                p["max_cool_rate_c_per_min"],
                p["max_heat_rate_c_per_min"],
            )
        elif self.effect == "chamber_cycling":
            # A = S + amp sin(2 pi t/P + phi)
            air = programme.chamber_at(grid) + p["amplitude_c"] * np.sin(
                2.0 * np.pi * grid * 60.0 / p["period_s"] + p["phase_rad"]
            )
        else:
            air = programme.chamber_at(grid)
        v = air + self.dt0_c
        if self.effect == "asymmetric_tau":
            temp = lag_foh_asymmetric(v, t0_c, p["tau_heat_s"] / 60.0, p["tau_cool_s"] / 60.0, h)
        elif self.effect == "tau_temperature":
            temp = lag_foh_tau_of_t(v, t0_c, self.tau_s / 60.0, p["tau_slope_per_c"], h)
        else:
            temp = lag_foh(v, t0_c, self.tau_s / 60.0, h)
        return air, temp, limited_at

    # -- files ---------------------------------------------------------------------------
    def to_json_dict(self) -> dict:
        out = {
            "schedsyn_model": 1,
            "tau_s": self.tau_s,
            "dt0_c": self.dt0_c,
            "effect": self.effect,
            "parameters": dict(self.parameters),
            "linear": self.is_linear,
        }
        if self.effect == "chamber_rate_limit":
            lim = self.planner_limits()
            out["planner_limits"] = {
                "rate_min_c_per_min": lim.rate_min_c_per_min,
                "rate_max_c_per_min": lim.rate_max_c_per_min,
            }
        return out

    @classmethod
    def from_json_dict(cls, d: Mapping) -> ModelSpec:
        if not isinstance(d, Mapping) or "tau_s" not in d or "dt0_c" not in d:
            raise ParameterError(
                "a model file is a JSON object with at least tau_s, dt0_c (and effect, "
                "parameters); write one with `schedsyn diagnose LOG.csv --out DIR`"
            )
        return cls(
            tau_s=d["tau_s"],
            dt0_c=d["dt0_c"],
            effect=str(d.get("effect", "none")),
            parameters=dict(d.get("parameters", {})),
        )


# --------------------------------------------------------------------------------------
# the library
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Effect:
    """One candidate effect: named parameters with units, bounds and starting guesses.

    ``guesses`` are starting points for the fit (several: the fit is multi-start);
    ``main_param`` is the parameter quoted when judging an estimate; ``nuisance`` are
    parameters fitted but not physically quoted (e.g. a phase).
    """

    name: str
    description: str
    param_names: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    guesses: tuple[tuple[float, ...], ...]
    main_param: str
    linear: bool
    uses_air: bool = False  # changes the chamber air (so the air channel tells it apart)
    nuisance: tuple[str, ...] = ()

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    def check(self, values: Mapping[str, float]) -> None:
        for name, (lo, hi) in zip(self.param_names, self.bounds, strict=True):
            v = float(values[name])
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ParameterError(
                    f"{self.name}: {name} = {v!r} is outside its range {lo:g} .. {hi:g}"
                )

    def augment(self, model: ModelSpec, values: Mapping[str, float] | tuple) -> ModelSpec:
        """A new model: ``model``'s base (tau_s, dt0_c) with this effect added."""
        if not isinstance(values, Mapping):
            values = dict(zip(self.param_names, values, strict=True))
        return ModelSpec(model.tau_s, model.dt0_c, self.name, dict(values))


def _library() -> dict[str, Effect]:
    effects = (
        Effect(
            "chamber_lag",
            "the chamber air follows the setpoint through a first-order lag",
            ("tau_chamber_s",),
            ((1e-3, 2e4),),
            ((60.0,), (150.0,), (400.0,), (1000.0,), (2500.0,)),
            "tau_chamber_s",
            linear=True,
            uses_air=True,
        ),
        Effect(
            "chamber_rate_limit",
            "the chamber cannot cool (or heat) as fast as programmed",
            ("max_cool_rate_c_per_min", "max_heat_rate_c_per_min"),
            ((1e-3, 1e6), (1e-3, 1e6)),
            (),  # guesses come from the programme
            "max_cool_rate_c_per_min",
            linear=False,
            uses_air=True,
        ),
        Effect(
            "chamber_cycling",
            "the chamber controller alternates heating and cooling around the setpoint",
            ("amplitude_c", "period_s", "phase_rad"),
            ((0.0, 20.0), (1.0, 1e5), (-4 * math.pi, 4 * math.pi)),
            (),  # from periodogram
            "amplitude_c",
            linear=False,
            uses_air=True,
            nuisance=("phase_rad",),
        ),
        Effect(
            "dead_time",
            "a transport delay between the chamber and the sensor",
            ("delay_s",),
            ((0.0, 1e4),),
            ((30.0,), (100.0,), (300.0,), (900.0,)),
            "delay_s",
            linear=True,
        ),
        Effect(
            "second_time_constant",
            "a second thermal mass between the chamber air and the sensor",
            ("tau2_s",),
            ((1e-3, 2e4),),
            ((60.0,), (150.0,), (400.0,), (1000.0,), (2500.0,)),
            "tau2_s",
            linear=True,
        ),
        Effect(
            "selfheat_slope",
            "the self-heating offset changes with temperature: dT0 = dt0 + s (T - 20)",
            ("dt0_slope_c_per_c",),
            ((-0.3, 0.3),),
            ((0.0,),),
            "dt0_slope_c_per_c",
            linear=True,
        ),
        Effect(
            "dt0_drift",
            "the self-heating offset drifts over the run: dT0 = dt0 + r t (warm-up)",
            ("dt0_drift_c_per_h",),
            ((-DT0_DRIFT_MAX_C_PER_H, DT0_DRIFT_MAX_C_PER_H),),
            ((0.0,),),
            "dt0_drift_c_per_h",
            linear=True,
        ),
        Effect(
            "asymmetric_tau",
            "heating and cooling time constants differ",
            ("tau_heat_s", "tau_cool_s"),
            ((1.0, 1e5), (1.0, 1e5)),
            (),  # from the base tau
            "tau_cool_s",
            linear=False,
        ),
        Effect(
            "tau_temperature",
            "the time constant changes with temperature: tau(T) = tau (1 + k (T - 20))",
            ("tau_slope_per_c",),
            ((-TAU_SLOPE_MAX_PER_C, TAU_SLOPE_MAX_PER_C),),
            ((0.0,),),
            "tau_slope_per_c",
            linear=False,
        ),
    )
    return {e.name: e for e in effects}


#: The library of candidate effects, by name.
EFFECTS: Mapping[str, Effect] = MappingProxyType(_library())

#: Pairs of effects that give the same internal temperature; told apart only by the air.
AIR_ONLY_DISTINCT = (("chamber_lag", "second_time_constant"),)
