"""Binder MB1 / MB2: the segment table of a programme.

Source: auger-prime-sde/ess, ``binder.py``:

* ``Binder_MKFT115_MB1`` / ``Binder_MKFT115_MB2``: ``NPROG = 25`` programmes (numbered
  0..24 over Modbus, shown as 1..25 on the chamber: "progno is displayed as progno+1"),
  ``NSEG = 100`` segments per programme (``load_prog``: "Max. 100 segments allowed").
* A segment is its **start value**, its **duration in whole seconds** (``ChamberProg.
  add_segment``: "duration - [int]. Segment length (seconds, positive)"; MB2
  ``ADDR_PGM_DURATION``: seconds) and, for ramps (MB2 segment type ``SG_RAMP``), a
  linear change to the next segment's start value; ``convert_chamber2binder`` writes
  each segment's start value as the previous segment's end temperature and appends a
  last segment of 1 s holding the final value (that is how a programme ends).
* Per segment also: the gradient (MB1 ``ADDR_PROG_GRAD``, left at the library's default),
  tolerance limits min/max (MB2 defaults -260 / 260 degC: off), the repeat
  (``numjump``: jumps back, ``segjump``: to which segment; 0 here), operating contacts.

The segment table schedsyn writes has one row per segment; ``gradient_c_per_min`` is
the ramp the segment makes (to the next start value), for the operator to read, not a
register. The library links no programmes: a programme longer than 99 segments (plus the
final one) is split; each part ends holding its last value for 1 s, after which the
chamber leaves programme mode: the operator starts the next programme at once (and
sets the manual setpoint to the hand-over temperature as a safeguard). The final
segments run after the path (``ControllerSpec.end_segment_s``), and
``export._room_for_end_segments`` makes room for them: each part but the last reaches its
end 1 s early, so the next starts on the step table's time, and where the last one would
pass the time limit, the last step is shortened by the overrun.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from ..errors import StepTableError
from ..export import ControllerSpec, Decoded, ExportSettings, split_metadata
from ..params import Limits
from ..programme import Programme
from . import _json

BINDER_MB = ControllerSpec(
    key="binder-mb",
    title="Binder MB1/MB2",
    time_step_s=1,
    temp_step_c=0.1,
    max_steps=100,
    reserved_steps=1,
    programmes=25,
    first_number=1,
    max_step_min=None,
    end_modes=(),
    file_suffix=".csv",
    end_segment_s=1,
    source=(
        "auger-prime-sde/ess binder.py (Binder_MKFT115_MB1/MB2: NPROG 25, NSEG 100, "
        "durations in s, start value per segment, final 1-s segment)"
    ),
)
COLUMNS = (
    "program",
    "progno",
    "segment",
    "start_value_c",
    "duration_s",
    "duration_hms",
    "gradient_c_per_min",
    "segment_type",
    "limit_min_c",
    "limit_max_c",
    "jump_count",
    "jump_to_segment",
    "note",
)
_LIMIT_OFF_C = 260.0  # MB2 Bprog.limit_temp_low/high: tolerance limits off


def _hms(seconds: int) -> str:
    return f"{seconds // 3600}:{(seconds % 3600) // 60:02d}:{seconds % 60:02d}"


class BinderCodec:
    """Binder segment table (CSV with ``# key: value`` header lines)."""

    def encode(
        self,
        parts: Sequence[Programme],
        numbers: Sequence[int],
        settings: ExportSettings,
        limits: Limits,
        header: Mapping[str, Any],
    ) -> str:
        rows = []
        for part, number in zip(parts, numbers, strict=True):
            tk = part.boundary_temps_c
            for i, d in enumerate(part.durations_min):
                seconds = int(round(float(d) * 60.0))
                rows.append(
                    {
                        "program": int(number),
                        "progno": int(number) - 1,
                        "segment": i + 1,
                        "start_value_c": round(float(tk[i]), 1),
                        "duration_s": seconds,
                        "duration_hms": _hms(seconds),
                        "gradient_c_per_min": round(float((tk[i + 1] - tk[i]) / d), 6),
                        "segment_type": "RAMP",
                        "limit_min_c": -_LIMIT_OFF_C,
                        "limit_max_c": _LIMIT_OFF_C,
                        "jump_count": 0,
                        "jump_to_segment": 0,
                        "note": "",
                    }
                )
            rows.append(
                {
                    "program": int(number),
                    "progno": int(number) - 1,
                    "segment": part.n_segments + 1,
                    "start_value_c": round(float(tk[-1]), 1),
                    "duration_s": 1,
                    "duration_hms": _hms(1),
                    "gradient_c_per_min": 0.0,
                    "segment_type": "RAMP",
                    "limit_min_c": -_LIMIT_OFF_C,
                    "limit_max_c": _LIMIT_OFF_C,
                    "jump_count": 0,
                    "jump_to_segment": 0,
                    "note": "end of programme (holds the final value, as binder.py writes it)",
                }
            )
        head = {
            "format": _json.FORMAT,
            "controller": BINDER_MB.key,
            "controller_title": BINDER_MB.title,
            "load_with": (
                "auger-prime-sde/ess binder.py: one programme per 'program' (load_prog takes "
                "progno = program - 1), segments in order"
            ),
            **{f"schedsyn_{k}": v for k, v in header.items()},
        }
        lines = [f"# {k}: {_flat(v)}\n" for k, v in head.items()]
        body = pd.DataFrame(rows, columns=list(COLUMNS)).to_csv(index=False)
        return "".join(lines) + body

    def decode(self, text: str, source: str, spec: ControllerSpec) -> Decoded:
        meta, body = split_metadata(text)
        if meta.get("controller", spec.key) != spec.key:
            raise StepTableError(
                f"{source}: written for controller {meta.get('controller')!r}, not {spec.key!r}"
            )
        try:
            frame = pd.read_csv(io.StringIO(body))
        except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            raise StepTableError(f"{source}: not a readable segment table ({exc})") from None
        need = ("program", "segment", "start_value_c", "duration_s", "segment_type")
        missing = [c for c in need if c not in frame.columns]
        if missing:
            raise StepTableError(
                f"{source}: missing column(s) {', '.join(missing)}; a Binder segment table "
                f"needs {', '.join(need)}"
            )
        if frame.empty:
            raise StepTableError(f"{source}: the segment table has no rows")
        numbers: list[int] = []
        groups: list[pd.DataFrame] = []
        for number, group in frame.groupby("program", sort=False):
            numbers.append(_int(number, f"{source}: program"))
            groups.append(group)
        programs = frame["program"].to_numpy()
        if np.any(np.diff([numbers.index(_int(p, source)) for p in programs]) < 0):
            raise StepTableError(f"{source}: the rows of one program must be consecutive")
        nums = _json.check_numbers(numbers, spec, source)
        parts, holds = [], []
        for number, group in zip(nums, groups, strict=True):
            where = f"{source}: program {number}"
            n = len(group)
            _json.check_step_count(n, spec, where)
            if n < 2:
                raise StepTableError(
                    f"{where}: needs at least one segment and the final one (the end)"
                )
            segs = [_int(s, f"{where} segment") for s in group["segment"]]
            if segs != list(range(1, n + 1)):
                raise StepTableError(f"{where}: segments must be numbered 1, 2, ..., {n}")
            if "progno" in group.columns:
                for p in group["progno"]:
                    if _int(p, f"{where} progno") != number - 1:
                        raise StepTableError(
                            f"{where}: progno must be program - 1 = {number - 1} "
                            "(the chamber shows progno + 1)"
                        )
            for col in ("jump_count",):
                if col in group.columns and any(_int(v, f"{where} {col}") for v in group[col]):
                    raise StepTableError(
                        f"{where}: {col} repeats segments; schedsyn reads back programmes "
                        "without repeats"
                    )
            starts = [
                _json.temperature(_num(v, f"{where} start_value_c"), where, spec.temp_step_c)
                for v in group["start_value_c"]
            ]
            secs = [_int(v, f"{where} duration_s") for v in group["duration_s"]]
            kinds = [str(k).strip().upper() for k in group["segment_type"]]
            for i in range(n):
                w = f"{where} segment {i + 1}"
                if secs[i] <= 0:
                    raise StepTableError(f"{w}: duration_s must be >= 1 s, got {secs[i]}")
                if kinds[i] not in ("RAMP", "STEP"):
                    raise StepTableError(f"{w}: segment_type must be RAMP or STEP")
                if i < n - 1 and kinds[i] == "STEP" and abs(starts[i + 1] - starts[i]) > 1e-9:
                    raise StepTableError(
                        f"{w}: a STEP segment jumps from {starts[i]:g} to {starts[i + 1]:g} °C; "
                        "a chamber programme must be continuous (use RAMP)"
                    )
            # the last segment ends the programme (1 s at the final value): not a step
            d = np.asarray(secs[:-1], dtype=float) / 60.0
            t = np.asarray(starts, dtype=float)
            parts.append(Programme(d, np.diff(t) / d, float(t[0])))
            holds.append(secs[-1] / 60.0)
        header = {k: v for k, v in meta.items() if k.startswith("schedsyn_")}
        return Decoded(spec.key, nums, tuple(parts), header, tuple(holds))

    def notes(
        self, parts: Sequence[Programme], numbers: Sequence[int], settings: ExportSettings
    ) -> list[str]:
        out = [
            f"start Binder programme {numbers[0]} (progno {numbers[0] - 1}) with the chamber "
            f"and the device at {parts[0].start_c:g} °C"
        ]
        t, hold = 0.0, BINDER_MB.end_segment_s / 60.0
        for k in range(1, len(parts)):
            t += parts[k - 1].total_min
            out.append(
                f"programme {numbers[k - 1]} ends at {t + hold:g} min at "
                f"{parts[k - 1].end_c:g} °C (after its {BINDER_MB.end_segment_s}-s end "
                f"segment): start programme {numbers[k]} at once (set the manual setpoint "
                f"to {parts[k - 1].end_c:g} °C beforehand; Binder programmes are not linked)"
            )
            t += hold
        out.append("each programme's last segment (1 s) holds its final value: the end marker")
        return out


def _int(v: Any, where: str) -> int:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise StepTableError(f"{where}: {v!r} is not a whole number") from None
    if not np.isfinite(f) or f != int(f):
        raise StepTableError(f"{where}: {v!r} is not a whole number")
    return int(f)


def _num(v: Any, where: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise StepTableError(f"{where}: {v!r} is not a number") from None
    if not np.isfinite(f):
        raise StepTableError(f"{where}: {v!r} is not finite")
    return f


def _flat(v: Any) -> str:
    """One-line header value (JSON for structures)."""
    if isinstance(v, str):
        return v.replace("\n", " ")
    return json.dumps(v, ensure_ascii=False)
