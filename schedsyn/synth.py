"""Synthetic measured logs with known truth, for tests and benchmarks.

A programme is simulated exactly through the planning model at the log's sample times;
the internal sensor reading is the true temperature plus white Gaussian noise, then
quantised to the sensor's resolution::

    t_int_c[k] = quant * round((T(t_k) + e_k) / quant),   e_k ~ N(0, noise_c^2)

The result is a DataFrame in the log format of :mod:`schedsyn.logs` (``time_s, t_int_c,
tk_set_c`` and optionally ``tk_air_c``) plus the columns that are the TRUTH, for tests
only (a real log never has them; the reader keeps them as extra columns)::

    t_true_c          the noise-free internal temperature, degC
    g_true_c_per_min  the true gradient dT/dt, degC/min

Here the chamber air follows the setpoint perfectly (``tk_air_c`` = setpoint plus sensor
noise); effects a real chamber adds are for the model-discrepancy step to build on top.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .errors import ParameterError
from .params import ThermalParams
from .programme import Programme
from .simulate import simulate


def sample_times_s(total_s: float, sample_s: float) -> np.ndarray:
    """Regular sample times ``0, h, 2h, ...`` up to and including ``total_s``."""
    if not (math.isfinite(sample_s) and sample_s > 0):
        raise ParameterError(f"sample_s must be > 0 s, got {sample_s!r}")
    n = int(math.floor(total_s / sample_s + 1e-9))
    return sample_s * np.arange(n + 1)


def measure(
    values: np.ndarray, noise_c: float, quant_c: float, rng: np.random.Generator
) -> np.ndarray:
    """Sensor reading: ``quant * round((x + N(0, noise^2)) / quant)`` (no rounding if 0)."""
    if not (math.isfinite(noise_c) and noise_c >= 0):
        raise ParameterError(f"noise_c must be >= 0 degC, got {noise_c!r}")
    if not (math.isfinite(quant_c) and quant_c >= 0):
        raise ParameterError(f"quant_c must be >= 0 degC, got {quant_c!r}")
    x = np.asarray(values, dtype=float) + noise_c * rng.standard_normal(np.shape(values))
    return quant_c * np.round(x / quant_c) if quant_c > 0 else x


def synth_log(
    programme: Programme,
    params: ThermalParams | None = None,
    *,
    sample_s: float = 10.0,
    noise_c: float = 0.02,
    quant_c: float = 0.01,
    seed: int = 0,
    with_air: bool = True,
    t0_c: float = 20.0,
) -> pd.DataFrame:
    """Simulate ``programme`` and return a noisy, quantised log with the truth beside it.

    Parameters
    ----------
    programme : Programme
        Chamber programme (e.g. from :func:`schedsyn.read_steps`).
    params : ThermalParams, optional
        Device model (default :class:`ThermalParams`).
    sample_s : float
        Sampling period, s (> 0).
    noise_c : float
        Standard deviation of the internal sensor's white noise, degC (>= 0).
    quant_c : float
        Sensor resolution, degC (0 = none).
    seed : int
        Seed of ``np.random.default_rng``.
    with_air : bool
        Add a ``tk_air_c`` column (the setpoint read by a sensor with the same noise).
    t0_c : float
        Internal temperature at t = 0, degC.

    Returns
    -------
    DataFrame with columns ``time_s, t_int_c, tk_set_c, [tk_air_c,] t_true_c,
    g_true_c_per_min``.
    """
    rng = np.random.default_rng(seed)
    time_s = sample_times_s(programme.total_min * 60.0, sample_s)
    traj = simulate(programme, params, times_min=time_s / 60.0, t0_c=t0_c)
    cols = {
        "time_s": time_s,
        "t_int_c": measure(traj.t_c, noise_c, quant_c, rng),
        "tk_set_c": traj.tk_c,
    }
    if with_air:
        cols["tk_air_c"] = measure(traj.tk_c, noise_c, quant_c, rng)
    cols["t_true_c"] = traj.t_c
    cols["g_true_c_per_min"] = traj.g_c_per_min
    return pd.DataFrame(cols)


def synth_effect_log(
    programme: Programme,
    model,
    *,
    sample_s: float = 10.0,
    noise_c: float = 0.02,
    quant_c: float = 0.01,
    seed: int = 0,
    with_air: bool = True,
    t0_c: float = 20.0,
) -> pd.DataFrame:
    """Like :func:`synth_log`, but the truth is an augmented model with a hidden effect.

    ``model`` is a :class:`schedsyn.effects.ModelSpec` (base ``tau_s, dt0_c`` plus one
    named effect and its parameters, e.g. ``ModelSpec(2400, 3, "chamber_lag",
    {"tau_chamber_s": 300})``). Linear effects are simulated exactly through the affine
    machinery, nonlinear ones on a grid of at most 1 s (see
    :meth:`~schedsyn.effects.ModelSpec.predict`). ``tk_air_c`` is the model's chamber air
    (lagged, rate-limited or cycling where the effect says so) read with the same noise.
    The columns are those of :func:`synth_log`.
    """
    rng = np.random.default_rng(seed)
    time_s = sample_times_s(programme.total_min * 60.0, sample_s)
    t = time_s / 60.0
    pred = model.predict(programme, t, t0_c=t0_c, grid_min=min(sample_s, 1.0) / 60.0)
    cols = {
        "time_s": time_s,
        "t_int_c": measure(pred.t_c, noise_c, quant_c, rng),
        "tk_set_c": programme.chamber_at(t),
    }
    if with_air:
        cols["tk_air_c"] = measure(pred.tk_air_c, noise_c, quant_c, rng)
    cols["t_true_c"] = pred.t_c
    cols["g_true_c_per_min"] = pred.g_c_per_min
    return pd.DataFrame(cols)
