"""Measured logs of a calibration run: read, validate, and report NaNs and gaps.

The log format (CSV, one row per sample, units in every column name)::

    time_s     required  seconds from the start, strictly increasing (irregular, gaps ok)
    t_int_c    required  the device's internal temperature sensor, degC (NaN = no reading)
    tk_set_c   optional  the chamber setpoint (the programme), degC
    tk_air_c   optional  the chamber's measured air temperature, degC
    drift_dph  optional  gyro drift (output minus the known reference rate), deg/h

Any other column is kept in :attr:`MeasuredLog.extra` and ignored by the estimator.

Nothing is dropped or interpolated: a NaN in ``t_int_c`` stays in the arrays (the
estimator skips its measurement update) and is counted in :attr:`MeasuredLog.report`
together with the time spans where the sampling step is much longer than usual.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import LogFormatError

REQUIRED_COLUMNS = ("time_s", "t_int_c")
OPTIONAL_COLUMNS = ("tk_set_c", "tk_air_c", "drift_dph")
TEMPERATURE_COLUMNS = ("t_int_c", "tk_set_c", "tk_air_c")

#: Fewer finite internal-temperature readings than this cannot give a gradient estimate.
MIN_FINITE_ROWS = 5
#: A sampling step longer than this many median steps is reported as a gap.
GAP_FACTOR = 3.0
#: Internal/chamber temperatures outside this range are not plausible in degC.
PLAUSIBLE_C = (-100.0, 150.0)
#: All readings above this look like kelvin (the coldest chamber is ~ -75 degC = 198 K).
KELVIN_FLOOR = 200.0


@dataclass(frozen=True, slots=True)
class LogReport:
    """What a log is missing: NaN counts per column, NaN runs and sampling gaps.

    Attributes
    ----------
    n_rows : int
        Rows in the log.
    nan_counts : dict[str, int]
        Number of NaN rows per known column (``t_int_c``, and the optional columns present).
    nan_spans_s : tuple of (start_s, end_s, n_rows)
        Runs of consecutive NaN ``t_int_c`` rows, by the time of their first and last row.
    gaps_s : tuple of (start_s, end_s)
        Sampling steps longer than ``GAP_FACTOR`` x the median step: the times of the two
        rows on either side of the gap, s.
    median_step_s : float
        Median sampling step, s.
    """

    n_rows: int
    nan_counts: dict[str, int]
    nan_spans_s: tuple[tuple[float, float, int], ...]
    gaps_s: tuple[tuple[float, float], ...]
    median_step_s: float

    @property
    def clean(self) -> bool:
        """True when there is no NaN and no gap."""
        return not self.gaps_s and not any(self.nan_counts.values())

    def lines(self) -> list[str]:
        """Human-readable report, one finding per line (empty when clean)."""
        out = []
        for col, n in self.nan_counts.items():
            if n:
                out.append(f"{col}: {n} of {self.n_rows} rows are NaN (kept; not interpolated)")
        for a, b, n in self.nan_spans_s[:10]:
            out.append(f"t_int_c NaN span {a:g} .. {b:g} s ({n} rows)")
        if len(self.nan_spans_s) > 10:
            out.append(f"... and {len(self.nan_spans_s) - 10} more t_int_c NaN spans")
        for a, b in self.gaps_s[:10]:
            out.append(
                f"gap in sampling {a:g} .. {b:g} s ({b - a:g} s; median step "
                f"{self.median_step_s:g} s)"
            )
        if len(self.gaps_s) > 10:
            out.append(f"... and {len(self.gaps_s) - 10} more gaps")
        return out

    def summary(self) -> str:
        lines = self.lines()
        head = f"{self.n_rows} rows, median step {self.median_step_s:g} s"
        return head + ("; no NaN, no gaps" if not lines else "; " + "; ".join(lines))


@dataclass(frozen=True, slots=True)
class MeasuredLog:
    """A validated measured log (see the module docstring for the format).

    Arrays are read-only float arrays of equal length; optional columns absent from the
    file are ``None``. ``extra`` holds every other column unchanged.
    """

    time_s: np.ndarray
    t_int_c: np.ndarray
    tk_set_c: np.ndarray | None
    tk_air_c: np.ndarray | None
    drift_dph: np.ndarray | None
    extra: pd.DataFrame
    source: str
    report: LogReport

    @property
    def n_rows(self) -> int:
        return int(self.time_s.size)

    @property
    def time_min(self) -> np.ndarray:
        """Sample times in minutes (the programme's time unit)."""
        return self.time_s / 60.0

    @property
    def gaps(self) -> tuple[tuple[float, float], ...]:
        """Sampling gaps ``(start_s, end_s)``; see :class:`LogReport`."""
        return self.report.gaps_s

    @property
    def nan_counts(self) -> dict[str, int]:
        return self.report.nan_counts

    @property
    def finite(self) -> np.ndarray:
        """Mask of rows with a finite internal-temperature reading."""
        return np.isfinite(self.t_int_c)

    def to_frame(self) -> pd.DataFrame:
        """The log in its CSV format: known columns first, then the extra columns."""
        cols: dict[str, np.ndarray] = {"time_s": self.time_s, "t_int_c": self.t_int_c}
        for name in OPTIONAL_COLUMNS:
            v = getattr(self, name)
            if v is not None:
                cols[name] = v
        frame = pd.DataFrame(cols)
        extra = self.extra.reset_index(drop=True)
        return pd.concat([frame, extra], axis=1) if extra.shape[1] else frame


def _numeric_column(frame: pd.DataFrame, col: str, source: str) -> np.ndarray:
    """Column as float; a value that is present but not a finite number is an error."""
    raw = frame[col]
    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float, copy=True)
    blank = raw.isna().to_numpy()
    if not pd.api.types.is_numeric_dtype(raw):
        text = raw.astype(str).str.strip().str.lower()
        blank = blank | text.isin(["", "nan", "na", "none", "null"]).to_numpy()
    bad = ~np.isfinite(values) & ~blank
    if bad.any():
        r = int(np.argmax(bad))
        raise LogFormatError(
            f"{source}: row {r + 1} (line {r + 2}), column {col}: {raw.iloc[r]!r} is not a "
            "finite number; fix or blank the value (a blank reading is kept as NaN)"
        )
    values[blank] = np.nan
    return values


