"""The one copy of the first-order lag (schedsyn.model) against scipy, and its users.

``tau dT/dt + T = v``: step and ramp responses against the matrix exponential of the
augmented state, the free response and the first-order-hold grid update against
``solve_ivp``; FirstOrderLag and the one-pole LinearEffectModel are the same numbers.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from schedsyn import FirstOrderLag, ThermalParams
from schedsyn.effects import LinearEffectModel
from schedsyn.model import lag_foh, lag_free, lag_ramp, lag_step

TAUS_MIN = [0.7, 40.0, 90.0]


@pytest.mark.parametrize("tau", TAUS_MIN)
def test_step_and_ramp_responses_match_the_matrix_exponential(tau):
    """State [T, Tk, U]: dT/dt = (Tk - T)/tau, dTk/dt = U, dU/dt = 0.

    A unit step of Tk (T = 0, Tk = 1, U = 0) gives S; a unit ramp (U = 1) gives R."""
    f = np.array([[-1.0 / tau, 1.0 / tau, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    xs = np.array([1e-6, 1e-3, 0.05, 0.5, 3.0, 17.0, 60.0, 250.0])
    step = [(expm(f * x) @ [0.0, 1.0, 0.0])[0] for x in xs]
    ramp = [(expm(f * x) @ [0.0, 0.0, 1.0])[0] for x in xs]
    np.testing.assert_allclose(lag_step(xs, tau), step, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(lag_ramp(xs, tau), ramp, rtol=1e-8, atol=1e-15)
    # causal: nothing before the input starts
    assert np.all(lag_step(np.array([-5.0, 0.0]), tau) == 0.0)
    assert np.all(lag_ramp(np.array([-5.0, 0.0]), tau) == 0.0)


@pytest.mark.parametrize("tau", TAUS_MIN)
def test_free_response_matches_solve_ivp(tau):
    t = np.linspace(0.0, 5 * tau, 41)
    target, t0 = 23.5, -7.0
    sol = solve_ivp(
        lambda _, y: [(target - y[0]) / tau], (0.0, t[-1]), [t0], t_eval=t, rtol=1e-12, atol=1e-12
    )
    temp, grad = lag_free(t, target, t0, tau)
    np.testing.assert_allclose(temp, sol.y[0], atol=1e-9)
    np.testing.assert_allclose(grad, (target - sol.y[0]) / tau, atol=1e-9)


@pytest.mark.parametrize(("tau", "h"), [(40.0, 1 / 6), (2.5, 0.4), (0.3, 0.25)])
def test_first_order_hold_update_matches_solve_ivp(tau, h, rng):
    """An input linear between grid points is followed exactly at the grid points."""
    n = 60
    v = 20.0 + np.cumsum(rng.normal(0.0, 1.0, n))
    grid = h * np.arange(n)
    t0 = 12.0

    def rhs(t, y):
        return [(np.interp(t, grid, v) - y[0]) / tau]

    ref = [t0]
    y = [t0]
    for a, b in zip(grid[:-1], grid[1:], strict=True):  # never across a kink of the input
        y = solve_ivp(rhs, (a, b), y, rtol=1e-12, atol=1e-12, method="DOP853").y[:, -1]
        ref.append(float(y[0]))
    np.testing.assert_allclose(lag_foh(v, t0, tau, h), ref, atol=1e-9)


def test_first_order_lag_and_one_pole_effect_model_are_the_same_numbers(rng):
    """The general model's one-pole case and FirstOrderLag share one implementation: equal
    to the last bit (not only within a tolerance)."""
    x = np.concatenate(([-3.0, 0.0, 1e-9], rng.uniform(0.0, 600.0, 200)))
    for tau_s, dt0_c in [(2400.0, 3.0), (180.0, -1.5), (5000.0, 0.0)]:
        lag = FirstOrderLag(ThermalParams(tau_s, dt0_c))
        gen = LinearEffectModel(tau_s, dt0_c)
        np.testing.assert_array_equal(gen.step(x), lag.step(x))
        np.testing.assert_array_equal(gen.ramp(x), lag.ramp(x))
        for a, b in zip(gen.free(x, 20.0, 17.0), lag.free(x, 20.0, 17.0), strict=True):
            np.testing.assert_array_equal(a, b)
        assert gen.gain == lag.gain == 1.0


def test_delay_and_slope_reuse_the_same_lag():
    """Dead time shifts the one-pole responses; a self-heating slope s scales the time
    constant and the gain: tau_eff = tau/(1-s), K = 1/(1-s)."""
    x = np.linspace(0.0, 300.0, 301)
    delayed = LinearEffectModel(2400.0, 3.0, delay_s=600.0)
    np.testing.assert_array_equal(delayed.ramp(x), lag_ramp(x - 10.0, 40.0))
    s = 0.2
    sloped = LinearEffectModel(2400.0, 3.0, dt0_slope_c_per_c=s)
    np.testing.assert_allclose(sloped.step(x), lag_step(x, 40.0 / (1 - s)), rtol=1e-15)
    temp, _ = sloped.free(x, 20.0, 20.0)
    # at rest the device settles where T = Tk + dt0 + s (T - 20): T = 20 + dt0/(1-s)
    assert temp[-1] == pytest.approx(20.0 + 3.0 / (1 - s) * (1 - np.exp(-300 / 50)), rel=1e-12)
