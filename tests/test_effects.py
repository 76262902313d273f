"""The effect library against scipy's ODE solver, and the model-file contract."""

import bisect
import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from schedsyn import FirstOrderLag, Programme, ThermalParams, affine_response, simulate
from schedsyn.effects import EFFECTS, LinearEffectModel, ModelSpec
from schedsyn.errors import ParameterError
from schedsyn.models_io import load_model, simulate_effect, write_model

PROG = Programme([30.0, 20.0, 40.0, 60.0, 25.0], [-1.0, 0.0, 2.5, -0.5, 0.0], 20.0)
TIMES = np.linspace(0.0, PROG.total_min + 15.0, 353)


EDGES = [0.0, *np.cumsum(PROG.durations_min).tolist()]
TEMPS = PROG.boundary_temps_c.tolist()
RATES = PROG.rates_c_per_min.tolist()


def _rate(t):
    i = bisect.bisect_right(EDGES, t) - 1
    return RATES[i] if i < len(RATES) else 0.0


def _setpoint(t):
    i = min(bisect.bisect_right(EDGES, t) - 1, len(RATES))
    return TEMPS[i] + (RATES[i] * (t - EDGES[i]) if i < len(RATES) else 0.0)


def _integrate(rhs, x0, shift=0.0):
    """Integrate piece by piece (never across a rate change, also ``shift`` later) at TIMES."""
    stops = np.unique(np.concatenate((EDGES, np.add(EDGES, shift), [TIMES[-1]])))
    stops = stops[stops <= TIMES[-1]]
    out = np.empty((len(x0), TIMES.size))
    x = np.asarray(x0, dtype=float)
    for a, b in zip(stops[:-1], stops[1:], strict=True):
        m = (TIMES >= a) & (TIMES <= b)
        sol = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=1e-11, atol=1e-11, dense_output=True)
        out[:, m] = sol.sol(TIMES[m])
        x = sol.y[:, -1]
    return out


@pytest.mark.parametrize(
    ("tau_s", "tau_c_s", "t0_c"), [(2400.0, 300.0, 18.0), (1800.0, 900.0, 21.0)]
)
def test_chamber_lag_matches_ode(tau_s, tau_c_s, t0_c):
    spec = ModelSpec(tau_s, 3.0, "chamber_lag", {"tau_chamber_s": tau_c_s})
    tau, tc = tau_s / 60, tau_c_s / 60

    # tau_c dA/dt + A = Tk_set;  tau dT/dt + T = A + dT0 (A starts at the setpoint)
    def rhs(t, x):
        return [_rate(t), (x[0] - x[1]) / tc, (x[1] + 3.0 - x[2]) / tau]

    ref = _integrate(rhs, [20.0, 20.0, t0_c])
    pred = spec.predict(PROG, TIMES, t0_c=t0_c)
    np.testing.assert_allclose(pred.t_c, ref[2], atol=1e-7)
    np.testing.assert_allclose(pred.g_c_per_min, (ref[1] + 3.0 - ref[2]) / tau, atol=1e-8)
    np.testing.assert_allclose(pred.tk_air_c, ref[1], atol=1e-7)


@pytest.mark.parametrize("tau2_s", [300.0, 1200.0, 2400.0])
def test_second_time_constant_matches_ode(tau2_s):
    spec = ModelSpec(2400.0, 2.0, "second_time_constant", {"tau2_s": tau2_s})
    tau, t2 = 40.0, tau2_s / 60

    def rhs(t, x):
        return [_rate(t), (x[0] - x[1]) / t2, (x[1] + 2.0 - x[2]) / tau]

    ref = _integrate(rhs, [20.0, 20.0, 19.0])
    pred = spec.predict(PROG, TIMES, t0_c=19.0)
    atol = 1e-7 if tau2_s != 2400.0 else 2e-3  # the double pole is approximated
    np.testing.assert_allclose(pred.t_c, ref[2], atol=atol)
    np.testing.assert_allclose(pred.tk_air_c, PROG.chamber_at(TIMES), atol=1e-12)


