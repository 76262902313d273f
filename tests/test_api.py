import os
import subprocess
import sys
import tomllib
from pathlib import Path

import schedsyn

ROOT = Path(__file__).resolve().parents[1]

#: The public API, on purpose: what a user plans, simulates, measures and diagnoses with.
#: Test fixtures (schedsyn.synth.blind_case, synth_effect_log), CLI parsers
#: (schedsyn.sweep.parse_grid, parse_range) and the parallel-map helper
#: (schedsyn.sweep.run_map) stay importable from their modules, not from here.
PUBLIC = {
    # parameters and errors
    "ThermalParams",
    "Limits",
    "SchedsynError",
    "ParameterError",
    "StepTableError",
    "LogFormatError",
    "InfeasiblePlanError",
    "SolverFailedError",
    # model and simulation
    "FirstOrderLag",
    "AffineResponse",
    "affine_response",
    "Programme",
    "read_steps",
    "programme_from_frame",
    "Trajectory",
    "simulate",
    # coverage
    "BinGrid",
    "CoverageReport",
    "coverage_report",
    "trajectory_coverage",
    # planning and campaigns
    "ExperimentSpec",
    "Plan",
    "plan_experiment",
    "check_programme",
    "robustness_price",
    "CampaignConfig",
    "CampaignResult",
    "default_campaign",
    "load_campaign",
    "plan_campaign",
    "chamber_requirement",
    # sweeps
    "SweepResult",
    "ReplanResult",
    "sweep_fixed",
    "sweep_replan",
    "verify_box",
    # measured runs
    "MeasuredLog",
    "LogReport",
    "read_log",
    "log_from_frame",
    "GradientEstimate",
    "NoiseLevels",
    "estimate_gradient",
    "estimate_gradient_model",
    "finite_difference_gradient",
    "RunComparison",
    "compare_run",
    "resample_run",
    "synth_log",
    # model discrepancy
    "Diagnosis",
    "DiagnoseSettings",
    "diagnose",
    "diagnose_frame",
    "ModelSpec",
    "EFFECTS",
    "LinearEffectModel",
    "simulate_effect",
    "load_model",
    "write_model",
}


def test_public_api_is_what_we_intend():
    assert len(schedsyn.__all__) == len(set(schedsyn.__all__)), "duplicates in __all__"
    assert set(schedsyn.__all__) == PUBLIC


def test_every_public_name_resolves_in_a_fresh_interpreter():
    """Each name of ``__all__`` (lazy ones too) resolves to the object of its module."""
    code = (
        "import inspect, schedsyn\n"
        "for n in schedsyn.__all__:\n"
        "    v = getattr(schedsyn, n)\n"
        "    assert v is not None, n\n"
        "    mod = getattr(v, '__module__', None)\n"
        "    if inspect.isclass(v) or inspect.isfunction(v):\n"
        "        assert mod.startswith('schedsyn.'), (n, mod)\n"
        "from schedsyn import *\n"
        "print(len(schedsyn.__all__))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert int(res.stdout) == len(PUBLIC)


def test_helpers_stay_in_their_modules():
    from schedsyn.sweep import parse_grid, parse_range, run_map
    from schedsyn.synth import blind_case, synth_effect_log

    for f in (parse_grid, parse_range, run_map, blind_case, synth_effect_log):
        assert f.__name__ not in schedsyn.__all__
        assert not hasattr(schedsyn, f.__name__), f.__name__


def test_import_is_light():
    """``import schedsyn`` loads neither matplotlib nor cvxpy (the planner is lazy)."""
    code = "import sys, schedsyn; print('matplotlib' in sys.modules, 'cvxpy' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["False", "False"]


def test_version_is_written_once():
    """pyproject reads the version from schedsyn.__version__ (no second copy to forget)."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    project = conf["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert conf["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "schedsyn.__version__"}
    parts = schedsyn.__version__.split(".")
    assert len(parts) == 3 and all(p.isdigit() for p in parts), schedsyn.__version__
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert f"## [{schedsyn.__version__}]" in changelog


def test_licence_file_matches_pyproject():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert conf["project"]["license"] == "MIT"
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_plotting_leaves_the_users_backend_alone(tmp_path):
    """schedsyn.plots draws on matplotlib.figure.Figure objects: it never switches the
    backend the user chose (here 'svg', which cannot show windows either)."""
    code = f"""
import sys
import matplotlib
matplotlib.use("svg")
import numpy as np
import schedsyn.plots as plots
from schedsyn import BinGrid, Programme, coverage_report, simulate, sweep_fixed
traj = simulate(Programme([30.0, 60.0, 30.0], [-1.0, 0.5, 0.0]))
rep = coverage_report(traj.t_c, traj.g_c_per_min, BinGrid(0, 10), levels_required=1)
plots.save_figure(plots.programme_plot(traj), r"{tmp_path / "p.png"}")
plots.save_figure(plots.phase_plot(traj.t_c, traj.g_c_per_min), r"{tmp_path / "f.png"}")
plots.save_figure(plots.coverage_plot(rep), r"{tmp_path / "c.png"}")
sw = sweep_fixed(Programme([30.0, 60.0], [-1.0, 0.5]), (0, 10), [2000.0, 2400.0], [2.0, 3.0])
axes = plots.sweep_panels([(sw.to_frame(), "coverage", "a"), (sw.to_frame(), "coverage", "b")])
plots.save_figure(axes[0], r"{tmp_path / "s.png"}")
print(matplotlib.get_backend())
"""
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "svg"
    for name in ("p", "f", "c", "s"):
        assert (tmp_path / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
