"""Chamber programmes (piecewise-linear Tk) and the step tables an operator types in.

A programme is a start temperature and a sequence of segments ``(duration_min,
rate_c_per_min)``. Its step table has exactly these first columns::

    step, start_min, duration_min, tk_start_c, tk_end_c, rate_c_per_min

followed by operator aids: ``duration_hhmm`` and ``segment_type`` (RAMP/HOLD). Where a
table has them they must agree with the numbers (``duration_hhmm`` is ``duration_min``
to the whole minute, a ``HOLD`` keeps its temperature): a table edited in one place only
is refused, as the operator would type another programme than the one read.

A table written by schedsyn for a plan starts with its metadata, one comment line per
key (:class:`StepTableMeta`)::

    # schedsyn_version: 0.1.0
    # experiment: W3
    # working_lo_c: 0.0
    # working_hi_c: 30.0
    # tau_s: 2400.0
    ...
    step,start_min,duration_min,tk_start_c,tk_end_c,rate_c_per_min,duration_hhmm,segment_type

so that ``schedsyn simulate``, ``compare`` and ``sweep`` know the working region and the
model it was planned for. A table without comment lines (e.g. one a spreadsheet saved
without them) still reads, as a table with no metadata. Read it with pandas as
``pd.read_csv(path, comment="#")``. Semicolon-separated tables with decimal commas (a
spreadsheet in a European locale) are recognised (:mod:`schedsyn.csvdialect`).
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .csvdialect import SEP_HINT, detect_csv_dialect
from .errors import ParameterError, StepTableError
from .params import Limits, ThermalParams

STEP_COLUMNS = ("step", "start_min", "duration_min", "tk_start_c", "tk_end_c", "rate_c_per_min")
OPERATOR_COLUMNS = ("duration_hhmm", "segment_type")

#: Temperatures are typed to 0.1 degC: a table is continuous within half of that.
TEMP_TOL_C = 0.05 + 1e-9
#: Rates are checked against limits with this slack (floating-point only).
RATE_TOL_C_PER_MIN = 1e-6


# ---------------------------------------------------------------------------------------
# metadata of a step table
# ---------------------------------------------------------------------------------------
_LIMIT_KEYS = tuple(f.name for f in fields(Limits))
_TEXT_KEYS = ("schedsyn_version", "experiment", "model", "status")
_INT_KEYS = ("levels_required", "max_steps")
_KEY = re.compile(r"^#\s*([A-Za-z_][A-Za-z0-9_]*)\s*:\s?(.*)$")


@dataclass(frozen=True, slots=True)
class StepTableMeta:
    """What a step table was planned for, written as ``# key: value`` lines at its top.

    Every field is optional (None: not recorded). Units are in the names.

    Attributes
    ----------
    schedsyn_version : str
        Version of schedsyn that wrote the table.
    experiment : str
        Experiment name (e.g. ``W3``).
    working_lo_c, working_hi_c : float
        Working region, degC: the region whose coverage the table was planned for.
    approx_lo_c, approx_hi_c : float
        Approximation region, degC.
    tau_s, dt0_c : float
        Nominal model: time constant, s, and self-heating offset, degC.
    levels_required : int
        Distinct gradient levels per 1 degC bin (the paper's 6).
    delta_c_per_min : float
        Minimum difference between two levels, degC/min.
    rate_min_c_per_min ... t_init_c : float
        The chamber, device and duration limits (the fields of
        :class:`~schedsyn.params.Limits`, same names).
    robust_tau_lo_s, robust_tau_hi_s : float
        Robust box of time constants the plan was made for, s.
    robust_dt0_lo_c, robust_dt0_hi_c : float
        Robust box of self-heating offsets, degC.
    end_soak_min : float
        Minutes the device needs after the last step, with the chamber held at its end
        temperature, to come within ``end_tol_c`` of the temperature it settles at there
        (``end_c + dt0_c`` for the running device).
    end_soak_included_min : float
        Length of the hold at the end that the table already contains for that purpose,
        min (``schedsyn plan --end-soak``), else None.
    model : str
        An augmented model the plan was made with, as the JSON of a model file
        (``schedsyn diagnose``), or None for the first-order lag of ``tau_s``, ``dt0_c``.
    max_steps : int
        The most steps the table was planned to have (the controller's).
    min_step_min : float
        The shortest step the table was planned to have, min.
    segment_min : float
        The control segment the planner chose the rates on, min (a planned step is made
        of such segments, before rounding; a re-planned rest's from the minute it starts).
        Longer than requested when the planner went to coarser segments to meet
        ``max_steps`` or ``min_step_min`` (the plan's notes say so).
    status : str
        The planner's verdict on the table: ``complete``, ``incomplete`` or ``limits
        violated`` (:attr:`schedsyn.planner.Plan.status`).
    extra : tuple of (key, value)
        Keys this version does not know, kept verbatim (written back unchanged).
    """

    schedsyn_version: str | None = None
    experiment: str | None = None
    working_lo_c: float | None = None
    working_hi_c: float | None = None
    approx_lo_c: float | None = None
    approx_hi_c: float | None = None
    tau_s: float | None = None
    dt0_c: float | None = None
    levels_required: int | None = None
    delta_c_per_min: float | None = None
    rate_min_c_per_min: float | None = None
    rate_max_c_per_min: float | None = None
    chamber_min_c: float | None = None
    chamber_max_c: float | None = None
    device_min_c: float | None = None
    device_max_c: float | None = None
    duration_max_min: float | None = None
    start_c: float | None = None
    end_c: float | None = None
    end_tol_c: float | None = None
    t_init_c: float | None = None
    robust_tau_lo_s: float | None = None
    robust_tau_hi_s: float | None = None
    robust_dt0_lo_c: float | None = None
    robust_dt0_hi_c: float | None = None
    end_soak_min: float | None = None
    end_soak_included_min: float | None = None
    model: str | None = None
    max_steps: int | None = None
    min_step_min: float | None = None
    segment_min: float | None = None
    status: str | None = None
    extra: tuple[tuple[str, str], ...] = field(default=())

    def __post_init__(self) -> None:
        from .params import real_number

        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or f.name == "extra":
                continue
            if f.name in _TEXT_KEYS:
                if not isinstance(v, str) or "\n" in v or "\r" in v:
                    raise ParameterError(f"{f.name} must be one line of text, got {v!r}")
            elif f.name in _INT_KEYS:
                x = real_number(f.name, v)
                if x != int(x):
                    raise ParameterError(f"{f.name} must be a whole number, got {v!r}")
                object.__setattr__(self, f.name, int(x))
            else:
                object.__setattr__(self, f.name, real_number(f.name, v))
        extra = tuple((str(k), str(v)) for k, v in self.extra)
        for k, v in extra:
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", k) or "\n" in v:
                raise ParameterError(f"metadata key {k!r} must be a name and its value one line")
        object.__setattr__(self, "extra", extra)

    # -- views ------------------------------------------------------------------------
    @property
    def working_region_c(self) -> tuple[float, float] | None:
        """``(lo, hi)`` of the working region, degC, or None when not recorded."""
        if self.working_lo_c is None or self.working_hi_c is None:
            return None
        return (self.working_lo_c, self.working_hi_c)

    @property
    def has_model(self) -> bool:
        """Whether the table records the model (``tau_s`` and ``dt0_c``)."""
        return self.tau_s is not None and self.dt0_c is not None

    def params(self, base: ThermalParams | None = None) -> ThermalParams | None:
        """The recorded model over ``base`` (default :class:`ThermalParams`), or None
        when the table records neither ``tau_s`` nor ``dt0_c``."""
        if self.tau_s is None and self.dt0_c is None:
            return None
        base = ThermalParams() if base is None else base
        changes = {k: getattr(self, k) for k in ("tau_s", "dt0_c") if getattr(self, k) is not None}
        return dataclasses.replace(base, **changes)

    def limits(self, base: Limits | None = None) -> Limits | None:
        """The recorded limits over ``base`` (default :class:`Limits`), or None when the
        table records none."""
        changes = {k: getattr(self, k) for k in _LIMIT_KEYS if getattr(self, k) is not None}
        if not changes:
            return None
        return dataclasses.replace(Limits() if base is None else base, **changes)

    @property
    def robust_box(self) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
        """``(tau_s_range, dt0_c_range)`` of a robust plan (each None when not robust)."""
        tau = (self.robust_tau_lo_s, self.robust_tau_hi_s)
        dt0 = (self.robust_dt0_lo_c, self.robust_dt0_hi_c)
        return (
            tau if None not in tau else None,  # type: ignore[return-value]
            dt0 if None not in dt0 else None,
        )

    def model_json(self) -> dict | None:
        """The recorded augmented model file content (a dict), or None."""
        if self.model is None:
            return None
        try:
            obj = json.loads(self.model)
        except json.JSONDecodeError as exc:
            raise StepTableError(f"metadata model is not valid JSON ({exc})") from None
        if not isinstance(obj, dict):
            raise StepTableError("metadata model must be a JSON object (a model file)")
        return obj

    # -- text form --------------------------------------------------------------------
    def to_lines(self) -> list[str]:
        """The comment lines, ``# key: value``, in field order (unknown keys last)."""
        out = []
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or f.name == "extra":
                continue
            out.append(f"# {f.name}: {v if isinstance(v, str | int) else repr(float(v))}")
        out += [f"# {k}: {v}" for k, v in self.extra]
        return out

    @classmethod
    def from_lines(cls, lines: Sequence[str], source: str = "step table") -> StepTableMeta:
        """Parse ``# key: value`` lines (others are free comments and ignored).

        Spreadsheet damage is tolerated: surrounding quotes, trailing separators
        (``# tau_s: 2400.0,,,,``) and a decimal comma (``# dt0_c: 3,5``). A value that is
        not a number where one is needed, or a key given twice, is an error naming the
        line.
        """
        known = {f.name for f in fields(cls)} - {"extra"}
        values: dict[str, Any] = {}
        extra: list[tuple[str, str]] = []
        where: dict[str, int] = {}
        for lineno, raw in enumerate(lines, start=1):
            text = _clean_comment(raw)
            m = _KEY.match(text)
            if not m:
                continue
            key, value = m.group(1), m.group(2).strip()
            if key in where:
                raise StepTableError(
                    f"{source}: line {lineno}: metadata key {key!r} is given twice "
                    f"(also on line {where[key]}); delete one of the lines"
                )
            where[key] = lineno
            if key not in known:
                extra.append((key, value))
            elif key in _TEXT_KEYS:
                values[key] = value
            else:
                values[key] = _meta_number(value, key, f"{source}: line {lineno}")
        try:
            return cls(**values, extra=tuple(extra))
        except ParameterError as exc:
            raise StepTableError(f"{source}: metadata: {exc}") from None

    @classmethod
    def from_plan(
        cls,
        plan: Any,
        *,
        end_soak_min: float | None = None,
        end_soak_included_min: float | None = None,
        model_json: dict | None = None,
        segment_min: float | None = None,
    ) -> StepTableMeta:
        """The metadata of a planned experiment (a :class:`schedsyn.planner.Plan`).

        Takes the experiment's name, regions, levels, delta and step limits from
        ``plan.spec``, the model from ``plan.params``, the limits from ``plan.limits``, the
        status from ``plan.status`` and, for a robust plan (several ``plan.scenarios``),
        the box they span. ``segment_min`` (default ``plan.spec.segment_min``): the
        segments the rates were chosen on, when the planner went coarser than the spec.
        """
        spec, params, limits = plan.spec, plan.params, plan.limits
        scen = tuple(getattr(plan, "scenarios", ()) or ())
        box: dict[str, Any] = {}
        if len(scen) > 1:
            taus = [p.tau_s for p in scen]
            dt0s = [p.dt0_c for p in scen]
            box = {
                "robust_tau_lo_s": min(taus),
                "robust_tau_hi_s": max(taus),
                "robust_dt0_lo_c": min(dt0s),
                "robust_dt0_hi_c": max(dt0s),
            }
        return cls(
            schedsyn_version=_version(),
            experiment=str(spec.name),
            working_lo_c=spec.working_lo_c,
            working_hi_c=spec.working_hi_c,
            approx_lo_c=spec.approx_lo_c,
            approx_hi_c=spec.approx_hi_c,
            tau_s=params.tau_s,
            dt0_c=params.dt0_c,
            levels_required=spec.levels_required,
            delta_c_per_min=spec.delta_c_per_min,
            **{k: getattr(limits, k) for k in _LIMIT_KEYS},
            **box,
            end_soak_min=end_soak_min,
            end_soak_included_min=end_soak_included_min,
            model=None if model_json is None else json.dumps(model_json, sort_keys=True),
            max_steps=getattr(spec, "max_steps", None),
            min_step_min=getattr(spec, "min_step_min", None),
            segment_min=getattr(spec, "segment_min", None) if segment_min is None else segment_min,
            status=getattr(plan, "status", None),
        )


def _version() -> str:
    from . import __version__

    return str(__version__)


def _clean_comment(raw: str) -> str:
    """A comment line as written, undoing what a spreadsheet adds around it."""
    text = raw.strip().lstrip("\ufeff")
    text = re.sub(r"[,;\t]+$", "", text).strip()  # empty cells after it
    if len(text) >= 2 and text[0] == '"' and text[-1] == '"':
        text = text[1:-1].replace('""', '"')
    return text.strip()


def _meta_number(value: str, key: str, where: str) -> float:
    text = value.strip()
    if re.fullmatch(r"[+-]?\d+,\d+", text):  # a decimal comma
        text = text.replace(",", ".")
    try:
        v = float(text)
    except ValueError:
        raise StepTableError(
            f"{where}: metadata {key} is {value!r}, not a number; fix the value or delete the line"
        ) from None
    if not math.isfinite(v):
        raise StepTableError(f"{where}: metadata {key} must be finite, got {value!r}")
    return v


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
    meta : StepTableMeta, optional
        What the programme was planned for (region, model, limits, ...); written at the
        top of its step table and read back by :func:`read_steps`.
    """

    durations_min: np.ndarray
    rates_c_per_min: np.ndarray
    start_c: float = 20.0
    meta: StepTableMeta | None = None

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
        if isinstance(self.start_c, bool) or not isinstance(self.start_c, int | float | np.number):
            raise StepTableError(f"start_c must be a number, got {self.start_c!r}")
        if not math.isfinite(self.start_c):
            raise StepTableError(f"start_c must be finite, got {self.start_c}")
        if self.meta is not None and not isinstance(self.meta, StepTableMeta):
            raise StepTableError(f"meta must be a StepTableMeta, got {type(self.meta).__name__}")
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
                f"step {i + 1}: rate {u[i]:.4f} °C/min outside the chamber limits "
                f"{lo} .. {hi} °C/min"
            )
        tk = self.boundary_temps_c
        for i in np.flatnonzero(
            (tk < limits.chamber_min_c - TEMP_TOL_C) | (tk > limits.chamber_max_c + TEMP_TOL_C)
        ):
            out.append(
                f"chamber temperature {tk[i]:.2f} °C at the "
                f"{'start' if i == 0 else f'end of step {i}'} lies outside the chamber limits "
                f"{limits.chamber_min_c} .. {limits.chamber_max_c} °C"
            )
        if abs(self.start_c - limits.start_c) > TEMP_TOL_C:
            out.append(f"the programme starts at {self.start_c:.2f} °C, not {limits.start_c}")
        if abs(self.end_c - limits.end_c) > limits.end_tol_c + 1e-9:
            out.append(
                f"the programme ends at {self.end_c:.2f} °C, more than {limits.end_tol_c} "
                f"°C from {limits.end_c} °C"
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
        return Programme(np.array(keep_d), np.array(keep_u), self.start_c, self.meta)

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
        return Programme(dur, rates, float(tk[0]), self.meta).merged(rate_tol_c_per_min=1e-9)

    def ending_at(self, end_c: float, limits: Limits) -> Programme:
        """The programme with the chamber's last temperature moved onto ``end_c``.

        A plan may end anywhere within ``limits.end_tol_c`` of the end temperature; the
        table an operator types should say the end temperature itself. The last ramp is
        steered onto it (the holds after it move with it); where that would break the
        rate limits, a short ramp onto it is appended (whole minutes, if the duration
        limit has room). Unchanged when it already ends there, or when neither fits.
        The caller re-checks coverage and limits (the device's path changes at the end).
        """
        gap = float(end_c) - self.end_c
        if abs(gap) < 1e-9:
            return self
        lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
        durations, rates = self.durations_min.copy(), self.rates_c_per_min.copy()
        ramps = np.flatnonzero(np.abs(rates) > 1e-12)
        k = int(ramps[-1]) if ramps.size else -1
        rate = float(rates[k] + gap / durations[k]) if k >= 0 else math.inf
        if lo - 1e-9 <= rate <= hi + 1e-9:
            rates[k] = rate
        else:
            fastest = hi if gap > 0 else -lo
            if fastest <= 0:
                return self
            extra = float(max(1, math.ceil(abs(gap) / fastest - 1e-9)))
            if self.total_min + extra > limits.duration_max_min + 1e-9:
                return self
            durations = np.append(durations, extra)
            rates = np.append(rates, gap / extra)
        return Programme(durations, rates, self.start_c, self.meta).merged(rate_tol_c_per_min=1e-9)

    # -- step table --------------------------------------------------------------------
    def to_frame(self) -> pd.DataFrame:
        """Step table as a DataFrame (one row per segment)."""
        tk = self.boundary_temps_c
        d = self.durations_min
        # whole minutes first: 59.7 min is 01:00, not 00:60 (the minutes were rounded
        # after the hours were taken)
        whole = [int(math.floor(float(m) + 0.5)) for m in d]
        hhmm = [f"{m // 60:02d}:{m % 60:02d}" for m in whole]
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

    def to_csv(self, path: Path | str, inputs: Iterable[Path | str] = ()) -> Path:
        """Write the step table atomically: the metadata lines (if ``meta``), then the table.

        Temperatures and times to 0.001, rates to 1e-6. The metadata records the schedsyn
        version that wrote it. ``inputs`` are paths that must not be overwritten.
        """
        from .io import write_atomic

        frame = self.to_frame()
        frame["start_min"] = frame["start_min"].round(3)
        frame["duration_min"] = frame["duration_min"].round(3)
        frame["tk_start_c"] = frame["tk_start_c"].round(3)
        frame["tk_end_c"] = frame["tk_end_c"].round(3)
        frame["rate_c_per_min"] = frame["rate_c_per_min"].round(6)
        header = ""
        if self.meta is not None:
            meta = dataclasses.replace(self.meta, schedsyn_version=_version())
            header = "".join(line + "\n" for line in meta.to_lines())

        def write(p: Path) -> None:
            with open(p, "w", encoding="utf-8", newline="") as fh:
                fh.write(header)
                frame.to_csv(fh, index=False, lineterminator="\n")

        return write_atomic(path, write, inputs)

    def with_meta(self, meta: StepTableMeta | None) -> Programme:
        """The same programme with other metadata."""
        return dataclasses.replace(self, meta=meta)

    def with_end_soak(self, soak_min: float, limits: Limits | None = None) -> Programme:
        """Append a hold at the end temperature for ``soak_min`` (rounded up to whole min).

        Re-validated against ``limits.duration_max_min``: a soak that does not fit raises
        :class:`~schedsyn.errors.ParameterError` saying by how much. A final hold step is
        lengthened rather than followed by a second one. The metadata (if any) records the
        included soak as ``end_soak_included_min``.
        """
        from .params import real_number

        limits = Limits() if limits is None else limits
        soak = real_number("soak_min", soak_min)
        if soak < 0:
            raise ParameterError(f"the end soak must be >= 0 min, got {soak:g} min")
        soak = float(math.ceil(soak - 1e-9))
        if soak == 0:
            return self
        total = self.total_min + soak
        if total > limits.duration_max_min + 1e-9:
            raise ParameterError(
                f"the end soak of {soak:g} min does not fit: the programme lasts "
                f"{self.total_min:g} min, {total:g} min with the soak, over the limit of "
                f"{limits.duration_max_min:g} min by {total - limits.duration_max_min:g} min; "
                "raise the duration limit (--duration-max-min) or hold the chamber at "
                "the end temperature outside the programme"
            )
        meta = self.meta
        if meta is not None:
            meta = dataclasses.replace(
                meta, end_soak_included_min=(meta.end_soak_included_min or 0.0) + soak
            )
        return Programme(
            np.append(self.durations_min, soak),
            np.append(self.rates_c_per_min, 0.0),
            self.start_c,
            meta,
        ).merged()


def programme_from_frame(
    frame: pd.DataFrame,
    limits: Limits | None = None,
    source: str = "step table",
    *,
    meta: StepTableMeta | None = None,
) -> Programme:
    """Validate a step table and build its :class:`Programme`.

    The chamber path is taken from what an operator types (``tk_start_c``, ``tk_end_c``,
    ``duration_min``); ``rate_c_per_min`` must agree with it. Every problem names the row
    (1-based step) and what to change. ``meta`` is attached to the programme as is.
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
            v = frame[c].iloc[r]
            shown = "an empty cell or NaN" if pd.isna(v) else repr(str(v).strip())
            raise StepTableError(f"{source}: row {r + 1}, column {c}: {shown} is not a number")
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
                f"{where}: the programme starts at {tk0[0]:g} °C, not at the required "
                f"{limits.start_c:g} °C"
            )
        if r > 0 and abs(tk0[r] - tk1[r - 1]) > TEMP_TOL_C:
            raise StepTableError(
                f"{where}: tk_start_c {tk0[r]:g} °C does not continue the previous step's "
                f"tk_end_c {tk1[r - 1]:g} °C (the chamber programme must be continuous)"
            )
        if abs(tk0[r] + rate[r] * dur[r] - tk1[r]) > 2 * TEMP_TOL_C:
            raise StepTableError(
                f"{where}: rate_c_per_min {rate[r]:g} over {dur[r]:g} min goes from "
                f"{tk0[r]:g} to {tk0[r] + rate[r] * dur[r]:.2f} °C, not to tk_end_c "
                f"{tk1[r]:g}; fix the rate or the end temperature"
            )
    # the chamber path as typed: continuous through the typed end temperatures
    temps = np.concatenate(([tk0[0]], tk1))
    rates = np.diff(temps) / dur
    lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
    for r in range(n):
        if not lo - RATE_TOL_C_PER_MIN <= rates[r] <= hi + RATE_TOL_C_PER_MIN:
            raise StepTableError(
                f"{source}: step {r + 1}: rate {rates[r]:.4f} °C/min is outside the chamber "
                f"limits {lo:g} .. {hi:g} °C/min; lengthen the step or lower its change"
            )
    for r in range(n + 1):
        if not limits.chamber_min_c - TEMP_TOL_C <= temps[r] <= limits.chamber_max_c + TEMP_TOL_C:
            raise StepTableError(
                f"{source}: step {max(r, 1)}: chamber temperature {temps[r]:g} °C is outside "
                f"the chamber limits {limits.chamber_min_c:g} .. {limits.chamber_max_c:g} °C"
            )
    _check_operator_columns(frame, dur, rates, source)
    total = float(dur.sum())
    if total > limits.duration_max_min + 1e-6:
        raise StepTableError(
            f"{source}: the programme lasts {total:g} min, more than the limit "
            f"{limits.duration_max_min:g} min; shorten it or raise duration_max_min"
        )
    return Programme(dur, rates, float(temps[0]), meta)


_HHMM = re.compile(r"^\s*(\d+):(\d{1,2})(?::(\d{1,2}))?\s*$")


def _check_operator_columns(
    frame: pd.DataFrame, dur: np.ndarray, rates: np.ndarray, source: str
) -> None:
    """The operator aids, where present, must say what the numbers say: ``duration_hhmm``
    is ``duration_min`` to the whole minute and a ``HOLD`` row does not change the
    temperature. An operator types from them, schedsyn reads the numbers: a table edited
    in one place only would run another programme than the one checked."""
    if "duration_hhmm" in frame.columns:
        for r, v in enumerate(frame["duration_hhmm"]):
            if v is None or (isinstance(v, float) and math.isnan(v)) or not str(v).strip():
                continue
            m = _HHMM.match(str(v))
            # minutes up to 60: tables written before 0df4213 showed 59.7 min as 00:60
            if m is None or int(m.group(2)) > 60 or int(m.group(3) or 0) > 59:
                raise StepTableError(
                    f"{source}: step {r + 1}: duration_hhmm {v!r} is not h:mm; fix it or "
                    "delete the column (schedsyn reads duration_min)"
                )
            shown = 60 * int(m.group(1)) + int(m.group(2)) + int(m.group(3) or 0) / 60.0
            if abs(shown - dur[r]) > 0.5 + 1e-6:
                raise StepTableError(
                    f"{source}: step {r + 1}: duration_hhmm {str(v).strip()} is {shown:g} min "
                    f"but duration_min is {dur[r]:g}; make them agree (an operator types "
                    "h:mm, schedsyn reads duration_min)"
                )
    if "segment_type" in frame.columns:
        for r, v in enumerate(frame["segment_type"]):
            if str(v).strip().upper() == "HOLD" and abs(rates[r]) > RATE_TOL_C_PER_MIN:
                raise StepTableError(
                    f"{source}: step {r + 1}: segment_type HOLD but the temperature changes "
                    f"at {rates[r]:g} °C/min; make them agree (RAMP, or equal tk_start_c "
                    "and tk_end_c)"
                )


def read_steps(path: Path | str, limits: Limits | None = None) -> Programme:
    """Read and validate a step-table CSV (see :func:`programme_from_frame`).

    Leading ``# key: value`` lines are the table's metadata (:class:`StepTableMeta`,
    available as ``programme.meta``; None when the table has none). Comma-separated
    tables with decimal points and semicolon- or tab-separated ones with decimal commas
    are recognised. Without ``limits`` the table is validated against the limits its
    metadata records, else against the default :class:`Limits`.
    """
    path = Path(path)
    if not path.is_file():
        raise StepTableError(f"step table {path} does not exist or is not a file")
    meta, body, dialect = _split_table(path)
    if limits is None and meta is not None:
        limits = meta.limits()
    try:
        frame = pd.read_csv(
            io.StringIO(body),
            sep=dialect.separator,
            decimal=dialect.decimal,
            skipinitialspace=True,
        )
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise StepTableError(
            f"{path}: not a readable CSV step table ({first}; read as {dialect.describe()})"
        ) from None
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in STEP_COLUMNS if c not in frame.columns]
    if missing:
        header = body.splitlines()[0] if body.strip() else ""
        raise StepTableError(
            f"{path}: missing column(s) {', '.join(missing)}; a step table needs "
            f"{', '.join(STEP_COLUMNS)} (the file was read as {dialect.describe()}, its "
            f"header is {header[:120]!r})"
        )
    return programme_from_frame(frame, limits, source=str(path), meta=meta)


def read_step_meta(path: Path | str) -> StepTableMeta | None:
    """Only the metadata of a step table (None when it has none); the table is not read."""
    path = Path(path)
    if not path.is_file():
        raise StepTableError(f"step table {path} does not exist or is not a file")
    return _split_table(path)[0]


def _read_text(path: Path) -> str:
    raw = path.read_bytes()
    for encoding in ("utf-8-sig", "cp1252"):  # cp1252: an older spreadsheet's export
        try:
            text = raw.decode(encoding)
        except UnicodeDecodeError:
            continue
        if "\x00" not in text:
            return text
    raise StepTableError(
        f"{path}: not a readable CSV step table (not UTF-8 text); save it as CSV (UTF-8)"
    )


def _split_table(path: Path):
    """``(meta or None, table text, dialect)``: leading comment lines are the metadata."""
    text = _read_text(path)
    lines = text.splitlines(keepends=True)
    k = 0
    while k < len(lines) and (not lines[k].strip() or _clean_comment(lines[k]).startswith("#")):
        k += 1
    comments = [ln for ln in lines[:k] if ln.strip()]
    body = "".join(lines[k:])
    dialect = detect_csv_dialect(body[:16384])
    if SEP_HINT.match(body.split("\n", 1)[0]):  # "sep=;": a hint, not the header
        body = body.split("\n", 1)[1] if "\n" in body else ""
    meta = StepTableMeta.from_lines(comments, str(path)) if comments else None
    if meta is not None and meta == StepTableMeta(extra=meta.extra) and not meta.extra:
        meta = None  # free comments only
    return meta, body, dialect
