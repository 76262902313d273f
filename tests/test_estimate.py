"""Kalman gradient estimation: discretisation vs scipy, filter/smoother vs batch Gaussian
conditioning, accuracy on synthetic logs with known truth, real TCLab logs."""

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.signal import lfilter

from schedsyn.cli import main
from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.estimate import (
    MAX_ML_ROWS,
    N_DIFFUSE,
    chamber_reading_noise_c,
    estimate_gradient,
    estimate_gradient_model,
    filter_smooth,
    finite_difference_gradient,
    kalman_filter,
    kinematic_transition,
    lag_input,
    lag_transition,
    quantisation_step,
    rts_smoother,
)
from schedsyn.logs import log_from_frame
from schedsyn.model import FirstOrderLag
from schedsyn.params import ThermalParams
from schedsyn.programme import Programme, read_steps
from schedsyn.synth import synth_log

TCLAB = Path(__file__).resolve().parent / "data" / "tclab"  # real logs, BSD-3 (README)
BASELINE = "data/baseline_exp1_steps.csv"


def _lag(tau_min):
    """The first-order lag with time constant ``tau_min`` minutes."""
    return FirstOrderLag(ThermalParams(tau_s=60.0 * tau_min))


def _van_loan(a_cont, g_vec, q, h):
    """Exact (F, Q) of dx = A x dt + G dW (density q) over h, by Van Loan's matrix exponential."""
    n = a_cont.shape[0]
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n] = -a_cont
    big[:n, n:] = q * np.outer(g_vec, g_vec)
    big[n:, n:] = a_cont.T
    e = expm(big * h)
    f = e[n:, n:].T
    return f, f @ e[:n, n:]


@pytest.mark.parametrize("h", [1 / 60, 1 / 6, 1.0, 37.0])
def test_kinematic_discretisation_matches_van_loan(h):
    q = 2.5e-3
    f, qd = _van_loan(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), q, h)
    a, b, q11, q12, q22 = kinematic_transition(np.array([h]), q)
    np.testing.assert_allclose([a[0], b[0]], [f[0, 0], f[0, 1]], rtol=1e-12)
    np.testing.assert_allclose([q11[0], q12[0], q22[0]], [qd[0, 0], qd[0, 1], qd[1, 1]], rtol=1e-9)


@pytest.mark.parametrize("h", [1 / 60, 1 / 6, 0.39, 5.0, 120.0])
def test_lag_discretisation_matches_van_loan(h):
    q, tau = 3e-4, 40.0
    a_cont = np.array([[-1.0 / tau, 1.0], [0.0, 0.0]])
    f, qd = _van_loan(a_cont, np.array([0.0, 1.0]), q, h)
    a, b, q11, q12, q22 = lag_transition(np.array([h]), _lag(tau), q)
    np.testing.assert_allclose([a[0], b[0]], [f[0, 0], f[0, 1]], rtol=1e-11)
    np.testing.assert_allclose([q11[0], q12[0], q22[0]], [qd[0, 0], qd[0, 1], qd[1, 1]], rtol=1e-6)


def test_lag_input_matches_ode():
    params = ThermalParams(tau_s=1800.0, dt0_c=2.0)
    model = FirstOrderLag(params)
    h, tk0, tk1, t_start = 7.5, -10.0, 5.0, 3.0
    u = lag_input(np.array([h]), np.array([tk0]), np.array([tk1]), model)[0]
    a, *_ = lag_transition(np.array([h]), model, 1.0)

    def rhs(t, x):
        tk = tk0 + (tk1 - tk0) * t / h
        return [(tk + params.dt0_c - x[0]) / params.tau_min]

    sol = solve_ivp(rhs, (0.0, h), [t_start], rtol=1e-11, atol=1e-12)
    assert a[0] * t_start + u == pytest.approx(sol.y[0, -1], abs=1e-9)


