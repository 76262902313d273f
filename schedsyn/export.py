"""Controller programmes: a step table in the shape a chamber controller takes.

A planned step table (:class:`~schedsyn.programme.Programme`) becomes a programme for a
particular controller in four stages, each checked:

1. **Quantise** to the controller's resolution (:func:`quantise`): boundary times on its
   time grid (1 min for ESPEC P-300 / SCP-220, 1 s for Watlow F4T and Binder MB),
   rounded cumulatively so that no boundary moves by more than half a grid step;
   boundary temperatures to 0.1 degC, moved by 0.1 degC steps back inside the chamber's
   rate and temperature limits where rounding would push them out; steps longer than the
   controller's longest step split.
2. **Split and chain** (:func:`split_parts`) when the programme has more steps than one
   controller programme holds: balanced parts, linked the way the controller allows
   (P-300: end mode RUN to the next programme; F4T and Binder: no link in their open
   libraries, so each part ends holding its last setpoint and the operator starts the
   next one; see :mod:`schedsyn.controllers`).
3. **Encode** in the controller's own structure (:mod:`schedsyn.controllers`), then
   **decode the encoded text again** with a strict reader that checks the controller's
   limits (steps per programme, programmes available, time and temperature resolution,
   the chain).
4. **Re-simulate** what was read back (:func:`schedsyn.simulate.simulate`) and score it
   with :func:`schedsyn.coverage.coverage_report`: the coverage of the exported programme,
   reported next to the coverage of the source table (:class:`ControllerExport`).

Nothing here prints or writes; :func:`write_export` writes atomically.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .coverage import CoverageReport, coverage_report
from .errors import ParameterError, StepTableError
from .grid import BinGrid
from .params import Limits, ThermalParams
from .programme import Programme
from .simulate import simulate

#: Exporters, in the order ``--help`` lists them.
CONTROLLER_KEYS = ("espec-p300", "espec-scp220", "watlow-f4t", "binder-mb", "csv")


@dataclass(frozen=True, slots=True)
class ControllerSpec:
    """What one controller can hold, and where that fact comes from.

    Attributes
    ----------
    key : str
        Exporter name (``--controller``).
    title : str
        Human name of the controller.
    time_step_s : int
        Duration resolution, s (60 for h:mm controllers, 1 for h:mm:ss).
    temp_step_c : float
        Setpoint resolution, degC.
    max_steps : int or None
        Steps (or segments) one programme holds, including the ``reserved_steps``;
        ``None`` for no limit.
    reserved_steps : int
        Steps each programme needs besides the chamber path (an end step, a start step,
        a terminating segment).
    programmes : int or None
        Programmes the controller stores (``None``: no limit).
    first_number : int
        Lowest programme number.
    max_step_min : float or None
        Longest single step, min (``None``: no limit).
    end_modes : tuple of str
        End modes accepted for the last programme (first entry is the default).
    file_suffix : str
        Suffix of the export file (``.json`` or ``.csv``).
    source : str
        Where these figures come from (file and function of the open library).
    end_segment_s : int
        Seconds each programme runs after its chamber path at its last setpoint (Binder:
        the 1-s final segment ``binder.py`` appends). Where they would take the run past
        ``duration_max_min``, the export takes them out of the last step (if the rate
        limits allow; else it reports the overrun).
    first_path_step : int
        The controller's number of a programme's first chamber-path step (F4T: 2, after
        the ``instant`` start step): the step numbers the operator sees on the controller.
    """

    key: str
    title: str
    time_step_s: int
    temp_step_c: float
    max_steps: int | None
    reserved_steps: int
    programmes: int | None
    first_number: int
    max_step_min: float | None
    end_modes: tuple[str, ...]
    file_suffix: str
    source: str
    end_segment_s: int = 0
    first_path_step: int = 1

    @property
    def time_step_min(self) -> float:
        return self.time_step_s / 60.0


@dataclass(frozen=True, slots=True)
class ExportSettings:
    """How to export: the controller and the choices its programmes leave open.

    Parameters
    ----------
    controller : str
        One of :data:`CONTROLLER_KEYS`.
    first_programme : int
        Number of the first programme written (the next parts take the following
        numbers). Default 1.
    max_steps : int, optional
        Steps one programme holds, overriding the controller's figure (e.g. from your
        controller's manual); includes the steps the exporter reserves.
    programmes : int, optional
        Programmes the controller stores, overriding the controller's figure.
    end_mode : str, optional
        End mode of the last programme (P-300: ``STANDBY``, ``OFF`` or ``CONSTANT``;
        F4T: ``hold``, ``user`` or ``off``). Default: the controller's first mode.
    name : str
        Programme name written into the controller (ASCII letters, digits, ``-``, ``_``;
        shortened to what the controller holds).
    """

    controller: str = "csv"
    first_programme: int = 1
    max_steps: int | None = None
    programmes: int | None = None
    end_mode: str | None = None
    name: str = "schedsyn"

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLER_KEYS:
            raise ParameterError(
                f"controller {self.controller!r} is not known; choose one of "
                f"{', '.join(CONTROLLER_KEYS)}"
            )
        for key in ("first_programme", "max_steps", "programmes"):
            v = getattr(self, key)
            if v is None and key != "first_programme":
                continue
            whole = not isinstance(v, bool) and isinstance(v, int | np.integer)
            # a programme number's least is the controller's (below): say that one
            if not whole or (v < 0 and key != "first_programme"):
                raise ParameterError(f"{key} must be a whole number >= 0, got {v!r}")
        spec = controller_spec(self.controller)
        if self.first_programme < spec.first_number:
            raise ParameterError(
                f"first_programme must be >= {spec.first_number} for {spec.title}, "
                f"got {self.first_programme}"
            )
        if self.max_steps is not None and self.max_steps < spec.reserved_steps + 1:
            raise ParameterError(
                f"max_steps must be >= {spec.reserved_steps + 1} for {spec.title} "
                f"({spec.reserved_steps} step(s) per programme are reserved), "
                f"got {self.max_steps}"
            )
        if spec.max_steps is None and self.max_steps is not None:
            raise ParameterError(
                f"max_steps does not apply to the {spec.title}: it has no step limit"
            )
        if self.programmes is not None and self.programmes < 1:
            raise ParameterError(f"programmes must be >= 1, got {self.programmes}")
        if self.end_mode is not None and self.end_mode not in spec.end_modes:
            raise ParameterError(
                f"end_mode {self.end_mode!r} is not one of {spec.title}'s end modes "
                f"{', '.join(spec.end_modes) or '(none)'}"
            )
        if not isinstance(self.name, str) or not re.fullmatch(r"[A-Za-z0-9_\-]{1,64}", self.name):
            raise ParameterError(
                f"name must be 1-64 ASCII letters, digits, '-' or '_', got {self.name!r}"
            )

    @property
    def spec(self) -> ControllerSpec:
        """The controller's figures with this export's overrides applied."""
        base = controller_spec(self.controller)
        changes: dict[str, Any] = {}
        if self.max_steps is not None:
            changes["max_steps"] = int(self.max_steps)
        if self.programmes is not None:
            changes["programmes"] = int(self.programmes)
        if not changes:
            return base
        import dataclasses

        return dataclasses.replace(base, **changes)

    @property
    def effective_end_mode(self) -> str:
        spec = controller_spec(self.controller)
        if self.end_mode is not None:
            return self.end_mode
        return spec.end_modes[0] if spec.end_modes else ""


def controller_spec(key: str) -> ControllerSpec:
    """The :class:`ControllerSpec` of exporter ``key`` (see :data:`CONTROLLER_KEYS`)."""
    from .controllers import SPECS

    try:
        return SPECS[key]
    except KeyError:
        raise ParameterError(
            f"controller {key!r} is not known; choose one of {', '.join(CONTROLLER_KEYS)}"
        ) from None


# ---------------------------------------------------------------------------------------
# step tables with metadata
# ---------------------------------------------------------------------------------------
_META_LINE = re.compile(r"^#\s*([A-Za-z_][A-Za-z0-9_]*)\s*:\s*(.*?)\s*$")


@dataclass(frozen=True, slots=True)
class StepTable:
    """A step table read from a file: its programme, its ``# key: value`` metadata lines
    (empty when the file has none) and the SHA-256 of the file's bytes."""

    path: Path
    programme: Programme
    meta: Mapping[str, str]
    sha256: str
    limits: Limits


