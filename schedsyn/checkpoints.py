"""What the operator should see during a run: checkpoints with tolerance bands.

The device's internal temperature T depends on model parameters that are only roughly
known (tau, dT0). The band at time t is the range of T(t) over a box of parameters:

    T_low(t)  = min over (tau, dT0) in box of T(t; tau, dT0)
    T_high(t) = max over (tau, dT0) in box of T(t; tau, dT0)

T is affine in dT0 for a fixed tau (superposition: the offset enters like a constant
chamber shift, T(t) = T(t; dT0 = 0) + dT0 (1 - exp(-t / tau))), so the extremes over
dT0 lie at the ends of its range and only tau needs sampling (``n_tau`` values, ends
included). The box is the plan's robust box when it has one, else tau +-15 % and
dT0 +-2 degC around the nominal model.

Every ``interval_min`` (30 min by default) a checkpoint lists the chamber setpoint, the
expected device temperature and its band, so that a run going wrong (a sensor off, the
chamber not following its programme, a wrong programme loaded) is noticed in the first
hour, not after nine. Pure computation: :mod:`schedsyn.sheet` renders it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np
import pandas as pd

from .errors import ParameterError
from .params import ThermalParams
from .programme import Programme
from .simulate import dense_times, simulate


@dataclass(frozen=True, slots=True)
class ToleranceBox:
    """Parameter box of the tolerance band.

    Parameters
    ----------
    tau_lo_s, tau_hi_s : float
        Time-constant range, s, ``0 < lo <= hi``.
    dt0_lo_c, dt0_hi_c : float
        Self-heating offset range, degC, ``lo <= hi``.
    n_tau : int
        tau values sampled (ends included), >= 2 unless the range is a point.
    source : str
        Where the box comes from (shown on the sheet).
    """

    tau_lo_s: float
    tau_hi_s: float
    dt0_lo_c: float
    dt0_hi_c: float
    n_tau: int = 9
    source: str = ""

    def __post_init__(self) -> None:
        for k in ("tau_lo_s", "tau_hi_s", "dt0_lo_c", "dt0_hi_c"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ParameterError(f"{k} must be a finite number, got {v!r}")
        if not 0 < self.tau_lo_s <= self.tau_hi_s:
            raise ParameterError(
                f"the band's tau range must have 0 < lo <= hi, got {self.tau_lo_s} .. "
                f"{self.tau_hi_s} s"
            )
        if not self.dt0_lo_c <= self.dt0_hi_c:
            raise ParameterError(
                f"the band's dT0 range must have lo <= hi, got {self.dt0_lo_c} .. "
                f"{self.dt0_hi_c} °C"
            )
        if isinstance(self.n_tau, bool) or not isinstance(self.n_tau, int) or self.n_tau < 2:
            raise ParameterError(f"n_tau must be a whole number >= 2, got {self.n_tau!r}")

    @classmethod
    def around(
        cls, params: ThermalParams, tau_rel: float = 0.15, dt0_c: float = 2.0, n_tau: int = 9
    ) -> ToleranceBox:
        """tau * (1 -+ ``tau_rel``) and dT0 -+ ``dt0_c`` around ``params``."""
        if not (math.isfinite(tau_rel) and 0 <= tau_rel < 1):
            raise ParameterError(f"tau_rel must be in [0, 1), got {tau_rel!r}")
        if not (math.isfinite(dt0_c) and dt0_c >= 0):
            raise ParameterError(f"dt0_c (band half-width) must be >= 0 °C, got {dt0_c!r}")
        return cls(
            params.tau_s * (1 - tau_rel),
            params.tau_s * (1 + tau_rel),
            params.dt0_c - dt0_c,
            params.dt0_c + dt0_c,
            n_tau,
            f"tau ±{tau_rel:.0%}, dT0 ±{dt0_c:g} °C around the nominal model",
        )

    def scenarios(self) -> list[ThermalParams]:
        """The sampled (tau, dT0) pairs: ``n_tau`` taus x both dT0 ends."""
        taus = np.linspace(self.tau_lo_s, self.tau_hi_s, self.n_tau)
        return [
            ThermalParams(float(t), float(d)) for t in taus for d in (self.dt0_lo_c, self.dt0_hi_c)
        ]

    def describe(self) -> str:
        return (
            f"tau {self.tau_lo_s:g}–{self.tau_hi_s:g} s × dT0 {self.dt0_lo_c:g}–"
            f"{self.dt0_hi_c:g} °C" + (f" ({self.source})" if self.source else "")
        )


@dataclass(frozen=True, slots=True)
class SheetSettings:
    """Choices of an operator sheet.

    Parameters
    ----------
    start : datetime, optional
        Wall-clock start of the programme (clock times on the sheet); without it the
        sheet gives elapsed times only.
    interval_min : float
        Minutes between checkpoints (default 30), in (0, 600].
    band_tau_rel : float
        Relative tau half-range of the band when the plan has no robust box (0.15).
    band_dt0_c : float
        dT0 half-range of the band, degC, when the plan has no robust box (2.0).
    n_tau : int
        tau values sampled for the band (9).
    """

    start: datetime | None = None
    interval_min: float = 30.0
    band_tau_rel: float = 0.15
    band_dt0_c: float = 2.0
    n_tau: int = 9

    def __post_init__(self) -> None:
        if self.start is not None and not isinstance(self.start, datetime):
            raise ParameterError(f"start must be a date and time, got {self.start!r}")
        v = self.interval_min
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v <= 600:
            raise ParameterError(f"interval_min must be in (0, 600] min, got {v!r}")
        ToleranceBox.around(ThermalParams(), self.band_tau_rel, self.band_dt0_c, self.n_tau)

    def box(
        self,
        params: ThermalParams,
        robust: tuple[tuple[float, float], tuple[float, float]] | None = None,
    ) -> ToleranceBox:
        """The plan's robust box when it has one, else the box around ``params``."""
        if robust is not None:
            (t0, t1), (d0, d1) = robust
            return ToleranceBox(t0, t1, d0, d1, self.n_tau, "the plan's robust box")
        return ToleranceBox.around(params, self.band_tau_rel, self.band_dt0_c, self.n_tau)


