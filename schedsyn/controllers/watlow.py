"""Watlow F4T: profiles as ChamberConnectLibrary's dictionaries.

Source: EspecNorthAmerica/ChamberConnectLibrary, ``chamberconnectlibrary/watlowf4t.py``:

* ``WatlowF4T.get_prgm(N)`` / ``WatlowF4T.set_prgm(N, prgm)`` (behind
  ``controller.get_program(N)`` / ``controller.set_program(N, prgm)``) read and write one
  profile (``N`` in 1..40, ``__range_check(N, 1, 40)``) as::

      {"name": str, "log": bool, "haswaits": bool, "hasenables": bool,
       "gs_dev": [{"value": float}],            # guaranteed-soak band per loop
       "steps": [step, ...]}

* A step: ``{"type": str, "duration": {"hours": int, "minutes": int, "seconds": int},
  "loops": [loop, ...], "events": [{"number": int, "value": str}, ...],
  "waits": [...], "jstep": int, "jcount": int}`` with types ``instant``, ``ramptime``,
  ``ramprate``, ``soak``, ``wait``, ``jump``, ``end``; ``set_prgm`` writes the duration
  of ``soak``/``instant``/``ramptime`` steps as hours, minutes, seconds (1-s resolution),
  the loop ``target`` of ``instant``/``ramptime``/``ramprate`` steps, the loop ``rate``
  of ``ramprate`` steps, the loop ``mode`` of ``end`` steps (``user``/``off``/``hold``)
  and the guaranteed-soak flag ``gsoak`` of the others. A loop as ``get_prgm`` returns
  it: the loop's range (``max``, ``min``) and ``mode``, ``gsoak``, ``target``, ``rate``,
  ``showEnable``, ``isCascade``, ``cascade``, ``enable``. Events take the values of
  ``watlow_val_dict``; schedsyn writes ``"nc"`` (no change) so that no event output the
  chamber uses is switched.

A ``jump`` step (``jstep``, ``jcount``) jumps within one profile; the library writes no
link from one profile to another. A programme longer than one profile is therefore
split into profiles that each end with an ``end`` step in mode ``hold`` (the chamber
keeps the last setpoint) and start with an ``instant`` step of 0 s to the temperature
the previous one ended at: the operator (or a script calling ``prgm_start(N, 1)``)
starts the next profile when the previous one has ended. Each profile holds at most 50
steps (assumed; **check your controller's manual** and override with ``max_steps``),
two of which are the start and end steps.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import StepTableError
from ..export import ControllerSpec, Decoded, ExportSettings
from ..params import Limits
from ..programme import Programme
from . import _json

F4T = ControllerSpec(
    key="watlow-f4t",
    title="Watlow F4T",
    time_step_s=1,
    temp_step_c=0.1,
    max_steps=50,
    reserved_steps=2,
    programmes=40,
    first_number=1,
    max_step_min=99 * 60 + 59 + 59 / 60,
    end_modes=("hold", "user", "off"),
    file_suffix=".json",
    first_path_step=2,  # step 1 is the instant step to the start temperature
    source=(
        "EspecNorthAmerica/ChamberConnectLibrary chamberconnectlibrary/watlowf4t.py "
        "(get_prgm, set_prgm: profiles 1..40, durations h:m:s); steps per profile: 50 "
        "assumed (not in the library)"
    ),
)
_LIBRARY = (
    "ChamberConnectLibrary (EspecNorthAmerica): for entry in programmes: "
    "controller.set_program(entry['number'], entry['program']); start the first profile, "
    "and each next one when the previous has ended (each ends holding its last setpoint)"
)
_NAME_LEN = 20  # get_prgm reads the name from 20 registers
_EVENTS = 8


def _duration(seconds: int) -> dict[str, int]:
    return {"hours": seconds // 3600, "minutes": (seconds % 3600) // 60, "seconds": seconds % 60}


class F4TCodec:
    """F4T profiles in ``WatlowF4T.get_prgm`` form (one control loop: temperature)."""

    def encode(
        self,
        parts: Sequence[Programme],
        numbers: Sequence[int],
        settings: ExportSettings,
        limits: Limits,
        header: Mapping[str, Any],
    ) -> str:
        spec = settings.spec

        def loop(target: float, mode: str = "") -> dict[str, Any]:
            return {
                "max": float(limits.chamber_max_c),
                "min": float(limits.chamber_min_c),
                "mode": mode,
                "gsoak": False,
                "target": round(float(target), 1),
                "rate": 0.0,
                "showEnable": False,
                "isCascade": False,
                "cascade": False,
                "enable": True,
            }

        def step(kind: str, seconds: int, target: float, mode: str = "") -> dict[str, Any]:
            return {
                "type": kind,
                "duration": _duration(seconds),
                "loops": [loop(target, mode)],
                "events": [{"number": j, "value": "nc"} for j in range(1, _EVENTS + 1)],
                "waits": [],
                "jstep": 0,
                "jcount": 0,
            }

        progs = []
        for k, (part, number) in enumerate(zip(parts, numbers, strict=True)):
            last = k == len(parts) - 1
            tk = part.boundary_temps_c
            steps = [step("instant", 0, float(tk[0]))]
            for i, d in enumerate(part.durations_min):
                seconds = int(round(float(d) * 60.0))
                ramp = abs(tk[i + 1] - tk[i]) > 1e-9
                steps.append(step("ramptime" if ramp else "soak", seconds, float(tk[i + 1])))
            end_mode = settings.effective_end_mode if last else "hold"
            steps.append(step("end", 0, 0.0, end_mode))
            progs.append(
                {
                    "number": int(number),
                    "program": {
                        "name": _json.short_name(settings.name, k + 1, len(parts), _NAME_LEN),
                        "log": False,
                        "haswaits": False,
                        "hasenables": False,
                        "gs_dev": [{"value": 3.0}],
                        "steps": steps,
                    },
                }
            )
        return _json.envelope(spec, _LIBRARY, header, progs)

    def decode(self, text: str, source: str, spec: ControllerSpec) -> Decoded:
        header, entries = _json.open_envelope(text, source, spec)
        numbers = _json.check_numbers([e["number"] for e in entries], spec, source)
        parts: list[Programme] = []
        for k, (entry, number) in enumerate(zip(entries, numbers, strict=True)):
            prog = entry["program"]
            where = f"{source}: profile {number}"
            steps = _json.get(prog, "steps", where)
            if not isinstance(steps, list):
                raise StepTableError(f"{where}: steps must be a list")
            _json.check_step_count(len(steps), spec, where)
            durations: list[float] = []
            temps: list[float] = []
            ended = None
            for i, st in enumerate(steps):
                w = f"{where} step {i + 1}"
                if ended is not None:
                    raise StepTableError(f"{w}: a step after the end step")
                kind = _json.get(st, "type", w)
                loops = _json.get(st, "loops", w)
                if not isinstance(loops, list) or not loops:
                    raise StepTableError(f"{w}: loops must be a non-empty list")
                lp = loops[0]
                if kind != "end" and _json.flag(lp, "gsoak", w):
                    raise StepTableError(
                        f"{w}: guaranteed soak is on; the planned timing holds only without it"
                    )
                if kind == "end":
                    ended = _json.get(lp, "mode", w)
                    if ended not in spec.end_modes:
                        raise StepTableError(
                            f"{w}: end mode {ended!r} is not one of {', '.join(spec.end_modes)}"
                        )
                    continue
                dur = _json.get(st, "duration", w) if kind != "ramprate" else None
                seconds = 0
                if dur is not None:
                    seconds = (
                        3600 * _json.whole(dur, "hours", w, 0, 99)
                        + 60 * _json.whole(dur, "minutes", w, 0, 59)
                        + _json.whole(dur, "seconds", w, 0, 59)
                    )
                if kind == "instant":
                    target = _json.temperature(_json.get(lp, "target", w), w, spec.temp_step_c)
                    if temps and abs(target - temps[-1]) > 1e-9:
                        raise StepTableError(
                            f"{w}: an instant step jumps the setpoint from {temps[-1]:g} to "
                            f"{target:g} °C; a chamber programme must be continuous"
                        )
                    if not temps:
                        temps.append(target)
                    if seconds > 0:
                        durations.append(seconds / 60.0)
                        temps.append(target)
                    continue
                if not temps:
                    raise StepTableError(
                        f"{w}: the profile must start with an instant step to its start "
                        "temperature (the previous setpoint is otherwise unknown)"
                    )
                if kind == "soak":
                    if seconds == 0:
                        continue
                    durations.append(seconds / 60.0)
                    temps.append(temps[-1])
                elif kind == "ramptime":
                    target = _json.temperature(_json.get(lp, "target", w), w, spec.temp_step_c)
                    if seconds == 0:
                        if abs(target - temps[-1]) > 1e-9:
                            raise StepTableError(f"{w}: a ramp of 0 s jumps the setpoint")
                        continue
                    durations.append(seconds / 60.0)
                    temps.append(target)
                elif kind == "ramprate":
                    target = _json.temperature(_json.get(lp, "target", w), w, spec.temp_step_c)
                    rate = _json.get(lp, "rate", w)
                    if isinstance(rate, bool) or not isinstance(rate, int | float) or rate <= 0:
                        raise StepTableError(f"{w}: rate must be > 0 °C/min, got {rate!r}")
                    if abs(target - temps[-1]) > 1e-9:
                        durations.append(abs(target - temps[-1]) / float(rate))
                        temps.append(target)
                else:
                    raise StepTableError(
                        f"{w}: step type {kind!r} is not read back (schedsyn writes instant, "
                        "ramptime, soak and end steps)"
                    )
            if ended is None:
                raise StepTableError(f"{where}: the profile has no end step")
            if k < len(entries) - 1 and ended != "hold":
                raise StepTableError(
                    f"{where} ends in mode {ended!r}, but a profile followed by another must "
                    "end in 'hold' so that the chamber keeps its setpoint until the next starts"
                )
            if not durations:
                raise StepTableError(f"{where}: the profile has no timed step")
            d = np.asarray(durations)
            t = np.asarray(temps)
            parts.append(Programme(d, np.diff(t) / d, float(t[0])))
        return Decoded(spec.key, numbers, tuple(parts), header)

    def notes(
        self, parts: Sequence[Programme], numbers: Sequence[int], settings: ExportSettings
    ) -> list[str]:
        out = [
            f"start Watlow F4T profile {numbers[0]} with the chamber and the device at "
            f"{parts[0].start_c:g} °C"
        ]
        t = 0.0
        for k in range(1, len(parts)):
            t += parts[k - 1].total_min
            out.append(
                f"profile {numbers[k - 1]} ends at {t:g} min holding {parts[k - 1].end_c:g} °C: "
                f"start profile {numbers[k]} at once (the F4T library links no profiles; "
                "every minute of delay is a hold the plan did not foresee)"
            )
        out.append(
            f"the last profile ends in mode {settings.effective_end_mode} at {parts[-1].end_c:g} °C"
        )
        return out + _json.name_note(settings.name, len(parts), _NAME_LEN)