def split_metadata(text: str) -> tuple[dict[str, str], str]:
    """Leading ``# key: value`` comment lines of a CSV text, and the rest of the text.

    Comment lines that are not ``key: value`` pairs are skipped; the first line that does
    not start with ``#`` ends the header.
    """
    meta: dict[str, str] = {}
    lines = text.splitlines(keepends=True)
    i = 0
    while i < len(lines) and lines[i].lstrip().startswith("#"):
        m = _META_LINE.match(lines[i].strip())
        if m:
            meta[m.group(1)] = m.group(2)
        i += 1
    return meta, "".join(lines[i:])


def _meta_float(meta: Mapping[str, str], key: str, source: str) -> float | None:
    if key not in meta:
        return None
    try:
        v = float(meta[key])
    except ValueError:
        raise StepTableError(
            f"{source}: metadata line '# {key}: {meta[key]}' is not a number"
        ) from None
    if not math.isfinite(v):
        raise StepTableError(f"{source}: metadata {key} must be finite, got {meta[key]!r}")
    return v


def limits_from_meta(
    meta: Mapping[str, str], base: Limits | None = None, source: str = ""
) -> Limits:
    """``Limits`` with every field the metadata names (e.g. ``# chamber_min_c: -60``)."""
    base = Limits() if base is None else base
    changes = {}
    for f in fields(Limits):
        v = _meta_float(meta, f.name, source)
        if v is not None:
            changes[f.name] = v
    if not changes:
        return base
    import dataclasses

    try:
        return dataclasses.replace(base, **changes)
    except ParameterError as exc:
        raise StepTableError(f"{source}: metadata limits: {exc}") from None


def read_step_table(path: Path | str, limits: Limits | None = None) -> StepTable:
    """Read a step-table CSV that may start with ``# key: value`` metadata lines.

    The limits used to validate it are ``limits`` (default :class:`Limits`) updated with
    any limit the metadata names. Errors name the file, the row and what to change
    (see :func:`schedsyn.programme.programme_from_frame`).
    """
    from .programme import _read_text, read_steps

    path = Path(path)
    if not path.is_file():
        raise StepTableError(f"step table {path} does not exist or is not a file")
    raw = path.read_bytes()
    meta, _ = split_metadata(_read_text(path))
    lim = limits_from_meta(meta, limits, str(path))
    # the table itself as every other command reads it: comma or semicolon/tab separated,
    # decimal point or comma, UTF-8 or an older spreadsheet's cp1252 (export read only
    # comma-separated UTF-8 and called a European spreadsheet's table "missing columns")
    prog = read_steps(path, lim)
    prog = Programme(prog.durations_min, prog.rates_c_per_min, prog.start_c)
    return StepTable(path, prog, meta, hashlib.sha256(raw).hexdigest(), lim)


def planned_for_notes(
    meta: Mapping[str, str], programme: Programme, source: str = "step table"
) -> list[str]:
    """What the table's metadata says it was planned for and it is not: a planner status
    other than ``complete`` (``schedsyn plan`` writes an incomplete or limit-breaking
    table too, marked NOT COMPLETE), more steps than its ``max_steps``, a step shorter
    than its ``min_step_min``. Empty for a table without those lines (older or hand-made
    tables). Red team: a table over its step limit exported without a word."""
    out = []
    status = meta.get("status")
    if status is not None and status != "complete":
        out.append(
            f"{source} was planned NOT COMPLETE (status {status}): it does not give every "
            "bin its levels, or breaks a limit; its plan's report says which"
        )
    max_steps = _meta_float(meta, "max_steps", source)
    if max_steps is not None and programme.n_segments > max_steps:
        out.append(
            f"{source} has {programme.n_segments} steps, more than the max_steps = "
            f"{max_steps:g} it was planned for"
        )
    min_step = _meta_float(meta, "min_step_min", source)
    shortest = float(np.min(programme.durations_min))
    if min_step is not None and shortest < min_step - 1e-9:
        out.append(
            f"{source}'s shortest step lasts {shortest:g} min, shorter than the min_step_min "
            f"= {min_step:g} min it was planned for"
        )
    return out


