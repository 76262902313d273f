"""Data the package needs at run time lives inside it (so a wheel carries it).

The wheel itself is built, installed into a fresh venv and run by scripts/check_wheel.sh
(in CI); these tests catch the usual slips without building anything.
"""

import fnmatch
import tomllib
from pathlib import Path

import pytest

import schedsyn
from schedsyn.campaign import (
    PAPER_BASELINE_EXP1,
    PAPER_CAMPAIGN_TOML,
    default_campaign,
    load_campaign,
    package_data,
)
from schedsyn.errors import SchedsynError

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(schedsyn.__file__).resolve().parent
PACKAGED = sorted(p for p in (PACKAGE / "data").iterdir() if p.is_file())


def test_default_campaign_files_are_inside_the_package():
    for path in (PAPER_CAMPAIGN_TOML, PAPER_BASELINE_EXP1):
        assert path.is_file()
        assert path.parent == PACKAGE / "data", path
    assert default_campaign().baseline_for(0) == PAPER_BASELINE_EXP1
    # the shipped TOML names the shipped baseline (relative to itself)
    assert load_campaign(PAPER_CAMPAIGN_TOML).baseline_for(0) == PAPER_BASELINE_EXP1


@pytest.mark.parametrize("path", PACKAGED, ids=lambda p: p.name)
def test_repository_copies_are_identical(path):
    """data/ keeps copies for the README examples and scripts: they must not drift."""
    copy = ROOT / "data" / path.name
    assert copy.is_file(), f"{copy} is missing (README and scripts use it)"
    assert copy.read_bytes() == path.read_bytes(), f"{copy} differs from {path}"


def test_package_data_patterns_match_every_shipped_file():
    """pyproject's package-data must select each file in schedsyn/data (and only data)."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = conf["tool"]["setuptools"]["package-data"]["schedsyn"]
    assert PACKAGED, "schedsyn/data is empty"
    for path in PACKAGED:
        rel = path.relative_to(PACKAGE).as_posix()
        assert any(fnmatch.fnmatch(rel, pat) for pat in patterns), (rel, patterns)


def test_a_missing_data_file_is_named():
    with pytest.raises(SchedsynError, match="no_such_file.csv"):
        package_data("no_such_file.csv")


def test_real_logs_the_tests_use_are_in_the_repository_with_their_licence():
    """The TCLab logs live in tests/data/tclab (BSD-3-Clause, attributed): a fresh clone
    runs the real-data tests instead of skipping them."""
    tclab = ROOT / "tests" / "data" / "tclab"
    licence = (tclab / "LICENSE").read_text(encoding="utf-8")
    assert licence.startswith("BSD 3-Clause License") and "Alexander Dowling" in licence
    readme = (tclab / "README.md").read_text(encoding="utf-8")
    assert "dowlinglab/pyomo-doe" in readme and "LICENSE" in readme
    used = [
        *(f"validation_experiment_env_2_step_50_run_{i}.csv" for i in (1, 2, 3)),
        "validation_experiment_env_2_sin_5_50_run_1.csv",
    ]
    for name in used:
        assert (tclab / name).stat().st_size > 10_000, name


def test_examples_command_writes_the_shipped_example_files(tmp_path, capsys):
    """A wheel user has no data/ folder: `schedsyn examples` writes the files the docs'
    examples use (red team: example_gyro.toml and sample_run_exp1.csv were not in the
    wheel), byte for byte the repository's copies."""
    from schedsyn.cli import main
    from schedsyn.cli.examples import EXAMPLE_FILES

    assert main(["examples", "--out", str(tmp_path / "ex")]) == 0
    for name in EXAMPLE_FILES:
        assert (tmp_path / "ex" / name).read_bytes() == (ROOT / "data" / name).read_bytes()
    assert "paper_campaign.toml" in capsys.readouterr().out
    assert main(["--version"]) == 0
    assert schedsyn.__version__ in capsys.readouterr().out


def test_a_copy_of_the_paper_campaign_elsewhere_finds_its_baseline(tmp_path):
    """The README's "a copy of data/paper_campaign.toml" failed anywhere but in data/
    (baseline_steps is relative to the campaign file): a shipped table's name falls back
    to the package's copy; any other missing table says where it was looked for and how
    to fix it."""
    from schedsyn.errors import ParameterError

    copy = tmp_path / "copy.toml"
    copy.write_text(PAPER_CAMPAIGN_TOML.read_text(encoding="utf-8"), encoding="utf-8")
    assert load_campaign(copy).baseline_for(0) == PAPER_BASELINE_EXP1
    text = PAPER_CAMPAIGN_TOML.read_text(encoding="utf-8")
    other = tmp_path / "other.toml"
    other.write_text(text.replace("baseline_exp1_steps.csv", "mine.csv"), encoding="utf-8")
    with pytest.raises(ParameterError, match="copy the table beside the campaign file"):
        load_campaign(other)