def _check_time(t: np.ndarray, source: str) -> None:
    if np.isnan(t).any():
        r = int(np.argmax(np.isnan(t)))
        raise LogFormatError(
            f"{source}: row {r + 1} (line {r + 2}), column time_s: the time is missing; every "
            "row needs a time (delete the row if it has none)"
        )
    step = np.diff(t)
    if (step == 0).any():
        r = int(np.argmax(step == 0)) + 1
        raise LogFormatError(
            f"{source}: row {r + 1} (line {r + 2}), column time_s: time {t[r]:g} s duplicates "
            "the previous row; remove the duplicate row"
        )
    if (step < 0).any():
        r = int(np.argmax(step < 0)) + 1
        raise LogFormatError(
            f"{source}: row {r + 1} (line {r + 2}), column time_s: time {t[r]:g} s is earlier "
            f"than the previous row's {t[r - 1]:g} s; time_s must be strictly increasing "
            "(sort the log or fix a clock reset)"
        )


def _check_temperature(v: np.ndarray, col: str, source: str) -> None:
    finite = v[np.isfinite(v)]
    if finite.size == 0:
        return
    lo, hi = float(finite.min()), float(finite.max())
    if lo > KELVIN_FLOOR and hi < 500.0:
        raise LogFormatError(
            f"{source}: column {col}: every value lies in {lo:g} .. {hi:g}, which looks like "
            "kelvin; the log needs degC (subtract 273.15)"
        )
    plo, phi = PLAUSIBLE_C
    if lo < plo or hi > phi:
        idx = np.flatnonzero(np.isfinite(v) & ((v < plo) | (v > phi)))
        r = int(idx[0])
        hint = ""
        if hi > phi and lo > -60.0:
            hint = "; if the log is in Fahrenheit convert with (F - 32) * 5 / 9"
        raise LogFormatError(
            f"{source}: row {r + 1} (line {r + 2}), column {col}: {v[r]:g} is not a plausible "
            f"temperature in degC (expected {plo:g} .. {phi:g}){hint}"
        )


