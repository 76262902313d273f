"""Model parameters and chamber/device limits: frozen, validated, units in every name.

The planning model (paper, eq. 1)::

    tau * dT/dt + T = Tk(t) + dT0        internal temperature T lags the chamber Tk
    dTk/dt = U(t)                        U piecewise constant, U_min <= U <= U_max
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields

from .errors import ParameterError


def real_number(name: str, value: object) -> float:
    """``value`` as a finite float, or a :class:`ParameterError` naming ``name``.

    Only real numbers are accepted (Python or numpy ints and floats): a string such as
    ``"3"`` or a bool is refused here, at construction, rather than failing later inside
    a computation.
    """
    if isinstance(value, bool | str | bytes) or not isinstance(value, numbers.Real):
        raise ParameterError(
            f"{name} must be a number (int or float), got {value!r} of type {type(value).__name__}"
        )
    v = float(value)
    if not math.isfinite(v):
        raise ParameterError(f"{name} must be finite, got {value!r}")
    return v


def _finite(name: str, value: float) -> float:
    return real_number(name, value)


def _store_floats(obj) -> None:
    """Check every field of a frozen parameter dataclass is a real number; store floats."""
    for f in fields(obj):
        object.__setattr__(obj, f.name, real_number(f.name, getattr(obj, f.name)))


def _check_range(name: str, value: float, lo: float | None, hi: float | None, unit: str) -> None:
    v = _finite(name, value)
    if (lo is not None and v <= lo) or (hi is not None and v > hi):
        lo_s = f"> {lo}" if lo is not None else ""
        hi_s = f"<= {hi}" if hi is not None else ""
        rng = " and ".join(s for s in (lo_s, hi_s) if s)
        raise ParameterError(f"{name} must be {rng} {unit}, got {value!r}")


#: The largest time constant, s, and self-heating offset magnitude, degC, a model accepts.
TAU_MAX_S = 1e6
DT0_ABS_MAX_C = 50.0


@dataclass(frozen=True, slots=True)
class ThermalParams:
    """First-order lag of the device: ``tau_s * dT/dt + T = Tk + dt0_c``.

    Parameters
    ----------
    tau_s : float
        Time constant, s, in (0, 1e6]. Default 2400 s: the paper's device settles in about
        2 h (~3 tau) after a step.
    dt0_c : float
        Self-heating offset of the running device, degC, in [-50, 50]. The paper gives no
        value; 3.0 degC is schedsyn's assumption.
    """

    tau_s: float = 2400.0
    dt0_c: float = 3.0

    def __post_init__(self) -> None:
        _check_range("tau_s", self.tau_s, 0.0, TAU_MAX_S, "s")
        v = _finite("dt0_c", self.dt0_c)
        if abs(v) > DT0_ABS_MAX_C:
            raise ParameterError(
                f"dt0_c must be within -{DT0_ABS_MAX_C:g} .. {DT0_ABS_MAX_C:g} °C, "
                f"got {self.dt0_c!r}"
            )
        _store_floats(self)

    @property
    def tau_min(self) -> float:
        """Time constant in minutes (the programme's time unit)."""
        return self.tau_s / 60.0

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True, slots=True)
class Limits:
    """Chamber, device and experiment limits.

    Defaults: ESPEC SET-Z-032U rates -1 .. +3 degC/min (paper); chamber air -70 .. +80 degC
    (a cascade-refrigerated chamber, assumption); device internal -52 .. +62 degC (the
    approximation regions of the paper plus 2 degC); at most 540 min (9 h); chamber and
    device start at 20 degC and the chamber ends at 20 +- 0.5 degC.
    """

    rate_min_c_per_min: float = -1.0
    rate_max_c_per_min: float = 3.0
    chamber_min_c: float = -70.0
    chamber_max_c: float = 80.0
    device_min_c: float = -52.0
    device_max_c: float = 62.0
    duration_max_min: float = 540.0
    start_c: float = 20.0
    end_c: float = 20.0
    end_tol_c: float = 0.5
    t_init_c: float = 20.0

    def __post_init__(self) -> None:
        _store_floats(self)
        if not self.rate_min_c_per_min < self.rate_max_c_per_min:
            raise ParameterError(
                "rate_min_c_per_min must be < rate_max_c_per_min, got "
                f"{self.rate_min_c_per_min} .. {self.rate_max_c_per_min} °C/min"
            )
        if not (self.rate_min_c_per_min <= 0.0 <= self.rate_max_c_per_min):
            raise ParameterError(
                "the rate limits must include 0 °C/min (a hold), got "
                f"{self.rate_min_c_per_min} .. {self.rate_max_c_per_min} °C/min"
            )
        if not self.chamber_min_c < self.chamber_max_c:
            raise ParameterError(
                f"chamber_min_c must be < chamber_max_c, got {self.chamber_min_c} .. "
                f"{self.chamber_max_c} °C"
            )
        if not self.device_min_c < self.device_max_c:
            raise ParameterError(
                f"device_min_c must be < device_max_c, got {self.device_min_c} .. "
                f"{self.device_max_c} °C"
            )
        _check_range("duration_max_min", self.duration_max_min, 0.0, 10080.0, "min")
        _check_range("end_tol_c", self.end_tol_c, 0.0, 50.0, "°C")
        for name in ("start_c", "end_c"):
            v = getattr(self, name)
            if not self.chamber_min_c <= v <= self.chamber_max_c:
                raise ParameterError(
                    f"{name} = {v} °C lies outside the chamber limits "
                    f"{self.chamber_min_c} .. {self.chamber_max_c} °C"
                )

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


#: Figures outside these ranges are legal but more likely a unit slip than a device or a
#: chamber: a time constant under a minute (minutes given as seconds?) or over ten hours,
#: a chamber rate beyond 30 degC/min (degC/h given as degC/min?), a self-heating offset
#: beyond 20 degC.
PLAUSIBLE_TAU_S = (60.0, 36000.0)
PLAUSIBLE_RATE_C_PER_MIN = 30.0
PLAUSIBLE_DT0_C = 20.0


def unit_slip_notes(params: ThermalParams, limits: Limits) -> list[str]:
    """Warnings for figures that are legal but look like a unit slip (red team: `plan
    --tau-s 40` and `--rate-max-c-per-min 180` planned without a word)."""
    notes = []
    lo, hi = PLAUSIBLE_TAU_S
    if params.tau_s < lo:
        notes.append(
            f"tau_s = {params.tau_s:g} s: the device settles in under a minute (a packaged "
            "gyro takes tens of minutes; the paper's 2400 s); tau_s is in seconds: if you "
            f"meant {params.tau_s:g} min, give {60.0 * params.tau_s:g}"
        )
    elif params.tau_s > hi:
        notes.append(
            f"tau_s = {params.tau_s:g} s is {params.tau_s / 3600.0:.1f} h: tau_s is in seconds "
            "(not milliseconds)"
        )
    for name in ("rate_min_c_per_min", "rate_max_c_per_min"):
        v = getattr(limits, name)
        if abs(v) > PLAUSIBLE_RATE_C_PER_MIN:
            notes.append(
                f"{name} = {v:g} °C/min: faster than chambers ramp (at most ~20 °C/min); "
                f"if you meant °C/h, give {v / 60.0:.3g}"
            )
    if abs(params.dt0_c) > PLAUSIBLE_DT0_C:
        notes.append(
            f"dt0_c = {params.dt0_c:g} °C: a device running {abs(params.dt0_c):g} °C "
            f"{'above' if params.dt0_c > 0 else 'below'} its chamber; dt0_c is in °C"
        )
    return notes
