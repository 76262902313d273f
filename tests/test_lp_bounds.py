"""The probe LPs' cheap infeasibility proof: one row against the rate bounds.

Most probes of the search scan transitions too short for the device to reach the window's
first knot; :func:`bounds_prove_infeasible` rejects those without a solver. It must never
reject an LP a solver can solve, and a plan must not change because of it. Also how a
probe reaches the solver: its rows assembled from the ``le``/``ge``/``eq`` blocks, and the
dense-to-CSC conversion handed to Clarabel.
"""

import numpy as np
import pytest
from scipy import optimize

from schedsyn import Limits, ThermalParams
from schedsyn.planner import ExperimentSpec, plan_experiment
from schedsyn.planner import lp as lp_module
from schedsyn.planner.lp import bounds_prove_infeasible

LIMITS = Limits()


def _random_lp(rng: np.random.Generator, n_rates: int, n_free: int):
    """Rows over the rates (some also over free columns, either sign), right-hand sides
    around what the rate bounds allow, a few equality rows."""
    m = n_rates + n_free
    n_eq, n_ub = int(rng.integers(0, 3)), int(rng.integers(1, 8))
    a = rng.normal(size=(n_eq + n_ub, m)) * (rng.random((n_eq + n_ub, m)) < 0.7)
    a[:, n_rates:] *= rng.random((n_eq + n_ub, 1)) < 0.3  # free columns in some rows only
    x0 = rng.uniform(LIMITS.rate_min_c_per_min, LIMITS.rate_max_c_per_min, m)
    b = a @ x0 + rng.normal(scale=3.0, size=n_eq + n_ub)
    return a, b, n_eq


def _highs_infeasible(a, b, n_eq, n_rates) -> bool:
    m = a.shape[1]
    bounds = [(LIMITS.rate_min_c_per_min, LIMITS.rate_max_c_per_min)] * n_rates
    bounds += [(None, None)] * (m - n_rates)
    res = optimize.linprog(
        np.zeros(m),
        A_ub=a[n_eq:],
        b_ub=b[n_eq:],
        A_eq=a[:n_eq] if n_eq else None,
        b_eq=b[:n_eq] if n_eq else None,
        bounds=bounds,
        method="highs",
    )
    assert res.status in (0, 2), res.message
    return res.status == 2


def test_the_bounds_prove_only_what_a_solver_also_finds_infeasible():
    rng = np.random.default_rng(7)
    proven = infeasible = 0
    for _ in range(400):
        n_rates, n_free = int(rng.integers(1, 6)), int(rng.integers(0, 3))
        a, b, n_eq = _random_lp(rng, n_rates, n_free)
        verdict = bounds_prove_infeasible(a, b, n_eq, n_rates, LIMITS)
        truth = _highs_infeasible(a, b, n_eq, n_rates)
        assert truth or not verdict, (a, b, n_eq, n_rates)
        proven += verdict
        infeasible += truth
    # not vacuous: it proves a good share of the infeasible ones (one row is the usual cause)
    assert proven >= 0.3 * infeasible > 0


def test_a_row_exactly_at_what_the_rates_allow_is_feasible():
    """Full rate on every segment meets the row with equality: not a proof."""
    a = np.array([[-1.0, -2.0], [-1.0, 0.0]])
    b = np.array([-LIMITS.rate_max_c_per_min * 3.0, 0.0])  # x1 + 2 x2 >= 3 max
    assert not bounds_prove_infeasible(a, b, 0, 2, LIMITS)
    b[0] -= 1e-3  # beyond the tolerance: proven
    assert bounds_prove_infeasible(a, b, 0, 2, LIMITS)
    # an equality row out of reach either way
    reach = 2 * LIMITS.rate_max_c_per_min
    assert bounds_prove_infeasible(np.array([[1.0, 1.0]]), np.array([reach + 1]), 1, 2, LIMITS)
    assert not bounds_prove_infeasible(np.array([[1.0, 1.0]]), np.array([reach]), 1, 2, LIMITS)
    # a free column with the right sign makes any right-hand side reachable
    assert not bounds_prove_infeasible(np.array([[1.0, -1.0]]), np.array([-50.0]), 0, 1, LIMITS)


def test_a_plan_is_the_same_with_and_without_the_bounds_proof(monkeypatch):
    """The proof saves solver calls (most of a search's probes) and changes nothing else."""
    spec = ExperimentSpec("S", -10.0, 0.0, -20.0, 10.0, levels_required=3)
    limits = Limits(duration_max_min=300.0)
    fast = plan_experiment(spec, ThermalParams(), limits)
    assert fast.lp["infeasible_by_bounds"] > fast.lp["lp_solves"] / 4
    monkeypatch.setattr(lp_module, "bounds_prove_infeasible", lambda *a, **k: False)
    slow = plan_experiment(spec, ThermalParams(), limits)
    assert slow.lp["infeasible_by_bounds"] == 0
    assert slow.lp["infeasible"] == fast.lp["infeasible"]
    assert slow.lp["lp_solves"] == fast.lp["lp_solves"]
    np.testing.assert_array_equal(slow.programme.durations_min, fast.programme.durations_min)
    np.testing.assert_allclose(
        slow.programme.rates_c_per_min, fast.programme.rates_c_per_min, atol=1e-9
    )
    assert slow.coverage.levels.tolist() == fast.coverage.levels.tolist()


