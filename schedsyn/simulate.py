"""Dense simulation of a chamber programme through the exact model."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import ParameterError
from .model import FirstOrderLag, LinearThermalModel, affine_response
from .params import ThermalParams
from .programme import Programme


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Sampled chamber temperature, internal temperature and its gradient.

    Attributes: ``time_min`` (min), ``tk_c`` (chamber, degC), ``t_c`` (internal, degC),
    ``g_c_per_min`` (dT/dt, degC/min).
    """

    time_min: np.ndarray
    tk_c: np.ndarray
    t_c: np.ndarray
    g_c_per_min: np.ndarray

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame(
            {
                "time_min": self.time_min,
                "tk_c": self.tk_c,
                "t_c": self.t_c,
                "g_c_per_min": self.g_c_per_min,
            }
        )

    @property
    def duration_min(self) -> float:
        return float(self.time_min[-1] - self.time_min[0])


def dense_times(total_min: float, dt_min: float) -> np.ndarray:
    """Sample times ``0, dt, 2 dt, ...`` up to and including ``total_min``."""
    if not (np.isfinite(dt_min) and dt_min > 0):
        raise ParameterError(f"dt_min must be > 0 min, got {dt_min!r}")
    n = int(np.floor(total_min / dt_min + 1e-9))
    t = dt_min * np.arange(n + 1)
    if total_min - t[-1] > 1e-9:
        t = np.append(t, total_min)
    return t


def simulate(
    programme: Programme,
    params: ThermalParams | None = None,
    *,
    model: LinearThermalModel | None = None,
    dt_min: float = 0.1,
    t0_c: float | None = None,
    times_min: np.ndarray | Sequence[float] | None = None,
) -> Trajectory:
    """Simulate ``programme`` exactly at ``dt_min`` spacing (or at ``times_min``).

    Parameters
    ----------
    programme : Programme
        The chamber programme (e.g. read from a step table).
    params : ThermalParams, optional
        Device model. Default: the model the programme's metadata records (the plan's
        tau and dT0, see :class:`~schedsyn.programme.StepTableMeta`), else the default
        :class:`ThermalParams` (tau 2400 s, dT0 3 degC).
    model : LinearThermalModel, optional
        Overrides ``params`` (e.g. an augmented linear model).
    dt_min : float
        Sample spacing, min, > 0.
    t0_c : float, optional
        Internal temperature at t = 0, degC (default: the metadata's ``t_init_c``, else
        20 degC).
    times_min : array, optional
        Sample times, min, instead of the regular grid.
    """
    if model is None:
        model = FirstOrderLag(model_params(programme, params))
    if t0_c is None:
        meta = programme.meta
        t0_c = meta.t_init_c if meta is not None and meta.t_init_c is not None else 20.0
    t = dense_times(programme.total_min, dt_min) if times_min is None else np.asarray(times_min)
    resp = affine_response(model, programme.durations_min, t, programme.start_c, t0_c)
    temp, grad, tk = resp.evaluate(programme.rates_c_per_min)
    return Trajectory(time_min=t, tk_c=tk, t_c=temp, g_c_per_min=grad)


def model_params(programme: Programme, params: ThermalParams | None = None) -> ThermalParams:
    """``params`` if given, else the model of the programme's metadata, else the default."""
    if params is not None:
        return params
    recorded = programme.meta.params() if programme.meta is not None else None
    return recorded if recorded is not None else ThermalParams()


def end_soak_min(
    programme: Programme,
    params: ThermalParams | None = None,
    *,
    model: LinearThermalModel | None = None,
    tol_c: float = 0.5,
    t0_c: float | None = None,
) -> float:
    """Minutes the device needs after the programme, the chamber held at its end
    temperature, to come and stay within ``tol_c`` of the temperature it settles at.

    For the first-order lag the device settles at ``Tk_end + dT0`` (the running device's
    self-heating offset) and, with ``T_end`` its temperature when the programme ends::

        t_soak = tau * ln(|T_end - Tk_end - dT0| / tol)      (0 if already within tol)

    Any linear model is handled the same way by evaluating its exact response past the
    end (the chamber holds its last temperature there). Rounded up to whole minutes.

    Parameters
    ----------
    programme : Programme
    params, model : see :func:`simulate`
    tol_c : float
        Tolerance, degC, > 0 (the end tolerance of the limits, 0.5 degC by default).
    t0_c : float, optional
        Internal temperature at t = 0, degC (see :func:`simulate`).
    """
    if not (np.isfinite(tol_c) and tol_c > 0):
        raise ParameterError(f"tol_c must be > 0 °C, got {tol_c!r}")
    if model is None:
        model = FirstOrderLag(model_params(programme, params))
    end = programme.total_min
    settled = float(
        simulate(programme, model=model, t0_c=t0_c, times_min=np.array([end + 1e6])).t_c[0]
    )
    horizon = 60.0
    while True:
        # 0.05-min samples after the end; the soak is the last time still outside tol
        after = np.arange(0.0, horizon + 1e-9, 0.05)
        temp = simulate(programme, model=model, t0_c=t0_c, times_min=end + after).t_c
        outside = np.flatnonzero(np.abs(temp - settled) > tol_c)
        if outside.size == 0:
            return 0.0
        if outside[-1] < after.size // 2 or horizon >= 1e6:
            return float(math.ceil(after[outside[-1]] + 0.05 - 1e-9))
        horizon *= 4.0
