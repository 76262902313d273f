"""Argument helpers shared by the subcommands (units in every option name)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from ..errors import ParameterError
from ..params import Limits, ThermalParams


def add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--tau-s", type=float, default=None, help="device time constant, s (default 2400)"
    )
    p.add_argument(
        "--dt0-c",
        type=float,
        default=None,
        help="self-heating offset, °C (default 3.0, an assumption)",
    )


def thermal_params(args: argparse.Namespace, base: ThermalParams | None = None) -> ThermalParams:
    base = ThermalParams() if base is None else base
    changes = {k: v for k, v in (("tau_s", args.tau_s), ("dt0_c", args.dt0_c)) if v is not None}
    return dataclasses.replace(base, **changes)


def add_region_option(
    p: argparse.ArgumentParser,
    default=(-50.0, -30.0),
    name="--region",
    help_text="working region LO HI, °C",
) -> None:
    p.add_argument(
        name,
        nargs=2,
        type=float,
        metavar=("LO_C", "HI_C"),
        default=list(default),
        help=f"{help_text} (default {default[0]:g} {default[1]:g})",
    )


def add_limit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--chamber-min-c", type=float, default=None, help="chamber air floor, °C (default -70)"
    )
    p.add_argument(
        "--chamber-max-c", type=float, default=None, help="chamber air ceiling, °C (default 80)"
    )


def limits(args: argparse.Namespace, base: Limits | None = None) -> Limits:
    base = Limits() if base is None else base
    changes = {
        k: getattr(args, k)
        for k in ("chamber_min_c", "chamber_max_c")
        if getattr(args, k, None) is not None
    }
    return dataclasses.replace(base, **changes)


def out_dir(path: str | None, default: str) -> Path:
    out = Path(path if path is not None else default)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out} exists and is not a directory")
    return out