def _batch_posterior(y, a, b, u, q11, q12, q22, r, x0, p0):
    """Smoothed mean/cov and -2 log L of y[N_DIFFUSE:] | y[:N_DIFFUSE] by dense algebra."""
    n = len(y)
    # x = M (z) + c with z = (x0 - prior, w_1..w_{n-1}) all independent Gaussians
    mean = np.zeros((n, 2))
    mean[0] = x0
    blocks = [np.array([[p0[0], p0[1]], [p0[1], p0[2]]])]
    trans = [np.eye(2)]
    for k in range(1, n):
        fk = np.array([[a[k], b[k]], [0.0, 1.0]])
        mean[k] = fk @ mean[k - 1] + [u[k], 0.0]
        trans.append(fk)
        blocks.append(np.array([[q11[k], q12[k]], [q12[k], q22[k]]]))
    big = np.zeros((2 * n, 2 * n))  # x_k = sum_{j<=k} Phi(k, j) z_j
    for k in range(n):
        phi = np.eye(2)
        for j in range(k, -1, -1):
            big[2 * k : 2 * k + 2, 2 * j : 2 * j + 2] = phi
            phi = phi @ trans[j]
    cz = np.zeros((2 * n, 2 * n))
    for j in range(n):
        cz[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = blocks[j]
    cov_x = big @ cz @ big.T
    obs = np.flatnonzero(np.isfinite(y))
    hsel = np.zeros((obs.size, 2 * n))
    hsel[np.arange(obs.size), 2 * obs] = 1.0
    s = hsel @ cov_x @ hsel.T + r * np.eye(obs.size)
    gain = cov_x @ hsel.T @ np.linalg.inv(s)
    resid = y[obs] - mean.ravel()[2 * obs]
    post_mean = mean.ravel() + gain @ resid
    post_cov = cov_x - gain @ hsel @ cov_x

    def m2ll(idx):
        ss = s[np.ix_(idx, idx)]
        rr = resid[idx]
        quad = rr @ np.linalg.solve(ss, rr)
        return idx.size * np.log(2 * np.pi) + np.linalg.slogdet(ss)[1] + quad

    full = m2ll(np.arange(obs.size))
    head = m2ll(np.arange(N_DIFFUSE))
    return post_mean.reshape(n, 2), post_cov, full - head


@pytest.mark.parametrize("kind", ["kinematic", "lag"])
def test_filter_and_smoother_equal_batch_conditioning(kind, rng):
    n = 25
    t = np.cumsum(rng.uniform(0.05, 0.5, n))
    t[15:] += 3.0  # a gap
    h = np.concatenate(([0.0], np.diff(t)))
    y = 20.0 + 0.3 * t + 0.05 * rng.standard_normal(n)
    y[[4, 5, 20]] = np.nan
    q, r = 0.02, 0.003
    if kind == "kinematic":
        a, b, q11, q12, q22 = kinematic_transition(h, q)
        u = np.zeros(n)
    else:
        a, b, q11, q12, q22 = lag_transition(h, _lag(2.0), q)
        tk = 25.0 + 3.0 * np.sin(t)
        u = np.concatenate(
            ([0.0], lag_input(h[1:], tk[:-1], tk[1:], FirstOrderLag(ThermalParams(tau_s=120.0))))
        )
    x0, p0 = (19.0, 0.1), (4.0, 0.3, 0.5)
    args = [v.tolist() for v in (a, b, u, q11, q12, q22)]
    filt, pred, innov, svar, m2ll = kalman_filter(y.tolist(), *args, r, x0, p0)
    sm = rts_smoother(filt, pred, a.tolist(), b.tolist(), *args[3:])
    mean, cov, m2ll_batch = _batch_posterior(y, a, b, u, q11, q12, q22, r, x0, p0)
    np.testing.assert_allclose(sm[0], mean[:, 0], atol=1e-9)
    np.testing.assert_allclose(sm[1], mean[:, 1], atol=1e-9)
    np.testing.assert_allclose(sm[2], np.diag(cov)[0::2], rtol=1e-6)
    # P12 is a difference of products and may be tiny by cancellation: judge its error
    # against its natural scale sqrt(P11 P22) (|P12| <= that, Cauchy-Schwarz)
    scale12 = np.sqrt(np.diag(cov)[0::2] * np.diag(cov)[1::2])
    assert np.all(np.abs(sm[3] - np.diag(cov, 1)[0::2]) <= 1e-6 * scale12)
    np.testing.assert_allclose(sm[4], np.diag(cov)[1::2], rtol=1e-6)
    assert m2ll == pytest.approx(m2ll_batch, rel=1e-9)
    assert np.isnan(innov[4]) and np.isnan(svar[20]) and np.isfinite(innov[3])


@pytest.fixture(scope="module")
def baseline():
    return read_steps(BASELINE)


@pytest.fixture(scope="module")
def synth10(baseline):
    return synth_log(baseline, sample_s=10.0, noise_c=0.02, quant_c=0.01, seed=11)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_smoother_accuracy_on_synthetic_log(synth10):
    """Acceptance: RMS error < 0.01 degC/min and >= 5x better than a finite difference."""
    log = log_from_frame(synth10)
    truth = synth10["g_true_c_per_min"].to_numpy()
    est = estimate_gradient(log)
    err = _rms(est.g_est_c_per_min - truth)
    fd = _rms(finite_difference_gradient(log.time_s, log.t_int_c) - truth)
    assert err < 0.01
    assert fd >= 5 * err
    # ML finds the sensor noise: 0.02^2 + 0.01^2/12 (quantisation)
    assert est.noise.quant_c == pytest.approx(0.01)
    assert est.r == pytest.approx(0.02**2 + 0.01**2 / 12, rel=0.15)
    assert set(est.noise.fitted) == {"q", "r"}
    # the reported uncertainty is not overconfident, and the innovations are ~ N(0, 1)
    z = (est.g_est_c_per_min - truth) / est.g_std_c_per_min
    assert _rms(z) < 1.5
    zi = est.normalised_innovations[np.isfinite(est.normalised_innovations)]
    assert 0.9 < np.std(zi) < 1.1
    frame = est.to_frame()
    assert list(frame.columns[:4]) == ["time_s", "t_est_c", "g_est_c_per_min", "g_std_c_per_min"]
    assert len(frame) == len(synth10)


def test_model_based_beats_kinematic_with_right_model(synth10):
    log = log_from_frame(synth10)
    truth = synth10["g_true_c_per_min"].to_numpy()
    kin = estimate_gradient(log)
    mod = estimate_gradient_model(log)
    assert mod.method == "model" and mod.params == ThermalParams()
    assert _rms(mod.g_est_c_per_min - truth) < 0.2 * _rms(kin.g_est_c_per_min - truth)
    # the two agree within their stated uncertainty
    diff = mod.g_est_c_per_min - kin.g_est_c_per_min
    assert _rms(diff / np.hypot(kin.g_std_c_per_min, mod.g_std_c_per_min)) < 1.5
    # the same data are better explained (higher likelihood) by the right model
    assert mod.log_likelihood > kin.log_likelihood


def test_model_based_with_wrong_model_falls_back_on_the_correction(synth10):
    """tau 25 % too small: the correction d takes up the error, estimate stays usable (within
    the 0.01 degC/min acceptance with margin; it was 1.5x the kinematic error, which has
    since halved with the kinks modelled)."""
    log = log_from_frame(synth10)
    truth = synth10["g_true_c_per_min"].to_numpy()
    right = estimate_gradient_model(log)
    wrong = estimate_gradient_model(log, ThermalParams(tau_s=1800.0))
    kin = estimate_gradient(log)
    assert wrong.q > 100 * right.q  # the fit notices the mismatch
    assert wrong.log_likelihood < right.log_likelihood
    assert _rms(wrong.g_est_c_per_min - truth) < 0.005
    assert _rms(wrong.g_est_c_per_min - truth) < 2.5 * _rms(kin.g_est_c_per_min - truth)


def test_model_driven_by_a_noisy_air_reading_counts_its_noise(synth10, rng):
    """g = (Tk + dT0 - T)/tau + d takes the air reading's noise straight in: its stated
    std must too (it ignored it: 4-20 % of errors within 2 sigma; stress test)."""
    frame = synth10.copy()
    truth = frame["g_true_c_per_min"].to_numpy()
    for noise in (0.05, 0.2):
        frame["tk_air_c"] = frame["tk_set_c"] + rng.normal(0.0, noise, len(frame))
        log = log_from_frame(frame)
        assert chamber_reading_noise_c(log.time_s, log.tk_air_c) == pytest.approx(noise, rel=0.1)
        est = estimate_gradient_model(log, chamber="tk_air_c")
        err = est.g_est_c_per_min - truth
        assert np.mean(np.abs(err) <= 2.0 * est.g_std_c_per_min) > 0.9
        assert 0.7 < _rms(err / est.g_std_c_per_min) < 1.3
    # the programme's setpoint is exact (its corners are few): no noise to add
    log = log_from_frame(synth10)
    assert chamber_reading_noise_c(log.time_s, log.tk_set_c) < 0.01


@pytest.mark.parametrize(("order", "nan_growth"), [(2, 1.1), (3, 1.01)])
def test_nan_rows_and_gaps_keep_every_row(baseline, order, nan_growth):
    """(Order 3's gradient is smooth, so two minutes without readings widen its band less;
    with its long smoother, most at the span's edges: the slope across it is known.)"""
    df = synth_log(baseline, sample_s=10.0, seed=5)
    df.loc[1000:1011, "t_int_c"] = np.nan  # two minutes without readings
    df = df.drop(index=range(2000, 2090)).reset_index(drop=True)  # 15 min gap
    log = log_from_frame(df)
    assert log.gaps and log.nan_counts["t_int_c"] == 12
    est = estimate_gradient(log, order=order)
    assert len(est.to_frame()) == len(df)
    assert np.all(np.isfinite(est.g_est_c_per_min)) and np.all(np.isfinite(est.t_est_c))
    assert np.isnan(est.innovation_c[1000:1012]).all()
    # uncertainty grows inside the NaN span and across the gap
    std = est.g_std_c_per_min
    assert np.max(std[996:1016]) > nan_growth * std[970]
    i_gap = int(np.searchsorted(log.time_s, log.gaps[0][0]))
    assert std[i_gap] > 1.5 * np.median(std)
    truth = df["g_true_c_per_min"].to_numpy()
    assert _rms((est.g_est_c_per_min - truth) / std) < 1.5


def test_user_overrides_noise_levels(synth10):
    log = log_from_frame(synth10)
    est = estimate_gradient(log, q=1e-3, r=5e-4)
    assert (est.q, est.r, est.noise.fitted) == (1e-3, 5e-4, ())
    only_r = estimate_gradient(log, q=1e-3)
    assert only_r.noise.fitted == ("r",) and only_r.q == 1e-3
    # a smaller q smooths more: lower stated gradient uncertainty
    smooth = estimate_gradient(log, q=1e-5, r=5e-4)
    assert np.median(smooth.g_std_c_per_min) < np.median(est.g_std_c_per_min)
    with pytest.raises(ParameterError, match="q must be > 0"):
        estimate_gradient(log, q=0.0)
    with pytest.raises(ParameterError, match="r must be > 0"):
        estimate_gradient(log, r=float("nan"))


def test_model_based_needs_chamber_column():
    t = 10.0 * np.arange(50)
    log = log_from_frame(pd.DataFrame({"time_s": t, "t_int_c": 20 + 0.001 * t}), source="a.csv")
    with pytest.raises(LogFormatError, match="a.csv.*tk_set_c"):
        estimate_gradient_model(log)
    tk = np.full(50, 20.0)
    tk[7] = np.nan
    log2 = log_from_frame(pd.DataFrame({"time_s": t, "t_int_c": 20 + 0.001 * t, "tk_set_c": tk}))
    with pytest.raises(LogFormatError, match="tk_set_c has 1 NaN row.*row 8"):
        estimate_gradient_model(log2)
    with pytest.raises(ParameterError, match="chamber"):
        estimate_gradient_model(log2, chamber="tk")


def test_long_log_uses_a_strided_search_and_still_fits(baseline):
    """A 1 s log (32 400 rows): noise search on a strided copy, final pass at full rate."""
    df = synth_log(baseline, sample_s=1.0, noise_c=0.02, quant_c=0.01, seed=2)
    assert len(df) > 10 * MAX_ML_ROWS
    log = log_from_frame(df)
    est = estimate_gradient(log)
    truth = df["g_true_c_per_min"].to_numpy()
    assert est.r == pytest.approx(0.02**2 + 0.01**2 / 12, rel=0.15)
    assert _rms(est.g_est_c_per_min - truth) < 0.01
    mod = estimate_gradient_model(log)
    assert _rms(mod.g_est_c_per_min - truth) < 0.002


def test_quantisation_step_detection(rng):
    grid = 0.01 * np.round(rng.normal(0, 1, 500) / 0.01)
    assert quantisation_step(grid) == pytest.approx(0.01)
    assert quantisation_step(rng.normal(0, 1, 500)) == 0.0
    uneven = np.cumsum(rng.choice([0.32, 0.33], 200))  # TCLab-like ADC grid
    assert quantisation_step(uneven) == pytest.approx(0.32)


def test_finite_difference_is_exact_on_a_line():
    t = np.array([0.0, 30.0, 45.0, 100.0, 160.0])
    np.testing.assert_allclose(finite_difference_gradient(t, 5.0 + 0.02 * t), 1.2)


def _tclab_logs():
    if not TCLAB.is_dir():
        return []
    return sorted(TCLAB.glob("*step_50_run_*.csv")) + sorted(TCLAB.glob("*sin_5_50_run_1.csv"))


@pytest.mark.skipif(not TCLAB.is_dir(), reason="../shared/data/tclab not present")
@pytest.mark.parametrize("path", _tclab_logs(), ids=lambda p: p.name)
def test_real_tclab_logs(path):
    """Real, coarsely quantised (~0.32 degC) logs: sensible estimates, r near step^2/12."""
    raw = pd.read_csv(path)
    log = log_from_frame(
        pd.DataFrame({"time_s": raw["Time"], "t_int_c": raw["T1"]}), source=str(path)
    )
    est = estimate_gradient(log)
    step = est.noise.quant_c
    assert step == pytest.approx(0.32, abs=0.01)
    assert step**2 / 12 <= est.r < 1.3 * step**2 / 12
    assert np.all(np.isfinite(est.g_std_c_per_min)) and np.all(est.g_std_c_per_min > 0)
    # the smoothed temperature stays within one quantisation step of every reading
    assert np.max(np.abs(est.t_est_c - log.t_int_c)) < step
    # far smoother than a finite difference of the raw readings
    fd = finite_difference_gradient(log.time_s, log.t_int_c)
    assert np.std(np.diff(est.g_est_c_per_min)) < 0.1 * np.std(np.diff(fd))
    # heated from room temperature: the mean gradient equals the net rise over the run
    net = (log.t_int_c[-1] - log.t_int_c[0]) / (log.time_min[-1] - log.time_min[0])
    mean_g = np.trapezoid(est.g_est_c_per_min, log.time_min) / (log.time_min[-1])
    assert mean_g == pytest.approx(net, abs=0.05)


def test_ml_noise_levels_beat_a_brute_force_grid(rng):
    """The optimiser's (q, r) is at least as likely as every point of a coarse grid
    (a TCLab-like coarsely quantised heating curve, 1 s sampling)."""
    t = np.arange(900.0)
    temp = 23.0 + 40.0 * (1.0 - np.exp(-t / 180.0)) + 0.05 * rng.standard_normal(t.size)
    y = 0.32 * np.round(temp / 0.32)
    log = log_from_frame(pd.DataFrame({"time_s": t, "t_int_c": y}))
    est = estimate_gradient(log)
    assert est.noise.quant_c == pytest.approx(0.32)
    grid = [
        estimate_gradient(log, q=q, r=r).minus2_log_likelihood
        for q in 10.0 ** np.arange(-3.0, 3.5, 0.5)
        for r in est.noise.quant_c**2 / 12 * np.array([1.0, 1.2, 1.5, 2.0])
    ]
    assert est.minus2_log_likelihood <= min(grid) + 0.5


def _fq(kind, h, q, tau=40.0):
    a, b, q11, q12, q22 = (
        kinematic_transition(np.array([h]), q)
        if kind == "kinematic"
        else lag_transition(np.array([h]), _lag(tau), q)
    )
    f = np.array([[a[0], b[0]], [0.0, 1.0]])
    return f, np.array([[q11[0], q12[0]], [q12[0], q22[0]]])


@settings(max_examples=60, deadline=None)
@given(
    h1=st.floats(1e-3, 200.0), h2=st.floats(1e-3, 200.0), kind=st.sampled_from(["kinematic", "lag"])
)
def test_two_steps_compose_into_one(h1, h2, kind):
    """F(h1 + h2) = F(h2) F(h1) and Q(h1 + h2) = F(h2) Q(h1) F(h2)^T + Q(h2)."""
    q = 1e-3
    f1, q1 = _fq(kind, h1, q)
    f2, q2 = _fq(kind, h2, q)
    f, qq = _fq(kind, h1 + h2, q)
    np.testing.assert_allclose(f, f2 @ f1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(qq, f2 @ q1 @ f2.T + q2, rtol=1e-7, atol=1e-14)


@pytest.mark.parametrize("kind", ["kinematic", "lag"])
def test_steady_state_fast_path_equals_plain_recursions(kind, rng, monkeypatch):
    """filter_smooth (vectorised where the filter is steady) = kalman_filter + rts_smoother
    on a log with NaN rows, a gap and an irregular stretch; the fast path is exercised."""
    import schedsyn.estimate as est_mod

    calls = []
    real_lti = est_mod._lti
    monkeypatch.setattr(est_mod, "_lti", lambda *a: calls.append(1) or real_lti(*a))
    n = 6000
    h = np.full(n, 1.0 / 6.0)  # 10 s steps, in minutes
    h[0] = 0.0
    h[2500] += 15.0  # a 15 min gap
    h[4000:4100] = rng.uniform(0.05, 0.3, 100)  # irregular sampling
    t = np.cumsum(h)
    y = 20.0 + 3.0 * np.sin(t / 30.0) + 0.02 * rng.standard_normal(n)
    y[[50, 51, 3000]] = np.nan
    y[5000:5040] = np.nan
    if kind == "kinematic":
        a, b, q11, q12, q22 = kinematic_transition(h, 1e-3)
        u = np.zeros(n)
    else:
        a, b, q11, q12, q22 = lag_transition(h, _lag(40.0), 1e-4)
        tk = 20.0 + 8.0 * np.sin(t / 25.0)
        u = np.concatenate(([0.0], lag_input(h[1:], tk[:-1], tk[1:], FirstOrderLag())))
    x0, p0 = (y[0], 0.0), (100.0, 0.0, 9.0)
    lists = [v.tolist() for v in (a, b, u, q11, q12, q22)]
    filt, pred, innov, svar, m2ll = kalman_filter(y.tolist(), *lists, 4e-4, x0, p0)
    ref = rts_smoother(filt, pred, a.tolist(), b.tolist(), *lists[3:])
    fast = filter_smooth(y, a, b, u, q11, q12, q22, 4e-4, x0, p0)
    assert len(calls) >= 4  # steady stretches were solved vectorised
    std_t, std_g = np.sqrt(ref[2]), np.sqrt(ref[4])
    np.testing.assert_allclose((fast[0] - ref[0]) / std_t, 0.0, atol=1e-7)
    np.testing.assert_allclose((fast[1] - ref[1]) / std_g, 0.0, atol=1e-7)
    for i in (2, 3, 4):
        np.testing.assert_allclose(fast[i], ref[i], rtol=1e-7, atol=1e-9 * np.max(ref[i]))
    np.testing.assert_allclose(fast[5], innov, atol=1e-9)
    np.testing.assert_allclose(fast[6], svar, rtol=1e-9)
    assert fast[7] == pytest.approx(m2ll, rel=1e-10)
    # likelihood only
    assert filter_smooth(y, a, b, u, q11, q12, q22, 4e-4, x0, p0, smooth=False)[7] == pytest.approx(
        m2ll, rel=1e-10
    )


def test_strided_copy_composes_the_chamber_input_exactly(rng):
    """The noise search's strided copy of a model-based log: its transition over a merged
    step equals the fine steps applied one after another."""
    import schedsyn.estimate as est_mod

    n, tau = 3000, 40.0
    h = np.concatenate(([0.0], rng.uniform(0.01, 0.5, n - 1)))
    u = np.concatenate(([0.0], rng.normal(0.0, 1.0, n - 1)))
    setup = est_mod._Setup(60.0 * np.cumsum(h), rng.normal(size=n), _lag(tau), None, u)
    coarse = setup.stride(7)
    idx = np.arange(0, n, 7)
    np.testing.assert_allclose(coarse.time_s, setup.time_s[idx])
    h_c, _, u_c = coarse.steps(0, idx.size)
    a_c, b_c, *_ = lag_transition(h_c, _lag(tau), 1.0)
    for k in (1, 2, 100, idx.size - 1):
        x = np.array([1.5, -0.2])  # (T, d) through the fine steps
        for j in range(idx[k - 1] + 1, idx[k] + 1):
            a, b, *_ = lag_transition(np.array([h[j]]), _lag(tau), 1.0)
            x = np.array([a[0] * x[0] + b[0] * x[1] + u[j], x[1]])
        direct = a_c[k] * 1.5 + b_c[k] * -0.2 + u_c[k]
        assert direct == pytest.approx(x[0], rel=1e-12, abs=1e-12)


def test_constant_readings_do_not_break_the_noise_search():
    """A sensor that never changes: r goes to its lower bound, not to 0 (no division by 0)."""
    t = np.arange(500.0)
    log = log_from_frame(pd.DataFrame({"time_s": t, "t_int_c": np.full(t.size, 20.0)}))
    est = estimate_gradient(log)
    assert est.r > 0 and np.all(np.isfinite(est.g_std_c_per_min))
    np.testing.assert_allclose(est.g_est_c_per_min, 0.0, atol=1e-9)
    np.testing.assert_allclose(est.t_est_c, 20.0, atol=1e-9)


# -- the order-3 kinematic model (T, g, dg/dt) ------------------------------------------
def _jerk_fq(h, q):
    from schedsyn.estimate import jerk_transition

    f, qq = jerk_transition(np.array([h]), q)
    f11, f12, f13, f22, f23 = f[:, 0]
    q11, q12, q13, q22, q23, q33 = qq[:, 0]
    fm = np.array([[f11, f12, f13], [0.0, f22, f23], [0.0, 0.0, 1.0]])
    qm = np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])
    return fm, qm


