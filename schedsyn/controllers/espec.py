"""ESPEC P-300 and SCP-220: programmes as ChamberConnectLibrary's dictionaries.

Source: EspecNorthAmerica/ChamberConnectLibrary, ``chamberconnectlibrary/p300.py``:

* ``P300.read_prgm(pgmnum)`` / ``P300.write_prgm(pgmnum, program)`` (behind
  ``controller.get_program(N)`` / ``controller.set_program(N, program)`` of
  ``controllerinterface.py``) read and write one programme as::

      {"name": str, "end": "OFF"|"CONSTANT"|"STANDBY"|"RUN", "next_prgm": int,
       "counter_a": {"start": int, "end": int, "cycles": int}, "counter_b": {...},
       "tempDetail": {"range": {"max": float, "min": float}, "mode": str,
                      "setpoint": float},
       "steps": [step, ...]}

  (``parse_prgm_data`` gives ``end``/``next_prgm``/counters, ``parse_prgm_data_detail``
  gives ``tempDetail``; ``write_prgm_data_details`` writes ``END,RUN,PTN<next_prgm>``
  when ``end`` is ``"RUN"`` and ``PRE MODE,TEMP,SV`` + ``PRE TSV,<setpoint>`` when the
  mode is ``"SV"``, the setpoint the programme starts from).
* A step (``read_prgm_data_step`` / ``write_prgm_data_step``)::

      {"number": int, "time": {"hour": int, "minute": int}, "paused": bool,
       "granty": bool, "refrig": {"mode": "auto", "setpoint": 0},
       "temperature": {"setpoint": float, "ramp": bool}, "relay": [bool] * 12}

  written as ``PRGM DATA WRITE,PGMn,STEPk,TEMPx.x,TRAMPON|OFF,TIMEh:m,GRANTY OFF,
  PAUSE OFF,REF9,...``: the setpoint has 0.1 degC resolution (``%0.1f``), the duration
  whole minutes (``TIME%d:%d``); with ``ramp`` on the setpoint moves linearly from the
  previous step's setpoint over the step's time, with ``ramp`` off it is the setpoint for
  the whole step (a hold when it equals the previous one). Humidity keys are left out
  (``write_prgm`` then leaves humidity off).
* ``P300.ramprgms = 40`` (``write_prgm`` refuses numbers above 40 on the P-300 and above
  20 on the SCP-220, ``scp220.py``: ``ramprgms = 20``).

The library encodes no maximum number of steps per programme; schedsyn assumes 99 (the
figure of the P-300 front panel as far as we know: **check your controller's manual**
and override with ``max_steps``). Long programmes are split into programmes chained by
end mode RUN to the next programme, which the controller runs without a pause.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from ..errors import StepTableError
from ..export import ControllerSpec, Decoded, ExportSettings
from ..params import Limits
from ..programme import Programme
from . import _json

_SOURCE = (
    "EspecNorthAmerica/ChamberConnectLibrary chamberconnectlibrary/p300.py "
    "(read_prgm, write_prgm, write_prgm_data_step, parse_prgm_data); steps per "
    "programme: 99 assumed (not in the library)"
)
_END_MODES = ("STANDBY", "OFF", "CONSTANT")

P300 = ControllerSpec(
    key="espec-p300",
    title="ESPEC P-300",
    time_step_s=60,
    temp_step_c=0.1,
    max_steps=99,
    reserved_steps=0,
    programmes=40,
    first_number=1,
    max_step_min=99 * 60 + 59,
    end_modes=_END_MODES,
    file_suffix=".json",
    source=_SOURCE,
)
SCP220 = ControllerSpec(
    key="espec-scp220",
    title="ESPEC SCP-220",
    time_step_s=60,
    temp_step_c=0.1,
    max_steps=99,
    reserved_steps=0,
    programmes=20,
    first_number=1,
    max_step_min=99 * 60 + 59,
    end_modes=_END_MODES,
    file_suffix=".json",
    source=_SOURCE.replace("p300.py", "p300.py, scp220.py (ramprgms = 20)"),
)
_LIBRARY = (
    "ChamberConnectLibrary (EspecNorthAmerica): for entry in programmes: "
    "controller.set_program(entry['number'], entry['program']); then start the first "
    "programme at step 1"
)
#: Programme names are kept short (the controller's limit is not in the library).
_NAME_LEN = 15


class EspecCodec:
    """P-300 / SCP-220 programmes in ``P300.read_prgm`` form."""

    def encode(
        self,
        parts: Sequence[Programme],
        numbers: Sequence[int],
        settings: ExportSettings,
        limits: Limits,
        header: Mapping[str, Any],
    ) -> str:
        spec = settings.spec
        progs = []
        for k, (part, number) in enumerate(zip(parts, numbers, strict=True)):
            last = k == len(parts) - 1
            tk = part.boundary_temps_c
            steps = []
            for i, d in enumerate(part.durations_min):
                minutes = int(round(float(d)))
                steps.append(
                    {
                        "number": i + 1,
                        "time": {"hour": minutes // 60, "minute": minutes % 60},
                        "paused": False,
                        "granty": False,
                        "refrig": {"mode": "auto", "setpoint": 0},
                        "temperature": {
                            "setpoint": round(float(tk[i + 1]), 1),
                            # a ramp moves from the previous setpoint; a hold keeps it
                            "ramp": bool(abs(tk[i + 1] - tk[i]) > 1e-9),
                        },
                        "relay": [False] * 12,
                    }
                )
            progs.append(
                {
                    "number": int(number),
                    "program": {
                        "name": _json.short_name(settings.name, k + 1, len(parts), _NAME_LEN),
                        "end": settings.effective_end_mode if last else "RUN",
                        "next_prgm": 0 if last else int(numbers[k + 1]),
                        "counter_a": {"start": 0, "end": 0, "cycles": 0},
                        "counter_b": {"start": 0, "end": 0, "cycles": 0},
                        "tempDetail": {
                            "range": {
                                "max": float(limits.chamber_max_c),
                                "min": float(limits.chamber_min_c),
                            },
                            "mode": "SV",
                            "setpoint": round(float(part.start_c), 1),
                        },
                        "steps": steps,
                    },
                }
            )
        return _json.envelope(spec, _LIBRARY, header, progs)

    def decode(self, text: str, source: str, spec: ControllerSpec) -> Decoded:
        header, entries = _json.open_envelope(text, source, spec)
        numbers = _json.check_numbers([e["number"] for e in entries], spec, source)
        parts = []
        for k, (entry, number) in enumerate(zip(entries, numbers, strict=True)):
            prog = entry["program"]
            where = f"{source}: programme {number}"
            end = _json.get(prog, "end", where)
            if k < len(entries) - 1:
                nxt = _json.get(prog, "next_prgm", where)
                if end != "RUN" or nxt != numbers[k + 1]:
                    raise StepTableError(
                        f"{where} ends with {end!r} (next {nxt!r}) but must chain to "
                        f"programme {numbers[k + 1]} with end mode RUN"
                    )
            elif end not in _END_MODES:
                raise StepTableError(
                    f"{where} is the last programme but ends with {end!r}; "
                    f"use one of {', '.join(_END_MODES)}"
                )
            for counter in ("counter_a", "counter_b"):
                c = prog.get(counter, {"cycles": 0})
                if _json.whole(c, "cycles", f"{where} {counter}") != 0:
                    raise StepTableError(
                        f"{where}: {counter} repeats steps; schedsyn exports and reads back "
                        "programmes without repeats"
                    )
            detail = _json.get(prog, "tempDetail", where)
            if _json.get(detail, "mode", f"{where} tempDetail") != "SV":
                raise StepTableError(
                    f"{where}: tempDetail mode must be 'SV' with the start setpoint, so that "
                    "step 1 ramps from a known temperature"
                )
            start = _json.temperature(
                _json.get(detail, "setpoint", f"{where} tempDetail"), where, spec.temp_step_c
            )
            steps = _json.get(prog, "steps", where)
            if not isinstance(steps, list):
                raise StepTableError(f"{where}: steps must be a list")
            _json.check_step_count(len(steps), spec, where)
            durations, temps = [], [start]
            for i, st in enumerate(steps):
                w = f"{where} step {i + 1}"
                if _json.whole(st, "number", w, 1) != i + 1:
                    raise StepTableError(f"{w}: number must be {i + 1} (steps count 1, 2, ...)")
                t = _json.get(st, "time", w)
                minutes = 60 * _json.whole(t, "hour", w, 0, 99) + _json.whole(t, "minute", w, 0, 59)
                if minutes == 0:
                    raise StepTableError(f"{w}: time is 0:00; a step lasts at least 1 min")
                for key in ("paused", "granty"):
                    if _json.flag(st, key, w):
                        raise StepTableError(
                            f"{w}: {key} is on; the planned timing holds only without "
                            "pauses and guaranteed soak"
                        )
                temp = _json.get(st, "temperature", w)
                sp = _json.temperature(_json.get(temp, "setpoint", w), w, spec.temp_step_c)
                ramp = _json.flag(temp, "ramp", w)
                if not ramp and abs(sp - temps[-1]) > 1e-9:
                    raise StepTableError(
                        f"{w}: ramp off jumps the setpoint from {temps[-1]:g} to {sp:g} °C; "
                        "a chamber programme must be continuous (turn the ramp on)"
                    )
                durations.append(float(minutes))
                temps.append(sp)
            parts.append(_part(durations, temps))
        return Decoded(spec.key, numbers, tuple(parts), header)

    def notes(
        self, parts: Sequence[Programme], numbers: Sequence[int], settings: ExportSettings
    ) -> list[str]:
        title = settings.spec.title
        out = [
            f"start {title} programme {numbers[0]} at step 1 with the chamber and the "
            f"device at {parts[0].start_c:g} °C"
        ]
        if len(parts) > 1:
            out.append(
                f"programmes {', '.join(str(n) for n in numbers)} are chained (end mode RUN to "
                "the next programme): the controller runs them without a pause"
            )
        out.append(
            f"the last programme ends with mode {settings.effective_end_mode} at "
            f"{parts[-1].end_c:g} °C"
        )
        return out + _json.name_note(settings.name, len(parts), _NAME_LEN)


def _part(durations: list[float], temps: list[float]) -> Programme:
    import numpy as np

    d = np.asarray(durations)
    t = np.asarray(temps)
    return Programme(d, np.diff(t) / d, float(t[0]))