def test_dead_time_matches_ode():
    spec = ModelSpec(2400.0, 3.0, "dead_time", {"delay_s": 300.0})
    d = 5.0

    # tau dT/dt + T = Tk(t - d) + dT0, the chamber at its start value before t = 0
    def rhs(t, x):
        return [(_setpoint(max(t - d, 0.0)) + 3.0 - x[0]) / 40.0]

    ref = _integrate(rhs, [18.0], shift=d)
    pred = spec.predict(PROG, TIMES, t0_c=18.0)
    np.testing.assert_allclose(pred.t_c, ref[0], atol=1e-7)


def test_selfheat_slope_matches_ode():
    s = 0.04
    spec = ModelSpec(2400.0, 3.0, "selfheat_slope", {"dt0_slope_c_per_c": s})

    # tau dT/dt + T = Tk + dt0 + s (T - 20)
    def rhs(t, x):
        return [_rate(t), (x[0] + 3.0 + s * (x[1] - 20.0) - x[1]) / 40.0]

    ref = _integrate(rhs, [20.0, 17.0])
    pred = spec.predict(PROG, TIMES, t0_c=17.0)
    np.testing.assert_allclose(pred.t_c, ref[1], atol=1e-7)
    g_ref = (ref[0] + 3.0 + s * (ref[1] - 20.0) - ref[1]) / 40.0
    np.testing.assert_allclose(pred.g_c_per_min, g_ref, atol=1e-8)


def test_rate_limit_matches_ode():
    spec = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.5, "max_heat_rate_c_per_min": 2.0},
    )
    k = 1e4  # a stiff proportional follower saturated at the limits approximates the limiter

    def rhs(t, x):
        return [min(max(k * (_setpoint(t) - x[0]), -0.5), 2.0), (x[0] + 3.0 - x[1]) / 40.0]

    times = np.arange(0.0, TIMES[-1], 0.25)  # on the coarse grid: the limiter is exact there
    sol = solve_ivp(
        rhs,
        (0, times[-1]),
        [20.0, 18.0],
        t_eval=times,
        method="LSODA",
        rtol=1e-9,
        atol=1e-9,
        max_step=0.05,
    )
    pred = spec.predict(PROG, times, t0_c=18.0, grid_min=0.25)
    # the follower lags by rate/k: 2.5e-4 degC; the grid update is exact for the limiter
    np.testing.assert_allclose(pred.tk_air_c, sol.y[0], atol=1e-3)
    np.testing.assert_allclose(pred.t_c, sol.y[1], atol=1e-3)
    assert np.min(np.diff(pred.tk_air_c) / np.diff(times)) >= -0.5 - 1e-9


@pytest.mark.parametrize("grid_min", [1.0 / 3.0, 0.3306])
def test_rate_limit_is_exact_with_the_setpoints_corners_between_grid_points(grid_min):
    """A +2 degC/min ramp turning at minute 10.1 into -1 degC/min under a 0.4 degC/min
    cooling limit: the air leaves the setpoint at the peak and descends at the limit. On a
    1/3-min grid the peak falls between grid points; sampled there, the limiter cut it off
    and carried the cut through the whole descent (red team: 0.19 degC in the air, 0.13 in
    the device). Truth: the stiff saturated follower through scipy, piece by piece."""
    prog = Programme([10.1, 30.7, 47.3], [2.0, -1.0, 0.25], 20.0)
    spec = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.4, "max_heat_rate_c_per_min": 3.0},
    )
    edges = np.concatenate(([0.0], np.cumsum(prog.durations_min)))
    k = 1e4

    def rhs(t, x):
        sp = float(prog.chamber_at(np.array([t]))[0])
        return [min(max(k * (sp - x[0]), -0.4), 3.0), (x[0] + 3.0 - x[1]) / 40.0]

    times = np.arange(0.0, prog.total_min, 0.5)
    x, ref = np.array([20.0, 19.0]), []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        m = (times >= a) & (times < b)
        sol = solve_ivp(
            rhs,
            (a, b),
            x,
            method="LSODA",
            rtol=1e-10,
            atol=1e-10,
            max_step=0.02,
            dense_output=True,
        )
        ref.append(sol.sol(times[m]))
        x = sol.y[:, -1]
    ref_air, ref_t = np.concatenate(ref, axis=1)
    pred = spec.predict(prog, times, t0_c=19.0, grid_min=grid_min)
    assert ref_air.max() > 40.0  # the peak (40.2 at 10.1 min) less 0.4 min at the limit
    np.testing.assert_allclose(pred.tk_air_c, ref_air, atol=2e-3)
    np.testing.assert_allclose(pred.t_c, ref_t, atol=2e-3)