@pytest.mark.parametrize("h", [1 / 600, 1 / 6, 1.0, 37.0])
def test_jerk_discretisation_matches_van_loan(h):
    q = 2.5e-5
    a_cont = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    f, qd = _van_loan(a_cont, np.array([0.0, 0.0, 1.0]), q, h)
    fm, qm = _jerk_fq(h, q)
    np.testing.assert_allclose(fm, f, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(qm, qd, rtol=1e-7)


@settings(max_examples=40, deadline=None)
@given(h1=st.floats(1e-3, 200.0), h2=st.floats(1e-3, 200.0))
def test_jerk_two_steps_compose_into_one(h1, h2):
    f1, q1 = _jerk_fq(h1, 1e-4)
    f2, q2 = _jerk_fq(h2, 1e-4)
    f, qq = _jerk_fq(h1 + h2, 1e-4)
    np.testing.assert_allclose(f, f2 @ f1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(qq, f2 @ q1 @ f2.T + q2, rtol=1e-7, atol=1e-14)


def _jerk_setup_rows(t_min, y, q):
    """Rows of the order-3 model over the given times, through the estimator's setup."""
    import schedsyn.estimate as est_mod

    setup = est_mod._Setup(60.0 * np.asarray(t_min), np.asarray(y, float), None, order=3)
    return setup, setup.rows(0, len(y), q)


def _dense_posterior(y, fs, qs, r, x0, p0, n_diffuse):
    """Smoothed means/covariances and -2 log L (after n_diffuse readings) of a linear
    Gaussian state-space model, by conditioning the joint Gaussian of all states."""
    n, d = len(y), len(x0)
    mean = np.zeros((n, d))
    mean[0] = x0
    phis = [np.eye(d)]
    for k in range(1, n):
        mean[k] = fs[k] @ mean[k - 1]
        phis.append(fs[k])
    big = np.zeros((d * n, d * n))  # x_k = sum_{j<=k} Phi(k, j) z_j
    for k in range(n):
        phi = np.eye(d)
        for j in range(k, -1, -1):
            big[d * k : d * k + d, d * j : d * j + d] = phi
            phi = phi @ phis[j]
    cz = np.zeros((d * n, d * n))
    cz[:d, :d] = p0
    for j in range(1, n):
        cz[d * j : d * j + d, d * j : d * j + d] = qs[j]
    cov_x = big @ cz @ big.T
    obs = np.flatnonzero(np.isfinite(y))
    hsel = np.zeros((obs.size, d * n))
    hsel[np.arange(obs.size), d * obs] = 1.0
    s = hsel @ cov_x @ hsel.T + r * np.eye(obs.size)
    gain = cov_x @ hsel.T @ np.linalg.inv(s)
    resid = y[obs] - mean.ravel()[d * obs]
    post_mean = (mean.ravel() + gain @ resid).reshape(n, d)
    post_cov = cov_x - gain @ hsel @ cov_x

    def m2ll(idx):
        ss = s[np.ix_(idx, idx)]
        rr = resid[idx]
        return (
            idx.size * np.log(2 * np.pi) + np.linalg.slogdet(ss)[1] + rr @ np.linalg.solve(ss, rr)
        )

    return post_mean, post_cov, m2ll(np.arange(obs.size)) - m2ll(np.arange(n_diffuse))


def test_order3_filter_and_smoother_equal_batch_conditioning(rng):
    """The three-state recursions, row by row, against dense Gaussian conditioning on
    irregular steps with NaN readings and a gap (the steady-state path is checked
    against these recursions in the next test)."""
    import schedsyn.estimate as est_mod

    n = 25
    t = np.cumsum(rng.uniform(0.05, 0.5, n))
    t[n // 2 :] += 3.0  # a gap
    y = 20.0 + 0.3 * t - 0.01 * t**2 + 0.05 * rng.standard_normal(n)
    y[[4, 5, n - 5]] = np.nan
    q, r = 2e-3, 0.003
    _, rows = _jerk_setup_rows(t, y, q)
    # a moderate prior: the dense check loses precision when a diffuse prior cancels (the
    # estimator's own diffuse prior is checked against the information form below)
    prior = est_mod._Carry((20.0, 0.3, 0.0, 1.0, 0.0, 0.0, 0.1, 0.0, 0.01))
    fwd = est_mod._forward(prior, rows, r, offset=0, store=True, fast=False)
    sm = est_mod._backward(fwd.filt, fwd.pred, fwd.cols, rows, (), None, fast=False)
    fs, qs = [], []
    for k in range(n):
        fm, qm = _jerk_fq(t[k] - t[k - 1] if k else 0.0, q)
        fs.append(fm)
        qs.append(qm)
    x0 = np.array(prior.state[:3])
    p0 = np.diag([prior.state[3], prior.state[6], prior.state[8]])
    mean, cov, m2ll = _dense_posterior(y, fs, qs, r, x0, p0, 3)
    var = np.diag(cov).reshape(n, 3)
    for i, row in ((0, 3), (1, 6), (2, 8)):  # means and variances of T, g, dg/dt
        assert np.max(np.abs(sm[i] - mean[:, i]) / np.sqrt(var[:, i])) < 1e-7
        np.testing.assert_allclose(sm[row], var[:, i], rtol=1e-6)
    # the covariances of T with g and of g with dg/dt, against their scales
    for row, (i, j) in ((4, (0, 1)), (7, (1, 2))):
        dense = np.array([cov[3 * k + i, 3 * k + j] for k in range(n)])
        assert np.all(np.abs(sm[row] - dense) <= 1e-6 * np.sqrt(var[:, i] * var[:, j]))
    assert fwd.m2ll == pytest.approx(m2ll, rel=1e-9)
    assert np.isnan(fwd.innov[4]) and np.isfinite(fwd.innov[3])


def _information_variances(setup, q, r):
    """Posterior variances of every state by inverting the information matrix of the
    whole log (prior, every step's process noise, every reading): no recursion, and no
    cancellation with a diffuse prior (its inverse only adds a little information)."""
    rows = setup.rows(0, setup.n, q)
    f, qq = rows.f[:, rows.idx], rows.q[:, rows.idx]
    n = setup.n
    info = np.zeros((3 * n, 3 * n))
    p = setup.prior().state
    info[:3, :3] = np.linalg.inv(
        np.array([[p[3], p[4], p[5]], [p[4], p[6], p[7]], [p[5], p[7], p[8]]])
    )
    for k in range(1, n):
        f11, f12, f13, f22, f23 = f[:, k]
        q11, q12, q13, q22, q23, q33 = qq[:, k]
        step = np.array([[f11, f12, f13], [0.0, f22, f23], [0.0, 0.0, 1.0]])
        noise = np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])
        a = np.hstack([-step, np.eye(3)])  # x_k - F x_k-1 = w_k
        info[3 * k - 3 : 3 * k + 3, 3 * k - 3 : 3 * k + 3] += a.T @ np.linalg.solve(noise, a)
    seen = np.flatnonzero(np.isfinite(setup.y))
    info[3 * seen, 3 * seen] += 1.0 / r
    return np.diag(np.linalg.inv(info)).reshape(n, 3)


@pytest.mark.parametrize("sparse", [False, True])
def test_smoother_variances_from_the_diffuse_prior_equal_the_information_form(rng, sparse):
    """The estimator's own prior (T 10 degC, g 3 degC/min, a 1 degC/min^2) on a log of
    irregular 40-130 s steps and small noise levels: the smoothed variances of the first
    rows are the difference of numbers ~1e6 larger, and the textbook RTS covariance went
    negative there (row 1's gradient variance -4e-6 against 1.5e-6 on a red team's
    log). Every row's variance of T, g and a against the information form, with and
    without a 40-min gap and missing readings."""
    import schedsyn.estimate as est_mod

    n = 90
    t_s = np.cumsum(rng.uniform(40.0, 130.0, n)) - 40.0
    t_s[0] = 0.0
    y = -12.5 - 0.002 * t_s / 60.0 + 0.002 * rng.standard_normal(n)
    if sparse:
        t_s[n // 2 :] += 2400.0
        y[[3, 4, n - 6]] = np.nan
    q, r = 3.5e-6, 3.4e-6
    setup = est_mod._Setup(t_s, y, None, order=3)
    got = np.full((n, 3), np.nan)

    def emit(rows, sm, innov, svar, states=True):
        got[rows] = sm[[3, 6, 8]].T

    est_mod._smooth(setup, q, r, None, emit, None)
    ref = _information_variances(setup, q, r)
    assert np.all(got > 0.0)
    np.testing.assert_allclose(got, ref, rtol=1e-3)


def test_order3_fast_path_equals_plain_recursions(rng, monkeypatch):
    """Order 3 with the steady-state path = the plain row-by-row recursions, on a log
    with NaN rows, a gap and an irregular stretch (the plain path is checked against
    dense conditioning above)."""
    import schedsyn.estimate as est_mod

    calls = []
    real_lti = est_mod._lti
    monkeypatch.setattr(est_mod, "_lti", lambda *a: calls.append(1) or real_lti(*a))
    n = 6000
    h = np.full(n, 1.0 / 6.0)
    h[0] = 0.0
    h[2500] += 15.0
    h[4000:4100] = rng.uniform(0.05, 0.3, 100)
    t = np.cumsum(h)
    y = 20.0 + 3.0 * np.sin(t / 30.0) + 0.02 * rng.standard_normal(n)
    y[[50, 51, 3000]] = np.nan
    y[5000:5040] = np.nan
    setup, rows = _jerk_setup_rows(t, y, 3e-6)
    prior = setup.prior()
    plain = est_mod._forward(prior, rows, 4e-4, offset=0, store=True, fast=False)
    ref = est_mod._backward(plain.filt, plain.pred, plain.cols, rows, (), None, fast=False)
    fast = est_mod._forward(prior, rows, 4e-4, offset=0, store=True, fast=True)
    out = est_mod._backward(fast.filt, fast.pred, fast.cols, rows, fast.stretches, None, fast=True)
    assert len(calls) >= 4
    for i, var in ((0, 3), (1, 6), (2, 8)):
        err = (out[i] - ref[i]) / np.sqrt(ref[var])
        assert np.max(np.abs(err)) < 1e-6
    for i in range(3, 9):
        np.testing.assert_allclose(out[i], ref[i], rtol=1e-6, atol=1e-9 * np.max(np.abs(ref[i])))
    np.testing.assert_allclose(fast.innov, plain.innov, atol=1e-9)
    assert fast.m2ll == pytest.approx(plain.m2ll, rel=1e-9)


def _lag_closed_form(durations_min, rates_c_per_min, tk0_c, tau_min, dt0_c, times_min):
    """Exact ``(T, g, Tk)`` of ``tau dT/dt + T = Tk + dT0`` under piecewise-linear ``Tk``,
    starting at equilibrium (per segment ``T = Tp + (T_0 - Tp_0) exp(-t/tau)``, ``Tp = Tk
    + dT0 - U tau``); independent of schedsyn's model code."""
    starts = np.concatenate(([0.0], np.cumsum(durations_min)))
    temp_c, tk_c = tk0_c + dt0_c, tk0_c
    out = np.full((3, times_min.size), np.nan)
    for i, (dur, u) in enumerate(zip(durations_min, rates_c_per_min, strict=True)):
        sel = (times_min >= starts[i]) & (times_min <= starts[i + 1])
        s = times_min[sel] - starts[i]
        off = temp_c - (tk_c + dt0_c - u * tau_min)
        decay = np.exp(-s / tau_min)
        out[0, sel] = tk_c + u * s + dt0_c - u * tau_min + off * decay
        out[1, sel] = u - off * decay / tau_min
        out[2, sel] = tk_c + u * s
        temp_c = tk_c + u * dur + dt0_c - u * tau_min + off * np.exp(-dur / tau_min)
        tk_c += u * dur
    return out


def test_model_sigma_holds_at_rate_changes_between_samples():
    """A chamber rate change between two samples of a 60-s log: the model-based gradient's
    error stays within its sigma (the step's input takes the setpoint's corner; linear
    interpolation across it left errors ~1e-4 degC/min at sigma ~1e-6: |z| in the 100s)."""
    durations_min = np.array([20.37, 25.81, 30.55, 15.23, 35.71, 30.0])
    rates_c_per_min = np.array([0.0, 2.5, -0.8, 0.0, 1.7, -1.0])
    tau_min, dt0_c = 1800.0 / 60.0, 2.0
    time_min = np.arange(0.0, durations_min.sum(), 1.0)
    temp_c, g_true, tk_c = _lag_closed_form(
        durations_min, rates_c_per_min, 20.0, tau_min, dt0_c, time_min
    )
    rng = np.random.default_rng(7)
    frame = pd.DataFrame(
        {
            "time_s": time_min * 60.0,
            "t_int_c": temp_c + 0.01 * rng.standard_normal(time_min.size),
            "tk_set_c": tk_c,
        }
    )
    log = log_from_frame(frame, source="corners between samples")
    est = estimate_gradient_model(log, ThermalParams(tau_s=tau_min * 60.0, dt0_c=dt0_c))
    err = est.g_est_c_per_min - g_true
    z = err / est.g_std_c_per_min
    changes_min = np.cumsum(durations_min)[:-1]
    near = np.any(np.abs(time_min[:, None] - changes_min[None, :]) <= 2.5, axis=1)
    assert np.mean(np.abs(z[near]) <= 2.0) >= 0.9
    assert np.max(np.abs(z)) < 5.0
    assert np.sqrt(np.mean(err**2)) < 1e-4


@pytest.mark.parametrize("knot", [2, 3])
def test_a_long_blank_stretch_widens_the_gradient_sigma_not_the_error(knot):
    """t_int_c blank for 70 min around a rate change of the paper-like programme (no
    setpoint: the kinematic smoother): the kink inside cannot be seen, and sigma did not
    know (red team: |z| up to 8-10, 30-55 % within 2 sigma; here 41-68 %). A pass that
    lets the largest kink found elsewhere happen anywhere in the stretch gives the sigmas:
    at least 85 % within 2 sigma there, |z| under 4. Truth: scipy on the table
    (tests/independent.py)."""
    from independent import chamber_knots, ode_trajectories

    from schedsyn.logs import log_from_frame

    kt, ktk = chamber_knots(Path(__file__).parents[1] / "data" / "baseline_exp1_steps.csv")
    t, temp, grad = ode_trajectories(kt, ktk, 2400.0, 3.0, dt_min=1 / 3)
    y = temp[0] + np.random.default_rng(0).normal(0.0, 0.01, t.size)
    gap = (t > kt[knot] - 35.0) & (t < kt[knot] + 35.0)
    y[gap] = np.nan
    est = estimate_gradient(log_from_frame(pd.DataFrame({"time_s": t * 60, "t_int_c": y}), "g"))
    z = (est.g_est_c_per_min - grad[0]) / est.g_std_c_per_min
    assert np.mean(np.abs(z[gap]) <= 2.0) >= 0.85, np.mean(np.abs(z[gap]) <= 2.0)
    assert np.max(np.abs(z[gap])) < 4.0
    assert np.mean(np.abs(z[~gap]) <= 2.0) >= 0.9  # and the rest is not made loose


def test_a_quantised_creep_at_the_end_of_a_hold_is_not_followed_step_by_step():
    """0.1 degC readings at 1 s with 0.001 degC of noise; in the 120-min hold after the
    ramps the device creeps through a few steps, minutes each. The staircase was detected
    but the estimate on every reading was kept: its q (set by the ramps) was not above
    the one-reading-per-step fit's, yet in the hold it followed each step (red team:
    |z| up to 16.6, false kinks; here 75 % within 2 sigma after 70 min, |z| 10.7). The
    two estimates' disagreement now decides."""
    prog = Programme(np.array([20.0, 40.0, 10.0, 120.0]), np.array([0.0, -1.0, 3.0, 0.0]))
    frame = synth_log(prog, sample_s=1.0, noise_c=0.001, quant_c=0.1, seed=0)
    log = log_from_frame(frame.drop(columns=["t_true_c", "g_true_c_per_min"]))
    est = estimate_gradient(log)
    z = (est.g_est_c_per_min - frame.g_true_c_per_min.to_numpy()) / est.g_std_c_per_min
    hold = frame.time_s.to_numpy() >= 70 * 60
    assert est.staircase_readings > 0
    assert np.mean(np.abs(z[hold]) <= 2.0) > 0.9
    assert np.max(np.abs(z)) < 5.0


def _end_cut_frame(durations, rates, tau_min, dt0_c, rng):
    """A 10-s log (readings to 0.01 degC, 0.02 degC of noise, the setpoint) of the
    closed-form lag under ``rates`` for ``durations``, and its true gradient."""
    time_min = np.arange(0.0, durations.sum() + 1e-9, 10.0 / 60.0)
    temp_c, g_true, tk_c = _lag_closed_form(
        durations, np.array(rates), 20.0, tau_min, dt0_c, time_min
    )
    frame = pd.DataFrame(
        {
            "time_s": time_min * 60.0,
            "t_int_c": np.round(temp_c + 0.02 * rng.standard_normal(time_min.size), 2),
            "tk_set_c": tk_c,
        }
    )
    return frame, g_true


def test_the_gradient_sigma_at_the_logs_end_holds_a_rate_change_just_before_it():
    """A log ending 0.5-3 min after the chamber's rate changes by +4 or -3 degC/min: the
    device's dg/dt = (U - g)/tau jumps there and the kinematic smoother, with no reading
    after, extrapolated the old rate (red team: last-row errors 0.03-0.10 degC/min at
    sigma 0.003-0.006, |z| 5-41; monitor/replan take that row as the state now). The
    logged setpoint's change, or the plan's given explicitly, is made a kink there."""
    tau_min, dt0_c = 40.0, 3.0
    rng = np.random.default_rng(400)
    worst = []
    for rates, after_min in [
        ((0.0, -1.0, 3.0), 1.0),
        ((0.0, 2.0, -1.0), 0.5),
        ((0.0, 2.0, -1.0), 2.0),
    ]:
        durations = np.array([20.0, 40.0, after_min])
        frame, g_true = _end_cut_frame(durations, rates, tau_min, dt0_c, rng)
        est = estimate_gradient(log_from_frame(frame))
        worst.append(abs(est.g_est_c_per_min[-1] - g_true[-1]) / est.g_std_c_per_min[-1])
        # no setpoint column: the plan's changes given
        bare = log_from_frame(frame[["time_s", "t_int_c"]])
        given = estimate_gradient(
            bare,
            rate_change_times_s=60.0 * np.cumsum(durations)[:-1],
            rate_change_jumps_c_per_min=np.diff(rates),
        )
        worst.append(abs(given.g_est_c_per_min[-1] - g_true[-1]) / given.g_std_c_per_min[-1])
    assert max(worst) < 2.5, worst


def test_without_a_setpoint_the_logs_end_may_hide_a_change_of_the_largest_size_seen():
    """No setpoint logged and no rate changes given: a change 0.5-1 min before the end
    cannot be seen, and the last row's sigma did not allow for one (judge, session 52:
    |z| 12-13.5; here 6.9 and 11.6). The sigmas at the log's ends now let the largest
    kink found elsewhere happen there (|z| 1.9 and 2.7; a change larger than any seen
    before can still exceed them: 17 -> 5.3 for a +4 degC/min reversal after -1)."""
    tau_min, dt0_c = 40.0, 3.0
    rng = np.random.default_rng(400)
    worst = []
    for rates, after_min in [((0.0, 2.0, -1.0), 0.5), ((1.0, -1.0, 2.0), 1.0)]:
        durations = np.array([20.0, 40.0, after_min])
        frame, g_true = _end_cut_frame(durations, rates, tau_min, dt0_c, rng)
        est = estimate_gradient(log_from_frame(frame.drop(columns="tk_set_c")))
        z = (est.g_est_c_per_min - g_true) / est.g_std_c_per_min
        worst.append(abs(z[-1]))
        # a setpoint with a blank is not read for its changes: unknown too (reviewer)
        blank = frame.assign(tk_set_c=frame["tk_set_c"].where(frame.index != 5))
        holed = estimate_gradient(log_from_frame(blank))
        worst.append(abs(holed.g_est_c_per_min[-1] - g_true[-1]) / holed.g_std_c_per_min[-1])
        assert np.mean(np.abs(z) <= 2.0) > 0.95  # the rest is not made loose
    assert max(worst) < 3.5, worst


@pytest.mark.parametrize(("rates", "lead_min"), [((1.0, -1.0), 1.0), ((1.0, -1.0), 2.0)])
def test_the_gradient_sigma_at_the_logs_start_holds_a_rate_change_just_after_it(rates, lead_min):
    """A log whose logger starts 1-2 min before the chamber's rate changes (the setpoint
    logged): with nothing before it the kink search did not see the change and the
    smoother carried the new rate back (judge, session 52: error 0.089 degC/min at |z| 12
    on the first row, 65 % within 2 sigma over the first 12 min). The setpoint's change is
    made a kink there, as at the log's end (here |z| on the first row 5.3-5.5, up to 8.2
    in the first 12 min before; 0.2-0.7 and 2.7 now). Truth: the closed-form lag."""
    tau_min, dt0_c = 40.0, 3.0
    durations = np.array([90.0, 40.0])
    time_min = np.arange(90.0 - lead_min, 130.0 - 1e-9, 10.0 / 60.0)
    temp_c, g_true, tk_c = _lag_closed_form(
        durations, np.array(rates), 20.0, tau_min, dt0_c, time_min
    )
    rng = np.random.default_rng(7)
    frame = pd.DataFrame(
        {
            "time_s": (time_min - time_min[0]) * 60.0,
            "t_int_c": temp_c + 0.02 * rng.standard_normal(time_min.size),
            "tk_set_c": tk_c,
        }
    )
    est = estimate_gradient(log_from_frame(frame))
    z = (est.g_est_c_per_min - g_true) / est.g_std_c_per_min
    first = time_min - time_min[0] <= 12.0
    assert abs(z[0]) < 2.0 and np.max(np.abs(z[first])) < 3.5, (z[0], np.abs(z[first]).max())


def test_model_t_sigma_counts_the_noise_of_the_air_reading_driving_it(synth10, rng):
    """The air reading's noise enters T through the model's input, each reading with
    weight S(h) = 1 - exp(-h/tau); T's stated std left it out (red team: 0.2 degC of air
    noise, 73 % of T errors within 2 sigma, RMS z 1.8). Its process noise now holds it."""
    frame = synth10.copy()
    frame["tk_air_c"] = frame["tk_set_c"] + rng.normal(0.0, 0.2, len(frame))
    est = estimate_gradient_model(log_from_frame(frame), chamber="tk_air_c")
    z = (est.t_est_c - frame["t_true_c"].to_numpy()) / est.t_std_c
    assert np.mean(np.abs(z) <= 2.0) > 0.9
    assert 0.7 < _rms(z) < 1.3


# -- innovations that are not white (judge, session 52) ------------------------------------
def _wander_log(noise: str, seed: int = 4) -> pd.DataFrame:
    """A 9-h 10-s log of a smooth device with white, AR(1) (correlated over 120 s) or
    white noise read to 0.5 degC."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 9 * 3600.0, 10.0)
    temp = 20.0 + 15.0 * np.sin(t / 3000.0)
    if noise == "ar":
        phi = math.exp(-10.0 / 120.0)
        e = rng.normal(0.0, 0.02 * math.sqrt(1 - phi**2), t.size)
        temp = temp + lfilter([1.0], [1.0, -phi], e)
    elif noise == "white":
        temp = temp + rng.normal(0.0, 0.02, t.size)
    else:  # white noise read by a coarse (0.5 degC) sensor
        temp = np.round((temp + rng.normal(0.0, 0.02, t.size)) / 0.5) * 0.5
    return pd.DataFrame({"time_s": t, "t_int_c": temp})


def test_correlated_sensor_noise_is_said_to_make_the_sigmas_too_small(tmp_path, capsys):
    """AR(1) sensor noise: the gradient's error is several times its stated sigma and the
    innovations' std is still 1.00; their lag-1 autocorrelation tells, and a warning says
    so. White noise, and white noise read to 0.5 degC (its innovations are correlated, its
    sigma honest), get none."""
    t = np.arange(0.0, 9 * 3600.0, 10.0)
    g_true = 15.0 / 3000.0 * np.cos(t / 3000.0) * 60.0
    ar = estimate_gradient(log_from_frame(_wander_log("ar")))
    z = (ar.g_est_c_per_min - g_true) / ar.g_std_c_per_min
    assert np.sqrt(np.mean(z**2)) > 1.5  # the sigma is too small ...
    assert ar.innovation_lag1 > 0.2 and len(ar.warnings()) == 1  # ... and it is said
    for kind in ("white", "quantised"):
        est = estimate_gradient(log_from_frame(_wander_log(kind)))
        assert est.warnings() == [], (kind, est.innovation_lag1)
        z = (est.g_est_c_per_min - g_true) / est.g_std_c_per_min
        assert np.mean(np.abs(z) < 2.0) > 0.9, kind  # honest: nothing to say
    coarse = estimate_gradient(log_from_frame(_wander_log("quantised")))
    assert coarse.innovation_lag1 > 0.15  # correlated, yet not warned of
    white = estimate_gradient(log_from_frame(_wander_log("white")))
    assert abs(white.innovation_lag1) < 0.1
    few = estimate_gradient(log_from_frame(_wander_log("white").iloc[:30]))
    assert "lag-1 autocorrelation n/a (fewer than 50" in few.summary() and not few.warnings()
    path = tmp_path / "ar.csv"
    _wander_log("ar").to_csv(path, index=False)
    assert main(["estimate", str(path), "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "warning:" in err and "innovations are not white" in err


@pytest.mark.parametrize("h", [1 / 600, 1 / 6, 1.0, 37.0])
def test_gradient_walk_at_steps_matches_van_loan(h):
    """The order-3 model with the gradient's extra random walk (setpoint steps): the
    step's process noise is Van Loan's for white jerk plus white noise on dg/dt."""
    import schedsyn.estimate as est_mod

    q, s = 2.5e-5, 0.3
    a_cont = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    _, q_jerk = _van_loan(a_cont, np.array([0.0, 0.0, 1.0]), q, h)
    _, q_walk = _van_loan(a_cont, np.array([0.0, 1.0, 0.0]), s, h)
    setup = est_mod._Setup(
        60.0 * np.array([0.0, h]), np.zeros(2), None, order=3, g_extra=np.array([0.0, s])
    )
    q11, q12, q13, q22, q23, q33 = setup.rows(0, 2, q).q_at(1)
    qm = np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])
    np.testing.assert_allclose(qm, q_jerk + q_walk, rtol=1e-7, atol=1e-300)


def test_setpoint_steps_are_found_and_ramps_are_not():
    from schedsyn.estimate import setpoint_steps

    t60 = np.arange(12) * 60.0
    step60 = np.array([14.9, 14.75, 14.58, 14.41, 14.24, 18.73, 18.73, 18.73, 18.73, 18.73,
                       18.73, 18.73])  # fmt: skip
    assert setpoint_steps(t60, step60) == [(5, pytest.approx(4.49))]  # 4.5 degC/min, alone
    ramp60 = np.concatenate((np.full(4, 20.0), 20.0 + 3.0 * np.arange(1, 9)))
    assert setpoint_steps(t60, ramp60) == []  # a 3 degC/min ramp logged every minute
    fast60 = np.concatenate((np.full(4, 20.0), 20.0 + 10.0 * np.arange(1, 9)))
    assert setpoint_steps(t60, fast60) == []  # 10 degC/min for 8 min: a fast chamber's ramp
    fast2 = np.concatenate((np.full(4, 20.0), [30.0, 40.0], np.full(6, 40.0)))
    assert len(setpoint_steps(t60, fast2)) == 2  # 20 degC over two rows: one step
    t10 = np.arange(0.0, 7200.0, 10.0)
    rounded = np.round(20.0 + 0.3 * np.maximum(t10 / 60.0 - 20.0, 0.0))  # logged to 1 degC
    assert setpoint_steps(t10, rounded) == []  # a 0.3 degC/min ramp, not 10 steps
    stairs = 20.0 + 2.0 * np.floor(t10 / 300.0)  # 2 degC every 5 min: a ramp to the device
    assert setpoint_steps(t10, stairs) == []
    two = np.where(t10 >= 1800.0, 35.0, 20.0) + np.where(t10 >= 4500.0, -20.0, 0.0)
    assert setpoint_steps(t10, two) == [(180, 15.0), (450, -20.0)]  # 45 min apart
    jitter = two + np.where((t10 > 1900.0) & (t10 < 2000.0), 1.0, 0.0)  # 1 degC beside 15
    assert (180, 15.0) in setpoint_steps(t10, jitter)
    t1 = np.arange(600.0)
    step1 = np.where(t1 >= 300.0, -30.0, -20.0) + 0.05 * (t1 / 60.0)
    assert setpoint_steps(t1, step1) == [(300, pytest.approx(-10.0, abs=1e-3))]
    small = np.where(t1 >= 300.0, 20.3, 20.0)  # 0.3 degC: below SETPOINT_STEP_MIN_C
    assert setpoint_steps(t1, small) == []
    with_nan = step1.copy()
    with_nan[300] = np.nan  # the step is seen across the blank row
    assert setpoint_steps(t1, with_nan) == [(301, pytest.approx(-10.0, abs=3e-3))]


def _step_log(step_times_min, levels_c, tau_min, dt0_c, sample_s, seed):
    """An ideal chamber that steps between holds (at ``step_times_min``, between samples)
    and the device's exact response; readings with 0.01 degC noise."""
    t_min = np.arange(0.0, step_times_min[-1] + 90.0, sample_s / 60.0)
    temp, grad, tk = np.empty(t_min.size), np.empty(t_min.size), np.empty(t_min.size)
    edges = np.concatenate(([0.0], step_times_min, [np.inf]))
    start_c = levels_c[0] + dt0_c
    for i, level in enumerate(levels_c):
        sel = (t_min >= edges[i]) & (t_min < edges[i + 1])
        decay = np.exp(-(t_min[sel] - edges[i]) / tau_min)
        temp[sel] = level + dt0_c + (start_c - level - dt0_c) * decay
        grad[sel] = -(start_c - level - dt0_c) * decay / tau_min
        tk[sel] = level
        if np.isfinite(edges[i + 1]):
            start_c = (
                level
                + dt0_c
                + (start_c - level - dt0_c) * math.exp(-(edges[i + 1] - edges[i]) / tau_min)
            )
    rng = np.random.default_rng(seed)
    frame = pd.DataFrame(
        {"time_s": t_min * 60.0, "t_int_c": temp + 0.01 * rng.standard_normal(t_min.size),
         "tk_set_c": tk}
    )  # fmt: skip
    return log_from_frame(frame, source="setpoint steps"), t_min, grad


@pytest.mark.parametrize("sample_s", [10.0, 60.0])
def test_the_gradient_sigma_holds_at_setpoint_steps(sample_s):
    """Red team 2026-12-05: at a setpoint step the device's gradient jumps by dS/tau; the
    kinematic smoother rounded the jump with sigmas 20-50x too small (|z| 30-53, 61-83 %
    within 2 sigma around the steps). With the gradient free to jump at the logged steps:
    at least 90 % within 2 sigma in the 12 min around them, |z| under 5, and the error no
    larger than before. Truth: the closed-form response to the steps."""
    steps_min = np.array([57.7, 110.8, 161.0, 212.5, 248.7, 298.7])
    levels_c = np.array([20.0, 28.0, 31.3, 38.3, 33.7, 27.5, 12.8])
    log, t_min, g_true = _step_log(steps_min, levels_c, 40.0, 3.0, sample_s, seed=1)
    est = estimate_gradient(log)
    err = est.g_est_c_per_min - g_true
    z = err / est.g_std_c_per_min
    near = np.any((t_min[:, None] >= steps_min - 2.0) & (t_min[:, None] <= steps_min + 10.0), 1)
    assert np.mean(np.abs(z[near]) <= 2.0) >= 0.9, np.mean(np.abs(z[near]) <= 2.0)
    assert np.max(np.abs(z)) < 5.0, np.max(np.abs(z))
    assert np.mean(np.abs(z[~near]) <= 2.0) >= 0.9  # and the rest is not made loose
    assert np.sqrt(np.mean(err[near] ** 2)) < 0.02


@pytest.mark.parametrize("c", [1e-5, 4e-4, 2e-3, 0.05, 0.7])
def test_step_instant_variance_matches_quadrature(c):
    """The variance a step's unknown instant adds to T: ``dS^2 var(exp(-x))`` for ``x``
    uniform on ``[0, c]``, against scipy's quadrature (both branches: series, closed)."""
    from scipy.integrate import quad

    from schedsyn.estimate import step_instant_var_c2
    from schedsyn.model import FirstOrderLag

    tau_min = 40.0
    h_min = c * tau_min
    mean = quad(lambda x: math.exp(-x) / c, 0.0, c, epsrel=1e-13)[0]
    var = quad(lambda x: (math.exp(-x) - mean) ** 2 / c, 0.0, c, epsabs=0.0, epsrel=1e-12)[0]
    t_s = 60.0 * np.array([0.0, 3.0, 3.0 + h_min, 10.0])
    got = step_instant_var_c2(t_s, [(2, -7.0)], FirstOrderLag(ThermalParams(tau_s=2400.0)))
    np.testing.assert_allclose(got, [0.0, 0.0, 49.0 * var, 0.0], rtol=1e-6, atol=0.0)


@pytest.mark.parametrize("sample_s", [2.0, 10.0, 60.0])
def test_the_model_based_sigma_holds_at_setpoint_steps(sample_s):
    """Red team 2026-12-05: the model-based smoother takes a step between two readings as
    a ramp over the step (its mean over the unknown instant), but not the spread of T
    that the instant leaves (``dS h / (tau sqrt 12)``, ~0.02 degC for 15 degC in 10 s):
    56 % within 2 sigma, |z| 8, and the correction ``d`` fitted to chase it. With that
    variance on the step: at least 95 % within 2 sigma and the error smaller than 2e-4
    degC/min (before: 1.8e-4 and 6.6e-4 at 10 s and 60 s). Truth: the closed-form response
    to the steps."""
    steps_min = np.array([57.7, 110.8, 161.0, 212.5, 248.7, 298.7]) + sample_s / 150.0
    levels_c = np.array([20.0, 28.0, 31.3, 38.3, 33.7, 27.5, 12.8])
    log, _, g_true = _step_log(steps_min, levels_c, 40.0, 3.0, sample_s, seed=2)
    est = estimate_gradient_model(log, ThermalParams(tau_s=2400.0, dt0_c=3.0))
    err = est.g_est_c_per_min - g_true
    z = err / est.g_std_c_per_min
    assert np.mean(np.abs(z) <= 2.0) >= 0.95, np.mean(np.abs(z) <= 2.0)
    assert np.max(np.abs(z)) < 4.0, np.max(np.abs(z))
    assert np.sqrt(np.mean(err**2)) < 2e-4, np.sqrt(np.mean(err**2))


def test_a_strided_copy_keeps_the_step_instant_variance():
    """The noise search's strided copy (long logs) carries each coarse step's share of
    the step-instant variance: the sum over the fine steps it merges."""
    import schedsyn.estimate as est_mod
    from schedsyn.model import FirstOrderLag

    n = 20
    extra = np.zeros(n)
    extra[[1, 5, 6, 13]] = [1e-4, 2e-4, 3e-4, 4e-4]
    t_s = 10.0 * np.arange(n)
    setup = est_mod._Setup(
        t_s, np.zeros(n), FirstOrderLag(ThermalParams()), np.full(n, 20.0), t_extra=extra
    )
    coarse = setup.stride(3)  # rows 0, 3, 6, ...: coarse step j merges fine rows 3j-2..3j
    want = [sum(extra[r] for r in range(max(3 * j - 2, 1), 3 * j + 1)) for j in range(7)]
    assert coarse.t_extra is not None
    np.testing.assert_allclose(coarse.t_extra, want, rtol=1e-12, atol=0.0)
    assert coarse.rows(0, coarse.n, 1.0).q_at(2)[0] > coarse.rows(0, coarse.n, 1.0).q_at(3)[0]


def test_a_setpoint_logged_to_a_coarse_resolution_is_a_ramp_not_steps(rng):
    """Red team 2026-12-05: a ramp programme's setpoint logged to 1 degC jumps a degree
    every 20 s - 2 min; every jump was taken for a setpoint step, the gradient allowed to
    jump at each, and its RMS error 5x larger (0.0015 -> 0.0081 degC/min). Rounded to
    1 or 0.5 degC, the estimate is now within 15 % of the one with the exact setpoint."""
    durations = np.array([60.0, 40.0, 60.0, 40.0, 60.0])
    frame, g_true = _end_cut_frame(durations, [0.5, 1.0, -1.0, 1.5, -0.8], 40.0, 3.0, rng)
    rms = {}
    for quantum in (0.0, 0.5, 1.0):
        f = frame.copy()
        if quantum:
            f["tk_set_c"] = np.round(f["tk_set_c"] / quantum) * quantum
        est = estimate_gradient(log_from_frame(f, source=f"setpoint to {quantum} degC"))
        rms[quantum] = float(np.sqrt(np.mean((est.g_est_c_per_min - g_true) ** 2)))
    assert rms[1.0] < 1.15 * rms[0.0] and rms[0.5] < 1.15 * rms[0.0], rms


def test_a_coarsely_logged_setpoint_is_read_as_its_programme():
    """Rounded to 0.1 or 1 degC, the setpoint at every row is the programme's own to a
    small part of the rounding, with the spread left over beyond the rounding as its
    variance; a finely logged one is returned as it is."""
    from schedsyn.estimate import setpoint_at_samples

    t_s = np.arange(0.0, 300 * 60.0, 10.0)
    t_min = t_s / 60.0
    prog = 20.0 + np.interp(t_min, [0, 40, 100, 170, 230, 300], [0, 20, -40, 30, 0, 10])
    same, var0 = setpoint_at_samples(t_s, np.round(prog, 2))
    np.testing.assert_array_equal(same, np.round(prog, 2))
    assert var0 == 0.0
    for quantum in (0.1, 1.0):
        got, var = setpoint_at_samples(t_s, np.round(prog / quantum) * quantum)
        err = got - prog
        assert np.sqrt(np.mean(err**2)) < 0.2 * quantum / math.sqrt(12.0), quantum
        assert 0.0 <= var < quantum**2 / 12.0


@pytest.mark.parametrize("quantum", [0.1, 1.0])
def test_the_model_based_estimate_reads_a_setpoint_logged_to_a_coarse_resolution(quantum, rng):
    """Red team 2026-12-05: the model-based smoother took each reading of a setpoint
    logged to 0.1 degC (1 degC) as the chamber's input and in g = (Tk + dT0 - T)/tau:
    RMS error 6e-4 (6e-3) degC/min at 32 % (31 %) within 2 sigma. Read as its programme,
    the error is under 2e-4 (2e-3) and at least 90 % within 2 sigma (without the
    programme's own error in sigma: 7-95 % on this log's seeds)."""
    durations = np.array([15.0, 20, 12, 25, 18, 30, 14, 22, 16, 20, 15, 25])
    rates = [1.2, -0.4, 2.0, -0.9, 0.3, -0.6, 1.7, -1.0, 0.8, -0.3, 1.1, -0.7]
    frame, g_true = _end_cut_frame(durations, rates, 40.0, 3.0, rng)
    frame["tk_set_c"] = np.round(frame["tk_set_c"] / quantum) * quantum
    log = log_from_frame(frame, source=f"setpoint to {quantum} degC")
    est = estimate_gradient_model(log, ThermalParams(tau_s=2400.0, dt0_c=3.0))
    err = est.g_est_c_per_min - g_true
    assert np.sqrt(np.mean(err**2)) < 2e-3 * quantum, np.sqrt(np.mean(err**2))
    cover = np.mean(np.abs(err / est.g_std_c_per_min) <= 2.0)
    assert cover >= 0.9, cover
