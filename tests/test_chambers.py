"""Chamber presets: each sets exactly its figures, explicit settings override it, every
figure names a source, and the step limit fits one programme of the preset's controller."""

from __future__ import annotations

import dataclasses
import json

import pytest

from schedsyn.campaign import campaign_from_dict
from schedsyn.chambers import (
    FIGURES,
    LIMIT_FIELDS,
    PRESETS,
    chamber_preset,
    limits_with_preset,
    presets_frame,
)
from schedsyn.cli import main
from schedsyn.errors import ParameterError
from schedsyn.export import controller_spec
from schedsyn.params import Limits

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")

# figures written out here, independently of the module, for the paper's chamber and the
# Binder MB-series step limit the issue names (100 segments, one the closing segment)
EXPECTED = {
    "espec-set-z-032u": (-1.0, 3.0, -70.0, 80.0, 99),
    "binder-mk-56": (-2.0, 3.0, -40.0, 180.0, 99),
}


def _doc(chamber=None, limits=None, settings=None, experiment_extra=None):
    doc = {
        "experiment": [
            {
                "name": "E",
                "working_lo_c": 10.0,
                "working_hi_c": 16.0,
                "approx_lo_c": 0.0,
                "approx_hi_c": 26.0,
                **(experiment_extra or {}),
            }
        ]
    }
    for key, table in (("chamber", chamber), ("limits", limits), ("settings", settings)):
        if table is not None:
            doc[key] = table
    return doc


@pytest.mark.parametrize("name", list(PRESETS))
def test_a_preset_sets_exactly_its_four_limits_and_nothing_else(name):
    preset = PRESETS[name]
    base = dataclasses.replace(Limits(), duration_max_min=333.0, device_min_c=-45.0)
    lim = preset.limits(base)
    for f in dataclasses.fields(Limits):
        want = getattr(preset, f.name) if f.name in LIMIT_FIELDS else getattr(base, f.name)
        assert getattr(lim, f.name) == want, f.name


@pytest.mark.parametrize("name, figures", EXPECTED.items())
def test_preset_figures_as_documented(name, figures):
    p = chamber_preset(name)
    assert (*[getattr(p, f) for f in LIMIT_FIELDS], p.max_steps) == figures


@pytest.mark.parametrize("name", list(PRESETS))
def test_every_figure_names_a_source_and_the_step_limit_fits_one_programme(name):
    p = PRESETS[name]
    sources = dict(p.sources)
    assert set(sources) == set(FIGURES)
    assert all(len(s) > 20 for s in sources.values())
    spec = controller_spec(p.controller)
    if spec.max_steps is not None:  # one programme holds the whole plan
        assert p.max_steps <= spec.max_steps - spec.reserved_steps
    if p.controller == "binder-mb":  # the issue: Binder MB programmes take <= 100 segments
        assert p.max_steps + spec.reserved_steps == 100


def test_names_are_case_insensitive_and_unknown_names_list_the_known_ones():
    assert chamber_preset(" Binder-MK-56 ") is PRESETS["binder-mk-56"]
    with pytest.raises(ParameterError, match="espec-set-z-032u") as exc:
        chamber_preset("espec-sh-999")
    assert "\n" not in str(exc.value)


def test_explicit_values_override_the_preset():
    lim = limits_with_preset("binder-mk-56", chamber_min_c=-45.0, rate_max_c_per_min=None)
    assert lim.chamber_min_c == -45.0  # explicit
    assert lim.rate_max_c_per_min == 3.0  # the preset's (None: not given)
    assert lim.chamber_max_c == 180.0
    with pytest.raises(ParameterError, match="chamber_min_c must be < chamber_max_c"):
        limits_with_preset("binder-mk-56", chamber_min_c=200.0)


def test_campaign_chamber_table_sets_limits_and_max_steps():
    cfg = campaign_from_dict(_doc(chamber={"preset": "binder-mk-56"}))
    p = PRESETS["binder-mk-56"]
    assert cfg.limits == p.limits(Limits())
    assert cfg.experiments[0].max_steps == p.max_steps


