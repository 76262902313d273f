"""Model files: the (augmented) model a diagnosis found, for ``simulate`` and the planner.

A model file is JSON (written by ``schedsyn diagnose LOG.csv --out DIR`` as
``DIR/model.json``)::

    {"schedsyn_model": 1, "tau_s": 2400.0, "dt0_c": 3.0,
     "effect": "chamber_lag", "parameters": {"tau_chamber_s": 300.0}, "linear": true}

``effect`` is ``none`` or a name from :data:`schedsyn.effects.EFFECTS`. Linear models go
through the exact affine machinery (:meth:`ModelSpec.linear_model` is a
``LinearThermalModel``); nonlinear ones are simulated on a grid and expose the chamber
limits they imply (:meth:`ModelSpec.planner_limits`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .effects import ModelSpec
from .errors import ParameterError, SchedsynError
from .io import write_json_atomic
from .programme import Programme
from .simulate import Trajectory, dense_times


def load_model(path: Path | str) -> ModelSpec:
    """Read and validate a model file."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"model file {path} does not exist or is not a file")
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ParameterError(f"model file {path} is not valid JSON ({exc})") from None
    try:
        return ModelSpec.from_json_dict(obj)
    except SchedsynError as exc:
        raise ParameterError(f"model file {path}: {exc}") from None


def write_model(path: Path | str, model: ModelSpec, inputs=()) -> Path:
    """Write ``model`` as a model file (atomically; never over an input)."""
    return write_json_atomic(path, model.to_json_dict(), inputs)


def simulate_effect(
    programme: Programme,
    model: ModelSpec,
    times_min: np.ndarray | None = None,
    *,
    dt_min: float = 0.1,
    t0_c: float = 20.0,
) -> Trajectory:
    """Simulate ``programme`` through an augmented model (linear or not).

    Linear models are evaluated exactly by :func:`schedsyn.model.affine_response`;
    nonlinear ones on a grid (see :meth:`ModelSpec.predict`). ``tk_c`` is the chamber
    AIR the model predicts (lagged, rate-limited or cycling where the effect says so).
    """
    t = dense_times(programme.total_min, dt_min) if times_min is None else np.asarray(times_min)
    pred = model.predict(programme, t, t0_c=t0_c)
    return Trajectory(time_min=t, tk_c=pred.tk_air_c, t_c=pred.t_c, g_c_per_min=pred.g_c_per_min)
