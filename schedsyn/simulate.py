"""Dense simulation of a chamber programme through the exact model."""

from __future__ import annotations

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
    t0_c: float = 20.0,
    times_min: np.ndarray | None = None,
) -> Trajectory:
    """Simulate ``programme`` exactly at ``dt_min`` spacing (or at ``times_min``).

    ``model`` overrides ``params`` (e.g. an augmented linear model); by default the
    first-order lag with ``params`` (default :class:`ThermalParams`).
    """
    if model is None:
        model = FirstOrderLag(params if params is not None else ThermalParams())
    t = dense_times(programme.total_min, dt_min) if times_min is None else np.asarray(times_min)
    resp = affine_response(model, programme.durations_min, t, programme.start_c, t0_c)
    temp, grad, tk = resp.evaluate(programme.rates_c_per_min)
    return Trajectory(time_min=t, tk_c=tk, t_c=temp, g_c_per_min=grad)
