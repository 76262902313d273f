"""Shared helpers of the controller codecs: the JSON envelope and strict field checks."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from ..errors import StepTableError
from ..export import ControllerSpec

FORMAT = "schedsyn controller programmes, version 1"


def envelope(
    spec: ControllerSpec, library: str, header: Mapping[str, Any], programmes: list[dict]
) -> str:
    """The JSON file: what it is, for which controller, how to load it, the programmes."""
    doc = {
        "format": FORMAT,
        "controller": spec.key,
        "controller_title": spec.title,
        "load_with": library,
        "schedsyn": dict(header),
        "programmes": programmes,
    }
    return json.dumps(doc, indent=1, ensure_ascii=False) + "\n"


def open_envelope(text: str, source: str, spec: ControllerSpec) -> tuple[dict, list[dict]]:
    """Parse an export JSON and return ``(header, programmes)``; each programme entry is
    ``{"number": int, "program": dict}``."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StepTableError(f"{source}: not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise StepTableError(f"{source}: the JSON must be an object with 'programmes'")
    if doc.get("controller") != spec.key:
        raise StepTableError(
            f"{source}: written for controller {doc.get('controller')!r}, not {spec.key!r}"
        )
    progs = doc.get("programmes")
    if not isinstance(progs, list) or not progs:
        raise StepTableError(f"{source}: 'programmes' must be a non-empty list")
    for k, entry in enumerate(progs, start=1):
        if not isinstance(entry, dict) or "number" not in entry or "program" not in entry:
            raise StepTableError(
                f"{source}: programmes entry {k} must be {{'number': N, 'program': {{...}}}}"
            )
        if not isinstance(entry["program"], dict):
            raise StepTableError(f"{source}: programmes entry {k}: 'program' must be an object")
    header = doc.get("schedsyn", {})
    return (header if isinstance(header, dict) else {}), progs


def check_numbers(numbers: Sequence[Any], spec: ControllerSpec, source: str) -> tuple[int, ...]:
    """Programme numbers: whole, distinct, within what the controller stores."""
    out = []
    last = None if spec.programmes is None else spec.first_number + spec.programmes - 1
    for n in numbers:
        if isinstance(n, bool) or not isinstance(n, int):
            raise StepTableError(f"{source}: programme number {n!r} is not a whole number")
        if n < spec.first_number or (last is not None and n > last):
            raise StepTableError(
                f"{source}: programme number {n} is outside {spec.title}'s programmes "
                f"{spec.first_number}..{last}"
            )
        out.append(n)
    dup = sorted({n for n in out if out.count(n) > 1})
    if dup:
        raise StepTableError(f"{source}: programme number(s) {dup} appear more than once")
    return tuple(out)


def check_step_count(n: int, spec: ControllerSpec, where: str) -> None:
    if spec.max_steps is not None and n > spec.max_steps:
        raise StepTableError(
            f"{where}: {n} steps, more than the {spec.max_steps} one {spec.title} "
            "programme holds; split it into chained programmes"
        )
    if n == 0:
        raise StepTableError(f"{where}: the programme has no steps")


def get(d: Mapping[str, Any], key: str, where: str) -> Any:
    if not isinstance(d, Mapping) or key not in d:
        raise StepTableError(f"{where}: missing key {key!r}")
    return d[key]


def whole(d: Mapping[str, Any], key: str, where: str, lo: int = 0, hi: int | None = None) -> int:
    v = get(d, key, where)
    if isinstance(v, bool) or not isinstance(v, int):
        raise StepTableError(f"{where}: {key} must be a whole number, got {v!r}")
    if v < lo or (hi is not None and v > hi):
        rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise StepTableError(f"{where}: {key} {v} is outside {rng}")
    return v


def flag(d: Mapping[str, Any], key: str, where: str) -> bool:
    v = get(d, key, where)
    if not isinstance(v, bool):
        raise StepTableError(f"{where}: {key} must be true or false, got {v!r}")
    return v


def temperature(v: Any, where: str, step_c: float) -> float:
    """A setpoint: a finite number on the controller's grid (e.g. 0.1 degC)."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise StepTableError(f"{where}: setpoint must be a number, got {v!r}")
    k = v / step_c
    if abs(k - round(k)) > 1e-6:
        raise StepTableError(
            f"{where}: setpoint {v!r} °C is finer than the controller's {step_c:g} °C"
        )
    return round(round(k) * step_c, 6)


def short_name(base: str, k: int, n: int, max_len: int) -> str:
    """Programme name: ``base`` (or ``base-k`` for part k of n) within ``max_len`` chars."""
    base = re.sub(r"[^A-Za-z0-9_\-]", "_", base)
    suffix = f"-{k}" if n > 1 else ""
    return base[: max(1, max_len - len(suffix))] + suffix


def name_note(base: str, n: int, max_len: int) -> list[str]:
    """A note when the name written (:func:`short_name`) is not the one given: cut to
    ``max_len`` characters or with characters replaced (red team: cut without a word)."""
    written = short_name(base, 1, n, max_len)
    if written == (f"{base}-1" if n > 1 else base):
        return []
    return [
        f"the programme name {base!r} is written as {written!r} (at most {max_len} "
        "characters: letters, digits, _ and -)"
    ]
