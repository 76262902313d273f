"""``schedsyn examples``: write the example files that ship with schedsyn into a folder.

The README's and the docs' examples use them as ``data/<file>`` of a checkout; an
installed schedsyn (a wheel) carries the same files inside the package. This writes
copies to edit and run:

* ``paper_campaign.toml``: the paper's four experiments W1-W4 (``schedsyn campaign``);
* ``baseline_exp1_steps.csv``: the paper-like baseline of experiment 1 it names;
* ``example_gyro.toml``: a synthetic gyro's drift (``simulate --gyro``, ``fit``);
* ``sample_run_exp1.csv``: a synthetic measured log of that baseline (``estimate``,
  ``compare``, ``diagnose``).
"""

from __future__ import annotations

import argparse
import shutil

from . import _common

#: The example files, in the order they are listed.
EXAMPLE_FILES = (
    "paper_campaign.toml",
    "baseline_exp1_steps.csv",
    "example_gyro.toml",
    "sample_run_exp1.csv",
)


def register(sub) -> None:
    p = sub.add_parser(
        "examples",
        help="write the example files (campaign, baseline, gyro, sample log) into a folder",
        description=_common.plain(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--out", default="schedsyn-examples", help="folder to write (default: schedsyn-examples)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..campaign import package_data
    from ..io import OutputDir

    out = OutputDir(args.out)
    out.check(EXAMPLE_FILES)
    for name in EXAMPLE_FILES:
        shutil.copyfile(package_data(name), out.path(name))
    out.commit()
    _common.say(
        f"wrote {out.target}/" + ", ".join(EXAMPLE_FILES),
        f"e.g. schedsyn campaign {out.target}/paper_campaign.toml --out out/campaign",
    )
    return 0
