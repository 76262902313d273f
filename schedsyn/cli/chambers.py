"""``schedsyn chambers``: list the chamber presets, each figure with its source.

A preset (``schedsyn plan --chamber NAME``, ``[chamber] preset = "NAME"`` in a campaign
file, ``schedsyn split --chamber NAME``) sets the chamber's cooling and heating rates,
its floor and ceiling, and the steps one programme of its controller holds (the plan's
max_steps). Options given beside it override it. Figures marked * are assumptions (no
public datasheet found): check them against your chamber, and prefer rates measured with
your fixture inside.
"""

from __future__ import annotations

import argparse

from . import _common


def register(sub) -> None:
    p = sub.add_parser(
        "chambers",
        help="list the chamber presets (rates, floor, ceiling, step limit, sources)",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "name", nargs="?", default=None, help="show only this preset (default: all of them)"
    )
    p.add_argument(
        "--csv", default=None, metavar="FILE.csv", help="also write the table to a CSV file"
    )
    p.set_defaults(func=run)


def preset_lines(preset) -> list[str]:
    """One preset in words: its figures (assumptions starred) and their sources."""
    from ..chambers import FIGURES

    star = {f: "*" if f in preset.assumed else "" for f in FIGURES}
    lines = [
        f"{preset.name}: {preset.title}",
        f"  rates {preset.rate_min_c_per_min:g}{star['rate_min_c_per_min']} .. "
        f"+{preset.rate_max_c_per_min:g}{star['rate_max_c_per_min']} °C/min, chamber "
        f"{preset.chamber_min_c:g}{star['chamber_min_c']} .. "
        f"{preset.chamber_max_c:g}{star['chamber_max_c']} °C, at most "
        f"{preset.max_steps}{star['max_steps']} steps per programme "
        f"(controller {preset.controller})",
    ]
    lines += [f"  {figure}: {source}" for figure, source in preset.sources]
    return lines


def run(args: argparse.Namespace) -> int:
    from ..chambers import PRESETS, chamber_preset, presets_frame

    presets = [chamber_preset(args.name)] if args.name else list(PRESETS.values())
    lines: list[str] = []
    for p in presets:
        lines += [*preset_lines(p), ""]
    lines.append("* an assumption: check it against your chamber's datasheet")
    if args.csv:
        from ..io import write_frame_atomic

        frame = presets_frame()
        write_frame_atomic(args.csv, frame[frame["name"].isin([p.name for p in presets])])
        lines.append(f"wrote {args.csv}")
    _common.say(*lines)
    return 0
