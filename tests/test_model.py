"""The exact discretisation against scipy's ODE solver and against theory."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from schedsyn import FirstOrderLag, Programme, ThermalParams, affine_response, simulate
from schedsyn.errors import ParameterError


def _ode_reference(programme, params, times_min, t0_c=20.0):
    """Integrate tau dT/dt + T = Tk + dT0, dTk/dt = U with tight tolerances."""
    tau = params.tau_s / 60.0
    edges = np.concatenate(([0.0], np.cumsum(programme.durations_min)))

    def rate(t):
        i = np.searchsorted(edges, t, side="right") - 1
        return programme.rates_c_per_min[i] if i < programme.n_segments else 0.0

    def rhs(t, x):
        tk, temp = x
        return [rate(t), (tk + params.dt0_c - temp) / tau]

    # integrate segment by segment so the solver never steps across a rate change
    out = np.empty((len(times_min), 3))
    x = np.array([programme.start_c, t0_c])
    stops = np.unique(np.concatenate((edges, [max(times_min.max(), edges[-1])])))
    for a, b in zip(stops[:-1], stops[1:], strict=True):
        mask = (times_min >= a) & (times_min <= b)
        sol = solve_ivp(
            rhs,
            (a, b),
            x,
            t_eval=times_min[mask] if mask.any() else None,
            rtol=1e-11,
            atol=1e-11,
            method="DOP853",
            first_step=1e-3,
            max_step=(b - a) / 4,
        )
        if mask.any():
            tk, temp = sol.y
            out[mask, 0] = temp
            out[mask, 1] = (tk + params.dt0_c - temp) / tau
            out[mask, 2] = tk
        x = sol.y[:, -1]
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_affine_response_matches_solve_ivp(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 12))
    durations = rng.uniform(0.5, 60.0, n)
    rates = rng.uniform(-1.0, 3.0, n)
    params = ThermalParams(tau_s=float(rng.uniform(600, 4000)), dt0_c=float(rng.uniform(-2, 6)))
    prog = Programme(durations, rates, start_c=20.0)
    edges = np.concatenate(([0.0], np.cumsum(durations)))
    inside = rng.uniform(0, edges[-1], 40)
    times = np.sort(np.concatenate((edges, inside, [edges[-1] + 17.0])))
    t0 = float(rng.uniform(15, 25))
    ref = _ode_reference(prog, params, times, t0_c=t0)
    resp = affine_response(FirstOrderLag(params), durations, times, tk0_c=20.0, t0_c=t0)
    temp, grad, tk = resp.evaluate(rates)
    np.testing.assert_allclose(temp, ref[:, 0], atol=1e-7)
    np.testing.assert_allclose(grad, ref[:, 1], atol=1e-8)
    np.testing.assert_allclose(tk, ref[:, 2], atol=1e-9)


def test_segment_boundaries_match_matrix_exponential():
    """T at segment ends equals the zero-order-hold discretisation of [Tk, T, 1]."""
    params = ThermalParams(tau_s=2400.0, dt0_c=3.0)
    tau = params.tau_min
    durations = np.array([10.0, 25.0, 7.0, 40.0])
    rates = np.array([-1.0, 2.5, 0.0, -0.3])
    # state x = [Tk, T, 1], input U: dx/dt = F x + G U
    f = np.array([[0, 0, 0], [1 / tau, -1 / tau, params.dt0_c / tau], [0, 0, 0]])
    g = np.array([1.0, 0.0, 0.0])
    x = np.array([20.0, 20.0, 1.0])
    ends = []
    for h, u in zip(durations, rates, strict=True):
        big = np.zeros((4, 4))
        big[:3, :3] = f * h
        big[:3, 3] = g * h
        e = expm(big)
        x = e[:3, :3] @ x + e[:3, 3] * u
        ends.append(x[1])
    resp = affine_response(FirstOrderLag(params), durations, np.cumsum(durations))
    temp, _, _ = resp.evaluate(rates)
    np.testing.assert_allclose(temp, ends, atol=1e-10)


def test_fixed_point_hold_settles_at_chamber_plus_offset():
    params = ThermalParams(tau_s=2400.0, dt0_c=3.0)
    prog = Programme([600.0], [0.0], start_c=20.0)
    traj = simulate(prog, params, dt_min=1.0)
    assert traj.t_c[-1] == pytest.approx(23.0, abs=1e-5)
    assert traj.g_c_per_min[-1] == pytest.approx(0.0, abs=1e-6)
    # one tau after the start the gap has closed by 1 - 1/e
    i = int(np.argmin(np.abs(traj.time_min - 40.0)))
    assert traj.t_c[i] == pytest.approx(20 + 3 * (1 - np.exp(-1)), abs=1e-9)


def test_two_half_segments_equal_one_segment():
    params = ThermalParams()
    times = np.linspace(0, 80, 161)
    one = affine_response(FirstOrderLag(params), [40.0, 40.0], times).evaluate([1.5, -0.5])
    two = affine_response(FirstOrderLag(params), [20.0, 20.0, 40.0], times).evaluate(
        [1.5, 1.5, -0.5]
    )
    for a, b in zip(one, two, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-10)


def test_gradient_is_derivative_of_temperature():
    params = ThermalParams(tau_s=1800.0, dt0_c=1.0)
    prog = Programme([30.0, 20.0, 50.0], [2.0, -1.0, 0.4])
    traj = simulate(prog, params, dt_min=0.01)
    fd = np.gradient(traj.t_c, traj.time_min)
    np.testing.assert_allclose(fd[5:-5], traj.g_c_per_min[5:-5], atol=2e-3)


def test_ramp_steady_state_lag():
    """Under a long ramp U the device trails the chamber by U*tau - dT0 and g -> U."""
    params = ThermalParams(tau_s=2400.0, dt0_c=3.0)
    prog = Programme([500.0], [0.1])
    traj = simulate(prog, params, dt_min=1.0)
    assert traj.g_c_per_min[-1] == pytest.approx(0.1, rel=1e-4)
    assert traj.tk_c[-1] - traj.t_c[-1] == pytest.approx(0.1 * 40.0 - 3.0, abs=1e-3)


@pytest.mark.parametrize("tau", [0.0, -5.0, float("nan"), float("inf"), "abc"])
def test_invalid_tau_is_named(tau):
    with pytest.raises(ParameterError, match="tau_s"):
        ThermalParams(tau_s=tau)


def test_invalid_dt0_is_named():
    with pytest.raises(ParameterError, match="dt0_c"):
        ThermalParams(dt0_c=float("nan"))