# ---------------------------------------------------------------------------------------
# the coverage check
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class CoverageCheck:
    """Region, model and requirement with which an export is re-simulated and scored.

    Parameters
    ----------
    grid : BinGrid
        Working region and its 1 degC bins.
    params : ThermalParams
        Device model (tau, dT0).
    levels_required : int
        Distinct gradient levels a bin needs (default 6).
    delta_c_per_min : float
        Minimum gradient difference between levels, degC/min (default 0.05).
    t0_c : float
        Device temperature at t = 0, degC (default 20).
    dt_min : float
        Simulation step, min (default 0.1: the coverage metric's grid).
    """

    grid: BinGrid
    params: ThermalParams = field(default_factory=ThermalParams)
    levels_required: int = 6
    delta_c_per_min: float = 0.05
    t0_c: float = 20.0
    dt_min: float = 0.1

    def report(self, programme: Programme) -> CoverageReport:
        """Coverage of the working region by ``programme``, simulated densely."""
        traj = simulate(programme, self.params, dt_min=self.dt_min, t0_c=self.t0_c)
        return coverage_report(
            traj.t_c, traj.g_c_per_min, self.grid, self.levels_required, self.delta_c_per_min
        )


def _pair(text: str, key: str, source: str) -> tuple[float, float]:
    parts = [p for p in re.split(r"\s*(?:,|:|\.\.|\s)\s*", text.strip("[]() ")) if p]
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise StepTableError(
            f"{source}: metadata {key} {text!r} is not two numbers LO, HI"
        ) from None
    return lo, hi


def check_from_meta(
    meta: Mapping[str, str],
    *,
    region: tuple[float, float] | None = None,
    tau_s: float | None = None,
    dt0_c: float | None = None,
    levels_required: int | None = None,
    delta_c_per_min: float | None = None,
    limits: Limits | None = None,
    source: str = "step table",
) -> CoverageCheck:
    """The coverage check of a step table: explicit arguments first, then its metadata.

    The working region comes from ``region`` or the metadata ``working_lo_c`` and
    ``working_hi_c``; with neither, a :class:`ParameterError` asks for ``--region``
    (a region is never guessed). tau and dT0 fall back to :class:`ThermalParams`.
    """
    if region is None:
        lo = _meta_float(meta, "working_lo_c", source)
        hi = _meta_float(meta, "working_hi_c", source)
        if lo is None or hi is None:
            raise ParameterError(
                f"{source} carries no working region (no '# working_lo_c' / "
                "'# working_hi_c' lines); give --region LO HI"
            )
        region = (lo, hi)
    base = ThermalParams()
    tau = tau_s if tau_s is not None else _meta_float(meta, "tau_s", source)
    dt0 = dt0_c if dt0_c is not None else _meta_float(meta, "dt0_c", source)
    params = ThermalParams(base.tau_s if tau is None else tau, base.dt0_c if dt0 is None else dt0)
    levels = levels_required
    if levels is None:
        v = _meta_float(meta, "levels_required", source)
        levels = 6 if v is None else int(v)
    delta = delta_c_per_min
    if delta is None:
        v = _meta_float(meta, "delta_c_per_min", source)
        delta = 0.05 if v is None else v
    lim = limits if limits is not None else limits_from_meta(meta, source=source)
    if int(levels) != levels or levels < 1:
        raise ParameterError(f"levels_required must be a whole number >= 1, got {levels}")
    if not (math.isfinite(delta) and delta > 0):
        raise ParameterError(f"delta_c_per_min must be > 0 °C/min, got {delta}")
    return CoverageCheck(
        BinGrid(float(region[0]), float(region[1])),
        params,
        int(levels),
        float(delta),
        t0_c=lim.t_init_c,
    )


