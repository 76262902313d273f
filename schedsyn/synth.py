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


#: Realistic ranges of the hidden effects' parameters for blind tests (uniform draws).
EFFECT_RANGES = {
    "chamber_lag": {"tau_chamber_s": (60.0, 600.0)},
    "chamber_rate_limit": {"max_cool_rate_c_per_min": (0.3, 0.8)},
    "chamber_cycling": {"amplitude_c": (0.3, 2.0), "period_s": (300.0, 1800.0)},
    "dead_time": {"delay_s": (60.0, 600.0)},
    "second_time_constant": {"tau2_s": (300.0, 1200.0)},
    "selfheat_slope": {"dt0_slope_c_per_c": (0.01, 0.05)},
    "asymmetric_tau": {"ratio": (1.15, 1.40)},
    "dt0_drift": {"dt0_drift_c_per_h": (0.1, 0.6)},
    "tau_temperature": {"tau_slope_per_c": (0.003, 0.010)},
}
#: Effects whose parameter ranges above are magnitudes: each draw gets a random sign.
SIGNED_EFFECTS = ("dt0_drift", "tau_temperature")


def random_effect_model(
    effect: str, rng: np.random.Generator, tau_s: float = 2400.0, dt0_c: float = 3.0
):
    """A :class:`~schedsyn.effects.ModelSpec` with ``effect`` drawn from EFFECT_RANGES.

    ``chamber_rate_limit`` limits cooling only (heating limit 10 degC/min, not binding);
    ``chamber_cycling`` gets a random phase; ``asymmetric_tau`` makes one of the two time
    constants ``ratio`` times the other (which one at random), around ``tau_s``;
    :data:`SIGNED_EFFECTS` get a random sign (a drift up or down, ``tau`` growing or
    shrinking with temperature).
    """
    from .effects import ModelSpec

    if effect == "none":
        return ModelSpec(tau_s, dt0_c)
    if effect not in EFFECT_RANGES:
        raise ParameterError(f"unknown effect {effect!r}; known: none, {', '.join(EFFECT_RANGES)}")
    draw = {k: float(rng.uniform(*v)) for k, v in EFFECT_RANGES[effect].items()}
    if effect == "chamber_rate_limit":
        draw["max_heat_rate_c_per_min"] = 10.0
    elif effect == "chamber_cycling":
        draw["phase_rad"] = float(rng.uniform(-np.pi, np.pi))
    elif effect in SIGNED_EFFECTS:
        sign = 1.0 if rng.integers(2) else -1.0
        draw = {k: sign * v for k, v in draw.items()}
    elif effect == "asymmetric_tau":
        ratio = draw.pop("ratio")
        slow, fast = tau_s * math.sqrt(ratio), tau_s / math.sqrt(ratio)
        heat_slow = bool(rng.integers(2))
        draw = {
            "tau_heat_s": slow if heat_slow else fast,
            "tau_cool_s": fast if heat_slow else slow,
        }
    return ModelSpec(tau_s, dt0_c, effect, draw)


def blind_programmes() -> dict[str, Programme]:
    """Two simple 9-hour programmes (20 degC start and end) for blind tests.

    ``cold``: down to -40 at -1 degC/min, up to +40 at +2, down to -10 at -0.8, back;
    ``warm``: up to +60 at +1, down to 0 at -1, up to +50 at +2.5, back at -0.6.
    """

    def build(steps: list[tuple[float, float]]) -> Programme:
        d = [s[0] for s in steps]
        return Programme(np.array(d + [540.0 - sum(d)]), np.array([s[1] for s in steps] + [0.0]))

    return {
        "cold": build(
            [(60, -1.0), (60, 0.0), (40, 2.0), (90, 0.0), (62.5, -0.8), (60, 0.0), (30, 1.0)]
        ),
        "warm": build(
            [(40, 1.0), (60, 0.0), (60, -1.0), (60, 0.0), (20, 2.5), (60, 0.0), (50, -0.6)]
        ),
    }


def blind_case(
    effect: str,
    seed: int,
    programme: Programme,
    *,
    sample_s: float | None = None,
    with_air: bool | None = None,
    noise_c: float | None = None,
    quant_c: float = 0.01,
):
    """One blind test log: ``(frame, truth ModelSpec, noise_c)``, all drawn from ``seed``.

    Base ``tau_s`` in 1800..3000 s, ``dt0_c`` in 1..5 degC, the effect's parameters from
    :data:`EFFECT_RANGES`, noise 0.01..0.03 degC, sampling 1, 2, 5 or 10 s, air channel
    with probability 1/2 (each unless given).
    """
    rng = np.random.default_rng(seed)
    tau_s = float(rng.uniform(1800.0, 3000.0))
    dt0_c = float(rng.uniform(1.0, 5.0))
    truth = random_effect_model(effect, rng, tau_s, dt0_c)
    noise = float(rng.uniform(0.01, 0.03)) if noise_c is None else noise_c
    samp = float(rng.choice([1.0, 2.0, 5.0, 10.0])) if sample_s is None else sample_s
    air = bool(rng.integers(2)) if with_air is None else with_air
    frame = synth_effect_log(
        programme,
        truth,
        sample_s=samp,
        noise_c=noise,
        quant_c=quant_c,
        seed=int(rng.integers(2**31)),
        with_air=air,
    )
    return frame, truth, noise
