"""The ``informative`` objective (issue 15 item 4): the shortest complete plan's sweeps run
on to the budget with every rate chosen for the drift fit's information.

Checked with separate code: the exported tables are integrated by scipy
(tests/independent.py), levels counted plainly, and the information of both tables
recomputed from those trajectories with numpy alone.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from independent import chamber_knots, ode_trajectories, table_check

from schedsyn.design import DesignSpace
from schedsyn.params import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, plan_experiment
from schedsyn.planner.bound import duration_lower_bound
from schedsyn.planner.informative import _log_det_and_gradient
from schedsyn.terms import TERMS, parse_terms

pytestmark = [
    pytest.mark.filterwarnings("ignore:Solution may be inaccurate:UserWarning"),
    pytest.mark.slow,
]

SPEC = ExperimentSpec("small", 0.0, 6.0, -4.0, 10.0, levels_required=3)
LIMITS = dataclasses.replace(Limits(), duration_max_min=240.0)


def _total_log_det(steps_csv, space: DesignSpace) -> float:
    """log det X'X of the full cubic over the table's 1-min samples in the approximation
    region, from scipy's trajectory and coding written out here (not schedsyn's)."""
    knots_t, knots_tk = chamber_knots(steps_csv)
    t_min, temp, grad = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=1.0)
    t, g = temp[0], grad[0]
    keep = (t >= space.approx_lo_c) & (t <= space.approx_hi_c)
    g_lo, g_hi = space.gradient_range_c_per_min
    u = (t[keep] - 0.5 * (space.approx_lo_c + space.approx_hi_c)) / (
        0.5 * (space.approx_hi_c - space.approx_lo_c)
    )
    v = (g[keep] - 0.5 * (g_lo + g_hi)) / (0.5 * (g_hi - g_lo))
    x = np.column_stack([u**i * v**j for i in range(4) for j in range(4 - i)])
    sign, logdet = np.linalg.slogdet(x.T @ x)
    assert sign > 0
    return float(logdet)


@pytest.fixture(scope="module")
def plans():
    shortest = plan_experiment(SPEC, ThermalParams(), LIMITS)
    informative = plan_experiment(
        dataclasses.replace(SPEC, objective="informative"), ThermalParams(), LIMITS
    )
    return shortest, informative


def test_informative_plan_is_complete_longer_and_more_informative(plans, tmp_path):
    shortest, informative = plans
    assert shortest.complete and informative.complete, informative.notes
    info = informative.informative
    assert info is not None, informative.notes
    # the price: more time than the shortest plan, within the budget
    assert info["shortest_duration_min"] == pytest.approx(shortest.duration_min)
    assert shortest.duration_min < informative.duration_min <= LIMITS.duration_max_min
    assert info["price_min"] == pytest.approx(informative.duration_min - shortest.duration_min)
    # the exported tables, integrated by scipy: both complete, within the device limits
    paths = {}
    for name, plan in (("shortest", shortest), ("informative", informative)):
        paths[name] = tmp_path / f"{name}.csv"
        plan.programme.to_csv(paths[name])
        res = table_check(paths[name], (SPEC.working_lo_c, SPEC.working_hi_c), 3)
        assert res["coverage"] == 1.0 and res["min_levels"] >= 3, name
        assert LIMITS.device_min_c <= res["device_min_c"] <= res["device_max_c"]
        assert res["device_max_c"] <= LIMITS.device_max_c
        assert res["chamber_end_c"] == pytest.approx(LIMITS.end_c, abs=0.051)
    # the gain, recomputed from scipy's trajectories: what the plan claims, and real
    space = DesignSpace(
        SPEC.working_lo_c, SPEC.working_hi_c, SPEC.approx_lo_c, SPEC.approx_hi_c,
        ThermalParams(), LIMITS, SPEC.max_cool_c_per_min, SPEC.max_heat_c_per_min,
    )  # fmt: skip
    p = len(TERMS)
    factor = math.exp(
        (_total_log_det(paths["informative"], space) - _total_log_det(paths["shortest"], space)) / p
    )
    assert factor > 1.05
    assert info["information_factor"] == pytest.approx(factor, rel=0.02)
    assert any(n.startswith("informative: ") and "min longer" in n for n in informative.notes)


def _minutes_in_region(plan, tmp_path, space_lo_c: float, space_hi_c: float) -> int:
    """1-min samples of the exported table's scipy trajectory inside [lo, hi] degC."""
    path = tmp_path / f"{plan.spec.objective}-in-region.csv"
    plan.programme.to_csv(path)
    knots_t, knots_tk = chamber_knots(path)
    _, temp, _ = ode_trajectories(knots_t, knots_tk, 2400.0, 3.0, dt_min=1.0)
    return int(((temp[0] >= space_lo_c) & (temp[0] <= space_hi_c)).sum())