def robust_box_from_meta(
    meta: Mapping[str, str], source: str = "step table"
) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The robust box ``((tau_lo_s, tau_hi_s), (dt0_lo_c, dt0_hi_c))`` a table was planned
    for, from ``# robust_tau_s: LO:HI`` / ``# robust_dt0_c: LO:HI`` (or the ``_lo_``/``_hi_``
    spelling), else ``None``."""
    out: list[tuple[float, float] | None] = []
    for key, lo_key, hi_key in (
        ("robust_tau_s", "robust_tau_lo_s", "robust_tau_hi_s"),
        ("robust_dt0_c", "robust_dt0_lo_c", "robust_dt0_hi_c"),
    ):
        if key in meta and meta[key].strip().lower() not in ("", "none", "null"):
            out.append(_pair(meta[key], key, source))
        elif lo_key in meta and hi_key in meta:
            lo = _meta_float(meta, lo_key, source)
            hi = _meta_float(meta, hi_key, source)
            out.append((float("nan") if lo is None else lo, float("nan") if hi is None else hi))
        else:
            out.append(None)
    if out[0] is None and out[1] is None:
        return None
    nominal = ThermalParams()
    tau = _meta_float(meta, "tau_s", source)
    dt0 = _meta_float(meta, "dt0_c", source)
    tau = nominal.tau_s if tau is None else tau
    dt0 = nominal.dt0_c if dt0 is None else dt0
    return (
        out[0] if out[0] is not None else (tau, tau),
        out[1] if out[1] is not None else (dt0, dt0),
    )


# ---------------------------------------------------------------------------------------
# quantisation and splitting
# ---------------------------------------------------------------------------------------
def _grid_round(x: float, step: float) -> float:
    """Round ``x`` to the nearest multiple of ``step`` (halves away from zero)."""
    q = x / step
    return math.copysign(math.floor(abs(q) + 0.5 + 1e-9), q) * step


def quantise(
    programme: Programme,
    time_step_min: float,
    limits: Limits,
    temp_step_c: float = 0.1,
    max_step_min: float | None = None,
) -> Programme:
    """The programme on a controller's grid.

    * Boundary times ``t_k`` are rounded to multiples of ``time_step_min`` cumulatively,
      ``t_k' = round(t_k / q) q``, so no boundary moves by more than ``q / 2`` and the
      total keeps its rounded length; a segment that rounds to zero length disappears
      (its neighbours join; the last boundary keeps the end temperature).
    * Boundary temperatures are rounded to ``temp_step_c`` and, where the rounded value
      would need a rate outside ``limits`` (``rate_min .. rate_max`` degC/min) or a
      temperature outside ``chamber_min .. chamber_max``, moved by grid steps to the
      nearest feasible value: ``Tk'_{k+1}`` in ``[Tk'_k + rate_min d_k, Tk'_k + rate_max d_k]``
      (on the grid). Rates are recomputed from the rounded temperatures.
    * Where that leaves the last boundary off the source's end temperature (times rounded
      shorter than the rate limits allow), the last step is lengthened by whole grid
      steps, by at most :func:`end_extension_max_min` and within ``duration_max_min``,
      so that it ends exactly there: the end temperature is the operator's end
      condition. Where that is not possible the path keeps its rounded length.
    * Equal-rate neighbours are merged (one controller step), then any step longer than
      ``max_step_min`` is cut into equal whole-grid pieces (their inner temperatures
      rounded the same way).
    """
    q = float(time_step_min)
    if not (math.isfinite(q) and q > 0):
        raise ParameterError(f"time_step_min must be > 0 min, got {time_step_min!r}")
    edges = np.concatenate(([0.0], np.cumsum(programme.durations_min)))
    ticks = np.array([int(math.floor(e / q + 0.5 + 1e-9)) for e in edges], dtype=np.int64)
    temps = programme.boundary_temps_c
    # keep the first boundary and, of several that round to the same tick, the last one
    keep = np.ones(ticks.size, dtype=bool)
    keep[1:-1] = ticks[1:-1] != ticks[2:]
    keep[0] = True
    ticks, temps = ticks[keep], temps[keep]
    if ticks.size >= 2 and ticks[1] == ticks[0]:
        ticks = np.delete(ticks, 1)
        temps = np.delete(temps, 1)
    if ticks.size < 2 or ticks[-1] == ticks[0]:
        raise StepTableError(
            f"the programme lasts {programme.total_min:g} min: shorter than one "
            f"{q * 60:g}-s step of the controller"
        )
    dur = np.diff(ticks) * q
    tk = _round_path(temps, dur, limits, temp_step_c)
    end_want = _grid_round(float(temps[-1]), temp_step_c)
    if abs(tk[-1] - end_want) > 1e-9:
        dur, tk = _extend_to_end(temps, dur, tk, end_want, q, limits, temp_step_c)
    out = Programme(dur, np.diff(tk) / dur, float(tk[0])).merged(rate_tol_c_per_min=1e-9)
    if max_step_min is not None:
        out = _cut_long_steps(out, max_step_min, q, limits, temp_step_c)
    return out


#: Bins that lost levels named in an export's summary (the rest are counted).
LOST_BINS_SHOWN = 8
#: Controller time steps the last step may be lengthened by so that the exported
#: programme ends at the source's end temperature (:func:`quantise`) ...
END_EXTEND_MAX_STEPS = 5
#: ... or minutes, whichever is longer: on a 1-s controller five steps are 5 s, while
#: a boundary held 0.1 degC short by the rate limit needs 6 s at -1 degC/min.
END_EXTEND_MAX_MIN = 5.0


def end_extension_max_min(time_step_min: float) -> float:
    """The longest the last step may be lengthened by (min) on a ``time_step_min`` grid."""
    return max(END_EXTEND_MAX_STEPS * time_step_min, END_EXTEND_MAX_MIN)


def _extend_to_end(
    temps: np.ndarray,
    dur: np.ndarray,
    tk: np.ndarray,
    end_want: float,
    q: float,
    limits: Limits,
    step: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Lengthen the last step by whole ``q`` steps until the rounded path ends at
    ``end_want``; the input unchanged where that takes more than
    :func:`end_extension_max_min` or ``limits.duration_max_min``."""
    cap_steps = int(math.floor(end_extension_max_min(q) / q + 1e-9))
    longer, path, extra = dur.copy(), tk, 0
    while abs(path[-1] - end_want) > 1e-9:
        # the last step runs at its rate limit: the time the missing degrees take there
        # (at least one step; rounding to the temperature grid may ask for one more)
        up = end_want > path[-1]
        rate = limits.rate_max_c_per_min if up else -limits.rate_min_c_per_min
        steps = max(1, math.ceil(abs(end_want - path[-1]) / max(rate, 1e-9) / q - 1e-9))
        extra += steps
        longer = longer.copy()
        longer[-1] += steps * q
        if extra > cap_steps or float(longer.sum()) > limits.duration_max_min + 1e-9:
            return dur, tk
        path = _round_path(temps, longer, limits, step)
    return longer, path


def _round_path(temps: np.ndarray, dur: np.ndarray, limits: Limits, step: float) -> np.ndarray:
    lo, hi = limits.rate_min_c_per_min, limits.rate_max_c_per_min
    t_lo = math.ceil(round(limits.chamber_min_c / step, 6)) * step
    t_hi = math.floor(round(limits.chamber_max_c / step, 6)) * step
    tk = np.empty(temps.size)
    tk[0] = _grid_round(float(temps[0]), step)
    for i in range(dur.size):
        want = _grid_round(float(temps[i + 1]), step)
        # the grid values reachable from tk[i] within the rate limits
        top = math.floor(round((tk[i] + hi * dur[i]) / step, 6)) * step
        bot = math.ceil(round((tk[i] + lo * dur[i]) / step, 6)) * step
        a, b = max(bot, t_lo), min(top, t_hi)
        if a > b:  # the temperature limits cannot be met at this rate: keep the rate limit
            a, b = bot, top
        tk[i + 1] = round(min(max(want, a), b), 6)
    return tk