def test_cycling_and_asymmetric_match_ode():
    cyc = ModelSpec(
        2400.0, 3.0, "chamber_cycling", {"amplitude_c": 1.0, "period_s": 600.0, "phase_rad": 0.3}
    )
    ref = _integrate(
        lambda t, x: [(_setpoint(t) + math.sin(2 * math.pi * t / 10 + 0.3) + 3.0 - x[0]) / 40.0],
        [18.0],
    )
    np.testing.assert_allclose(
        cyc.predict(PROG, TIMES, t0_c=18.0, grid_min=0.02).t_c, ref[0], atol=1e-4
    )

    asym = ModelSpec(2400.0, 3.0, "asymmetric_tau", {"tau_heat_s": 2000.0, "tau_cool_s": 2800.0})

    def rhs(t, x):
        v = _setpoint(t) + 3.0
        return [(v - x[0]) / (2000.0 / 60 if v > x[0] else 2800.0 / 60)]

    sol = solve_ivp(rhs, (0, TIMES[-1]), [18.0], t_eval=TIMES, rtol=1e-10, atol=1e-10, max_step=0.5)
    np.testing.assert_allclose(
        asym.predict(PROG, TIMES, t0_c=18.0, grid_min=0.02).t_c, sol.y[0], atol=1e-4
    )


def test_linear_effect_model_is_a_planner_model():
    """No effect = the first-order lag exactly; effects go through simulate(model=...)."""
    plain = LinearEffectModel(2400.0, 3.0)
    a = affine_response(plain, PROG.durations_min, TIMES, 20.0, 19.0)
    b = affine_response(
        FirstOrderLag(ThermalParams(2400.0, 3.0)), PROG.durations_min, TIMES, 20.0, 19.0
    )
    np.testing.assert_allclose(a.a_t, b.a_t, atol=1e-12)
    np.testing.assert_allclose(a.b_t, b.b_t, atol=1e-12)
    spec = ModelSpec(2400.0, 3.0, "dead_time", {"delay_s": 120.0})
    traj = simulate(PROG, model=spec.linear_model(), times_min=TIMES, t0_c=20.0)
    np.testing.assert_allclose(traj.t_c, spec.predict(PROG, TIMES).t_c, atol=1e-12)
    # a step response starts flat for the delay and the ramp response is its integral
    x = np.linspace(0, 200, 4001)
    m = spec.linear_model()
    assert np.all(m.step(x[x <= 2.0]) == 0.0)
    integral = np.concatenate(([0], np.cumsum(0.5 * (m.step(x)[1:] + m.step(x)[:-1]) * np.diff(x))))
    np.testing.assert_allclose(m.ramp(x), integral, atol=1e-4)


