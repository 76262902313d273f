"""schedsyn: plan thermal calibration tests of gyroscopes.

The data flow (one module per stage)::

    params -> model (exact discretisation) -> planner -> Programme -> simulate -> Trajectory
           -> coverage -> CoverageReport -> step tables / plots

``import schedsyn`` never loads matplotlib: plots live in :mod:`schedsyn.plots` and the
command line in :mod:`schedsyn.cli`.
"""

from .coverage import CoverageReport, coverage_report, trajectory_coverage
from .errors import (
    InfeasiblePlanError,
    LogFormatError,
    ParameterError,
    SchedsynError,
    SolverFailedError,
    StepTableError,
)
from .grid import BinGrid
from .model import AffineResponse, FirstOrderLag, affine_response
from .params import Limits, ThermalParams
from .programme import Programme, programme_from_frame, read_steps
from .simulate import Trajectory, simulate

__version__ = "0.1.0"

__all__ = [
    "AffineResponse",
    "BinGrid",
    "CoverageReport",
    "FirstOrderLag",
    "InfeasiblePlanError",
    "Limits",
    "LogFormatError",
    "ParameterError",
    "Programme",
    "SchedsynError",
    "SolverFailedError",
    "StepTableError",
    "ThermalParams",
    "Trajectory",
    "affine_response",
    "coverage_report",
    "programme_from_frame",
    "read_steps",
    "simulate",
    "trajectory_coverage",
]