def _cut_long_steps(
    prog: Programme, max_step_min: float, q: float, limits: Limits, step: float
) -> Programme:
    max_ticks = int(math.floor(max_step_min / q + 1e-9))
    if max_ticks < 1:
        raise ParameterError(f"max_step_min {max_step_min} is shorter than the time step {q}")
    ticks: list[int] = [0]
    temps: list[float] = [prog.start_c]
    tk = prog.boundary_temps_c
    for i, d in enumerate(prog.durations_min):
        n_ticks = int(round(d / q))
        pieces = max(1, math.ceil(n_ticks / max_ticks))
        base = ticks[-1]
        for j in range(1, pieces + 1):
            ticks.append(base + (n_ticks * j) // pieces)
            temps.append(float(tk[i] + (tk[i + 1] - tk[i]) * j / pieces))
    tick_arr = np.asarray(ticks, dtype=float)
    dur = np.diff(tick_arr) * q
    path = _round_path(np.asarray(temps), dur, limits, step)
    return Programme(dur, np.diff(path) / dur, float(path[0]))


def split_parts(programme: Programme, capacity: int | None) -> tuple[Programme, ...]:
    """Cut a programme into consecutive parts of at most ``capacity`` steps each.

    The parts are as equal as possible (``ceil(n / capacity)`` parts whose sizes differ by
    at most one); part ``k + 1`` starts at the temperature where part ``k`` ends, so the
    concatenation is the programme itself.
    """
    n = programme.n_segments
    if capacity is None or n <= capacity:
        return (programme,)
    if capacity < 1:
        raise ParameterError(f"a programme must hold at least one step, got {capacity}")
    n_parts = math.ceil(n / capacity)
    sizes = [n // n_parts + (1 if k < n % n_parts else 0) for k in range(n_parts)]
    tk = programme.boundary_temps_c
    out, i = [], 0
    for s in sizes:
        out.append(
            Programme(
                programme.durations_min[i : i + s],
                programme.rates_c_per_min[i : i + s],
                float(tk[i]),
            )
        )
        i += s
    return tuple(out)


def join_parts(
    parts: Sequence[Programme], source: str = "export", holds_min: Sequence[float] = ()
) -> Programme:
    """The parts of a chained programme as one programme (each must start where the
    previous ended, within 1e-6 degC). ``holds_min``: per part, how long the chamber holds
    its last value after its path before the next part starts (Binder: the 1-s end
    segment); the holds between parts are in the result, the last part's is not."""
    if not parts:
        raise StepTableError(f"{source}: no programme in the file")
    for k in range(1, len(parts)):
        if abs(parts[k].start_c - parts[k - 1].end_c) > 1e-6:
            raise StepTableError(
                f"{source}: part {k + 1} starts at {parts[k].start_c:g} °C but part {k} "
                f"ends at {parts[k - 1].end_c:g} °C; the chained programmes must be continuous"
            )
    durations, rates = [], []
    for k, p in enumerate(parts):
        durations.append(p.durations_min)
        rates.append(p.rates_c_per_min)
        if k < len(parts) - 1 and k < len(holds_min) and holds_min[k] > 0:
            durations.append(np.array([float(holds_min[k])]))
            rates.append(np.zeros(1))
    return Programme(np.concatenate(durations), np.concatenate(rates), parts[0].start_c)


# ---------------------------------------------------------------------------------------
# export
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Decoded:
    """A controller file read back: programme numbers, the chamber path of each
    programme, and its header (what schedsyn wrote about it)."""

    controller: str
    numbers: tuple[int, ...]
    parts: tuple[Programme, ...]
    header: Mapping[str, Any]
    #: per programme, how long it holds its last value after its path, min (Binder: its
    #: 1-s end segment); the next programme starts after it
    holds_min: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if len(self.numbers) != len(self.parts):
            raise StepTableError(
                f"{self.controller} export: {len(self.numbers)} programme numbers for "
                f"{len(self.parts)} programmes"
            )
        join_parts(self.parts, f"{self.controller} export")  # the chain is continuous

    @property
    def programme(self) -> Programme:
        """The chamber's path through every programme, with the holds between them."""
        return join_parts(self.parts, f"{self.controller} export", self.holds_min)


@dataclass(frozen=True, slots=True)
class ControllerExport:
    """A programme exported for one controller, read back and re-checked.

    Attributes
    ----------
    spec : ControllerSpec
        The controller's figures (with the settings' overrides).
    settings : ExportSettings
    source : Programme
        The step table that was exported.
    decoded : Decoded
        The export file's text read back by the strict reader.
    text : str
        The export file's content.
    source_coverage, export_coverage : CoverageReport or None
        Coverage of the source table and of the exported (read-back) programme, both
        re-simulated with the same model and region (``None`` without a check).
    check : CoverageCheck or None
    max_boundary_shift_s : float
        Largest move of a step boundary in time, s.
    max_chamber_deviation_c : float
        Largest difference between the exported and the source chamber path, degC
        (sampled every 0.1 min).
    notes : tuple of str
        What the operator must know (chaining, parts, end mode).
    limit_breaks : tuple of str
        Limits the exported programme breaks although its step table meets them (the end
        temperature when the rounded last step cannot reach it within the time limit; the
        device range, re-simulated, when the rounding takes it past a device limit or
        further past it than the table does). Reported like lost coverage.
    """

    spec: ControllerSpec
    settings: ExportSettings
    source: Programme
    decoded: Decoded
    text: str
    source_coverage: CoverageReport | None
    export_coverage: CoverageReport | None
    check: CoverageCheck | None
    max_boundary_shift_s: float
    max_chamber_deviation_c: float
    notes: tuple[str, ...]
    limit_breaks: tuple[str, ...] = ()

    @property
    def exported(self) -> Programme:
        """The exported programme as the controller will run it (read back)."""
        return self.decoded.programme

    @property
    def numbers(self) -> tuple[int, ...]:
        return self.decoded.numbers

    @property
    def coverage_lost(self) -> bool:
        """The exported programme covers less than the source table (or has fewer
        distinct levels in some bin)."""
        s, e = self.source_coverage, self.export_coverage
        if s is None or e is None:
            return False
        return bool(e.coverage < s.coverage - 1e-12 or np.any(e.levels < s.levels))

    @property
    def faithful(self) -> bool:
        """The export covers what its table covers and meets every limit the table meets
        (the exit code of ``schedsyn export`` is 0 exactly then)."""
        return not (self.coverage_lost or self.limit_breaks)

    def to_frame(self) -> pd.DataFrame:
        """One row per exported step: programme number, the step's number in it as the
        controller counts (F4T: from 2, after the start step), times and temperatures
        (what the controller runs, read back from the file)."""
        rows = []
        step = 0
        t = 0.0
        for number, part in zip(self.decoded.numbers, self.decoded.parts, strict=True):
            tk = part.boundary_temps_c
            for i, (d, u) in enumerate(zip(part.durations_min, part.rates_c_per_min, strict=True)):
                step += 1
                rows.append(
                    {
                        "step": step,
                        "programme": number,
                        "programme_step": i + self.spec.first_path_step,
                        "start_min": t,
                        "duration_min": float(d),
                        "duration_hms": _hms(float(d) * 60.0),
                        "tk_start_c": float(tk[i]),
                        "tk_end_c": float(tk[i + 1]),
                        "rate_c_per_min": float(u),
                    }
                )
                t += float(d)
        return pd.DataFrame(rows)

    def summary_dict(self) -> dict[str, Any]:
        s, e = self.source_coverage, self.export_coverage
        return {
            "controller": self.spec.key,
            "controller_title": self.spec.title,
            "programmes": list(self.decoded.numbers),
            "steps_per_programme": [p.n_segments for p in self.decoded.parts],
            "max_steps_per_programme": self.spec.max_steps,
            "time_step_s": self.spec.time_step_s,
            "temp_step_c": self.spec.temp_step_c,
            "source_steps": self.source.n_segments,
            "source_duration_min": self.source.total_min,
            "export_duration_min": self.exported.total_min,
            "max_boundary_shift_s": self.max_boundary_shift_s,
            "max_chamber_deviation_c": self.max_chamber_deviation_c,
            "region_c": None
            if self.check is None
            else [self.check.grid.lo_c, self.check.grid.hi_c],
            "tau_s": None if self.check is None else self.check.params.tau_s,
            "dt0_c": None if self.check is None else self.check.params.dt0_c,
            "source_coverage": None if s is None else s.coverage,
            "export_coverage": None if e is None else e.coverage,
            "source_min_levels": None if s is None else s.min_levels,
            "export_min_levels": None if e is None else e.min_levels,
            "coverage_lost": self.coverage_lost,
            "limit_breaks": list(self.limit_breaks),
            "notes": list(self.notes),
        }

    def _end_segments_text(self) -> str:
        n, sec = len(self.decoded.parts), self.spec.end_segment_s
        if not sec:
            return ""
        between = f" (the {n - 1} end segment(s) between programmes included)" if n > 1 else ""
        total_min = self.exported.total_min + sec / 60
        return f"{between} + the last end segment of {sec} s = {total_min:g} min"

    def summary(self) -> list[str]:
        """Lines for the operator; a lost coverage says so loudly."""
        parts = self.decoded.parts
        lines = [
            f"{self.spec.title}: {len(parts)} programme(s) "
            f"{', '.join(str(n) for n in self.decoded.numbers)} with "
            f"{', '.join(str(p.n_segments) for p in parts)} step(s) "
            "("
            + (
                "no step limit per programme"
                if self.spec.max_steps is None
                else f"at most {self.spec.max_steps} per programme"
            )
            + f", {self.spec.time_step_s} s and {self.spec.temp_step_c:g} °C resolution)",
            f"  rounding: boundaries moved by at most {self.max_boundary_shift_s:.0f} s, chamber "
            f"path by at most {self.max_chamber_deviation_c:.3f} °C; "
            f"{self.exported.total_min:g} min{self._end_segments_text()} (source "
            f"{self.source.total_min:g} min)",
        ]
        if self.source_coverage is not None and self.export_coverage is not None:
            s, e = self.source_coverage, self.export_coverage
            lines.append(
                f"  coverage of [{s.grid.lo_c:g}, {s.grid.hi_c:g}] °C re-simulated: source "
                f"{s.coverage:.1%} (min {s.min_levels} levels), exported {e.coverage:.1%} "
                f"(min {e.min_levels} levels)"
            )
            if self.coverage_lost:
                lines.insert(
                    0,
                    f"*** the {self.spec.title} export covers LESS than its step table: "
                    "check the rounding notes below ***",
                )
                lo = s.grid.lower_c
                fewer = np.flatnonzero(e.levels < s.levels)
                shown = ", ".join(
                    f"[{lo[k]:g}, {lo[k] + s.grid.bin_c:g}) {s.levels[k]} -> {e.levels[k]}"
                    for k in fewer[:LOST_BINS_SHOWN]
                )
                more = fewer.size - LOST_BINS_SHOWN
                lines.append(
                    f"  bins with fewer levels exported ({fewer.size}): {shown}"
                    + (f" and {more} more" if more > 0 else "")
                )
        if self.limit_breaks:
            lines.insert(
                0,
                f"*** the {self.spec.title} export breaks limits its step table meets: "
                "the rounding to the controller's grid could not keep them ***",
            )
            lines += [f"  limit broken by the export: {b}" for b in self.limit_breaks]
        lines += [f"  note: {n}" for n in self.notes]
        return lines


def _hms(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{(s % 3600) // 60:02d}:{s % 60:02d}"


def _rounding_shift_s(source: Programme, time_step_min: float) -> float:
    """Largest move of a source boundary time by the cumulative rounding, s (<= half a
    time step)."""
    edges = np.concatenate(([0.0], np.cumsum(source.durations_min)))
    q = time_step_min
    rounded = np.floor(edges / q + 0.5 + 1e-9) * q
    return float(np.max(np.abs(rounded - edges)) * 60.0)


def _path_deviation_c(source: Programme, exported: Programme) -> float:
    t_end = max(source.total_min, exported.total_min)
    t = np.linspace(0.0, t_end, max(2, int(math.ceil(t_end / 0.1)) + 1))
    edges = np.concatenate(
        ([0.0], np.cumsum(source.durations_min), np.cumsum(exported.durations_min))
    )
    t = np.union1d(t, edges)
    return float(np.max(np.abs(source.chamber_at(t) - exported.chamber_at(t))))


#: Device temperature, degC, by which the exported programme may take the device further
#: past a device limit than its step table does before that is reported.
DEVICE_LIMIT_TOL_C = 1e-3


def _shortened(
    part: Programme, cut_min: float, q: float, limits: Limits, k: int = -1
) -> Programme | None:
    """``part`` with its step ``k`` (default the last) ``cut_min`` shorter, reaching the
    same temperature that much earlier (the steps after it run that much earlier); None
    where the step would be shorter than ``q`` or its rate outside the limits."""
    d = part.durations_min.copy()
    k = k % d.size
    if d[k] - cut_min < q - 1e-9:
        return None
    tk = part.boundary_temps_c
    rate = float(tk[k + 1] - tk[k]) / (d[k] - cut_min)
    if not limits.rate_min_c_per_min - 1e-9 <= rate <= limits.rate_max_c_per_min + 1e-9:
        return None
    d[k] -= cut_min
    rates = part.rates_c_per_min.copy()
    rates[k] = rate
    return Programme(d, rates, part.start_c)


def _room_for_end_segments(
    parts: tuple[Programme, ...], spec: ControllerSpec, limits: Limits
) -> tuple[Programme, ...]:
    """``parts`` with room for the controller's end segments, between the programmes and
    within ``duration_max_min``.

    Each programme runs ``spec.end_segment_s`` at its last setpoint after its path (Binder:
    the 1-s final segment), and the next starts after it. So that every programme after
    the first still starts on the step table's time, each but the last has its last step
    shortened by that much (red team: 21 hand-overs put the path 21 s late, 1.1 °C on a
    fast ramp, with "0.000 °C" reported); where the rate limits forbid it, the delay stays
    and the path check reports it. Where the last end segment would take the run past the
    time limit, the last step of the last part is shortened by the overrun (whole time
    steps), or where the rate limits forbid it the latest step they allow (the steps after
    it run that much earlier). Each shortened step reaches the same temperature that much
    earlier and the end segment holds the end.
    """
    q = spec.time_step_min
    hold_min = math.ceil(spec.end_segment_s / 60.0 / q - 1e-6) * q
    parts = tuple(
        (_shortened(p, hold_min, q, limits) or p) if k < len(parts) - 1 else p
        for k, p in enumerate(parts)
    )
    run_min = sum(p.total_min for p in parts) + len(parts) * spec.end_segment_s / 60.0
    over_min = run_min - limits.duration_max_min
    if over_min <= 1e-9:
        return parts
    cut_min = math.ceil(over_min / q - 1e-6) * q
    # the last step, else the latest one the rate limits let run that much shorter (red
    # team: a plan of exactly its budget ending on a full-rate ramp ran 0.017 min over it
    # on Binder, "limit broken"; a hold before that ramp can give the second)
    for k in range(parts[-1].n_segments - 1, -1, -1):
        last = _shortened(parts[-1], cut_min, q, limits, k)
        if last is not None:
            return (*parts[:-1], last)
    return parts


def _device_range(p: Programme, check: CoverageCheck) -> tuple[float, float]:
    """Lowest and highest device temperature of ``p`` under ``check``'s model, degC."""
    t = simulate(p, check.params, dt_min=check.dt_min, t0_c=check.t0_c).t_c
    return float(np.min(t)), float(np.max(t))


def _table_device_notes(
    table_range_c: tuple[float, float], limits: Limits, check: CoverageCheck
) -> list[str]:
    """A note where the step table itself (its device range ``table_range_c``) takes
    the device past a device limit (the export keeps what the table does, so this is
    not a break of its own; red team: a table reaching 65.7 °C against 62 was exported
    without a word)."""
    out = []
    for value, limit, word in (
        (table_range_c[1], limits.device_max_c, "above"),
        (table_range_c[0], limits.device_min_c, "below"),
    ):
        if (value - limit) * (1 if word == "above" else -1) > DEVICE_LIMIT_TOL_C:
            out.append(
                f"the step table itself takes the device to {value:.2f} °C, {word} its limit "
                f"{limit:g} °C (tau {check.params.tau_s:g} s, dT0 {check.params.dt0_c:g} °C): "
                "the export runs it as written; plan again or fix the table"
            )
    return out


def _limit_breaks(
    source: Programme,
    exported: Programme,
    limits: Limits,
    check: CoverageCheck | None,
    end_segments_min: float = 0.0,
    source_range_c: tuple[float, float] | None = None,
) -> tuple[str, ...]:
    """Limits ``exported`` breaks that ``source`` meets (chamber side: rates, range, start,
    end, duration, the latter with the controller's ``end_segments_min``; with a
    ``check``: the simulated device range, where the export goes further past a device
    limit than the source, whose range ``source_range_c`` is simulated unless given)."""
    before = set(source.violations(limits))
    out = [v for v in exported.violations(limits) if v not in before]
    run_min = exported.total_min + end_segments_min
    if end_segments_min > 0 and run_min > limits.duration_max_min + 1e-9:
        out.append(
            f"the programme runs {run_min:.3f} min with its end segment(s) of "
            f"{end_segments_min * 60:g} s, longer than the limit "
            f"{limits.duration_max_min:g} min (the last step cannot be shortened within "
            "the rate limits)"
        )
    if check is not None:
        s_lo, s_hi = source_range_c or _device_range(source, check)
        e_lo, e_hi = _device_range(exported, check)
        over_hi = max(s_hi - limits.device_max_c, 0.0)
        if e_hi - limits.device_max_c > over_hi + DEVICE_LIMIT_TOL_C:
            out.append(
                f"the device reaches {e_hi:.3f} °C, above its limit {limits.device_max_c:g} °C "
                f"(the step table: {s_hi:.3f} °C)"
            )
        under_lo = max(limits.device_min_c - s_lo, 0.0)
        if limits.device_min_c - e_lo > under_lo + DEVICE_LIMIT_TOL_C:
            out.append(
                f"the device reaches {e_lo:.3f} °C, below its limit {limits.device_min_c:g} °C "
                f"(the step table: {s_lo:.3f} °C)"
            )
    return tuple(out)


def _device_start_note(note: str, limits: Limits) -> str:
    """A codec's note with the device's start temperature the plan assumes: the codecs say
    "the chamber and the device at START" (the chamber's start); a plan for a device that
    is not soaked there (``t_init_c``) needs it at ``t_init_c`` (red team: an operator
    following the note on a plan for a device at 28 °C, the chamber at 20, got 67 %)."""
    if abs(limits.t_init_c - limits.start_c) < 1e-9:
        return note
    return re.sub(
        r"the chamber and the device at (\S+) °C",
        lambda m: (
            f"the chamber at {m.group(1)} °C and the device at {limits.t_init_c:g} °C (the plan "
            f"assumes the device there, not soaked at the chamber's {m.group(1)} °C)"
        ),
        note,
    )


def export_programme(
    programme: Programme,
    settings: ExportSettings,
    *,
    limits: Limits | None = None,
    check: CoverageCheck | None = None,
    header: Mapping[str, Any] | None = None,
) -> ControllerExport:
    """Export ``programme`` for ``settings.controller`` and re-check it.

    Parameters
    ----------
    programme : Programme
        The step table (e.g. ``Plan.programme`` or :func:`read_step_table`).
    settings : ExportSettings
        Controller, programme numbers, overrides.
    limits : Limits, optional
        Chamber limits (rates, temperatures) the rounding must respect (default
        :class:`Limits`).
    check : CoverageCheck, optional
        Region and model for the re-simulation; without it coverage is not reported.
    header : mapping, optional
        Extra facts written into the file's header (source file, its SHA-256, ...).

    Returns
    -------
    ControllerExport

    Raises
    ------
    StepTableError
        The programme needs more programmes than the controller stores, or the encoded
        file does not read back (a bug: the message says what differs).
    """
    from .controllers import CODECS

    limits = Limits() if limits is None else limits
    broken = programme.violations(limits)
    if broken:
        raise StepTableError(
            f"the programme breaks the limits it is exported with: {broken[0]}"
            + (f" (and {len(broken) - 1} more)" if len(broken) > 1 else "")
            + "; fix the step table or export with the chamber's own limits"
        )
    spec = settings.spec
    codec = CODECS[spec.key]
    q = quantise(programme, spec.time_step_min, limits, spec.temp_step_c, spec.max_step_min)
    capacity = None if spec.max_steps is None else spec.max_steps - spec.reserved_steps
    parts = split_parts(q, capacity)
    if spec.end_segment_s:
        parts = _room_for_end_segments(parts, spec, limits)
    numbers = tuple(range(settings.first_programme, settings.first_programme + len(parts)))
    last_allowed = None if spec.programmes is None else spec.first_number + spec.programmes - 1
    if last_allowed is not None and numbers[-1] > last_allowed:
        raise StepTableError(
            f"the programme needs {len(parts)} {spec.title} programme(s) of at most "
            f"{spec.max_steps} steps ({q.n_segments} steps in all), numbered "
            f"{numbers[0]}..{numbers[-1]}, but the controller stores programmes "
            f"{spec.first_number}..{last_allowed}; choose a lower first programme or "
            "a shorter programme"
        )
    notes = [_device_start_note(n, limits) for n in codec.notes(parts, numbers, settings)]
    table_range_c = None if check is None else _device_range(programme, check)
    if check is not None and table_range_c is not None:
        notes += _table_device_notes(table_range_c, limits, check)
    head: dict[str, Any] = dict(header or {})
    text = codec.encode(parts, numbers, settings, limits, head)
    decoded = codec.decode(text, f"{spec.key} export", spec)
    _same_parts(parts, decoded.parts, spec)
    exported = decoded.programme
    src_cov = exp_cov = None
    if check is not None:
        src_cov = check.report(programme)
        exp_cov = check.report(exported)
    result = ControllerExport(
        spec,
        settings,
        programme,
        decoded,
        text,
        src_cov,
        exp_cov,
        check,
        # a step shortened for the end segment between two programmes ends that much early
        max(
            _rounding_shift_s(programme, spec.time_step_min),
            float(spec.end_segment_s) if len(parts) > 1 else 0.0,
        ),
        _path_deviation_c(programme, exported),
        tuple(notes),
        _limit_breaks(
            programme,
            exported,
            limits,
            check,
            spec.end_segment_s / 60.0,  # the last one (those between are in the path)
            table_range_c,
        ),
    )
    # write the check into the file's header too
    head["check"] = {
        k: v
        for k, v in result.summary_dict().items()
        if k not in ("controller", "controller_title", "programmes", "notes")
    }
    head["notes"] = list(notes)
    text = codec.encode(parts, numbers, settings, limits, head)
    decoded2 = codec.decode(text, f"{spec.key} export", spec)
    _same_parts(parts, decoded2.parts, spec)
    import dataclasses

    return dataclasses.replace(result, decoded=decoded2, text=text)


def _same_parts(want: Sequence[Programme], got: Sequence[Programme], spec: ControllerSpec) -> None:
    """The read-back parts equal the encoded ones to the controller's resolution."""
    if len(want) != len(got):
        raise StepTableError(
            f"{spec.title} export reads back as {len(got)} programme(s), not {len(want)}"
        )
    for k, (a, b) in enumerate(zip(want, got, strict=True), start=1):
        if a.n_segments != b.n_segments:
            raise StepTableError(
                f"{spec.title} export: programme part {k} reads back with {b.n_segments} "
                f"steps, not {a.n_segments}"
            )
        ta = np.cumsum(a.durations_min)
        tb = np.cumsum(b.durations_min)
        if np.max(np.abs(ta - tb)) > 1e-6:
            raise StepTableError(
                f"{spec.title} export: programme part {k} reads back with other step times"
            )
        if np.max(np.abs(a.boundary_temps_c - b.boundary_temps_c)) > 1e-6:
            raise StepTableError(
                f"{spec.title} export: programme part {k} reads back with other setpoints"
            )


def read_export(path: Path | str, controller: str | None = None) -> Decoded:
    """Read a controller export file back (JSON for ESPEC/Watlow, CSV for Binder and the
    generic step table), checking the controller's limits and the chain.

    ``controller`` defaults to the one the file names (``"controller"`` in JSON, a
    ``# controller:`` line in CSV; a CSV without one is a step table).
    """
    from .controllers import CODECS

    path = Path(path)
    if not path.is_file():
        raise StepTableError(f"export file {path} does not exist or is not a file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise StepTableError(f"{path}: not a UTF-8 text file") from None
    if controller is None:
        controller = _detect_controller(text, str(path))
    spec = controller_spec(controller)
    return CODECS[controller].decode(text, str(path), spec)


def _detect_controller(text: str, source: str) -> str:
    stripped = text.lstrip()
    if stripped.startswith("{"):
        import json

        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise StepTableError(f"{source}: not valid JSON ({exc})") from None
        key = doc.get("controller") if isinstance(doc, dict) else None
        if key not in CONTROLLER_KEYS:
            raise StepTableError(
                f"{source}: JSON without a known 'controller' key; give the controller"
            )
        return str(key)
    meta, _ = split_metadata(text)
    return meta.get("controller", "csv")


def write_export(
    path: Path | str, export: ControllerExport, inputs: Sequence[Path | str] = ()
) -> Path:
    """Write the export file atomically (never over an input)."""
    from .io import write_text_atomic

    return write_text_atomic(path, export.text, inputs)


def default_export_path(steps_path: Path | str, controller: str) -> Path:
    """Beside the step table: ``STEM.<controller><suffix>`` (e.g. ``steps.espec-p300.json``),
    ``STEM.typed.csv`` for the plain step table."""
    p = Path(steps_path)
    tag = "typed" if controller == "csv" else controller
    return p.with_name(f"{p.stem}.{tag}{controller_spec(controller).file_suffix}")
