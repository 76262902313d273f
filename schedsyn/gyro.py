"""A synthetic gyro: thermal drift polynomial in (T, g), white noise and a bias random walk.

The drift in deg/h at internal temperature ``T`` (degC) and gradient ``g = dT/dt``
(degC/min) is the polynomial of :mod:`schedsyn.terms` plus two noises::

    drift_dph(t_k) = P(T(t_k) - t_ref, g(t_k)) + b(t_k) + w_k
    P(T', g) = sum_terms c_ab T'^a g^b                       (total order a + b <= 3)
    b(t_k) = b(t_k-1) + K sqrt(h_k / 3600 s) z_k,  b(0) = 0   (bias random walk)
    w_k ~ N(0, N^2 / h_k)                                    (white noise, averaged over h_k)

``N`` is the white-noise density ``white_noise_dph_per_rt_hz`` in deg/h/sqrt(Hz) (an angle
random walk of ``N/60`` deg/sqrt(h)); a row's ``drift_dph`` is the mean rate over its
sampling interval ``h_k`` (s), so its standard deviation is ``N/sqrt(h_k)``. ``K`` is the
bias random walk ``bias_walk_dph_per_rt_h`` in deg/h/sqrt(h): after one hour the bias has
wandered by ``K`` (one sigma). The coefficients ``c_ab`` are in deg/h per degC^a per
(degC/min)^b (:func:`schedsyn.terms.unit_of`).

A gyro file is TOML with a ``[gyro]`` table::

    [gyro]
    name = "FOG-A"
    t_ref_c = -36.0                  # reference temperature of the polynomial, degC
    white_noise_dph_per_rt_hz = 0.3  # N, deg/h/sqrt(Hz)
    bias_walk_dph_per_rt_h = 0.01    # K, deg/h/sqrt(h)
    sensor_noise_c = 0.02            # internal temperature sensor: white noise, degC
    sensor_quant_c = 0.01            # ... and resolution, degC (0 = none)

    [gyro.drift_dph]                 # coefficient of each term (missing terms are 0)
    1 = 0.4
    t = 0.02
    g = 0.6

The log (:func:`gyro_log`) is the format of :mod:`schedsyn.logs` (``time_s, t_int_c,
tk_set_c``, optional ``tk_air_c``, ``drift_dph``) plus TRUTH columns for tests and
benchmarks (a real log has none; the reader keeps them as extra columns):
``t_true_c, g_true_c_per_min, drift_true_dph`` (the polynomial alone) and
``bias_walk_dph`` (``b``).
"""

from __future__ import annotations

import difflib
import json
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import ParameterError
from .params import ThermalParams
from .programme import Programme
from .synth import synth_log
from .terms import EXPONENTS, TERMS, evaluate

#: Keys a ``[gyro]`` table must give (0 is a value, a missing key is not): the
#: polynomial's origin and the noise, which defaults would change without a word.
REQUIRED_GYRO_KEYS = ("t_ref_c", "white_noise_dph_per_rt_hz", "bias_walk_dph_per_rt_h")
#: Keys of the ``[gyro]`` table besides ``drift_dph``.
GYRO_KEYS = (
    "name",
    "t_ref_c",
    "white_noise_dph_per_rt_hz",
    "bias_walk_dph_per_rt_h",
    "sensor_noise_c",
    "sensor_quant_c",
)