def parse_start(text: str) -> datetime:
    """``"2026-11-24 08:00"`` (or ISO ``2026-11-24T08:00[:ss]``) as a datetime."""
    s = str(text).strip()
    if re.fullmatch(r"\d{4}-\d{2}-\d{2}[ T]\d{1,2}:\d{2}(:\d{2})?", s):
        try:
            return datetime.fromisoformat(s.replace(" ", "T") if "T" not in s else s)
        except ValueError:
            pass
    raise ParameterError(f"start {text!r} is not a date and time; write it like '2026-11-24 08:00'")


def clock(start: datetime | None, minutes: float) -> str:
    """Wall-clock ``HH:MM`` (with the date when it is not the start's day), or ``T+h:mm``."""
    if start is None:
        m = int(round(minutes))
        return f"T+{m // 60}:{m % 60:02d}"
    t = start + timedelta(minutes=float(minutes))
    t = (t + timedelta(seconds=30)).replace(second=0, microsecond=0)
    return t.strftime("%H:%M") if t.date() == start.date() else t.strftime("%a %d %b %H:%M")


def hmm(minutes: float) -> str:
    m = int(round(minutes))
    return f"{m // 60}:{m % 60:02d}"


@dataclass(frozen=True, slots=True)
class Checkpoints:
    """Expected chamber and device temperatures of a programme, with the device's band.

    Attributes
    ----------
    programme : Programme
    params : ThermalParams
        Nominal model.
    box : ToleranceBox
        Parameter box of the band.
    start : datetime or None
        Wall-clock start.
    time_min, tk_c, t_c, t_low_c, t_high_c : arrays
        Dense curves (min, degC): chamber, expected device temperature, band.
    check_min : array
        Checkpoint times, min (every ``interval_min`` and the end).
    check_tk_c, check_t_c, check_low_c, check_high_c, check_g_c_per_min : arrays
        Values at the checkpoints (gradient in degC/min).
    """

    programme: Programme
    params: ThermalParams
    box: ToleranceBox
    start: datetime | None
    time_min: np.ndarray
    tk_c: np.ndarray
    t_c: np.ndarray
    t_low_c: np.ndarray
    t_high_c: np.ndarray
    check_min: np.ndarray
    check_tk_c: np.ndarray
    check_t_c: np.ndarray
    check_low_c: np.ndarray
    check_high_c: np.ndarray
    check_g_c_per_min: np.ndarray

    @property
    def end(self) -> datetime | None:
        return (
            None if self.start is None else self.start + timedelta(minutes=self.programme.total_min)
        )

    def to_frame(self) -> pd.DataFrame:
        """One row per checkpoint: clock, elapsed time, chamber setpoint, expected device
        temperature, its band and expected gradient."""
        return pd.DataFrame(
            {
                "checkpoint": np.arange(1, self.check_min.size + 1),
                "clock": [clock(self.start, m) for m in self.check_min],
                "elapsed_min": self.check_min,
                "elapsed_hmm": [hmm(m) for m in self.check_min],
                "chamber_setpoint_c": self.check_tk_c,
                "device_expected_c": self.check_t_c,
                "device_low_c": self.check_low_c,
                "device_high_c": self.check_high_c,
                "gradient_expected_c_per_min": self.check_g_c_per_min,
            }
        )

    def steps_frame(self) -> pd.DataFrame:
        """The step table with wall-clock start and end of every step."""
        frame = self.programme.to_frame()
        starts = frame["start_min"].to_numpy(float)
        ends = starts + frame["duration_min"].to_numpy(float)
        frame.insert(1, "clock_start", [clock(self.start, m) for m in starts])
        frame.insert(2, "clock_end", [clock(self.start, m) for m in ends])
        return frame

    def band_width_at(self, minutes: float) -> float:
        """Width of the device band at a time, degC."""
        return float(
            np.interp(minutes, self.time_min, self.t_high_c)
            - np.interp(minutes, self.time_min, self.t_low_c)
        )


