"""A continuation falls back on sweeps designed for a sub-region when the whole region's
sweeps do not fit in the time left (schedsyn.planner.continuation, as a fresh plan does).

Truth: scipy's integration of the lag over the returned step table, passes counted by a
plain loop.
"""

from __future__ import annotations

import numpy as np
import pytest
from independent import table_check

from schedsyn import Limits, ThermalParams
from schedsyn.planner import Continuation, ExperimentSpec, plan_experiment, search
from schedsyn.programme import Programme

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")


def _levels(prog: Programme, params: ThermalParams, tmp_path, lo_c=-10.0) -> np.ndarray:
    """Distinct levels per bin of [lo_c, 0] degC: the exported table integrated by scipy,
    passes counted plainly (tests/independent.py)."""
    prog.to_csv(tmp_path / "steps.csv")
    return table_check(tmp_path / "steps.csv", (lo_c, 0.0), 3, params.tau_s, params.dt0_c)["levels"]


def test_a_continuation_that_fits_only_with_sub_region_sweeps_still_completes(
    monkeypatch, tmp_path
):
    """30 min of cooling done, nothing measured, 200 min in all: three sweeps of the whole
    region [-10, 0] do not fit, sweeps designed for a
    narrower sub-region do and still pass every bin three times 0.05 degC/min apart.

    Without the pinned structures (tried before the sub-regions, they fit this one too:
    the fallback under test would not be reached)."""
    monkeypatch.setattr(search, "PINNED", ())
    spec = ExperimentSpec("C", -10.0, 0.0, -20.0, 10.0, levels_required=3)
    params = ThermalParams()
    prefix = Programme(np.array([30.0]), np.array([-0.5]))
    cont = Continuation(prefix, tuple(np.zeros(0) for _ in range(spec.grid.n_bins)))
    plan = plan_experiment(spec, params, Limits(duration_max_min=200.0), continuation=cont)
    assert plan.complete and plan.duration_min <= 200.0
    assert any("sub-region" in n for n in plan.notes)
    prog = plan.programme
    np.testing.assert_array_equal(prog.durations_min[:1], prefix.durations_min)
    np.testing.assert_array_equal(prog.rates_c_per_min[:1], prefix.rates_c_per_min)
    assert min(_levels(prog, params, tmp_path)) >= 3


def test_when_not_even_sub_region_sweeps_fit_the_most_sweeps_that_do_are_planned(
    monkeypatch, tmp_path
):
    """The same start on [-5, 0] degC with 120 min in all: neither three sweeps of the
    whole region nor of a sub-region fit; the rest is two sweeps (it was an error: the run
    went on as planned, however far from complete), said in the notes, the executed step
    kept, every bin passed at two levels by scipy's integration of the returned table.
    ([-10, 0] degC in 140 min is the same case, with searches twice as long.)"""
    monkeypatch.setattr(search, "PINNED", ())
    spec = ExperimentSpec("C", -5.0, 0.0, -15.0, 10.0, levels_required=3)
    params = ThermalParams()
    prefix = Programme(np.array([30.0]), np.array([-0.5]))
    cont = Continuation(prefix, tuple(np.zeros(0) for _ in range(spec.grid.n_bins)))
    limits = Limits(duration_max_min=120.0)
    plan = plan_experiment(spec, params, limits, continuation=cont)
    assert not plan.complete
    assert any("only 2 new sweep(s) fit, of the 3" in n for n in plan.notes), plan.notes
    # why three do not fit: each reason once, and a horizon past the limit said to be one
    (why,) = [n for n in plan.notes if "do not fit" in n]
    reasons = why.split(": ", 1)[1].split("; ")
    assert len(reasons) == len(set(reasons)) and "the 120-min limit" in why, why
    prog = plan.programme
    assert prog.total_min <= 120.0 + 1e-9
    assert not [p for p in prog.violations(limits) if "starts at" not in p]
    np.testing.assert_array_equal(prog.durations_min[:1], prefix.durations_min)
    np.testing.assert_array_equal(prog.rates_c_per_min[:1], prefix.rates_c_per_min)
    levels = _levels(prog, params, tmp_path, lo_c=-5.0)
    assert min(levels) >= 2, levels
    assert plan.coverage.min_levels == min(levels)


def test_a_sweep_count_that_does_not_fit_gives_each_reason_once(monkeypatch):
    """The search repeats a reason once per candidate structure it rejects (the W4 red
    team's note said the same sentence twice per sweep count); the note names each reason
    once, in the order found. No search runs: every search is a stub that finds nothing,
    so the continuation fails and its error carries the notes."""
    from types import SimpleNamespace

    from schedsyn.errors import InfeasiblePlanError
    from schedsyn.planner import continuation as cont_mod

    reasons = ["the sweep overruns by 12 min", "the sweep overruns by 12 min", "floor"]
    stub = SimpleNamespace(best=None, reasons=reasons)
    monkeypatch.setattr(cont_mod, "synthesise", lambda *a, **k: stub)
    monkeypatch.setattr(cont_mod, "_cut", lambda *a, **k: None)
    spec = ExperimentSpec("C", -10.0, 0.0, -20.0, 10.0, levels_required=3)
    prefix = Programme(np.array([30.0]), np.array([-0.5]))
    cont = Continuation(prefix, tuple(np.zeros(0) for _ in range(spec.grid.n_bins)))
    with pytest.raises(InfeasiblePlanError) as err:
        plan_experiment(spec, ThermalParams(), Limits(duration_max_min=140.0), continuation=cont)
    msg = str(err.value)
    assert "3 new sweep(s) do not fit: the sweep overruns by 12 min; floor" in msg, msg
    assert "12 min; the sweep overruns" not in msg, msg