def _nan_spans(time_s: np.ndarray, isnan: np.ndarray) -> tuple[tuple[float, float, int], ...]:
    if not isnan.any():
        return ()
    edges = np.diff(np.concatenate(([0], isnan.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)  # exclusive
    return tuple(
        (float(time_s[a]), float(time_s[b - 1]), int(b - a))
        for a, b in zip(starts, ends, strict=True)
    )


def log_report(
    time_s: np.ndarray, columns: dict[str, np.ndarray], gap_factor: float = GAP_FACTOR
) -> LogReport:
    """NaN counts, NaN runs of ``t_int_c`` and sampling gaps (step > ``gap_factor`` x median)."""
    t = np.asarray(time_s, dtype=float)
    step = np.diff(t)
    med = float(np.median(step)) if step.size else float("nan")
    big = np.flatnonzero(step > gap_factor * med) if step.size else np.zeros(0, dtype=int)
    gaps = tuple((float(t[i]), float(t[i + 1])) for i in big)
    nan_counts = {k: int(np.isnan(v).sum()) for k, v in columns.items()}
    spans = _nan_spans(t, np.isnan(columns["t_int_c"]))
    return LogReport(int(t.size), nan_counts, spans, gaps, med)


def log_from_frame(frame: pd.DataFrame, source: str = "log") -> MeasuredLog:
    """Validate a log table and build its :class:`MeasuredLog`.

    Raises
    ------
    LogFormatError
        Missing required column, non-numeric value, time missing/not strictly increasing/
        duplicated, temperatures that look like kelvin or are implausible in degC (with a
        Fahrenheit hint), or fewer than ``MIN_FINITE_ROWS`` finite ``t_int_c`` readings.
        The message names the source, the column and the row.
    """
    if not isinstance(frame, pd.DataFrame):
        raise LogFormatError(f"{source}: expected a pandas DataFrame, got {type(frame).__name__}")
    cols = [str(c).strip() for c in frame.columns]
    if len(set(cols)) != len(cols):
        dup = sorted({c for c in cols if cols.count(c) > 1})
        raise LogFormatError(f"{source}: column(s) {', '.join(dup)} appear more than once")
    frame = frame.set_axis(cols, axis=1).reset_index(drop=True)
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise LogFormatError(
            f"{source}: missing required column(s) {', '.join(missing)}; a log needs "
            f"{', '.join(REQUIRED_COLUMNS)} (optional: {', '.join(OPTIONAL_COLUMNS)}); "
            f"found {', '.join(cols) or 'no columns'}"
        )
    known = [c for c in REQUIRED_COLUMNS + OPTIONAL_COLUMNS if c in frame.columns]
    values = {c: _numeric_column(frame, c, source) for c in known}
    for v in values.values():
        v.setflags(write=False)
    _check_time(values["time_s"], source)
    for c in TEMPERATURE_COLUMNS:
        if c in values:
            _check_temperature(values[c], c, source)
    n_finite = int(np.isfinite(values["t_int_c"]).sum())
    if n_finite < MIN_FINITE_ROWS:
        raise LogFormatError(
            f"{source}: column t_int_c has {n_finite} finite reading(s) in {len(frame)} rows; "
            f"at least {MIN_FINITE_ROWS} are needed to estimate a gradient"
        )
    report = log_report(values["time_s"], {c: values[c] for c in known if c != "time_s"})
    extra = frame[[c for c in frame.columns if c not in known]].copy()
    return MeasuredLog(
        time_s=values["time_s"],
        t_int_c=values["t_int_c"],
        tk_set_c=values.get("tk_set_c"),
        tk_air_c=values.get("tk_air_c"),
        drift_dph=values.get("drift_dph"),
        extra=extra,
        source=source,
        report=report,
    )


def read_log(path: Path | str) -> MeasuredLog:
    """Read and validate a measured-log CSV (see :func:`log_from_frame`)."""
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"log {path} does not exist or is not a file")
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise LogFormatError(f"{path}: not a readable CSV log ({first})") from None
    return log_from_frame(frame, source=str(path))