def test_augment_returns_new_model_and_validates():
    base = ModelSpec(2400.0, 3.0)
    lag = EFFECTS["chamber_lag"].augment(base, (300.0,))
    assert base.effect == "none" and dict(base.parameters) == {}
    assert lag.effect == "chamber_lag" and lag.parameters["tau_chamber_s"] == 300.0
    assert EFFECTS["chamber_cycling"].n_params == 3 and EFFECTS["dead_time"].n_params == 1
    assert lag.is_linear and not EFFECTS["asymmetric_tau"].augment(base, (2000.0, 2800.0)).is_linear
    with pytest.raises(ParameterError, match="unknown effect"):
        ModelSpec(2400.0, 3.0, "gremlins", {})
    with pytest.raises(ParameterError, match="missing"):
        ModelSpec(2400.0, 3.0, "dead_time", {})
    with pytest.raises(ParameterError, match="outside its range"):
        ModelSpec(2400.0, 3.0, "dead_time", {"delay_s": -5.0})
    with pytest.raises(ParameterError, match="dt0_slope"):
        LinearEffectModel(2400.0, 3.0, dt0_slope_c_per_c=0.9)


def test_rate_limit_gives_planner_limits():
    spec = ModelSpec(
        2400.0,
        3.0,
        "chamber_rate_limit",
        {"max_cool_rate_c_per_min": 0.6, "max_heat_rate_c_per_min": 20.0},
    )
    lim = spec.planner_limits()
    assert lim.rate_min_c_per_min == pytest.approx(-0.6)
    assert lim.rate_max_c_per_min == 3.0
    assert ModelSpec(2400.0, 3.0).planner_limits().rate_min_c_per_min == -1.0


def test_model_file_round_trip(tmp_path):
    for spec in (
        ModelSpec(2000.0, 2.5, "second_time_constant", {"tau2_s": 500.0}),
        ModelSpec(
            2000.0,
            2.5,
            "chamber_cycling",
            {"amplitude_c": 0.5, "period_s": 900.0, "phase_rad": 1.0},
        ),
    ):
        path = write_model(tmp_path / f"{spec.effect}.json", spec)
        back = load_model(path)
        assert back == spec
        traj = simulate_effect(PROG, back, TIMES)
        np.testing.assert_allclose(traj.t_c, spec.predict(PROG, TIMES).t_c)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"tau_s": 2400}))
    with pytest.raises(ParameterError, match="tau_s, dt0_c"):
        load_model(bad)
    bad.write_text("{not json")
    with pytest.raises(ParameterError, match="not valid JSON"):
        load_model(bad)
    with pytest.raises(ParameterError, match="does not exist"):
        load_model(tmp_path / "missing.json")


def test_planner_params_match_the_mean_delay():
    """tau of the first-order equivalent = first moment of the impulse response: the
    large-x asymptote of the unit-ramp response is x - tau_equivalent."""
    for spec in (
        ModelSpec(2400.0, 3.0, "dead_time", {"delay_s": 300.0}),
        ModelSpec(2400.0, 3.0, "chamber_lag", {"tau_chamber_s": 600.0}),
        ModelSpec(2400.0, 3.0, "selfheat_slope", {"dt0_slope_c_per_c": 0.04}),
    ):
        m = spec.linear_model()
        x = 2000.0
        tau_eq_min = x - m.ramp(np.array([x]))[0] / 1.0
        assert spec.planner_params().tau_min == pytest.approx(tau_eq_min, rel=1e-9)
        assert spec.planner_params().dt0_c == 3.0


