"""A continuation falls back on sweeps designed for a sub-region when the whole region's
sweeps do not fit in the time left (schedsyn.planner.continuation, as a fresh plan does).

Truth: scipy's integration of the lag over the returned step table, passes counted by a
plain loop.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from schedsyn import Limits, ThermalParams
from schedsyn.coverage import distinct_levels
from schedsyn.planner import Continuation, ExperimentSpec, plan_experiment, search
from schedsyn.programme import Programme

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning")


def _levels_by_solve_ivp(prog: Programme, params: ThermalParams, lo_c: float, n_bins: int):
    """Distinct levels (0.05 degC/min apart) per 1 degC bin from ``lo_c``: scipy's
    integration of the lag over ``prog``, passes counted by a plain loop."""
    tau = params.tau_s / 60.0
    t = np.arange(0.0, prog.total_min + 1e-9, 0.1)
    sol = solve_ivp(
        lambda s, y: [(prog.chamber_at([s])[0] + params.dt0_c - y[0]) / tau],
        (0.0, prog.total_min),
        [20.0],
        t_eval=t,
        rtol=1e-10,
        atol=1e-10,
        max_step=0.5,
    )
    temp = sol.y[0]
    grad = (prog.chamber_at(t) + params.dt0_c - temp) / tau
    runs: dict[int, list[list[float]]] = {}
    cur = None
    for x, g in zip(temp, grad, strict=True):
        k = int(np.floor(x - lo_c)) if lo_c <= x < lo_c + n_bins else None
        if k is not None and k == cur:
            runs[k][-1].append(g)
        elif k is not None:
            runs.setdefault(k, []).append([g])
        cur = k
    return [
        distinct_levels(np.array([np.mean(r) for r in runs.get(b, [])]), 0.05)
        for b in range(n_bins)
    ]


def test_a_continuation_that_fits_only_with_sub_region_sweeps_still_completes(monkeypatch):
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
    assert min(_levels_by_solve_ivp(prog, params, -10.0, 10)) >= 3


def test_when_not_even_sub_region_sweeps_fit_the_most_sweeps_that_do_are_planned(monkeypatch):
    """The same start with 140 min in all: neither three sweeps of the whole region nor
    of a sub-region fit; the rest is two sweeps (it was an error: the run went on as
    planned, however far from complete), said in the notes, the executed step kept, every
    bin passed at two levels by scipy's integration of the returned table."""
    monkeypatch.setattr(search, "PINNED", ())
    spec = ExperimentSpec("C", -10.0, 0.0, -20.0, 10.0, levels_required=3)
    params = ThermalParams()
    prefix = Programme(np.array([30.0]), np.array([-0.5]))
    cont = Continuation(prefix, tuple(np.zeros(0) for _ in range(spec.grid.n_bins)))
    limits = Limits(duration_max_min=140.0)
    plan = plan_experiment(spec, params, limits, continuation=cont)
    assert not plan.complete
    assert any("only 2 new sweep(s) fit, of the 3" in n for n in plan.notes), plan.notes
    prog = plan.programme
    assert prog.total_min <= 140.0 + 1e-9
    assert not [p for p in prog.violations(limits) if "starts at" not in p]
    np.testing.assert_array_equal(prog.durations_min[:1], prefix.durations_min)
    np.testing.assert_array_equal(prog.rates_c_per_min[:1], prefix.rates_c_per_min)
    levels = _levels_by_solve_ivp(prog, params, -10.0, 10)
    assert min(levels) >= 2, levels
    assert plan.coverage.min_levels == min(levels)
