"""What `schedsyn plan` and `campaign` write for the next commands: step tables that carry
their metadata, the end soak, the outputs' manifest (issue 13, items 1 and 4)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from schedsyn import Limits, ThermalParams, read_steps, simulate, trajectory_coverage
from schedsyn.cli import main
from schedsyn.io import MANIFEST

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")

SMALL = ["--working", "-10", "0", "--approx", "-20", "10", "--levels", "2", "--quiet"]


@pytest.fixture(scope="module")
def tau2000_plan(tmp_path_factory):
    """A plan made for tau 2000 s (the issue: simulated with defaults it lost coverage)."""
    out = tmp_path_factory.mktemp("plan") / "p"
    rc = main(
        ["plan", *SMALL, "--name", "T2k", "--tau-s", "2000", "--dt0-c", "2", "--out", str(out)]
    )
    return out, rc


def test_the_step_table_records_what_it_was_planned_for(tau2000_plan):
    out, rc = tau2000_plan
    plan = json.loads((out / "plan.json").read_text())
    assert rc == (0 if plan["complete"] else 1)
    meta = read_steps(out / "steps.csv").meta
    assert meta.experiment == "T2k"
    assert meta.working_region_c == (-10.0, 0.0)
    assert (meta.approx_lo_c, meta.approx_hi_c) == (-20.0, 10.0)
    assert meta.params() == ThermalParams(2000.0, 2.0)
    assert meta.levels_required == 2 and meta.delta_c_per_min == 0.05
    assert meta.limits() == Limits()
    assert meta.schedsyn_version
    # end_soak_min, checked against the first-order solution on the exported table
    prog = read_steps(out / "steps.csv")
    t_end = simulate(prog, ThermalParams(2000.0, 2.0), times_min=[prog.total_min]).t_c[0]
    excess = abs(t_end - (prog.end_c + 2.0))
    t_star = 2000.0 / 60.0 * math.log(excess / 0.5) if excess > 0.5 else 0.0
    assert meta.end_soak_min == plan["end_soak_min"]
    assert math.ceil(t_star) <= meta.end_soak_min <= math.ceil(t_star + 0.05)


def test_simulate_api_and_cli_use_the_plan_model(tau2000_plan, tmp_path, capsys):
    out, _ = tau2000_plan
    plan = json.loads((out / "plan.json").read_text())
    prog = read_steps(out / "steps.csv")
    rep = trajectory_coverage(simulate(prog), -10, 0, levels_required=2)
    assert rep.coverage == pytest.approx(plan["coverage"])  # schedsyn.simulate(programme)
    default = simulate(prog.with_meta(None))
    assert np.max(np.abs(default.t_c - simulate(prog).t_c)) > 0.5  # the model matters
    assert main(["simulate", str(out / "steps.csv"), "--out", str(tmp_path / "s")]) == 0
    text = capsys.readouterr().out
    assert f"coverage of [-10, 0] °C: {plan['coverage']:.1%}" in text
    assert "tau 2000 s, dT0 2 °C (from the step table)" in text
    assert f"needs {plan['end_soak_min']:.0f} min more" in text or plan["end_soak_min"] == 0


def test_end_soak_is_appended_and_rechecked(tmp_path, capsys):
    out = tmp_path / "soak"
    rc = main(["plan", *SMALL, "--name", "soak", "--end-soak", "--out", str(out)])
    plan = json.loads((out / "plan.json").read_text())
    assert rc == (0 if plan["complete"] else 1)
    prog = read_steps(out / "steps.csv")
    meta = prog.meta
    assert meta.end_soak_included_min > 0 and meta.end_soak_min == 0.0
    assert prog.rates_c_per_min[-1] == 0.0
    assert prog.durations_min[-1] >= meta.end_soak_included_min
    # independent check: the device ends within 0.5 degC of where it settles (20 + dT0)
    traj = simulate(prog, ThermalParams(), dt_min=0.1)
    assert abs(traj.t_c[-1] - (prog.end_c + 3.0)) <= 0.5
    # and the reported coverage is that of the soaked table
    rep = trajectory_coverage(traj, -10, 0, levels_required=2)
    assert rep.coverage == pytest.approx(plan["coverage"])
    assert rep.min_levels == plan["min_levels"]
    assert prog.total_min == pytest.approx(plan["duration_min"])
    # the soak warms the device towards 23 degC: its range is that of the soaked table
    assert plan["device_max_c"] == pytest.approx(traj.t_c.max(), abs=1e-6)
    assert plan["device_max_c"] > prog.end_c + 2.5
    text = capsys.readouterr().out
    assert "end soak already" in text or "within ±0.5 °C" in text


def test_an_end_soak_that_does_not_fit_is_a_clear_error(tmp_path, capsys):
    out = tmp_path / "nofit"
    argv = ["plan", *SMALL, "--end-soak", "--duration-max-min", "140", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--end-soak" in err and "does not fit" in err
    assert "140 min" in err
    assert "--objective informative with --end-soak" in err  # what may fit instead
    assert not out.exists()


SMALL_TOML = """
[settings]
levels_required = 2
[[experiment]]
name = "S"
working_lo_c = -10
working_hi_c = 0
approx_lo_c = -20
approx_hi_c = 10
"""


def test_campaign_tables_carry_metadata_and_a_manifest_lists_the_run(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text(SMALL_TOML)
    out = tmp_path / "out"
    (out / "OLD").mkdir(parents=True)
    rc = main(["campaign", str(cfg), "--out", str(out), "--quiet"])
    assert rc in (0, 1)
    meta = read_steps(out / "S" / "steps.csv").meta
    assert meta.experiment == "S" and meta.working_region_c == (-10.0, 0.0)
    assert meta.params() == ThermalParams()
    listed = {f["path"] for f in json.loads((out / MANIFEST).read_text())["files"]}
    want = {"summary.csv"} | {f"S/{n}" for n in ("steps.csv", "plan.json", "program.png")}
    assert want <= listed and not any(p.startswith("OLD") for p in listed)
    assert "end: the chamber ends at" in capsys.readouterr().out


def test_campaign_end_soak_that_does_not_fit_is_reported_and_exit_1(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[limits]\nduration_max_min = 140\n" + SMALL_TOML)
    out = tmp_path / "out"
    rc = main(["campaign", str(cfg), "--out", str(out), "--end-soak", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 1
    assert "*** S: --end-soak: the end soak of" in text and "WITHOUT an end soak" in text
    assert "no end soak fits in S" in text
    prog = read_steps(out / "S" / "steps.csv")
    assert prog.meta.end_soak_included_min is None and prog.meta.end_soak_min > 0
    assert prog.total_min <= 140
