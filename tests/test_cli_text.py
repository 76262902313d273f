"""What the command line prints: help without raw markup, one spelling of units, the
findings of diagnose in words (issue 13: "Answers that mislead", "Help texts show raw
markup; output mixes °C and degC")."""

from __future__ import annotations

import re

import pytest

from schedsyn.cli import COMMANDS, build_parser, main
from schedsyn.cli._common import plain, units_text

STEPS = "data/baseline_exp1_steps.csv"
SAMPLE = "data/sample_run_exp1.csv"
MARKUP = re.compile(r"`|:(?:func|class|mod|meth|data):|\bdegC\b")


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_has_no_raw_markup(command, capsys):
    argv = ["--help"] if command is None else [command, "--help"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert text.strip()
    bad = sorted({m.group(0) for m in MARKUP.finditer(text)})
    assert not bad, f"raw markup {bad} in the help of {command}:\n{text}"


def test_every_option_says_what_it_is():
    """Each option of each subcommand has a help text (argparse would show none)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        for action in p._actions:
            if action.dest in ("help",) or action.help == "==SUPPRESS==":
                continue
            assert action.help, f"{name} {action.option_strings or action.dest}"


def test_units_text_and_plain():
    assert units_text("[-50, -30] degC at 0.05 degC/min, 1 .. 3 C/min") == (
        "[-50, -30] °C at 0.05 °C/min, 1 .. 3 °C/min"
    )
    assert units_text("already 3 °C/min and 20 deg C") == "already 3 °C/min and 20 °C"
    assert plain("see :func:`schedsyn.simulate.simulate` and ``--region``") == (
        "see simulate and --region"
    )


def _assert_one_spelling(text: str) -> None:
    assert "degC" not in text and "deg C" not in text, text
    assert not re.search(r"(?<![°\w])C/min", text), text


def test_outputs_of_every_quick_command_spell_units_one_way(tmp_path, capsys):
    runs = [
        ["simulate", STEPS, "--region", "-50", "-30", "--out", str(tmp_path / "s")],
        [
            "sweep",
            STEPS,
            "--region",
            "-50",
            "-30",
            "--tau-s",
            "2000:2800:3",
            "--dt0-c",
            "0:6:3",
            "--workers",
            "1",
            "--out",
            str(tmp_path / "w"),
        ],
        ["estimate", SAMPLE, "--out", str(tmp_path / "e")],
        ["compare", SAMPLE, STEPS, "--region", "-50", "-30", "--out", str(tmp_path / "c")],
        ["simulate", STEPS, "--out", str(tmp_path / "x")],  # an error message
    ]
    for argv in runs:
        main(argv)
        captured = capsys.readouterr()
        _assert_one_spelling(captured.out + captured.err)


def test_a_planner_error_is_spelt_the_same_way(tmp_path, capsys):
    argv = ["plan", "--working", "-10", "-8", "--approx", "-20", "0", "--levels", "2"]
    argv += ["--duration-max-min", "20", "--out", str(tmp_path / "o"), "--quiet"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "best reachable coverage" in err
    _assert_one_spelling(err)


@pytest.mark.slow
def test_diagnose_prints_the_fitted_model_and_the_effect(tmp_path, capsys):
    """The sample run is a device with tau 2700 s and dT0 2 °C (data/README.md)."""
    assert main(["diagnose", SAMPLE, "--out", str(tmp_path / "d"), "--no-plots"]) == 0
    text = capsys.readouterr().out
    _assert_one_spelling(text)
    m = re.search(r"fitted device model: tau ([0-9.]+) ± ([0-9.e-]+) s, dT0 ([-0-9.]+) ±", text)
    assert m, text
    tau, tau_se, dt0 = float(m.group(1)), float(m.group(2)), float(m.group(3))
    import json

    js = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert tau == pytest.approx(js["model"]["tau_s"], abs=0.05)
    assert dt0 == pytest.approx(js["model"]["dt0_c"], abs=5e-4)
    assert tau_se == pytest.approx(js["uncertainty"]["tau_s"], rel=0.05)
    assert abs(tau - 2700.0) < 100.0 and abs(dt0 - 2.0) < 0.5  # the synthetic truth
    assert re.search(r"^effect: ", text, re.M)