def test_vectorised_nonlinear_updates_equal_step_by_step_loops():
    """The run-vectorised limiter and asymmetric lag equal plain per-step loops."""
    from schedsyn.effects import _rate_limited_step, lag_foh_asymmetric, rate_limited

    rng = np.random.default_rng(7)
    for _ in range(30):
        n, h = int(rng.integers(2, 400)), float(rng.uniform(0.05, 1.0))
        s = 20.0 + np.cumsum(np.repeat(rng.uniform(-3, 3, n // 10 + 1), 10)[:n] * h)
        c, r = rng.uniform(0.2, 2.0, 2)
        loop = [s[0]]
        for k in range(n - 1):
            loop.append(_rate_limited_step(loop[-1], s[k], s[k + 1], h, c, r))
        np.testing.assert_allclose(rate_limited(s, h, c, r), loop, atol=1e-9)
        th, tc = rng.uniform(5.0, 60.0, 2)
        t = [float(rng.uniform(10, 30))]
        for k in range(n - 1):  # T[k+1] = a T + (1-a) v0 + (v1 - v0)(1 - tau (1-a)/h)
            tau = th if 0.5 * (s[k] + s[k + 1]) > t[-1] else tc
            a = math.exp(-h / tau)
            t.append(a * t[-1] + (1 - a) * s[k] + (s[k + 1] - s[k]) * (1 - tau * (1 - a) / h))
        np.testing.assert_allclose(lag_foh_asymmetric(s, t[0], th, tc, h), t, atol=1e-9)


@pytest.mark.parametrize("r_c_per_h", [0.5, -1.2])
def test_dt0_drift_matches_ode_and_goes_through_the_planner_model(r_c_per_h):
    """dT0 = dt0 + r t: the exact prediction, the gradient, and the affine response the
    planner's LP uses (the drift lives in the free response; the rates' matrix is the
    base model's)."""
    spec = ModelSpec(2400.0, 3.0, "dt0_drift", {"dt0_drift_c_per_h": r_c_per_h})
    r = r_c_per_h / 60.0

    def rhs(t, x):
        return [_rate(t), (x[0] + 3.0 + r * t - x[1]) / 40.0]

    ref = _integrate(rhs, [20.0, 17.0])
    pred = spec.predict(PROG, TIMES, t0_c=17.0)
    np.testing.assert_allclose(pred.t_c, ref[1], atol=1e-7)
    g_ref = (ref[0] + 3.0 + r * TIMES - ref[1]) / 40.0
    np.testing.assert_allclose(pred.g_c_per_min, g_ref, atol=1e-8)
    resp = affine_response(spec.linear_model(), PROG.durations_min, TIMES, 20.0, 17.0)
    base = affine_response(FirstOrderLag(ThermalParams()), PROG.durations_min, TIMES, 20.0, 17.0)
    np.testing.assert_array_equal(resp.a_t, base.a_t)
    np.testing.assert_allclose(resp.evaluate(PROG.rates_c_per_min)[0], ref[1], atol=1e-7)
    # the first-order heuristics take the offset in the middle of a 9-hour run
    assert spec.planner_params().dt0_c == pytest.approx(3.0 + r_c_per_h * 4.5)
    assert spec.planner_params().tau_s == 2400.0


@pytest.mark.parametrize("k_per_c", [0.008, -0.006])
def test_tau_temperature_matches_ode(k_per_c):
    spec = ModelSpec(2400.0, 3.0, "tau_temperature", {"tau_slope_per_c": k_per_c})

    def rhs(t, x):
        return [(_setpoint(t) + 3.0 - x[0]) / (40.0 * (1.0 + k_per_c * (x[0] - 20.0)))]

    ref = _integrate(rhs, [17.0])
    pred = spec.predict(PROG, TIMES, t0_c=17.0, grid_min=0.05)
    np.testing.assert_allclose(pred.t_c, ref[0], atol=5e-5)  # linear interpolation
    g_ref = (np.array([_setpoint(t) for t in TIMES]) + 3.0 - ref[0]) / (
        40.0 * (1.0 + k_per_c * (ref[0] - 20.0))
    )
    np.testing.assert_allclose(pred.g_c_per_min, g_ref, atol=5e-5)
    # the default grid (1/6 min) is within a thousandth of a degree
    np.testing.assert_allclose(spec.predict(PROG, TIMES, t0_c=17.0).t_c, ref[0], atol=1e-3)


def test_tau_temperature_without_slope_is_the_base_lag():
    flat = ModelSpec(2400.0, 3.0, "tau_temperature", {"tau_slope_per_c": 0.0})
    base = simulate(PROG, ThermalParams(), t0_c=17.0, dt_min=0.5)
    pred = flat.predict(PROG, base.time_min, t0_c=17.0, grid_min=0.5)
    np.testing.assert_allclose(pred.t_c, base.t_c, atol=1e-9)


@pytest.mark.parametrize(
    ("effect", "values"),
    [
        ("dt0_drift", {"dt0_drift_c_per_h": 11.0}),
        ("tau_temperature", {"tau_slope_per_c": -0.02}),
    ],
)
def test_new_effects_refuse_parameters_outside_their_range(effect, values):
    with pytest.raises(ParameterError, match=next(iter(values))):
        ModelSpec(2400.0, 3.0, effect, values)


def test_tau_temperature_is_linearised_where_the_plan_works():
    """The planner's linear part of tau(T) uses tau at the working region's middle: its
    step response there matches the nonlinear model's for a small step around it."""
    spec = ModelSpec(2400.0, 3.0, "tau_temperature", {"tau_slope_per_c": -0.006})
    assert spec.tau_at(-40.0) == pytest.approx(2400.0 * 1.36)
    assert spec.linear_model().tau_s == 2400.0  # default: at 20 degC
    lin = spec.linear_model(around_c=-40.0)
    assert lin.tau_s == pytest.approx(2400.0 * 1.36)
    assert spec.planner_params(around_c=-40.0).tau_s == pytest.approx(2400.0 * 1.36)
    # a hold at -43 degC chamber (device settles at -40) from -40.5: tau as linearised
    prog = Programme([200.0], [0.0], -43.0)
    times = np.linspace(0.0, 200.0, 41)
    pred = spec.predict(prog, times, t0_c=-40.5, grid_min=0.05)
    lin_t = affine_response(lin, prog.durations_min, times, -43.0, -40.5).evaluate([0.0])[0]
    np.testing.assert_allclose(pred.t_c, lin_t, atol=2e-3)
    base_t = affine_response(spec.linear_model(), prog.durations_min, times, -43.0, -40.5)
    assert np.max(np.abs(base_t.evaluate([0.0])[0] - pred.t_c)) > 0.02  # tau at 20 is off


_EVERY_EFFECT = {
    "none": {},
    "chamber_lag": {"tau_chamber_s": 400.0},
    "chamber_rate_limit": {"max_cool_rate_c_per_min": 0.6, "max_heat_rate_c_per_min": 1.5},
    "chamber_cycling": {"amplitude_c": 0.4, "period_s": 900.0, "phase_rad": 0.7},
    "dead_time": {"delay_s": 240.0},
    "second_time_constant": {"tau2_s": 500.0},
    "selfheat_slope": {"dt0_slope_c_per_c": 0.02},
    "dt0_drift": {"dt0_drift_c_per_h": 0.2},
    "asymmetric_tau": {"tau_heat_s": 2000.0, "tau_cool_s": 2900.0},
    "tau_temperature": {"tau_slope_per_c": 0.004},
}


@pytest.mark.parametrize("effect", list(_EVERY_EFFECT))
def test_the_fits_channels_are_predict_s_own_numbers(effect):
    """``predict_channels`` (what the diagnosis fits call, thousands of times, without the
    gradient) gives exactly ``predict``'s temperature and air, with and without air
    times, on samples that do not fall on the simulation grid."""
    assert set(_EVERY_EFFECT) == {"none", *EFFECTS}  # every effect has a case
    spec = ModelSpec(2300.0, 2.5, effect, _EVERY_EFFECT[effect])
    rng = np.random.default_rng(5)
    t = np.sort(rng.uniform(0.0, PROG.total_min + 20.0, 211))
    air_t = np.sort(rng.uniform(0.0, PROG.total_min, 97))
    for grid_min in (None, 1.0 / 3.0):
        temp, none = spec.predict_channels(PROG, t, None, t0_c=19.0, grid_min=grid_min)
        assert none is None
        both = spec.predict(PROG, np.concatenate((t, air_t)), t0_c=19.0, grid_min=grid_min)
        temp2, air = spec.predict_channels(PROG, t, air_t, t0_c=19.0, grid_min=grid_min)
        np.testing.assert_array_equal(temp2, both.t_c[: t.size])
        np.testing.assert_array_equal(air, both.tk_air_c[t.size :])
        if effect != "chamber_rate_limit":  # there the samples are the limiter's knots
            alone = spec.predict(PROG, t, t0_c=19.0, grid_min=grid_min)
            np.testing.assert_array_equal(temp, alone.t_c)


def test_the_rate_limited_air_kept_for_the_next_call_is_the_right_one():
    """The limiter's air is kept between calls (a fit holds the limits while it fits the
    device): each answer equals a fresh computation whatever was asked before (another
    limit, programme, grid or samples), and changing a returned array changes no later
    answer."""
    from schedsyn import effects

    rng = np.random.default_rng(11)
    other = Programme([30.0, 20.0, 40.0, 60.0, 25.0], [-1.0, 0.0, 2.0, -0.5, 0.0], 20.0)
    samples = np.sort(rng.uniform(0.0, PROG.total_min, 50))
    grid = effects.uniform_grid_min(PROG.total_min, 1.0 / 3.0)
    asks = [
        (PROG, grid, 1.0 / 3.0, samples, 0.5, 2.0),
        (PROG, grid, 1.0 / 3.0, samples, 0.4, 2.0),  # another cooling limit
        (PROG, grid, 1.0 / 3.0, samples, 0.5, 1.0),  # another heating limit
        (other, grid, 1.0 / 3.0, samples, 0.5, 2.0),  # same durations, other temperatures
        (PROG, grid, 1.0 / 3.0, samples + 0.05, 0.5, 2.0),  # other samples
        (PROG, grid, 1.0 / 3.0, None, 0.5, 2.0),
        (PROG, effects.uniform_grid_min(PROG.total_min, 0.25), 0.25, samples, 0.5, 2.0),
    ]

    def fresh(args):
        effects._LIMITED_AIR_CACHE.clear()
        return effects._rate_limited_air(*args)

    expected = [fresh(a) for a in asks]
    assert len({e[0].tobytes() for e in expected}) == len(asks)  # every ask differs
    effects._LIMITED_AIR_CACHE.clear()
    for _ in range(2):  # second round: every answer from the cache
        for args, (air_e, at_e) in zip(asks, expected, strict=True):
            air, at = effects._rate_limited_air(*args)
            np.testing.assert_array_equal(air, air_e)
            if at_e is None:
                assert at is None
            else:
                np.testing.assert_array_equal(at, at_e)
                at += 100.0  # the caller's copy
            air += 100.0
    assert len(effects._LIMITED_AIR_CACHE) == len(asks)


@pytest.mark.parametrize("effect", list(_EVERY_EFFECT))
def test_a_fit_s_unchecked_model_is_the_checked_one(effect):
    """The diagnosis fits build their trial models without the value checks
    (``ModelSpec.unchecked``): the same model, the same predictions."""
    params = dict(_EVERY_EFFECT[effect])
    fast = ModelSpec.unchecked(2300.0, 2.5, effect, params)
    checked = ModelSpec(2300.0, 2.5, effect, params)
    assert fast == checked and fast.is_linear == checked.is_linear
    a, b = fast.predict(PROG, TIMES, t0_c=19.0), checked.predict(PROG, TIMES, t0_c=19.0)
    np.testing.assert_array_equal(a.t_c, b.t_c)
    np.testing.assert_array_equal(a.tk_air_c, b.tk_air_c)


def test_a_model_pickles_for_process_pool_workers():
    """A model crosses to process-pool workers (sweeps through it): its read-only
    parameters are rebuilt, equal and still read-only."""
    import pickle

    model = ModelSpec(2100.0, 1.5, "asymmetric_tau", {"tau_heat_s": 1800.0, "tau_cool_s": 2600.0})
    back = pickle.loads(pickle.dumps(model))
    assert back == model and dict(back.parameters) == dict(model.parameters)
    with pytest.raises(TypeError):
        back.parameters["tau_heat_s"] = 1.0
