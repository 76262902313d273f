"""Argument helpers shared by the subcommands (units in every option name), the one way
to print results, and where the region and model come from."""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from pathlib import Path

from ..errors import ParameterError
from ..io import OutputDir
from ..params import Limits, ThermalParams
from ..progress import Progress

# ---------------------------------------------------------------------------------------
# text: one spelling of units, no markup in help
# ---------------------------------------------------------------------------------------
_DEG_C = re.compile(r"\bdeg\s?C\b")
_BARE_C_PER_MIN = re.compile(r"(?<![°\w])C/min\b")


def units_text(text: str) -> str:
    """User-facing text with one spelling of units: ``degC`` -> ``°C``, ``C/min`` ->
    ``°C/min``. (Docstrings and messages of the library may say degC; what the command
    line prints never does.)"""
    return _BARE_C_PER_MIN.sub("°C/min", _DEG_C.sub("°C", text))


def say(*lines: str) -> None:
    """Print result lines to stdout (units spelt one way)."""
    for line in lines:
        print(units_text(str(line)))


def plain(doc: str | None) -> str:
    """A docstring as plain help text: no reST markup (``x``, :func:`y`), units as °C."""
    text = doc or ""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", lambda m: m.group(1).split(".")[-1], text)
    text = text.replace("``", "").replace("`", "")
    return units_text(text)


def add_quiet_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress on stderr (results and errors are still printed)",
    )


def progress_of(args: argparse.Namespace) -> Progress:
    """The run's progress reporter: off with ``--quiet``."""
    return Progress(enabled=not getattr(args, "quiet", False))


# ---------------------------------------------------------------------------------------
# model, region, limits
# ---------------------------------------------------------------------------------------
def add_model_options(p: argparse.ArgumentParser, default_from: str = "") -> None:
    where = f"{default_from}, else " if default_from else ""
    p.add_argument(
        "--tau-s", type=float, default=None, help=f"device time constant, s (default: {where}2400)"
    )
    p.add_argument(
        "--dt0-c",
        type=float,
        default=None,
        help=f"self-heating offset, °C (default: {where}3.0, an assumption)",
    )


def thermal_params(args: argparse.Namespace, base: ThermalParams | None = None) -> ThermalParams:
    base = ThermalParams() if base is None else base
    changes = {k: v for k, v in (("tau_s", args.tau_s), ("dt0_c", args.dt0_c)) if v is not None}
    return dataclasses.replace(base, **changes)


def model_from_table(
    args: argparse.Namespace,
    meta,
    names: tuple[str, str] = ("tau_s", "dt0_c"),
    table: bool = True,
) -> tuple[ThermalParams, str]:
    """``(params, where they come from)``: the options over the step table's recorded model,
    else the defaults (said so: "default").

    ``names``: the ``args`` attributes of the tau and dT0 options (``--tau-s``,
    ``--dt0-c`` by default); ``table``: whether there is a step table at all (without one
    the defaults are just "default").
    """
    recorded = meta.params() if meta is not None else None
    given = {
        k: getattr(args, name)
        for k, name in zip(("tau_s", "dt0_c"), names, strict=True)
        if getattr(args, name) is not None
    }
    params = dataclasses.replace(ThermalParams() if recorded is None else recorded, **given)
    if len(given) == 2:
        source = "given"
    elif recorded is not None:
        source = "from the step table" + (" and the options" if given else "")
    elif given:
        source = "default and the options"
    else:
        source = "default" + ("; the step table records none" if table else "")
    return params, source


def augmented_model(model_path: str | None, meta, steps: str | None):
    """``(ModelSpec or None, where it comes from)``: the ``--model`` file, else the
    augmented model the step table records (``schedsyn plan --model`` writes it), else
    none."""
    from ..effects import ModelSpec
    from ..errors import SchedsynError, StepTableError
    from ..models_io import load_model

    if model_path is not None:
        return load_model(model_path), model_path
    recorded = meta.model_json() if meta is not None else None
    if recorded is None:
        return None, None
    try:
        return ModelSpec.from_json_dict(recorded), "the step table"
    except SchedsynError as exc:
        raise StepTableError(f"{steps}: metadata model: {exc}") from None


def add_region_option(
    p: argparse.ArgumentParser,
    name: str = "--region",
    help_text: str = "working region LO HI, °C (default: the one the step table records)",
) -> None:
    p.add_argument(
        name, nargs=2, type=float, metavar=("LO_C", "HI_C"), default=None, help=help_text
    )


def region_from_table(args: argparse.Namespace, meta, steps: str) -> tuple[float, float]:
    """The working region: ``--region`` if given, else the step table's; never a guess."""
    if args.region is not None:
        return float(args.region[0]), float(args.region[1])
    region = meta.working_region_c if meta is not None else None
    if region is None:
        raise ParameterError(
            f"{steps} carries no working region; give --region LO HI (°C), e.g. "
            "--region -50 -30 for the paper's W1"
        )
    return region


def add_limit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--chamber-min-c",
        type=float,
        default=None,
        help="chamber air floor, °C (default: the step table's, else -70)",
    )
    p.add_argument(
        "--chamber-max-c",
        type=float,
        default=None,
        help="chamber air ceiling, °C (default: the step table's, else 80)",
    )


def add_device_options(p: argparse.ArgumentParser) -> None:
    """The device's own temperature limits (its rating): the planner keeps the internal
    temperature within them."""
    p.add_argument(
        "--device-min-c",
        type=float,
        default=None,
        help="lowest internal temperature the device may reach, °C (default -52)",
    )
    p.add_argument(
        "--device-max-c",
        type=float,
        default=None,
        help="highest internal temperature the device may reach, °C (default 62)",
    )


