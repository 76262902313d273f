"""schedsyn: plan thermal calibration tests of gyroscopes.

The data flow (one module per stage)::

    params -> model (exact discretisation) -> planner -> Programme -> simulate -> Trajectory
           -> coverage -> CoverageReport -> step tables / plots
    measured log -> logs -> estimate (Kalman) -> compare / discrepancy (identify, augment)
           -> augmented model -> simulate / planner again

``import schedsyn`` never loads matplotlib: plots live in :mod:`schedsyn.plots` and the
command line in :mod:`schedsyn.cli`. The planner and the campaign (which import cvxpy,
slow to load) and the discrepancy workflow are loaded on first use of their names.

``__all__`` is what users need; helpers for tests, benchmarks and the command line stay
in their modules (e.g. :func:`schedsyn.synth.blind_case`, :func:`schedsyn.sweep.parse_grid`,
:func:`schedsyn.sweep.run_map`).
"""

from importlib import import_module

from .compare import RunComparison, compare_run, resample_run
from .coverage import CoverageReport, coverage_report, trajectory_coverage
from .errors import (
    InfeasiblePlanError,
    LogFormatError,
    ParameterError,
    SchedsynError,
    SolverFailedError,
    StepTableError,
)
from .estimate import (
    GradientEstimate,
    NoiseLevels,
    estimate_gradient,
    estimate_gradient_model,
    finite_difference_gradient,
)
from .grid import BinGrid
from .logs import LogReport, MeasuredLog, log_from_frame, read_log
from .model import AffineResponse, FirstOrderLag, affine_response
from .params import Limits, ThermalParams
from .programme import Programme, programme_from_frame, read_steps
from .simulate import Trajectory, simulate
from .sweep import ReplanResult, SweepResult, sweep_fixed, sweep_replan, verify_box
from .synth import synth_log

#: The one place the version is written (pyproject.toml reads it from here).
__version__ = "0.1.0"

#: Names loaded lazily: name -> module.
_LAZY = {
    "ExperimentSpec": "planner",
    "Plan": "planner",
    "plan_experiment": "planner",
    "check_programme": "planner",
    "robustness_price": "planner",
    "CampaignConfig": "campaign",
    "CampaignResult": "campaign",
    "default_campaign": "campaign",
    "load_campaign": "campaign",
    "plan_campaign": "campaign",
    "chamber_requirement": "campaign",
    "Diagnosis": "discrepancy",
    "DiagnoseSettings": "discrepancy",
    "diagnose": "discrepancy",
    "diagnose_frame": "discrepancy",
    "ModelSpec": "effects",
    "EFFECTS": "effects",
    "LinearEffectModel": "effects",
    "simulate_effect": "models_io",
    "load_model": "models_io",
    "write_model": "models_io",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'schedsyn' has no attribute {name!r}")


__all__ = [
    "AffineResponse",
    "BinGrid",
    "CoverageReport",
    "FirstOrderLag",
    "GradientEstimate",
    "InfeasiblePlanError",
    "Limits",
    "LogFormatError",
    "LogReport",
    "MeasuredLog",
    "NoiseLevels",
    "ParameterError",
    "Programme",
    "ReplanResult",
    "RunComparison",
    "SchedsynError",
    "SolverFailedError",
    "StepTableError",
    "SweepResult",
    "ThermalParams",
    "Trajectory",
    "affine_response",
    "compare_run",
    "coverage_report",
    "estimate_gradient",
    "estimate_gradient_model",
    "finite_difference_gradient",
    "log_from_frame",
    "programme_from_frame",
    "read_log",
    "read_steps",
    "resample_run",
    "simulate",
    "sweep_fixed",
    "sweep_replan",
    "synth_log",
    "trajectory_coverage",
    "verify_box",
    *_LAZY,
]