@pytest.mark.parametrize("solved_by", ["bounds", "solver"])
def test_solver_failures_are_still_reported_when_only_the_bounds_proved_anything(solved_by):
    from schedsyn.errors import SolverFailedError
    from schedsyn.planner.lp import LpStats, require_solvable

    stats = LpStats()
    stats.record("failed", 0.1, "numerical trouble")
    stats.record("infeasible", 0.0)
    if solved_by == "bounds":
        stats.infeasible_by_bounds += 1
        with pytest.raises(SolverFailedError, match="failed on 1 of 1 problems"):
            require_solvable(stats, "S")
    else:
        require_solvable(stats, "S")  # a solver proved one infeasible: a verdict


def test_dense_to_csc_is_scipys_own_matrix():
    """The probes' fast dense-to-CSC conversion gives scipy's arrays exactly (zeros, signed
    zeros and NaN included), so Clarabel sees the same problem."""
    from scipy import sparse

    from schedsyn.planner.lp import dense_to_csc

    rng = np.random.default_rng(3)
    mats = [
        rng.normal(size=(int(rng.integers(1, 40)), int(rng.integers(1, 12))))
        * (rng.random((1, 1)) < 0.5 + rng.random((1, 1)))
        for _ in range(30)
    ]
    mats += [np.zeros((3, 4)), np.array([[np.nan, 0.0, -0.0, 1e-300], [0.0, 2.0, 0.0, -1.0]])]
    for a in mats:
        a = a * (rng.random(a.shape) < 0.6)
        ref, got = sparse.csc_matrix(a), dense_to_csc(a)
        assert got.shape == ref.shape
        np.testing.assert_array_equal(got.indptr, ref.indptr)
        np.testing.assert_array_equal(got.indices, ref.indices)
        np.testing.assert_array_equal(got.data, ref.data)


def test_the_probe_rows_mean_what_le_ge_and_eq_say():
    """Each block's rows, assembled once for the solver, hold exactly when the constraint
    it was given as holds: ``le`` as given, ``ge`` with both sides negated (its extra
    columns keep their sign), ``eq`` as equalities; scalar and per-row right-hand sides."""
    from schedsyn.model import FirstOrderLag
    from schedsyn.planner import Scenario
    from schedsyn.planner.lp import Context, LpStats, Responses, SubLP

    spec = ExperimentSpec("S", -10.0, 0.0, -20.0, 10.0, levels_required=3)
    p = ThermalParams()
    ctx = Context(
        spec, LIMITS, Responses([Scenario(p, FirstOrderLag(p))], 12, 5.0, LIMITS), LpStats()
    )
    lp = SubLP(ctx, np.array([1.0, -0.5]), 12, extra=2)
    rng = np.random.default_rng(5)
    n = lp.n
    m_le, m_ge, m_eq = rng.normal(size=(3, n)), rng.normal(size=(4, n)), rng.normal(size=n)
    rhs_le, rhs_ge = rng.normal(size=3), 0.7
    lp.eq(m_eq, 1.5)
    lp.le(m_le, rhs_le, {1: 2.0})
    lp.ge(m_ge, rhs_ge, {0: -1.0})
    lp.le(m_le[0], 4.0)
    n_t, a, b, n_eq = lp._matrices(0.3)
    assert (n_t, n_eq) == (n, 1) and a.shape == (1 + 3 + 4 + 1 + 2 * n + 2 * n, n + 2 + n)
    x = rng.normal(size=n + 2 + n)
    u, e = x[:n], x[n : n + 2]
    slack = b - a @ x  # >= 0 where a row holds
    np.testing.assert_allclose(slack[0], 1.5 - m_eq @ u)
    np.testing.assert_allclose(slack[1:4], rhs_le - (m_le @ u + 2.0 * e[1]))
    np.testing.assert_allclose(slack[4:8], (m_ge @ u - (-1.0) * e[0]) - rhs_ge)
    np.testing.assert_allclose(slack[8], 4.0 - m_le[0] @ u)
    np.testing.assert_allclose(slack[9 : 9 + n], LIMITS.rate_max_c_per_min - u)
    np.testing.assert_allclose(slack[9 + n : 9 + 2 * n], u - LIMITS.rate_min_c_per_min)
    t = x[n + 2 :]
    np.testing.assert_allclose(slack[9 + 2 * n :], np.concatenate((t - u, t + u)))