def test_the_pull_brings_the_run_on_minutes_into_the_region(plans, tmp_path):
    """The region is far from the 20 degC start and end: the minutes the informative plan
    runs on begin as holds at the end temperature, where a sample carries no information
    and no gradient of log det would move it. The pull brings most of them in (without it,
    PULL_SAMPLES_PER_C = 0, the plan had 129 minutes in the region against 202)."""
    shortest, informative = plans
    lo, hi = SPEC.approx_lo_c, SPEC.approx_hi_c
    in_shortest = _minutes_in_region(shortest, tmp_path, lo, hi)
    in_informative = _minutes_in_region(informative, tmp_path, lo, hi)
    price = informative.duration_min - shortest.duration_min
    assert in_informative >= in_shortest + 0.5 * price, (in_shortest, in_informative, price)


def test_shortest_objective_does_not_run_on(plans):
    shortest, _ = plans
    assert shortest.informative is None
    assert not any(n.startswith("informative") for n in shortest.notes)


def test_log_det_gradient_matches_finite_differences():
    space = DesignSpace(0.0, 6.0, -4.0, 10.0)
    rng = np.random.default_rng(3)
    t = rng.uniform(-5.0, 11.0, 300)  # some outside the approximation region
    g = rng.uniform(-0.6, 0.8, 300)
    terms = parse_terms("full")
    d, d_t, d_g = _log_det_and_gradient(t, g, space, terms)
    assert d == pytest.approx(np.linalg.slogdet(_x(t, g, space).T @ _x(t, g, space))[1])
    h = 1e-5
    for k in rng.choice(300, 12, replace=False):
        for arr, grad in ((t, d_t), (g, d_g)):
            up, down = arr.copy(), arr.copy()
            up[k] += h
            down[k] -= h
            args_up = (up, g) if arr is t else (t, up)
            args_down = (down, g) if arr is t else (t, down)
            fd = (_ld(*args_up, space) - _ld(*args_down, space)) / (2 * h)
            assert grad[k] == pytest.approx(fd, rel=1e-4, abs=1e-7)


def _x(t, g, space):
    keep = (t >= space.approx_lo_c) & (t <= space.approx_hi_c)
    u, v = space.code(t[keep], g[keep])
    return np.column_stack([u**i * v**j for i in range(4) for j in range(4 - i)])


def _ld(t, g, space) -> float:
    x = _x(t, g, space)
    return float(np.linalg.slogdet(x.T @ x)[1])


def test_the_settled_temperature_of_a_model_is_the_lag_s_own():
    """Where the device settles with the chamber held at the end temperature (the bound of
    --end-soak's informative plans): end_c + dT0 for the first-order lag, and the same from
    the model's own response when a model is given (here the lag itself, other numbers)."""
    from schedsyn.model import FirstOrderLag
    from schedsyn.planner.core import _settled_c

    params = ThermalParams(tau_s=1800.0, dt0_c=4.5)
    limits = dataclasses.replace(Limits(), end_c=25.0)
    assert _settled_c(limits, params, None) == pytest.approx(29.5)
    assert _settled_c(limits, ThermalParams(), FirstOrderLag(params)) == pytest.approx(29.5)


def test_a_graded_plan_keeps_what_its_objective_did(plans):
    """A request planned graded returns the complete plan for fewer levels under the
    request's own notes: that plan's "informative: ..." note (what it ran on and for how
    much information) comes with it (it was dropped with the rest of its notes)."""
    from schedsyn.planner.core import _Fewer, _graded

    _, informative = plans
    asked = dataclasses.replace(informative.spec, levels_required=SPEC.levels_required + 3)
    graded = _graded(
        None, asked, ThermalParams(), LIMITS, ("why not",), _Fewer(3, informative, (3,))
    )
    assert graded is not None and graded.levels_planned == 3 and not graded.complete
    assert graded.notes[0] == "why not" and graded.notes[1].startswith("GRADED")
    # proven or not, by the duration bound (red team: "the most the search fits" read as
    # a proof where the bound was 142 of 540 min)
    bound = duration_lower_bound(asked, ThermalParams(), LIMITS).lower_bound_min
    said = "; proven: " if bound > LIMITS.duration_max_min else "; not proven: the duration bound"
    assert said in graded.notes[1], (bound, graded.notes[1])
    kept = [n for n in graded.notes if n.startswith("informative: ")]
    assert kept == [n for n in informative.notes if n.startswith("informative: ")] != []
    # ... and says the plan it ran on was complete for 3 levels, not for the request's 6
    # (fuzz: "longer than the shortest complete plan" under a GRADED note)
    assert "than the shortest complete plan for 3 levels per bin (" in kept[0]