def _number(name: str, value: object, lo: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ParameterError(f"{name} must be finite, got {value!r}")
    if lo is not None and v < lo:
        raise ParameterError(f"{name} must be >= {lo:g}, got {value!r}")
    return v


@dataclass(frozen=True, slots=True)
class Gyro:
    """A gyro's thermal drift and noise (see the module docstring for the equations).

    Parameters
    ----------
    coefficients_dph : mapping term -> float
        Drift coefficient of each term of :data:`schedsyn.terms.TERMS`, deg/h per degC^a
        per (degC/min)^b about ``t_ref_c``; missing terms are 0.
    t_ref_c : float
        Reference temperature of the polynomial, degC (-100 .. 150).
    white_noise_dph_per_rt_hz : float
        White-noise density ``N`` of the drift, deg/h/sqrt(Hz), >= 0.
    bias_walk_dph_per_rt_h : float
        Bias random walk ``K``, deg/h/sqrt(h), >= 0.
    sensor_noise_c, sensor_quant_c : float
        Internal temperature sensor: white noise (degC, >= 0) and resolution (degC, >= 0;
        0 = no quantisation), as :func:`schedsyn.synth.synth_log`.
    name : str
        A label.
    """

    coefficients_dph: Mapping[str, float] = field(default_factory=dict)
    t_ref_c: float = 20.0
    white_noise_dph_per_rt_hz: float = 0.0
    bias_walk_dph_per_rt_h: float = 0.0
    sensor_noise_c: float = 0.02
    sensor_quant_c: float = 0.01
    name: str = "gyro"

    def __post_init__(self) -> None:
        if not isinstance(self.coefficients_dph, Mapping):
            raise ParameterError(
                f"coefficients_dph must map term names to numbers, got {self.coefficients_dph!r}"
            )
        unknown = [k for k in self.coefficients_dph if k not in EXPONENTS]
        if unknown:
            raise ParameterError(
                f"gyro {self.name!r}: unknown drift term(s) {', '.join(map(str, unknown))}; "
                f"the terms are {', '.join(TERMS)}"
            )
        coefs = {t: _number(f"drift_dph.{t}", self.coefficients_dph.get(t, 0.0)) for t in TERMS}
        object.__setattr__(self, "coefficients_dph", coefs)
        t_ref = _number("t_ref_c", self.t_ref_c)
        if not -100.0 <= t_ref <= 150.0:
            raise ParameterError(f"t_ref_c must be within -100 .. 150 °C, got {t_ref!r}")
        object.__setattr__(self, "t_ref_c", t_ref)
        for name in (
            "white_noise_dph_per_rt_hz",
            "bias_walk_dph_per_rt_h",
            "sensor_noise_c",
            "sensor_quant_c",
        ):
            object.__setattr__(self, name, _number(name, getattr(self, name), 0.0))
        if not isinstance(self.name, str):
            raise ParameterError(f"name must be a string, got {self.name!r}")

    @property
    def coefficient_vector(self) -> np.ndarray:
        """Coefficients in the order of :data:`schedsyn.terms.TERMS`."""
        return np.array([self.coefficients_dph[t] for t in TERMS])

    @property
    def has_gradient_terms(self) -> bool:
        """True when a term with ``g`` has a non-zero coefficient."""
        return any(self.coefficients_dph[t] != 0.0 for t in TERMS if EXPONENTS[t][1] > 0)

    def drift_dph(self, t_c: np.ndarray, g_c_per_min: np.ndarray) -> np.ndarray:
        """The noise-free drift polynomial ``P(T - t_ref, g)``, deg/h."""
        t = np.asarray(t_c, dtype=float) - self.t_ref_c
        return evaluate(self.coefficient_vector, TERMS, t, np.asarray(g_c_per_min, dtype=float))

    def to_toml(self) -> str:
        """The gyro as a TOML document with a ``[gyro]`` table (round-trips)."""
        lines = [
            "[gyro]",
            f"name = {json.dumps(self.name)}",
            f"t_ref_c = {self.t_ref_c!r}",
            f"white_noise_dph_per_rt_hz = {self.white_noise_dph_per_rt_hz!r}",
            f"bias_walk_dph_per_rt_h = {self.bias_walk_dph_per_rt_h!r}",
            f"sensor_noise_c = {self.sensor_noise_c!r}",
            f"sensor_quant_c = {self.sensor_quant_c!r}",
            "",
            "[gyro.drift_dph]  # °/h per °C^a per (°C/min)^b about t_ref_c",
        ]
        lines += [f"{t} = {self.coefficients_dph[t]!r}" for t in TERMS]
        return "\n".join(lines) + "\n"


def gyro_from_dict(doc: Mapping, source: str = "<gyro>") -> Gyro:
    """A :class:`Gyro` from a parsed TOML document with a ``[gyro]`` table."""
    table = doc.get("gyro")
    if not isinstance(table, Mapping):
        found = sorted(k for k, v in doc.items() if isinstance(v, Mapping))
        close = difflib.get_close_matches("gyro", found, n=1, cutoff=0.6)
        raise ParameterError(
            f"{source}: no [gyro] table"
            + (f" ([{close[0]}]: did you mean [gyro]?)" if close else "")
            + (f"; its tables: {', '.join(f'[{k}]' for k in found)}" if found and not close else "")
            + f"; a gyro file needs [gyro] (keys {', '.join(GYRO_KEYS)}) and [gyro.drift_dph] "
            f"(terms {', '.join(TERMS)})"
        )
    unknown = sorted(set(table) - set(GYRO_KEYS) - {"drift_dph"})
    if unknown:
        raise ParameterError(
            f"{source}: [gyro] has unknown key(s) {unknown}; allowed: "
            f"{', '.join(GYRO_KEYS)}, drift_dph"
        )
    missing = [k for k in REQUIRED_GYRO_KEYS if k not in table]
    if missing:
        near = [
            k
            for k in difflib.get_close_matches("gyro", [str(k) for k in doc], n=3, cutoff=0.6)
            if k != "gyro" and isinstance(doc.get(k), Mapping)
        ]
        raise ParameterError(
            f"{source}: [gyro] lacks {', '.join(missing)}"
            + (f" (they are under [{near[0]}]: did you mean [gyro]?)" if near else "")
            + "; give each (0 for no noise of that kind): t_ref_c is the temperature the "
            "coefficients are about, degC"
        )
    if "drift_dph" not in table:
        raise ParameterError(
            f"{source}: no [gyro.drift_dph] table: give the drift's coefficients as term = "
            f"number (terms {', '.join(TERMS)}; a missing term is 0)"
        )
    coefs = table["drift_dph"]
    if not isinstance(coefs, Mapping):
        raise ParameterError(f"{source}: [gyro.drift_dph] must be a table of term = number")
    kwargs = {k: table[k] for k in GYRO_KEYS if k in table}
    try:
        return Gyro(coefficients_dph=dict(coefs), **kwargs)
    except ParameterError as exc:
        raise ParameterError(f"{source}: {exc}") from None


def load_gyro(path: Path | str) -> Gyro:
    """Read a gyro TOML file (``[gyro]``); errors name the file and the key."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"gyro file {path} does not exist or is not a file")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{path} is not valid TOML ({exc})") from None
    return gyro_from_dict(doc, str(path))


# -- random gyros for benchmarks ----------------------------------------------------------
#: Standard deviations of the coefficients of a random gyro in *scaled* variables
#: ``x = (T - centre)/half`` (half = half the region's width) and ``y = g / 1 degC/min``:
#: each is the drift (deg/h) its term contributes at the region's edge and 1 degC/min.
RANDOM_T_SCALE_DPH = {"1": 0.5, "t": 1.0, "t2": 0.5, "t3": 0.3}
RANDOM_G_SCALE_DPH = {"tg": 0.3, "g2": 0.2, "t2g": 0.15, "tg2": 0.1, "g3": 0.1}
#: The main gradient term's magnitude, deg/h per degC/min (drawn uniformly, random sign).
RANDOM_G_MAIN_DPH = (0.3, 1.0)
#: Noise ranges (uniform): white-noise density deg/h/sqrt(Hz), bias walk deg/h/sqrt(h),
#: temperature sensor noise degC; sensor resolution drawn from RANDOM_QUANT_C.
RANDOM_WHITE_DPH_PER_RT_HZ = (0.1, 0.5)
RANDOM_WALK_DPH_PER_RT_H = (0.005, 0.02)
RANDOM_SENSOR_NOISE_C = (0.01, 0.03)
RANDOM_QUANT_C = (0.01, 0.0625)


def random_gyro(
    rng: np.random.Generator,
    region_c: tuple[float, float],
    *,
    gradient_terms: bool = True,
    name: str = "random",
) -> Gyro:
    """A random gyro for benchmarks, its polynomial scaled to ``region_c`` (degC).

    In scaled variables ``x = (T - centre)/half``, ``y = g/(1 degC/min)`` the T-only
    coefficients are normal with the standard deviations of :data:`RANDOM_T_SCALE_DPH`
    (deg/h at the region's edge); with ``gradient_terms`` the main gradient term ``g`` is
    uniform in :data:`RANDOM_G_MAIN_DPH` deg/h per degC/min with a random sign (a FOG's
    Shupe-like gradient sensitivity) and the other gradient terms are normal with
    :data:`RANDOM_G_SCALE_DPH`; without, they are all 0. Noise levels are uniform in the
    ``RANDOM_*`` ranges. ``t_ref_c`` is the region's centre.
    """
    lo, hi = float(region_c[0]), float(region_c[1])
    if not hi > lo:
        raise ParameterError(f"region_c must be (lo, hi) with lo < hi, got {region_c!r}")
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    scaled = {t: float(rng.normal(0.0, s)) for t, s in RANDOM_T_SCALE_DPH.items()}
    for t, s in RANDOM_G_SCALE_DPH.items():
        scaled[t] = float(rng.normal(0.0, s))
    g_main = float(rng.uniform(*RANDOM_G_MAIN_DPH)) * float(rng.choice([-1.0, 1.0]))
    scaled["g"] = g_main
    if not gradient_terms:
        scaled = {t: (c if EXPONENTS[t][1] == 0 else 0.0) for t, c in scaled.items()}
    coefs = {t: c / half ** EXPONENTS[t][0] for t, c in scaled.items()}
    return Gyro(
        coefficients_dph=coefs,
        t_ref_c=centre,
        white_noise_dph_per_rt_hz=float(rng.uniform(*RANDOM_WHITE_DPH_PER_RT_HZ)),
        bias_walk_dph_per_rt_h=float(rng.uniform(*RANDOM_WALK_DPH_PER_RT_H)),
        sensor_noise_c=float(rng.uniform(*RANDOM_SENSOR_NOISE_C)),
        sensor_quant_c=float(rng.choice(RANDOM_QUANT_C)),
        name=name,
    )


# -- the log ----------------------------------------------------------------------------
def drift_noise(
    time_s: np.ndarray, gyro: Gyro, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``(white, walk)`` noise of the drift at ``time_s`` (deg/h), module-docstring model.

    The first row's interval is taken equal to the second's (a log has no row before it).
    """
    t = np.asarray(time_s, dtype=float)
    h = np.diff(t)
    if h.size == 0 or np.any(h <= 0):
        raise ParameterError("time_s must have at least two strictly increasing samples")
    h = np.concatenate(([h[0]], h))
    white = gyro.white_noise_dph_per_rt_hz / np.sqrt(h) * rng.standard_normal(t.size)
    steps = gyro.bias_walk_dph_per_rt_h * np.sqrt(h / 3600.0) * rng.standard_normal(t.size)
    steps[0] = 0.0
    return white, np.cumsum(steps)


def gyro_log(
    programme: Programme,
    gyro: Gyro,
    params: ThermalParams | None = None,
    *,
    sample_s: float = 10.0,
    seed: int = 0,
    with_air: bool = True,
    t0_c: float = 20.0,
) -> pd.DataFrame:
    """Simulate a run of ``programme`` with ``gyro`` and return its log (module docstring).

    The internal temperature and its sensor are those of :func:`schedsyn.synth.synth_log`
    (exact model, the gyro's sensor noise and resolution); the drift is the gyro's
    polynomial at the true ``(T, g)`` plus white noise and the bias random walk.

    Parameters
    ----------
    programme : Programme
        Chamber programme.
    gyro : Gyro
    params : ThermalParams, optional
        The device's thermal model (default :class:`ThermalParams`).
    sample_s : float
        Sampling period, s (> 0).
    seed : int
        Seed of the temperature sensor's noise; the drift noise uses an independent
        stream spawned from the same seed.
    with_air : bool
        Add ``tk_air_c`` (the setpoint read by a sensor with the same noise).
    t0_c : float
        Internal temperature at t = 0, degC.

    Returns
    -------
    DataFrame with ``time_s, t_int_c, tk_set_c, [tk_air_c,] drift_dph`` and the truth
    ``t_true_c, g_true_c_per_min, drift_true_dph, bias_walk_dph``.
    """
    frame = synth_log(
        programme,
        params,
        sample_s=sample_s,
        noise_c=gyro.sensor_noise_c,
        quant_c=gyro.sensor_quant_c,
        seed=seed,
        with_air=with_air,
        t0_c=t0_c,
    )
    drift_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])
    true = gyro.drift_dph(frame["t_true_c"].to_numpy(), frame["g_true_c_per_min"].to_numpy())
    white, walk = drift_noise(frame["time_s"].to_numpy(), gyro, drift_rng)
    truth = frame[["t_true_c", "g_true_c_per_min"]]
    known = frame.drop(columns=["t_true_c", "g_true_c_per_min"])
    known = known.assign(drift_dph=true + walk + white)
    return pd.concat(
        [known, truth, pd.DataFrame({"drift_true_dph": true, "bias_walk_dph": walk})], axis=1
    )


def coefficient_table(gyros: Sequence[Gyro]) -> pd.DataFrame:
    """One row per gyro: name, t_ref_c, noise levels and the ten coefficients."""
    rows = []
    for g in gyros:
        row: dict[str, object] = {
            "name": g.name,
            "t_ref_c": g.t_ref_c,
            "white_noise_dph_per_rt_hz": g.white_noise_dph_per_rt_hz,
            "bias_walk_dph_per_rt_h": g.bias_walk_dph_per_rt_h,
        }
        row.update({f"c_{t}": g.coefficients_dph[t] for t in TERMS})
        rows.append(row)
    return pd.DataFrame(rows)