def device_limits(args: argparse.Namespace, base: Limits) -> Limits:
    """``base`` with ``--device-min-c`` / ``--device-max-c`` where given."""
    changes = {
        k: getattr(args, k)
        for k in ("device_min_c", "device_max_c")
        if getattr(args, k, None) is not None
    }
    return dataclasses.replace(base, **changes)


def limits(args: argparse.Namespace, base: Limits | None = None) -> Limits:
    base = Limits() if base is None else base
    changes = {
        k: getattr(args, k)
        for k in ("chamber_min_c", "chamber_max_c")
        if getattr(args, k, None) is not None
    }
    return device_limits(args, dataclasses.replace(base, **changes))


# ---------------------------------------------------------------------------------------
# outputs
# ---------------------------------------------------------------------------------------
def out_dir(path: str | None, default: str) -> Path:
    out = Path(path if path is not None else default)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out} exists and is not a directory")
    return out


#: Output folders of the running command; :func:`discard_uncommitted` cleans up after a
#: command that failed before committing them.
_OPEN: list[OutputDir] = []


def output_dir(path: str | None, default: str, inputs=(), names=()) -> OutputDir:
    """The run's :class:`~schedsyn.io.OutputDir`, checked (inputs vs outputs, writable).

    Call it before any long work; ``names`` are the files the command will write.
    """
    out = OutputDir(path if path is not None else default, inputs)
    _OPEN.append(out)
    out.check(names)
    return out


def discard_uncommitted() -> None:
    """Remove the staged outputs of every output folder the command did not commit."""
    while _OPEN:
        _OPEN.pop().discard()


def stderr(message: str) -> None:
    """A note on stderr (units spelt one way)."""
    print(units_text(message), file=sys.stderr)


def log_record(log) -> dict:
    """What the output JSON says about the log's readings: warnings, the glitch readings
    excluded (``LogReport.glitches``; rows 1-based like the messages), the runs of a
    held reading whose repeats were excluded (``LogReport.stuck_s``) and the runs that
    jumped off the curve and back (``LogReport.excursions_s``)."""
    return {
        "source": log.source,
        "warnings": list(log.report.warnings),
        "excluded_glitches": [
            {"row": row + 1, "time_s": t_s, "t_int_c": value_c, "off_c": off_c}
            for row, t_s, value_c, off_c in log.report.glitches
        ],
        "excluded_held_readings": [
            {"start_s": a, "end_s": b, "t_int_c": value_c, "jump_c": jump_c}
            for a, b, value_c, jump_c in log.report.stuck_s
        ],
        "excluded_excursions": [
            {"start_s": a, "end_s": b, "n_rows": k, "off_c": off_c}
            for a, b, k, off_c in log.report.excursions_s
        ],
    }


def log_warnings(log) -> None:
    """The log's suspicious readings (``LogReport.warnings``) on stderr, one line each."""
    for w in log.report.warnings:
        stderr(f"warning: {log.source}: {w}")


def add_coverage_options(p: argparse.ArgumentParser) -> None:
    """``--levels`` and ``--delta-c-per-min``, by default the step table's (else 6, 0.05)."""
    p.add_argument(
        "--levels",
        type=int,
        default=None,
        help="required distinct gradient levels (default: the step table's, else 6)",
    )
    p.add_argument(
        "--delta-c-per-min",
        type=float,
        default=None,
        help="minimum gradient difference between levels, °C/min (default: the step "
        "table's, else 0.05)",
    )


def coverage_settings(args: argparse.Namespace, meta) -> tuple[int, float]:
    """``(levels_required, delta_c_per_min)``: the options, else the table's, else 6, 0.05."""
    (levels, _), (delta, _) = coverage_sources(args.levels, args.delta_c_per_min, meta)
    return levels, delta


def coverage_sources(
    levels: int | None, delta_c_per_min: float | None, meta
) -> tuple[tuple[int, str], tuple[float, str]]:
    """``((levels_required, where from), (delta_c_per_min, where from))``: the given
    value (``"given"``), else the step table's (``"from the step table"``), else 6 and
    0.05 °C/min (``"default"``)."""

    def pick(value, recorded, default):
        if value is not None:
            return value, "given"
        if recorded:
            return recorded, "from the step table"
        return default, "default"

    lv, lv_src = pick(levels, meta.levels_required if meta is not None else None, 6)
    dv, dv_src = pick(delta_c_per_min, meta.delta_c_per_min if meta is not None else None, 0.05)
    return (int(lv), lv_src), (float(dv), dv_src)


def end_soak_text(programme, t_end_c: float, soak_min: float, settled_c: float, limits) -> str:
    """What the operator should know about the end: where the device is, how long to hold."""
    included = programme.meta.end_soak_included_min if programme.meta is not None else None
    head = f"end: the chamber ends at {programme.end_c:.1f} °C and the device at {t_end_c:.1f} °C"
    if soak_min <= 0:
        return head + f", within ±{limits.end_tol_c:g} °C of where it settles ({settled_c:.1f} °C)"
    text = (
        f"{head}; it needs {soak_min:.0f} min more at {programme.end_c:.1f} °C to come within "
        f"±{limits.end_tol_c:g} °C of where it settles ({settled_c:.1f} °C)"
    )
    if included:
        text += f" (the table's last {included:.0f} min are an end soak already)"
    else:
        text += "; add it to the table with --end-soak (plan, campaign)"
    return text
