"""The generic export: schedsyn's own step table, for a controller typed in by hand.

Whole minutes and 0.1 degC (what an operator types on any front panel), one table,
no limit on steps. The header lines (``# key: value``) name the limits the table was
rounded for, so that reading it back validates it with the same limits.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any

import pandas as pd

from ..errors import StepTableError
from ..export import ControllerSpec, Decoded, ExportSettings, limits_from_meta, split_metadata
from ..params import Limits
from ..programme import Programme, programme_from_frame
from . import _json
from .binder import _flat

CSV = ControllerSpec(
    key="csv",
    title="step table (typed in by hand)",
    time_step_s=60,
    temp_step_c=0.1,
    max_steps=None,
    reserved_steps=0,
    programmes=None,
    first_number=1,
    max_step_min=None,
    end_modes=(),
    file_suffix=".csv",
    source="schedsyn step table (whole minutes, 0.1 °C)",
)


class CsvCodec:
    """schedsyn step table with ``# key: value`` header lines."""

    def encode(
        self,
        parts: Sequence[Programme],
        numbers: Sequence[int],
        settings: ExportSettings,
        limits: Limits,
        header: Mapping[str, Any],
    ) -> str:
        if len(parts) != 1:
            raise StepTableError("a step table export is one table")
        frame = parts[0].to_frame()
        for c in ("start_min", "duration_min", "tk_start_c", "tk_end_c"):
            frame[c] = frame[c].round(3)
        frame["rate_c_per_min"] = frame["rate_c_per_min"].round(6)
        head: dict[str, Any] = {
            "format": _json.FORMAT,
            "controller": CSV.key,
            **{f.name: getattr(limits, f.name) for f in fields(Limits)},
            **{f"schedsyn_{k}": v for k, v in header.items()},
        }
        lines = [f"# {k}: {_flat(v)}\n" for k, v in head.items()]
        return "".join(lines) + frame.to_csv(index=False)

    def decode(self, text: str, source: str, spec: ControllerSpec) -> Decoded:
        meta, body = split_metadata(text)
        limits = limits_from_meta(meta, source=source)
        try:
            frame = pd.read_csv(io.StringIO(body))
        except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            raise StepTableError(f"{source}: not a readable step table ({exc})") from None
        prog = programme_from_frame(frame, limits, source=source)
        # the typed values must be on the step table's grid (whole minutes, 0.1 degC)
        for r, d in enumerate(prog.durations_min, start=1):
            if abs(d - round(d)) > 1e-6:
                raise StepTableError(f"{source}: step {r}: duration {d:g} min is not whole")
        for r, t in enumerate(prog.boundary_temps_c):
            _json.temperature(float(t), f"{source}: boundary {r}", spec.temp_step_c)
        header = {k: v for k, v in meta.items() if k.startswith("schedsyn_")}
        return Decoded(spec.key, (1,), (prog,), header)

    def notes(
        self, parts: Sequence[Programme], numbers: Sequence[int], settings: ExportSettings
    ) -> list[str]:
        return [
            f"type the steps in as listed, starting with the chamber and the device at "
            f"{parts[0].start_c:g} °C"
        ]
