"""Chamber programmes (piecewise-linear Tk) and the step tables an operator types in.

A programme is a start temperature and a sequence of segments ``(duration_min,
rate_c_per_min)``. Its step table has exactly these first columns::

    step, start_min, duration_min, tk_start_c, tk_end_c, rate_c_per_min

followed by operator aids: ``duration_hhmm`` and ``segment_type`` (RAMP/HOLD).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import StepTableError
from .params import Limits

STEP_COLUMNS = ("step", "start_min", "duration_min", "tk_start_c", "tk_end_c", "rate_c_per_min")
OPERATOR_COLUMNS = ("duration_hhmm", "segment_type")

#: Temperatures are typed to 0.1 degC: a table is continuous within half of that.
TEMP_TOL_C = 0.05 + 1e-9
#: Rates are checked against limits with this slack (floating-point only).
RATE_TOL_C_PER_MIN = 1e-6


@dataclass(frozen=True, slots=True)
class Programme:
    """Piecewise-linear chamber programme starting at ``start_c``.

    Attributes
    ----------
    durations_min : array (n,)
        Segment durations, min, each > 0.
    rates_c_per_min : array (n,)
        Chamber ramp rate of each segment, degC/min (0 = hold).
    start_c : float
        Chamber temperature at t = 0, degC.
    """

    durations_min: np.ndarray
    rates_c_per_min: np.ndarray
    start_c: float = 20.0

    def __post_init__(self) -> None:
        d = np.atleast_1d(np.asarray(self.durations_min, dtype=float)).copy()
        u = np.atleast_1d(np.asarray(self.rates_c_per_min, dtype=float)).copy()
        if d.ndim != 1 or d.shape != u.shape or d.size == 0:
            raise StepTableError(
                "a programme needs equally many durations and rates (at least one), got "
                f"{d.shape} and {u.shape}"
            )
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(u))):
            raise StepTableError("programme durations and rates must be finite numbers")
        if np.any(d <= 0):
            i = int(np.argmax(d <= 0))
            raise StepTableError(f"segment {i + 1}: duration_min must be > 0, got {d[i]}")
        if not math.isfinite(self.start_c):
            raise StepTableError(f"start_c must be finite, got {self.start_c}")
        d.setflags(write=False)
        u.setflags(write=False)
        object.__setattr__(self, "durations_min", d)
        object.__setattr__(self, "rates_c_per_min", u)
        object.__setattr__(self, "start_c", float(self.start_c))

    # -- geometry ---------------------------------------------------------------------
    @property
    def n_segments(self) -> int:
        return int(self.durations_min.size)

    @property
    def total_min(self) -> float:
        return float(self.durations_min.sum())

    @property
    def starts_min(self) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(self.durations_min)[:-1]))

    @property
    def boundary_temps_c(self) -> np.ndarray:
        """Chamber temperature at every segment boundary, length ``n + 1``."""
        return self.start_c + np.concatenate(
            ([0.0], np.cumsum(self.durations_min * self.rates_c_per_min))
        )

    @property
    def end_c(self) -> float:
        return float(self.boundary_temps_c[-1])

    def chamber_at(self, times_min: np.ndarray) -> np.ndarray:
        """Chamber temperature at arbitrary times (holds the last value past the end)."""
        edges = np.concatenate(([0.0], np.cumsum(self.durations_min)))
        return np.interp(np.asarray(times_min, dtype=float), edges, self.boundary_temps_c)

    # -- limits ------------------------------------------------------------------------
    def violations(self, limits: Limits) -> list[str]:
        """Every chamber-side limit this programme breaks, as readable sentences."""
        out: list[str] = []
        u = self.rates_c_per_min
        lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
        for i in np.flatnonzero((u < lo - RATE_TOL_C_PER_MIN) | (u > hi + RATE_TOL_C_PER_MIN)):
            out.append(
                f"step {i + 1}: rate {u[i]:.4f} degC/min outside the chamber limits "
                f"{lo} .. {hi} degC/min"
            )
        tk = self.boundary_temps_c
        for i in np.flatnonzero(
            (tk < limits.chamber_min_c - TEMP_TOL_C) | (tk > limits.chamber_max_c + TEMP_TOL_C)
        ):
            out.append(
                f"chamber temperature {tk[i]:.2f} degC at the "
                f"{'start' if i == 0 else f'end of step {i}'} lies outside the chamber limits "
                f"{limits.chamber_min_c} .. {limits.chamber_max_c} degC"
            )
        if abs(self.start_c - limits.start_c) > TEMP_TOL_C:
            out.append(f"the programme starts at {self.start_c:.2f} degC, not {limits.start_c}")
        if abs(self.end_c - limits.end_c) > limits.end_tol_c + 1e-9:
            out.append(
                f"the programme ends at {self.end_c:.2f} degC, more than {limits.end_tol_c} "
                f"degC from {limits.end_c} degC"
            )
        if self.total_min > limits.duration_max_min + 1e-9:
            out.append(
                f"the programme lasts {self.total_min:.1f} min, longer than the limit "
                f"{limits.duration_max_min:.0f} min"
            )
        return out

    # -- operator form -----------------------------------------------------------------
    def merged(self, rate_tol_c_per_min: float = 1e-9) -> Programme:
        """Merge consecutive segments with equal rates (same chamber path, fewer steps)."""
        d, u = self.durations_min, self.rates_c_per_min
        keep_d, keep_u = [float(d[0])], [float(u[0])]
        for di, ui in zip(d[1:], u[1:], strict=True):
            if abs(ui - keep_u[-1]) <= rate_tol_c_per_min:
                # same rate: combine, preserving the temperature change exactly
                total = keep_d[-1] + di
                keep_u[-1] = (keep_u[-1] * keep_d[-1] + ui * di) / total
                keep_d[-1] = total
            else:
                keep_d.append(float(di))
                keep_u.append(float(ui))
        return Programme(np.array(keep_d), np.array(keep_u), self.start_c)

    def rounded(self, limits: Limits, exact_start: bool = False) -> Programme:
        """What an operator types: whole minutes, boundary temperatures to 0.1 degC.

        Boundary times are rounded cumulatively (the total keeps its rounded length);
        boundary temperatures are rounded to 0.1 degC and, where rounding would push a
        rate past a chamber limit, moved by 0.1 degC steps back inside. Rates are then
        recomputed from the rounded temperatures, so table and simulation agree exactly,
        and equal-rate neighbours are merged. ``exact_start`` keeps the start temperature
        as it is (a programme that continues a run from the chamber's current setpoint).
        """
        t_edges = np.round(np.concatenate(([0.0], np.cumsum(self.durations_min))))
        tk_target = self.boundary_temps_c
        keep = np.concatenate(([True], np.diff(t_edges) > 0))
        t_edges, tk_target = t_edges[keep], tk_target[keep]
        if t_edges.size < 2:
            raise StepTableError(
                f"the programme lasts {self.total_min:.2f} min: less than one whole minute"
            )
        dur = np.diff(t_edges)
        tk = np.empty_like(tk_target)
        tk[0] = float(tk_target[0]) if exact_start else round(float(tk_target[0]), 1)
        lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
        for i in range(dur.size):
            want = round(float(tk_target[i + 1]), 1)
            # the tightest 0.1-grid values reachable from tk[i] within the rate limits
            top = math.floor(round((tk[i] + hi * dur[i]) * 10, 6)) / 10
            bot = math.ceil(round((tk[i] + lo * dur[i]) * 10, 6)) / 10
            tk[i + 1] = min(max(want, bot), top)
        rates = np.diff(tk) / dur
        return Programme(dur, rates, float(tk[0])).merged(rate_tol_c_per_min=1e-9)

    # -- step table --------------------------------------------------------------------
    def to_frame(self) -> pd.DataFrame:
        """Step table as a DataFrame (one row per segment)."""
        tk = self.boundary_temps_c
        d = self.durations_min
        hhmm = [f"{int(m // 60):02d}:{int(round(m % 60)):02d}" for m in d]
        seg_type = np.where(np.abs(self.rates_c_per_min) < 1e-12, "HOLD", "RAMP")
        return pd.DataFrame(
            {
                "step": np.arange(1, self.n_segments + 1),
                "start_min": self.starts_min,
                "duration_min": d,
                "tk_start_c": tk[:-1],
                "tk_end_c": tk[1:],
                "rate_c_per_min": self.rates_c_per_min,
                "duration_hhmm": hhmm,
                "segment_type": seg_type,
            }
        )

    def to_csv(self, path: Path | str, inputs=()) -> Path:
        """Write the step table atomically. Temperatures to 0.01 degC, rates to 1e-6."""
        from .io import write_atomic

        frame = self.to_frame()
        frame["start_min"] = frame["start_min"].round(3)
        frame["duration_min"] = frame["duration_min"].round(3)
        frame["tk_start_c"] = frame["tk_start_c"].round(3)
        frame["tk_end_c"] = frame["tk_end_c"].round(3)
        frame["rate_c_per_min"] = frame["rate_c_per_min"].round(6)
        return write_atomic(path, lambda p: frame.to_csv(p, index=False), inputs)


def programme_from_frame(
    frame: pd.DataFrame, limits: Limits | None = None, source: str = "step table"
) -> Programme:
    """Validate a step table and build its :class:`Programme`.

    The chamber path is taken from what an operator types (``tk_start_c``, ``tk_end_c``,
    ``duration_min``); ``rate_c_per_min`` must agree with it. Every problem names the row
    (1-based step) and what to change.
    """
    limits = Limits() if limits is None else limits
    missing = [c for c in STEP_COLUMNS if c not in frame.columns]
    if missing:
        raise StepTableError(
            f"{source}: missing column(s) {', '.join(missing)}; a step table needs "
            f"{', '.join(STEP_COLUMNS)}"
        )
    if len(frame) == 0:
        raise StepTableError(f"{source}: the step table has no rows")
    values = {}
    for c in STEP_COLUMNS:
        col = pd.to_numeric(frame[c], errors="coerce")
        bad = col.isna().to_numpy()
        if bad.any():
            r = int(np.argmax(bad))
            raise StepTableError(
                f"{source}: row {r + 1}, column {c}: {frame[c].iloc[r]!r} is not a number"
            )
        values[c] = col.to_numpy(dtype=float)
        if not np.all(np.isfinite(values[c])):
            r = int(np.argmax(~np.isfinite(values[c])))
            raise StepTableError(f"{source}: row {r + 1}, column {c}: value is not finite")
    step, start, dur = values["step"], values["start_min"], values["duration_min"]
    tk0, tk1, rate = values["tk_start_c"], values["tk_end_c"], values["rate_c_per_min"]
    n = len(frame)
    if not np.array_equal(step, np.arange(1, n + 1)):
        r = int(np.argmax(step != np.arange(1, n + 1)))
        raise StepTableError(
            f"{source}: row {r + 1}: step is {step[r]:g}, expected {r + 1} (steps count 1, 2, ...)"
        )
    for r in range(n):
        where = f"{source}: step {r + 1}"
        if dur[r] <= 0:
            raise StepTableError(f"{where}: duration_min must be > 0, got {dur[r]:g}")
        expected_start = 0.0 if r == 0 else start[r - 1] + dur[r - 1]
        if abs(start[r] - expected_start) > 0.01:
            raise StepTableError(
                f"{where}: start_min is {start[r]:g} but the previous steps end at "
                f"{expected_start:g} min; fix start_min or the durations"
            )
        if r == 0 and abs(tk0[0] - limits.start_c) > TEMP_TOL_C:
            raise StepTableError(
                f"{where}: the programme starts at {tk0[0]:g} degC, not at the required "
                f"{limits.start_c:g} degC"
            )
        if r > 0 and abs(tk0[r] - tk1[r - 1]) > TEMP_TOL_C:
            raise StepTableError(
                f"{where}: tk_start_c {tk0[r]:g} degC does not continue the previous step's "
                f"tk_end_c {tk1[r - 1]:g} degC (the chamber programme must be continuous)"
            )
        if abs(tk0[r] + rate[r] * dur[r] - tk1[r]) > 2 * TEMP_TOL_C:
            raise StepTableError(
                f"{where}: rate_c_per_min {rate[r]:g} over {dur[r]:g} min goes from "
                f"{tk0[r]:g} to {tk0[r] + rate[r] * dur[r]:.2f} degC, not to tk_end_c "
                f"{tk1[r]:g}; fix the rate or the end temperature"
            )
    # the chamber path as typed: continuous through the typed end temperatures
    temps = np.concatenate(([tk0[0]], tk1))
    rates = np.diff(temps) / dur
    lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
    for r in range(n):
        if not lo - RATE_TOL_C_PER_MIN <= rates[r] <= hi + RATE_TOL_C_PER_MIN:
            raise StepTableError(
                f"{source}: step {r + 1}: rate {rates[r]:.4f} degC/min is outside the chamber "
                f"limits {lo:g} .. {hi:g} degC/min; lengthen the step or lower its change"
            )
    for r in range(n + 1):
        if not limits.chamber_min_c - TEMP_TOL_C <= temps[r] <= limits.chamber_max_c + TEMP_TOL_C:
            raise StepTableError(
                f"{source}: step {max(r, 1)}: chamber temperature {temps[r]:g} degC is outside "
                f"the chamber limits {limits.chamber_min_c:g} .. {limits.chamber_max_c:g} degC"
            )
    total = float(dur.sum())
    if total > limits.duration_max_min + 1e-6:
        raise StepTableError(
            f"{source}: the programme lasts {total:g} min, more than the limit "
            f"{limits.duration_max_min:g} min; shorten it or raise duration_max_min"
        )
    return Programme(dur, rates, float(temps[0]))


def read_steps(path: Path | str, limits: Limits | None = None) -> Programme:
    """Read and validate a step-table CSV (see :func:`programme_from_frame`)."""
    path = Path(path)
    if not path.is_file():
        raise StepTableError(f"step table {path} does not exist or is not a file")
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise StepTableError(f"{path}: not a readable CSV step table ({first})") from None
    return programme_from_frame(frame, limits, source=str(path))