def test_campaign_limits_and_settings_keys_override_the_preset():
    cfg = campaign_from_dict(
        _doc(
            chamber={"preset": "binder-mk-56"},
            limits={"chamber_min_c": -38.0, "duration_max_min": 400.0},
            settings={"max_steps": 60},
        )
    )
    assert cfg.limits.chamber_min_c == -38.0  # [limits] wins
    assert cfg.limits.chamber_max_c == 180.0  # the preset's
    assert cfg.limits.rate_min_c_per_min == -2.0
    assert cfg.limits.duration_max_min == 400.0
    assert cfg.experiments[0].max_steps == 60  # [settings] wins
    cfg = campaign_from_dict(
        _doc(chamber={"preset": "binder-mk-56"}, experiment_extra={"max_steps": 40})
    )
    assert cfg.experiments[0].max_steps == 40  # the experiment's own key wins


def test_without_a_preset_nothing_changes():
    cfg = campaign_from_dict(_doc())
    assert cfg.limits == Limits()
    assert cfg.experiments[0].max_steps == 80


@pytest.mark.parametrize(
    "chamber, words",
    [
        ({"preset": "nope"}, ["[chamber]", "unknown chamber preset 'nope'"]),
        ({"preset": 3}, ["[chamber] preset must be a preset name"]),
        ({"name": "binder-mk-56"}, ["[chamber]", "unknown key(s) ['name']"]),
    ],
)
def test_campaign_chamber_table_bad_input_is_one_line(chamber, words):
    with pytest.raises(ParameterError) as exc:
        campaign_from_dict(_doc(chamber=chamber), "my.toml")
    text = str(exc.value)
    assert "\n" not in text and "my.toml" in text
    for w in words:
        assert w in text


def test_chambers_command_lists_every_preset_with_sources(tmp_path, capsys):
    csv = tmp_path / "chambers.csv"
    assert main(["chambers", "--csv", str(csv)]) == 0
    out = capsys.readouterr().out
    for name, p in PRESETS.items():
        assert f"{name}: {p.title}" in out
        for figure, source in p.sources:
            assert f"  {figure}: {source}" in out
    # the paper's figures are not assumptions, the default floor is
    head = "  rates -1 .. +3 °C/min, chamber -70*"
    line = next(x for x in out.splitlines() if x.startswith(head))
    assert "99*" in line
    frame = presets_frame()
    assert csv.read_text(encoding="utf-8").count("\n") == len(frame) + 1
    assert main(["chambers", "nope"]) == 2


def test_plan_with_a_chamber_preset_records_its_limits_and_overrides(tmp_path, capsys):
    out = tmp_path / "p"
    rc = main(
        [
            "plan",
            "--working", "12", "16",
            "--levels", "2",
            "--chamber", "binder-mk-56",
            "--chamber-max-c", "150",
            "--rate-min-c-per-min", "-1.5",
            "--duration-max-min", "300",
            "--out", str(out),
            "--quiet",
        ]
    )  # fmt: skip
    assert rc in (0, 1)
    capsys.readouterr()
    doc = json.loads((out / "plan.json").read_text(encoding="utf-8"))
    lim = doc["limits"]
    assert lim["chamber_min_c"] == -40.0  # the preset's
    assert lim["chamber_max_c"] == 150.0  # explicit
    assert lim["rate_min_c_per_min"] == -1.5  # explicit
    assert lim["rate_max_c_per_min"] == 3.0  # the preset's
    assert lim["duration_max_min"] == 300.0
    assert lim["device_min_c"] == Limits().device_min_c  # not the chamber's business
    assert doc["spec"]["max_steps"] == PRESETS["binder-mk-56"].max_steps
    # and an explicit --max-steps wins
    rc = main(
        [
            "plan", "--working", "12", "16", "--levels", "2", "--chamber", "binder-mk-56",
            "--max-steps", "50", "--out", str(tmp_path / "q"), "--quiet",
        ]
    )  # fmt: skip
    assert rc in (0, 1)
    doc = json.loads((tmp_path / "q" / "plan.json").read_text(encoding="utf-8"))
    assert doc["spec"]["max_steps"] == 50