def checkpoints(
    programme: Programme,
    params: ThermalParams | None = None,
    box: ToleranceBox | None = None,
    *,
    interval_min: float = 30.0,
    start: datetime | None = None,
    t0_c: float = 20.0,
    dt_min: float = 0.5,
) -> Checkpoints:
    """Checkpoints every ``interval_min`` and the band of the device temperature.

    Parameters
    ----------
    programme : Programme
        The programme the chamber runs.
    params : ThermalParams, optional
        Nominal model (default :class:`ThermalParams`).
    box : ToleranceBox, optional
        Band box (default tau +-15 %, dT0 +-2 degC around ``params``).
    interval_min : float
        Minutes between checkpoints.
    start : datetime, optional
        Wall-clock start.
    t0_c : float
        Device temperature at the start, degC.
    dt_min : float
        Step of the dense curves, min.
    """
    params = ThermalParams() if params is None else params
    box = ToleranceBox.around(params) if box is None else box
    if not (math.isfinite(interval_min) and interval_min > 0):
        raise ParameterError(f"interval_min must be > 0 min, got {interval_min!r}")
    total = programme.total_min
    checks = np.arange(0.0, total + 1e-9, float(interval_min))
    if total - checks[-1] > 1e-6:
        checks = np.append(checks, total)
    dense = np.union1d(dense_times(total, dt_min), checks)
    nominal = simulate(programme, params, times_min=dense, t0_c=t0_c)
    runs = [simulate(programme, p, times_min=dense, t0_c=t0_c).t_c for p in box.scenarios()]
    stack = np.vstack([nominal.t_c, *runs])
    low, high = stack.min(axis=0), stack.max(axis=0)
    idx = np.searchsorted(dense, checks)
    return Checkpoints(
        programme,
        params,
        box,
        start,
        dense,
        nominal.tk_c,
        nominal.t_c,
        low,
        high,
        checks,
        nominal.tk_c[idx],
        nominal.t_c[idx],
        low[idx],
        high[idx],
        nominal.g_c_per_min[idx],
    )
