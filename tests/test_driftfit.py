"""Drift fit: errors-in-variables maths, noise model and standard errors against dense
computation, recovery of known polynomials from synthetic gyro logs, term selection,
compensation table, bad input and the `schedsyn fit` command."""

import dataclasses
import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from schedsyn import driftfit
from schedsyn.cli import main
from schedsyn.driftfit import (
    LACK_OF_FIT_DELTA_BIC,
    WALK_UPPER_DELTA_M2LL,
    Coding,
    FitSettings,
    Samples,
    _leverage,
    _normal_pieces,
    _walk_weighted,
    cross_validate,
    drift_outliers,
    estimation_errors,
    estimator_model,
    fit_coefficients,
    fit_drift,
    fit_samples,
    noise_fit,
    pass_blocks,
    walk_basis,
    walk_covariance,
    walk_normal_matrix,
)
from schedsyn.errors import LogFormatError, ParameterError
from schedsyn.estimate import estimate_gradient
from schedsyn.gyro import Gyro, drift_noise, gyro_log
from schedsyn.logs import log_from_frame
from schedsyn.params import ThermalParams
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate
from schedsyn.terms import (
    CANDIDATES,
    EXPONENTS,
    TERM_SETS,
    TERMS,
    coded_to_physical,
    corrected_monomials,
    monomials,
    parse_terms,
)

BASELINE = "data/baseline_exp1_steps.csv"
REGION = (-50.0, -21.0)  # where the baseline run goes (it reaches -51.7 .. 20 degC)
CENTRE = 0.5 * (REGION[0] + REGION[1])

#: A gyro with a strong gradient sensitivity (Shupe-like) and curvature in T and g.
GRAD_COEFS = {"1": 0.3, "t": -0.02, "t2": 4e-4, "t3": -2e-5, "g": 0.8, "tg": 0.01, "g2": -0.2,
              "g3": 0.15}  # fmt: skip
T_COEFS = {"1": 0.3, "t": -0.02, "t2": 4e-4, "t3": -2e-5}


@pytest.fixture(scope="module")
def programme():
    return read_steps(BASELINE)


def _gyro(coefs, white=0.2, walk=0.005, **kw):
    return Gyro(coefs, t_ref_c=CENTRE, white_noise_dph_per_rt_hz=white,
                bias_walk_dph_per_rt_h=walk, **kw)  # fmt: skip


@pytest.fixture(scope="module")
def grad_fit(programme):
    """A gradient gyro fitted on one run, held out on a second run of the same gyro."""
    gyro = _gyro(GRAD_COEFS)
    f1 = gyro_log(programme, gyro, sample_s=20.0, seed=1)
    f2 = gyro_log(programme, gyro, sample_s=20.0, seed=2)
    fit = fit_drift(log_from_frame(f1, "run1"), REGION, holdout=log_from_frame(f2, "run2"))
    return gyro, f1, fit


@pytest.fixture(scope="module")
def tonly_fit(programme):
    gyro = _gyro(T_COEFS)
    f1 = gyro_log(programme, gyro, sample_s=20.0, seed=3)
    return gyro, f1, fit_drift(log_from_frame(f1, "run3"), REGION)


# -- the polynomial terms ------------------------------------------------------------------
def test_term_sets_are_nested_and_of_order_three():
    for small, big in zip(CANDIDATES[:-1], CANDIDATES[1:], strict=True):
        assert set(TERM_SETS[small]) < set(TERM_SETS[big]), (small, big)
    for name, terms in TERM_SETS.items():
        assert all(sum(EXPONENTS[t]) <= 3 for t in terms), name
        # each set holds every term of total order <= 3 up to its order in g
        gmax = max(EXPONENTS[t][1] for t in terms)
        want = {t for t in TERMS if EXPONENTS[t][1] <= gmax}
        assert set(terms) == want, name
    assert parse_terms("g,1,t") == ("1", "t", "g")
    for bad in ("cubic", "1,t,x", "t,g", "1,t,t"):
        with pytest.raises(ParameterError):
            parse_terms(bad)


def test_coded_to_physical_matches_direct_evaluation(rng):
    # x = (T - t_ref)/t_half, y = (g - g_mid)/g_half; physical about another reference
    t_ref, t_half, g_mid, g_half, t_out = -36.0, 16.0, 0.075, 0.925, -30.0
    terms = TERM_SETS["full"]
    c_coded = rng.normal(size=len(terms))
    j = coded_to_physical(terms, t_ref, t_half, g_mid, g_half, t_out)
    c_phys = j @ c_coded
    t = rng.uniform(-52, -20, 50)
    g = rng.uniform(-0.85, 1.0, 50)
    coded = monomials((t - t_ref) / t_half, (g - g_mid) / g_half, terms) @ c_coded
    direct = sum(c_phys[i] * (t - t_out) ** a * g**b for i, (a, b) in enumerate(EXPONENTS.values()))
    np.testing.assert_allclose(coded, direct, rtol=1e-10, atol=1e-10)


def test_corrected_monomials_are_unbiased_under_correlated_errors(rng):
    x0, y0 = 0.7, -0.4
    s = np.array([[0.04, 0.012], [0.012, 0.09]])
    e = np.linalg.cholesky(s) @ rng.standard_normal((2, 1_000_000))
    powers = [(a, b) for a in range(7) for b in range(7) if a + b <= 6]
    u = corrected_monomials(x0 + e[0], y0 + e[1], s[0, 0], s[0, 1], s[1, 1], powers)
    for a, b in powers:
        se = u[(a, b)].std() / math.sqrt(e.shape[1])
        assert abs(u[(a, b)].mean() - x0**a * y0**b) < 5 * se + 1e-12, (a, b)
    # no error: the plain monomials
    z = corrected_monomials(np.array([0.3]), np.array([-2.0]), 0.0, 0.0, 0.0, powers)
    for a, b in powers:
        assert z[(a, b)][0] == pytest.approx(0.3**a * (-2.0) ** b)


# -- errors in variables ---------------------------------------------------------------------
@pytest.mark.parametrize("walk_ratio_per_h", [0.0, 0.5])
def test_adjusted_least_squares_removes_classical_error_bias(rng, walk_ratio_per_h):
    """Regressors with known Gaussian errors: plain least squares attenuates and shifts
    the gradient terms; adjusted least squares does not (mean over replicates), also
    weighted for a bias walk (``walk_ratio_per_h`` = K^2/sigma^2 > 0)."""
    n = 3000
    if walk_ratio_per_h:  # a run's structure: the gradient follows time (passes)
        phase = np.arange(n) * 10.0 / 3600.0 * 2 * np.pi / 1.5
        t = -35 + 15 * np.sin(0.37 * phase + rng.uniform(0, 6)) * np.abs(np.cos(phase))
        g = 0.1 + 0.9 * np.sin(phase) + 0.05 * rng.standard_normal(n)
    else:
        t = rng.uniform(-50, -20, n)
        g = rng.uniform(-0.8, 1.0, n)
    d = 0.2 + 0.01 * (t + 35) + 1.0 * g + 0.5 * g**3
    coding = Coding(-35.0, 15.0, 1.0)
    # weighted, the fit learns from the gradient's changes within a few minutes (the walk
    # takes the slow ones): a smaller error is as large against them
    sd_t, sd_g = (0.05, 0.08) if walk_ratio_per_h else (0.05, 0.15)
    truth = np.zeros(10)
    truth[[0, 1, 2, 9]] = [0.2, 0.01 * 15, 1.0, 0.5]  # coded: x = (T + 35)/15, y = g
    errs = {True: [], False: []}
    for _ in range(30):
        s = Samples(
            np.arange(n) * 10.0,
            t + sd_t * rng.standard_normal(n),
            g + sd_g * rng.standard_normal(n),
            d,
            np.full(n, sd_t**2),
            np.zeros(n),
            np.full(n, sd_g**2),
        )
        for eiv in (True, False):
            if walk_ratio_per_h:
                pieces = _normal_pieces(s, coding, TERMS, eiv)
                a, b = pieces.a_k.sum(axis=0), pieces.b_k.sum(axis=0)
                res = _walk_weighted(s, pieces, a, b, walk_ratio_per_h)
                assert res is not None
                coef = res[0]
            else:
                coef = fit_coefficients(s, "full", coding, eiv=eiv)
            errs[eiv].append(coef - truth)
    plain = np.mean(errs[False], axis=0)
    adjusted = np.mean(errs[True], axis=0)
    se = np.std(errs[False], axis=0, ddof=1) / math.sqrt(30)
    for k in (2, 9):  # g and g3
        assert abs(plain[k]) > 10 * se[k]  # a real bias ...
        assert abs(adjusted[k]) < 0.2 * abs(plain[k])  # ... removed


def test_weighted_fit_holds_when_the_walk_dwarfs_the_white_noise(rng):
    """White noise far below the walk (K^2/sigma^2 ~ 1e4 per hour): the walk between the
    5-min knots is not linear, and unless that bridge counts as noise the terms follow the
    walk inside the knot intervals. The weighted fit stays as good as the unweighted one."""
    n = 3000
    t = np.arange(n) * 10.0
    phase = t / 3600.0 * 2 * np.pi / 1.5
    temp = -20 + 12 * np.sin(0.37 * phase) * np.abs(np.cos(phase))
    grad = 0.1 + 0.9 * np.sin(phase)
    coding = Coding(-20.0, 12.0, 1.0)
    x = monomials(*coding.code(temp, grad), TERMS)
    c_true = rng.normal(size=10) * 0.1
    zeros = np.zeros(n)
    err = {"gls": [], "ols": []}
    for _ in range(6):
        walk = np.cumsum(0.03 * np.sqrt(10.0 / 3600.0) * rng.standard_normal(n))
        d = x @ c_true + walk + 0.0005 * rng.standard_normal(n)
        s = Samples(t, temp, grad, d, zeros, zeros, zeros)
        for w in err:
            fit = fit_samples(s, "full", coding, eiv=False, weighting=w)
            e = x @ (fit.coef_coded - c_true)
            err[w].append(np.sqrt(np.mean((e - e.mean()) ** 2)))  # the shape, not the level
    assert fit.walk_dph_per_rt_h > 10 * fit.white_sigma_dph
    assert np.median(err["gls"]) < 1.2 * np.median(err["ols"]), err


def test_weighted_normal_matrix_is_unbiased_under_regressor_errors(rng):
    """With the walk profiled out, the adjusted normal matrix of the coefficients (the
    Schur complement) averages to the error-free one over draws of the regressors'
    errors (every entry's mean within a few standard errors); without the leverage term
    it does not."""
    n = 1200
    phase = np.arange(n) * 10.0 / 3600.0 * 2 * np.pi / 1.5
    t = -35 + 15 * np.sin(0.37 * phase) * np.abs(np.cos(phase))
    g = 0.1 + 0.9 * np.sin(phase) + 0.05 * rng.standard_normal(n)
    coding = Coding(-35.0, 15.0, 1.0)
    sd_t, sd_g, ratio = 0.05, 0.15, 3.0
    zeros, p = np.zeros(n), len(TERMS)

    def schur(s, eiv, leverage=True):
        pieces = _normal_pieces(s, coding, TERMS, eiv)
        big, _ = walk_normal_matrix(s, pieces, pieces.a_k.sum(axis=0), ratio)
        if not leverage:
            big[:p, :p] = pieces.a_k.sum(axis=0)
        ub = big[:p, p:]
        return big[:p, :p] - ub @ np.linalg.solve(big[p:, p:], ub.T)

    true = schur(Samples(np.arange(n) * 10.0, t, g, zeros, zeros, zeros, zeros), False)
    draws: dict[str, list] = {"adjusted": [], "no leverage": [], "plain": []}
    for _ in range(160):
        s = Samples(np.arange(n) * 10.0, t + sd_t * rng.standard_normal(n),
                    g + sd_g * rng.standard_normal(n), zeros, np.full(n, sd_t**2), zeros,
                    np.full(n, sd_g**2))  # fmt: skip
        draws["adjusted"].append(schur(s, True))
        draws["no leverage"].append(schur(s, True, leverage=False))
        draws["plain"].append(schur(s, False))
    iu = np.triu_indices(p)
    top = np.abs(true[iu]).max()

    def z_max(v):  # the largest z-score of the mean's error over the matrix's entries
        v = np.asarray(v)
        err = np.abs(np.mean(v, axis=0) - true)[iu]
        se = (np.std(v, axis=0, ddof=1) / np.sqrt(len(v)))[iu]
        fixed = se <= 1e-9 * top  # entries without errors (the constant's)
        assert np.all(err[fixed] <= 1e-6 * top)
        return float(np.max(err[~fixed] / se[~fixed]))

    z = {k: z_max(v) for k, v in draws.items()}
    assert z["adjusted"] < 4.0, z  # 45 entries' means: |z| < 4 unless biased
    assert z["no leverage"] > 5.0 and z["plain"] > 50, z


def test_walk_basis_interpolates_and_its_leverage_matches_dense(rng):
    """The walk's basis interpolates knot levels linearly (0 at the first sample), and
    the leverage h_k = B_k' Q B_k computed from its two entries per row is the dense one."""
    t = np.sort(rng.uniform(0, 9 * 3600, 700))
    basis, step_h = walk_basis(t)
    assert step_h == pytest.approx(5 / 60) and np.diff(basis.indptr).max() <= 2
    knots = rng.normal(size=basis.shape[1])
    t_h = (t - t[0]) / 3600.0
    grid = step_h * np.arange(basis.shape[1] + 1)
    np.testing.assert_allclose(basis @ knots, np.interp(t_h, grid, np.r_[0.0, knots]))
    a = rng.normal(size=(basis.shape[1],) * 2)
    q = a @ a.T
    dense = np.einsum("ki,ij,kj->k", basis.toarray(), q, basis.toarray())
    np.testing.assert_allclose(_leverage(basis, q), dense, rtol=1e-10, atol=1e-10)


def test_gradient_noise_bias_is_removed(programme):
    """Noise on the estimated gradient biases the g2/g3 coefficients of a plain least-squares
    fit (errors in variables); given the noise's variance the adjusted fit removes most of it.
    The noise is drawn here with a known covariance, the size of a Kalman smoother's on a
    noisy 30-s log (0.05 degC/min on g, 0.02 degC on T, correlated)."""
    gyro = Gyro({"1": 0.2, "t": 0.01, "g": 1.0, "g3": 0.5}, t_ref_c=-36.0, sensor_noise_c=0.0,
                sensor_quant_c=0.0)  # fmt: skip
    f = gyro_log(programme, gyro, sample_s=30.0, seed=0, with_air=False)
    t, g = f["t_true_c"].to_numpy(), f["g_true_c_per_min"].to_numpy()
    d, ts = f["drift_true_dph"].to_numpy(), f["time_s"].to_numpy()
    m = (t >= REGION[0]) & (t <= REGION[1])
    t, g, d, ts = t[m], g[m], d[m], ts[m]
    sd_t, sd_g, rho = 0.02, 0.05, 0.5
    cov = np.array([[sd_t**2, rho * sd_t * sd_g], [rho * sd_t * sd_g, sd_g**2]])
    ones = np.ones_like(t)
    coding = Coding(CENTRE, 14.5, 1.0)
    truth = np.zeros(10)
    truth[[0, 1, 2, 9]] = [gyro.drift_dph(np.array([CENTRE]), np.array([0.0]))[0], 0.01 * 14.5,
                           1.0, 0.5]  # fmt: skip
    rng = np.random.default_rng(5)
    errs: dict[bool, list[np.ndarray]] = {True: [], False: []}
    n_rep = 24
    for _ in range(n_rep):
        e = rng.multivariate_normal([0.0, 0.0], cov, size=t.size)
        s = Samples(ts, t + e[:, 0], g + e[:, 1], d, cov[0, 0] * ones, cov[0, 1] * ones,
                    cov[1, 1] * ones)  # fmt: skip
        for eiv in (True, False):
            errs[eiv].append(fit_coefficients(s, "full", coding, eiv=eiv) - truth)
    k = [TERMS.index("g2"), TERMS.index("g3")]
    plain = np.mean(errs[False], axis=0)[k]
    adjusted = np.mean(errs[True], axis=0)[k]
    se = np.std(errs[False], axis=0, ddof=1)[k] / math.sqrt(n_rep)
    assert np.linalg.norm(plain / se) > 4  # the plain fit is biased
    assert np.linalg.norm(adjusted) < 0.5 * np.linalg.norm(plain)


def test_error_draws_measure_the_actual_gradient_error(programme):
    """The stated variance of the (default, order-3 kinematic) smoother's gradient matches
    its actual error on a synthetic log; the readings' noise alone (the draws) would
    understate it by about a quarter, the ramp corners' share."""
    f = gyro_log(programme, Gyro({}, sensor_noise_c=0.1, sensor_quant_c=0.1), sample_s=10.0,
                 seed=4)  # fmt: skip
    log = log_from_frame(f)
    est = estimate_gradient(log)
    _, _, var_g = estimation_errors(log, est, ThermalParams(), n_draws=16, seed=2)
    actual = np.sqrt(np.mean((est.g_est_c_per_min - f["g_true_c_per_min"]) ** 2))
    drawn = np.sqrt(np.mean(var_g))
    assert drawn == pytest.approx(actual, rel=0.15)


# -- noise model and standard errors --------------------------------------------------------
def test_walk_covariance_matches_dense(rng):
    t = np.sort(rng.uniform(0, 9 * 3600, 60))
    x = rng.normal(size=(60, 3))
    c = np.minimum.outer(t, t) / 3600.0 - t[0] / 3600.0
    np.testing.assert_allclose(walk_covariance(t, x), x.T @ c @ x, rtol=1e-10)


def _dense_objective(t_h, d, x, lam, reml):
    """-2 log L (ML) or the REML criterion with the dense covariance sigma^2 (I + lam C)."""
    n, p = x.shape
    v = np.eye(n) + lam * (np.minimum.outer(t_h, t_h) - t_h[0])
    vi = np.linalg.inv(v)
    a = x.T @ vi @ x
    beta = np.linalg.solve(a, x.T @ vi @ d)
    r = d - x @ beta
    dof = n - p if reml else n
    s2 = float(r @ vi @ r) / dof
    m2 = dof * (math.log(2 * math.pi * s2) + 1.0) + np.linalg.slogdet(v)[1]
    return (m2 + np.linalg.slogdet(a)[1] if reml else m2), s2


@pytest.mark.parametrize("n_rows, period_s", [(3240, 10.0), (32400, 1.0)])
def test_the_noise_model_counts_every_reading(n_rows, period_s):
    """A 9-h log at 10 s and at 1 s (white 0.3 deg/h/sqrt(Hz), walk 0.01 deg/h/sqrt(h)),
    fitted whole, as 2000 block means, and with one reading left out: the same white
    noise and walk. (Every k-th row, as before: one reading blanked moved the 10-s log's
    walk from 0.0076 to 0.00003, and the 1-s log's every 17th row lost the walk.)"""
    rng = np.random.default_rng(0)
    t = np.arange(n_rows) * period_s
    x = np.column_stack([np.ones(n_rows), np.sin(t / 3000), (t / 30000) ** 2])
    white = rng.normal(0, 0.3 / math.sqrt(period_s), n_rows)
    walk = np.cumsum(rng.normal(0, 0.01 * math.sqrt(period_s / 3600), n_rows))
    d = x @ [1.0, 0.1, 0.05] + white + walk
    whole = noise_fit(t, d, x, max_rows=n_rows)
    for fit in (
        noise_fit(t, d, x, max_rows=2000),
        noise_fit(np.delete(t, 7), np.delete(d, 7), np.delete(x, 7, axis=0), max_rows=2000),
        noise_fit(np.delete(t, 7), np.delete(d, 7), np.delete(x, 7, axis=0)),
    ):
        assert fit.sigma_dph == pytest.approx(whole.sigma_dph, rel=0.03)
        assert fit.walk_dph_per_rt_h == pytest.approx(whole.walk_dph_per_rt_h, rel=0.1)
        assert fit.walk_upper_dph_per_rt_h == pytest.approx(whole.walk_upper_dph_per_rt_h, rel=0.1)
    assert whole.sigma_dph == pytest.approx(0.3 / math.sqrt(period_s), rel=0.05)


def test_noise_fit_is_quiet_where_the_walk_makes_the_terms_singular():
    """Red team: a slow monotone ramp (the gradient constant to 1e-12) printed scipy's
    RuntimeWarnings from the walk search (the likelihood infinite at some walks)."""
    rng = np.random.default_rng(0)
    t = np.arange(2000) * 10.0
    d = 0.3 + 0.1 * rng.standard_normal(2000) + 0.001 * np.cumsum(rng.standard_normal(2000))
    x = np.column_stack([np.ones(2000), t / 1e4, 0.5 + 1e-12 * rng.standard_normal(2000)])
    nf = noise_fit(t, d, x)  # warnings are errors in this suite
    assert math.isfinite(nf.sigma_dph) and nf.sigma_dph > 0


@pytest.mark.parametrize("reml", [True, False])
def test_noise_fit_matches_dense_likelihood(rng, reml):
    """The Kalman-whitened profile likelihood equals the dense Gaussian one, and its
    optimum is the dense grid's."""
    n = 200
    t = np.cumsum(rng.uniform(5, 15, n))
    x = np.column_stack([np.ones(n), np.sin(t / 2000), (t / t[-1]) ** 2])
    walk = np.cumsum(0.05 * np.sqrt(np.diff(t, prepend=t[0]) / 3600) * rng.standard_normal(n))
    d = x @ [0.3, 0.1, -0.2] + 0.02 * rng.standard_normal(n) + walk
    fit = noise_fit(t, d, x, reml=reml)
    lam = (fit.walk_dph_per_rt_h / fit.sigma_dph) ** 2
    t_h = t / 3600.0
    grid = np.exp(np.linspace(np.log(lam) - 1.0, np.log(lam) + 1.0, 41))
    dense = [_dense_objective(t_h, d, x, v, reml)[0] for v in grid]
    # the found optimum is the dense one (within the grid's resolution)
    assert min(dense) >= _dense_objective(t_h, d, x, lam, reml)[0] - 1e-6
    s2 = _dense_objective(t_h, d, x, lam, reml)[1]
    assert fit.sigma_dph == pytest.approx(math.sqrt(s2), rel=1e-6)
    assert fit.minus2_log_likelihood == pytest.approx(
        _dense_objective(t_h, d, x, lam, reml)[0], rel=1e-8
    )
    # the walk for standard errors: where the dense criterion has risen by
    # WALK_UPPER_DELTA_M2LL on the side of larger walks
    best = _dense_objective(t_h, d, x, lam, reml)[0]
    up = brentq(
        lambda v: _dense_objective(t_h, d, x, math.exp(v), reml)[0] - best - WALK_UPPER_DELTA_M2LL,
        math.log(lam),
        math.log(lam) + 12.0,
    )
    k_up = math.sqrt(math.exp(up) * _dense_objective(t_h, d, x, math.exp(up), reml)[1])
    assert fit.walk_upper_dph_per_rt_h == pytest.approx(k_up, rel=0.03)
    assert fit.walk_upper_dph_per_rt_h > 1.05 * fit.walk_dph_per_rt_h


def test_standard_errors_are_calibrated_under_a_bias_random_walk(programme):
    """z = (estimate - truth)/std error over replicates has unit spread, for the weighted
    (gls) and the unweighted (ols) fit; standard errors that ignore the walk are several
    times too small."""
    traj = simulate(programme, dt_min=1 / 3)
    m = (traj.t_c >= REGION[0]) & (traj.t_c <= REGION[1])
    time_s = traj.time_min * 60.0
    gyro = _gyro(GRAD_COEFS, white=0.3, walk=0.02)
    true = gyro.drift_dph(traj.t_c, traj.g_c_per_min)
    truth = gyro.coefficient_vector
    coding = Coding(CENTRE, 14.5, 1.0)
    zeros = np.zeros(int(m.sum()))
    rng = np.random.default_rng(11)
    z: dict[str, list] = {"gls": [], "ols": []}
    z_iid = []
    for _ in range(40):
        white, walk = drift_noise(time_s, gyro, rng)
        s = Samples(time_s[m], traj.t_c[m], traj.g_c_per_min[m], (true + white + walk)[m],
                    zeros, zeros, zeros)  # fmt: skip
        for w in z:
            # the walk is 0 at the log's start (time 0), an hour before the region
            fit = fit_samples(s, "full", coding, eiv=False, weighting=w, walk_start_s=0.0)
            assert fit.weighting == w
            z[w].append((fit.coefficients_dph - truth) / fit.std_errors)
        x = monomials(*coding.code(s.t_c, s.g_c_per_min), TERMS)
        resid = s.drift_dph - x @ fit.coef_coded
        cov_iid = np.linalg.inv(x.T @ x) * np.mean(resid**2)
        j = np.diag(np.diag(coded_to_physical(TERMS, CENTRE, 14.5, 0.0, 1.0)))
        z_iid.append((fit.coefficients_dph - truth) / np.sqrt(np.diag(j @ cov_iid @ j)))
    for w in z:
        spread = np.std(z[w], axis=0)
        # the standard errors allow for the largest walk the run cannot rule out (a one-
        # sided 95 % profile-likelihood bound): conservative by up to 1.9x on the terms
        # (spreads gls 0.59-0.89, ols 0.54-0.75; 0.66-1.09 with the earlier bound, 1.0
        # above the best -2 log L, which the true walk exceeded in a fifth of the runs);
        # the constant, the walk's level, had a spread of 1.9 with the run's own estimate
        # of the walk and 1.5 (gls) when the walk before the first sample was left out
        assert np.all(spread > 0.5) and np.all(spread < 1.3), (w, spread)
    iid = np.std(z_iid, axis=0)  # the ols fit's coefficients with iid standard errors
    assert np.median(iid) > 1.5 and iid.max() > 3.0, iid


def test_weighted_fit_is_generalised_least_squares(rng, monkeypatch):
    """The weighted fit (the walk as a piecewise-linear regressor with its prior) equals
    dense generalised least squares with the covariance I + lambda min(t_i, t_j), and is
    closer to the truth than the unweighted fit when the walk dominates."""
    n = 1500
    t = np.cumsum(rng.uniform(8, 12, n)) + 3000.0
    temp = -40 + 10 * np.sin(t / 3000)
    grad = 0.5 * np.cos(t / 3000) + 0.1 * np.sin(t / 700)
    coding = Coding(-40.0, 10.0, 0.6)
    x = monomials(*coding.code(temp, grad), TERMS)
    c_true = rng.normal(size=10) * 0.1
    walk = np.cumsum(0.05 * np.sqrt(np.diff(t, prepend=t[0]) / 3600) * rng.standard_normal(n))
    d = x @ c_true + 0.05 * rng.standard_normal(n) + walk
    zeros = np.zeros(n)
    s = Samples(t, temp, grad, d, zeros, zeros, zeros)
    gls = fit_samples(s, "full", coding, eiv=False)
    ols = fit_samples(s, "full", coding, eiv=False, weighting="ols")
    assert gls.weighting == "gls" and ols.weighting == "ols"
    lam = (gls.walk_dph_per_rt_h / gls.white_sigma_dph) ** 2
    t_h = t / 3600.0
    chol = np.linalg.cholesky(np.eye(n) + lam * (np.minimum.outer(t_h, t_h) - t_h[0]))
    xw = np.linalg.solve(chol, x)
    dense = np.linalg.lstsq(xw, np.linalg.solve(chol, d), rcond=None)[0]
    se = np.sqrt(np.diag(gls.cov_coded))
    assert np.max(np.abs(gls.coef_coded - dense) / se) < 0.1
    assert np.max(np.abs(ols.coef_coded - dense) / se) > 0.3  # the check can tell them apart
    # the standard errors: the linear map's, with the dense covariance at the same walk
    k = gls.walk_for_std_errors_dph_per_rt_h
    cov_noise = gls.white_sigma_dph**2 * np.eye(n) + k**2 * (np.minimum.outer(t_h, t_h) - t_h[0])
    a_inv = np.linalg.inv(xw.T @ xw)
    gmap = np.linalg.solve(chol.T, xw) @ a_inv  # dense GLS: coef = gmap' d
    dense_se = np.sqrt(np.diag(gmap.T @ cov_noise @ gmap))
    np.testing.assert_allclose(se, dense_se, rtol=0.05)
    # a vanishing walk: the weighted solve is the unweighted one
    pieces = _normal_pieces(s, coding, TERMS, False)
    a, b = pieces.a_k.sum(axis=0), pieces.b_k.sum(axis=0)
    res = _walk_weighted(s, pieces, a, b, 1e-10)
    assert res is not None
    coef, gmap0 = res
    np.testing.assert_allclose(coef, np.linalg.solve(a, b), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(gmap0, x @ np.linalg.inv(a), rtol=1e-5, atol=1e-12)
    # a weighted normal matrix that is not positive definite (an errors-in-variables
    # correction larger than what is left once the walk is out) is refused ...
    shrink = 0.999 * np.linalg.eigvalsh(a)[-1] * np.eye(a.shape[0])
    assert _walk_weighted(s, pieces, a - shrink, b, lam) is None
    # ... and the fit falls back to weighting every sample alike, and says so
    monkeypatch.setattr(driftfit, "_walk_weighted", lambda *args: None)
    fallback = fit_samples(s, "full", coding, eiv=False)
    assert fallback.weighting == "ols"
    np.testing.assert_allclose(fallback.coef_coded, ols.coef_coded)


# -- end to end on synthetic logs -------------------------------------------------------------
def test_fit_recovers_a_gradient_gyro(grad_fit):
    gyro, f1, fit = grad_fit
    assert fit.estimator == "model"
    assert set(fit.terms) >= {"g", "g3"}  # the gradient model is selected
    s = fit.samples
    err = fit.predict(s.t_c, s.g_c_per_min) - gyro.drift_dph(s.t_c, s.g_c_per_min)
    assert np.sqrt(np.mean(err**2)) < 0.03  # deg/h, against a 0.1 deg/h noise floor
    coefs = dict(zip(fit.terms, fit.model.coefficients_dph, strict=True))
    ses = dict(zip(fit.terms, fit.model.std_errors, strict=True))
    for t in fit.terms:
        assert abs(coefs[t] - gyro.coefficients_dph[t]) < 4.5 * ses[t] + 1e-9, t
    # the T-only reference cannot follow the gradient: much larger residuals
    assert fit.reference.residual_rms_dph > 2 * fit.model.residual_rms_dph


def test_the_smoothers_model_is_identified_from_the_log(programme):
    """A device off the nominal model (tau 2000 s, dT0 5 degC): without a given model the
    fit identifies it from the log, and its gradient coefficients are closer to the truth
    than with the nominal model (whose smoother has a systematic gradient error the error
    draws do not see); a given model is used as given."""
    gyro = _gyro(GRAD_COEFS, white=0.05, walk=0.0)
    device = ThermalParams(2000.0, 5.0)
    f = gyro_log(programme, gyro, device, sample_s=10.0, seed=7)
    log = log_from_frame(f, "off-model")
    settings = FitSettings(terms="full")
    found = fit_drift(log, REGION, settings)
    nominal = fit_drift(log, REGION, settings, ThermalParams())
    assert found.estimator_params.tau_s == pytest.approx(2000.0, rel=0.02)
    assert found.estimator_params.dt0_c == pytest.approx(5.0, abs=0.1)
    assert found.estimator_params_source.startswith("identified from the log")
    assert nominal.estimator_params_source == "given"
    assert nominal.estimator_params == ThermalParams()
    doc = found.to_json_dict()["gradient_estimator_model"]
    assert doc["tau_s"] == found.estimator_params.tau_s and "identified" in doc["source"]
    assert any("identified from the log" in line for line in found.summary_lines())
    s = found.samples
    # a log that does not determine tau (the device held flat): the nominal model, said so
    t = np.arange(0.0, 7200.0, 10.0)
    noise = 0.02 * np.random.default_rng(0).standard_normal(t.size)
    flat = pd.DataFrame({"time_s": t, "t_int_c": 23.0 + noise, "tk_set_c": 20.0,
                         "drift_dph": 0.1})  # fmt: skip
    params, source = estimator_model(log_from_frame(flat, "flat"), "model", None)
    assert params == ThermalParams() and "does not determine tau" in source, source
    # the regressors: the identified smoother's gradient is far closer to the truth (the
    # fitted drift barely differs here: the nominal smoother's error is 0.002 degC/min)
    g_true = dict(zip(f["time_s"], f["g_true_c_per_min"], strict=True))
    g_err = {}
    for name, fit in (("identified", found), ("nominal", nominal)):
        truth = np.array([g_true[t] for t in fit.samples.time_s])
        g_err[name] = float(np.sqrt(np.mean((fit.samples.g_c_per_min - truth) ** 2)))
    assert g_err["identified"] < 0.1 * g_err["nominal"], g_err
    assert (
        np.max(np.abs(found.predict(s.t_c, s.g_c_per_min) - gyro.drift_dph(s.t_c, s.g_c_per_min)))
        < 0.05
    )


def test_selection_keeps_the_t_only_model_without_gradient_terms(tonly_fit):
    gyro, _, fit = tonly_fit
    assert fit.terms == TERM_SETS["t-only"]
    table = fit.selection
    assert table.loc[table["chosen"], "candidate"].tolist() == ["t-only"]
    assert (table["delta_bic"] >= 0).all()
    # nested candidates: the likelihood never gets worse with more terms
    m2ll = table.set_index("candidate").loc[list(CANDIDATES), "minus2_log_likelihood"]
    assert np.all(np.diff(m2ll.to_numpy()) <= 1e-6)
    s = fit.samples
    err = fit.predict(s.t_c, s.g_c_per_min) - gyro.drift_dph(s.t_c, s.g_c_per_min)
    assert np.sqrt(np.mean(err**2)) < 0.02


def test_t_only_reference_is_fitted_like_the_peers_fit_it(grad_fit):
    """The T-only reference of a gyro with gradient terms is the cubic in T that every
    sample fits alike (PX4, ArduPilot): checked against numpy's least squares on the
    estimates (the errors-in-variables correction is tiny in T). Weighted by a walk
    fitted to its own residuals it took the missing gradient terms for walk and its
    constant moved by ~0.7 deg/h (issue found by a stress test)."""
    _, _, fit = grad_fit
    s, ref = fit.samples, fit.reference
    assert ref.terms == TERM_SETS["t-only"]
    x = np.vander(s.t_c - ref.coding.t_ref_c, 4, increasing=True)
    lstsq = np.linalg.lstsq(x, s.drift_dph, rcond=None)[0]
    assert np.allclose(ref.coefficients_dph, lstsq, rtol=0.02, atol=2e-3 * np.abs(lstsq).max())
    assert abs(float(np.mean(s.drift_dph - ref.predict(s.t_c, s.g_c_per_min)))) < 1e-6


def test_holdout_on_a_second_run(grad_fit):
    gyro, _, fit = grad_fit
    h = fit.holdout
    assert h is not None and h.n_in_domain > 0.5 * h.n_samples
    # the model's held-out residual is the noise (white 0.2/sqrt(20 s) plus a small walk)
    assert h.rms_dph < 1.3 * 0.2 / math.sqrt(20.0) + 0.02
    assert h.reference_rms_dph > 2 * h.rms_dph


def test_json_coefficients_reproduce_the_fit(grad_fit):
    _, _, fit = grad_fit
    doc = json.loads(json.dumps(fit.to_json_dict()))
    t = np.linspace(REGION[0], REGION[1], 7)
    g = np.linspace(-0.5, 0.8, 7)
    by_hand = sum(
        c["coefficient"] * (t - doc["t_ref_c"]) ** c["power_t"] * g ** c["power_g"]
        for c in doc["coefficients"]
    )
    np.testing.assert_allclose(by_hand, fit.predict(t, g), rtol=1e-9, atol=1e-12)
    assert doc["terms"] in TERM_SETS and doc["condition_number"] > 1
    assert len(doc["selection"]) == len(CANDIDATES)
    # a FOG-like temperature coefficient: T_hat's mK errors are nothing in °/h
    assert 0.0 < doc["noise"]["regressor_error_share"] < 0.01
    assert not any("temperature and gradient estimates" in n for n in doc["notes"])


def test_compensation_table_stays_inside_the_reached_gradients(grad_fit):
    _, _, fit = grad_fit
    comp = fit.compensation_frame()
    assert list(comp.columns) == ["t_c", "g_c_per_min", "drift_dph"]
    res = fit.residual_frame()
    for t, grp in comp.groupby("t_c"):
        near = res[np.abs(res["t_est_c"] - t) <= 0.5]
        assert grp["g_c_per_min"].min() >= near["g_est_c_per_min"].min() - 1e-9
        assert grp["g_c_per_min"].max() <= near["g_est_c_per_min"].max() + 1e-9
    assert comp["t_c"].min() >= REGION[0] and comp["t_c"].max() <= REGION[1]
    np.testing.assert_allclose(comp["drift_dph"], fit.predict(comp["t_c"], comp["g_c_per_min"]))
    assert comp["t_c"].nunique() >= 25  # every degree of the region that the run crossed


def test_every_reached_temperature_keeps_a_compensation_row(grad_fit):
    """Red team: a slow monotone ramp reaches one gradient per degree, a range narrower than
    the 0.05 degC/min grid; those temperatures were dropped (a table with 0 rows, exit 0)."""

    _, _, fit = grad_fit
    domain = pd.DataFrame(
        {
            "t_c": [10.0, 11.0, 12.0],
            "g_min_c_per_min": [0.012, 0.04, -0.033],
            "g_max_c_per_min": [0.031, 0.06, -0.032],
            "n": [5, 5, 5],
        }
    )
    comp = dataclasses.replace(fit, domain=domain).compensation_frame()
    assert list(comp["t_c"]) == [10.0, 11.0, 12.0]
    np.testing.assert_allclose(comp["g_c_per_min"], [0.0215, 0.05, -0.0325])
    np.testing.assert_allclose(comp["drift_dph"], fit.predict(comp["t_c"], comp["g_c_per_min"]))


def test_pass_blocks_follow_the_gradient_sign_and_gaps():
    t = np.arange(100) * 10.0
    t[60:] += 3000.0  # left the region and came back
    g = np.where(np.arange(100) < 30, 0.5, -0.4)
    g[45] = 0.1  # a one-sample blip is merged, not a pass
    s = Samples(t, np.zeros(100), g, np.zeros(100), *(np.zeros(100),) * 3)
    labels = pass_blocks(s)
    assert labels[0] == labels[29] != labels[30]
    assert labels[30] == labels[59] != labels[60]
    assert np.unique(labels).size == 3
    cv = cross_validate(s, (TERM_SETS["t-only"],), Coding(0, 1, 1), blocks=labels)
    assert cv["n"].sum() == 100


# -- bad input ----------------------------------------------------------------------------
def test_bad_logs_get_clear_errors(programme):
    f = gyro_log(programme, _gyro(T_COEFS), sample_s=60.0, seed=0)
    with pytest.raises(LogFormatError, match="no drift_dph column"):
        fit_drift(log_from_frame(f.drop(columns=["drift_dph"])), REGION)
    # the rate in an IMU's own units: the error says what to rename and by what to
    # multiply, and doing what it says gives the log back (°/s and rad/s)
    import re

    for unit, scale in [("dps", 1 / 3600.0), ("rad_s", math.pi / 180.0 / 3600.0)]:
        other = f.drop(columns=["drift_dph"]).assign(**{f"gyro_z_{unit}": f["drift_dph"] * scale})
        with pytest.raises(LogFormatError) as info:
            fit_drift(log_from_frame(other), REGION)
        (factor,) = re.findall(
            rf"gyro_z_{unit} looks like .* rename it drift_dph and "
            r"multiply it by ([0-9.]+)",
            str(info.value),
        )
        np.testing.assert_allclose(
            other[f"gyro_z_{unit}"] * float(factor), f["drift_dph"], rtol=1e-5
        )
        assert "\n" not in str(info.value)
    with pytest.raises(LogFormatError, match="no drift_dph column") as info:
        fit_drift(log_from_frame(f.drop(columns=["drift_dph"]).assign(x_dps=1.0)), REGION)
    assert "looks like" not in str(info.value)  # a name that says nothing of a rate
    with pytest.raises(ParameterError, match="never enters the region 30 .. 60"):
        fit_drift(log_from_frame(f), (30.0, 60.0))
    # red team: drift_dph blank after row 5 was told the run never entered the region
    blank = f.copy()
    blank.loc[5:, "drift_dph"] = np.nan
    with pytest.raises(LogFormatError, match=r"enters the region .* none of its drift_dph"):
        fit_drift(log_from_frame(blank), REGION)
    # the refusal says where the run went (red team: a region partly outside the log was
    # refused without the span it covers)
    span = rf"narrow --region to where the run went, {f['t_int_c'].min():.1f} \.\. "
    with pytest.raises(ParameterError, match=r"bins -54 .. -52 °C have fewer than 5.*" + span):
        fit_drift(log_from_frame(f), (-54.0, -21.0))
    # one row in the region is too few samples, not a stuck channel
    with pytest.raises(ParameterError, match="too few samples"):
        fit_drift(log_from_frame(f), (-54.0, -21.0), FitSettings(min_points_per_bin=1))
    with pytest.raises(ParameterError, match="lo < hi"):
        fit_drift(log_from_frame(f), (-20.0, -30.0))
    with pytest.raises(ParameterError, match="unknown drift term"):
        FitSettings(terms="1,t,tt")
    with pytest.raises(ParameterError, match="n_error_draws"):
        FitSettings(n_error_draws=1)


def test_a_hold_and_a_single_pass_are_told_what_they_cannot_fit(programme):
    """Red team: a log holding one temperature got "normal matrix singular"; a 10-minute log
    through the region was fitted without a word."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 3 * 3600.0, 10.0)
    noise = rng.standard_normal((2, t.size))
    hold = pd.DataFrame({"time_s": t, "t_int_c": np.round(-37.0 + 0.02 * noise[0], 2),
                         "tk_set_c": -40.0, "drift_dph": 0.5 + 0.01 * noise[1]})  # fmt: skip
    with pytest.raises(ParameterError, match=r"stays within -37\.\d\d \.\. -3[67]\.\d\d °C, less"):
        fit_drift(log_from_frame(hold, "hold"), (-38.0, -36.0))
    frame = gyro_log(programme, _gyro(T_COEFS), sample_s=10.0, seed=4)
    g_true = frame["g_true_c_per_min"].to_numpy()
    cooling = int(np.flatnonzero(g_true < -0.01)[0])
    down = frame.iloc[: cooling + int(np.flatnonzero(g_true[cooling:] > 0)[0])]  # 20 -> -48
    fit = fit_drift(log_from_frame(down, "down"), (-45.0, -25.0))
    note = next(n for n in fit.notes if "come from one pass" in n)
    minutes = (fit.samples.time_s[-1] - fit.samples.time_s[0]) / 60.0
    assert f"({minutes:.0f} min, one sign" in note
    whole = fit_drift(log_from_frame(frame, "whole"), (-45.0, -25.0))
    assert not any("one pass" in n for n in whole.notes)


# -- the command line ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def logs_dir(tmp_path_factory, programme):
    d = tmp_path_factory.mktemp("fitlogs")
    gyro = _gyro(GRAD_COEFS)
    gyro_log(programme, gyro, sample_s=30.0, seed=1).to_csv(d / "run1.csv", index=False)
    gyro_log(programme, gyro, sample_s=30.0, seed=2).to_csv(d / "run2.csv", index=False)
    return d


def test_cli_fit_writes_every_output(logs_dir, tmp_path, capsys):
    out = tmp_path / "fit"
    rc = main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21", "--holdout",
               str(logs_dir / "run2.csv"), "--out", str(out)])  # fmt: skip
    assert rc == 0
    text = capsys.readouterr().out
    assert "term selection" in text and "held out" in text and "°/h" in text
    for name in ("coefficients.json", "compensation.csv", "residuals.csv", "residuals_t.png",
                 "residuals_g.png", "surface.png"):  # fmt: skip
        assert (out / name).stat().st_size > 0, name
    doc = json.loads((out / "coefficients.json").read_text())
    assert doc["holdout"]["n_in_domain"] > 0
    assert doc["gradient_estimator_model"]["source"].startswith("identified from the log")
    assert "thermal model of the smoother: identified" in text
    comp = pd.read_csv(out / "compensation.csv")
    assert list(comp.columns) == ["t_c", "g_c_per_min", "drift_dph"]


def test_cli_fit_terms_option_and_errors(logs_dir, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21", "--terms",
                 "t-only", "--out", str(out)]) == 0  # fmt: skip
    doc = json.loads((out / "coefficients.json").read_text())
    assert [c["term"] for c in doc["coefficients"]] == list(TERM_SETS["t-only"])
    # the weighting: as asked, in the JSON and the summary
    out_ols = tmp_path / "fit_ols"
    assert main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21", "--terms",
                 "t-only", "--weighting", "ols", "--tau-s", "2300", "--out",
                 str(out_ols)]) == 0  # fmt: skip
    assert "ordinary least squares" in capsys.readouterr().out
    doc_ols = json.loads((out_ols / "coefficients.json").read_text())
    assert doc_ols["weighting"]["method"] == "ols"
    model = doc_ols["gradient_estimator_model"]  # one option given: the other's default
    assert (model["tau_s"], model["dt0_c"], model["source"]) == (2300.0, 3.0, "given")
    # weighted where the run's fitted walk is not 0 (where it is, the two are the same)
    walk = doc["noise"]["bias_walk_dph_per_rt_h"]
    assert doc["weighting"]["method"] == ("gls" if walk > 0 else "ols"), (doc["weighting"], walk)
    assert main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21",
                 "--weighting", "wls", "--out", str(out)]) == 2  # fmt: skip
    assert "--weighting" in capsys.readouterr().err
    assert main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21",
                 "--outliers", "ignore", "--out", str(out)]) == 2  # fmt: skip
    assert "--outliers" in capsys.readouterr().err
    # a glitch: left out and said so; --outliers keep fits it
    glitch = tmp_path / "glitch.csv"
    frame = pd.read_csv(logs_dir / "run1.csv")
    frame.loc[
        frame.index[(frame["t_true_c"] > -40) & (frame["t_true_c"] < -30)][5], "drift_dph"
    ] = 999.9
    frame.to_csv(glitch, index=False)
    assert main(["fit", str(glitch), "--region", "-50", "-21", "--out", str(tmp_path / "g1")]) == 0
    assert "left out 1 drift_dph reading(s)" in capsys.readouterr().out
    assert main(["fit", str(glitch), "--region", "-50", "-21", "--outliers", "keep",
                 "--out", str(tmp_path / "g2")]) == 0  # fmt: skip
    assert "left out" not in capsys.readouterr().out
    for argv, words in (
        (["--region", "30", "60"], "never enters"),
        (["--region", "-50", "-21", "--terms", "cubic"], "unknown term set"),
    ):
        assert main(["fit", str(logs_dir / "run1.csv"), *argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err, err
    no_drift = tmp_path / "nodrift.csv"
    pd.read_csv(logs_dir / "run1.csv").drop(columns=["drift_dph"]).to_csv(no_drift, index=False)
    assert main(["fit", str(no_drift), "--region", "-50", "-21", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "drift_dph" in err
    # a log with a gap in its sampling is fitted, and the gap said (red team: no word)
    gappy = tmp_path / "gappy.csv"
    frame = pd.read_csv(logs_dir / "run1.csv")
    cut = (frame["time_s"] > 12000) & (frame["time_s"] < 13200)
    frame[~cut].to_csv(gappy, index=False)
    assert main(["fit", str(gappy), "--region", "-50", "-21", "--out", str(tmp_path / "gap")]) == 0
    err = capsys.readouterr().err
    assert "1 gap(s) in the sampling, the longest 20.0 min (12000 .. 13200 s)" in err, err
    # a stuck channel (0 or a constant on every row): said so, not "use a longer log"
    for value in (0.0, 0.5):
        stuck = tmp_path / f"stuck{value:g}.csv"
        pd.read_csv(logs_dir / "run1.csv").assign(drift_dph=value).to_csv(stuck, index=False)
        assert main(["fit", str(stuck), "--region", "-50", "-21", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"drift_dph reads {value:g} °/h on every one" in err


@pytest.mark.parametrize(
    "extra, axis",
    [
        (lambda t, g: 0.3 * np.tanh((t + 40.0) / 5.0), "t"),  # a knee in T
        (lambda t, g: 0.15 * np.tanh(g / 0.05), "g"),  # heating and cooling differ
        (None, None),
    ],
)
def test_lack_of_fit_names_a_drift_that_is_not_a_polynomial(programme, extra, axis):
    """A drift the cubic cannot follow is named (and in which variable) instead of being
    taken for bias walk; a polynomial drift is not (nor the fixtures' gyros)."""
    frame = gyro_log(programme, _gyro(GRAD_COEFS), sample_s=20.0, seed=6)
    if extra is not None:
        e = extra(frame["t_true_c"].to_numpy(), frame["g_true_c_per_min"].to_numpy())
        frame["drift_dph"] += e
    fit = fit_drift(log_from_frame(frame, "misfit"), REGION)
    notes = [n for n in fit.notes if n.startswith("lack of fit")]
    found = fit.lack_of_fit
    deltas = {k: v for k, v in found.items() if k.startswith("delta_bic")}
    if axis is None:
        assert notes == [] and min(deltas.values()) > 0, found
        return
    assert len(notes) == 1, fit.notes
    assert found[f"delta_bic_{axis}"] < -20, found
    other = "g" if axis == "t" else "t"
    assert found[f"delta_bic_{other}"] > -10, found
    assert ("with T" in notes[0]) == (axis == "t") and ("with g" in notes[0]) == (axis == "g")
    assert fit.to_json_dict()["lack_of_fit"]["delta_bic_" + axis] == found["delta_bic_" + axis]


def test_polynomial_gyros_show_no_lack_of_fit(grad_fit, tonly_fit):
    for _, _, fit in (grad_fit, tonly_fit):
        deltas = [v for k, v in fit.lack_of_fit.items() if k.startswith("delta_bic")]
        assert len(deltas) == 3 and min(deltas) > -LACK_OF_FIT_DELTA_BIC, fit.lack_of_fit
        assert not any(n.startswith("lack of fit") for n in fit.notes)


def _lag_exact(time_s, x, tau_s):
    """A first-order lag by scipy's ODE solver on x linear between samples (apart from
    driftfit.lagged)."""
    from scipy.integrate import solve_ivp

    sol = solve_ivp(
        lambda t, y: (np.interp(t, time_s, x) - y) / tau_s,
        (time_s[0], time_s[-1]),
        [x[0]],
        t_eval=time_s,
        max_step=10.0,
        rtol=1e-9,
        atol=1e-9,
    )
    return sol.y[0]


@pytest.mark.parametrize("uniform", [True, False])
def test_lagged_matches_an_ode_solution(uniform):
    """Irregular sampling (the recursion) and uniform (the same as a linear filter)."""
    steps = np.full(400, 20.0) if uniform else np.random.default_rng(3).uniform(5.0, 30.0, 400)
    t = np.cumsum(np.r_[0.0, steps])
    x = 20.0 + 10.0 * np.sin(t / 900.0) + 0.5 * (t > 4000)
    assert np.max(np.abs(driftfit.lagged(t, x, 600.0) - _lag_exact(t, x, 600.0))) < 1e-5


def test_a_drift_that_follows_a_lagged_temperature_is_named(programme):
    """Red team: a T-only gyro whose drift follows the temperature 300-1200 s late (a
    thermal mass between the sensor and the sensing element) was fitted with its lag taken
    for bias walk (0.12-0.37 against 0.01 deg/h/sqrt h) and no note."""
    coefs = {k: 20.0 * v for k, v in T_COEFS.items()}
    gyro = _gyro(coefs)
    frame = gyro_log(programme, gyro, sample_s=20.0, seed=6)
    t_s, t_true = frame["time_s"].to_numpy(), frame["t_true_c"].to_numpy()
    zero = np.zeros(t_s.size)
    late = _lag_exact(t_s, t_true, 600.0)
    frame["drift_dph"] += gyro.drift_dph(late, zero) - gyro.drift_dph(t_true, zero)
    fit = fit_drift(log_from_frame(frame, "lagged"), REGION)
    found = fit.lack_of_fit
    assert found["delta_bic_lag"] < -LACK_OF_FIT_DELTA_BIC, found
    assert found["lag_s"] in driftfit.LACK_OF_FIT_LAGS_S
    note = next(n for n in fit.notes if n.startswith("lack of fit"))
    assert f"lags the measured one by about {found['lag_s']:.0f} s" in note


def test_a_partly_blank_setpoint_column_says_why_the_kinematic_smoother_is_used(programme):
    frame = gyro_log(programme, _gyro(T_COEFS), sample_s=20.0, seed=5)
    frame.loc[frame.index[100:140], "tk_set_c"] = np.nan
    fit = fit_drift(log_from_frame(frame, "partial"), REGION)
    assert fit.estimator == "kinematic"
    assert any("tk_set_c is blank on 40 of" in n for n in fit.notes), fit.notes
    assert any("tk_set_c is blank" in line for line in fit.summary_lines())
    whole = fit_drift(log_from_frame(frame.drop(columns=["tk_set_c"]), "none"), REGION)
    assert whole.estimator == "kinematic" and whole.notes == ()


def test_a_region_narrower_than_the_tables_step_still_plots(programme):
    """A region narrower than the table's 1 degC step: the table has its two ends (it had
    one temperature, and the surface plot raised TypeError inside matplotlib, after the
    table was written)."""
    from schedsyn import fitplots

    frame = gyro_log(programme, _gyro(T_COEFS), sample_s=10.0, seed=4)
    fit = fit_drift(log_from_frame(frame, "narrow"), (-36.0, -35.5))
    assert list(fit.domain["t_c"]) == [-36.0, -35.5]
    ax = fitplots.fit_surface_plot(fit)
    assert ax.collections  # the contours and the samples
    import matplotlib.pyplot as plt

    plt.close(ax.figure)


# -- glitches in drift_dph ------------------------------------------------------------------
def test_drift_outliers_find_glitches_not_noise_steps_kinks_or_quantisation(rng):
    """Spikes (20 sigma, either sign, single and paired) and a long block of sentinels
    are found; Gaussian noise on a trend steeper than the noise per row, a real step, a
    kink, a noise-free curve and a coarsely quantised series are not."""
    n, sigma = 3000, 0.01
    t_s = 10.0 * np.arange(n)
    smooth = 0.3 * np.sin(t_s / 4000.0) + 0.02 * t_s / 60.0  # trend 3 sigma per row
    smooth[1800:] += 0.5  # a real step
    smooth[2200:] += 0.0004 * (t_s[2200:] - t_s[2200]) / 10.0  # a kink
    assert drift_outliers(t_s, smooth)[0].size == 0  # noise-free
    assert drift_outliers(t_s, np.round(smooth + rng.normal(0, sigma, n), 1))[0].size == 0
    d = smooth + rng.normal(0, sigma, n)
    assert drift_outliers(t_s, d)[0].size == 0
    spikes = np.array([5, 700, 701, 1500, 2999])
    d[spikes] += 20 * sigma * np.array([1, -1, -1, 1, -3])  # the last row: 16 sigma needed
    d[2500:2540] = 999.9
    rows, z = drift_outliers(t_s, d)
    expected = np.concatenate([spikes, np.arange(2500, 2540)])
    assert sorted(rows) == sorted(expected)
    assert np.all(z > 8)
    # NaN readings are skipped, not outliers, and the rows stay the log's
    d2 = d.copy()
    d2[::7] = np.nan
    rows2, _ = drift_outliers(t_s, d2)
    assert set(rows2) == set(rows) - set(range(0, n, 7))


def test_fit_leaves_out_glitches_lists_them_and_refuses_a_bad_column(programme):
    gyro = _gyro(GRAD_COEFS)
    frame = gyro_log(programme, gyro, sample_s=20.0, seed=1)
    inside = np.flatnonzero((frame["t_true_c"] > -45) & (frame["t_true_c"] < -25))
    glitches = inside[[10, 200, 400]]
    dirty = frame.copy()
    dirty.loc[glitches, "drift_dph"] = 999.9
    clean_fit = fit_drift(log_from_frame(frame, "clean"), REGION)
    fit = fit_drift(log_from_frame(dirty, "dirty"), REGION)
    assert [r for r, *_ in fit.outliers] == sorted(glitches)
    assert clean_fit.outliers == ()
    assert fit.terms == clean_fit.terms
    se = fit.model.std_errors
    assert np.all(np.abs(fit.model.coefficients_dph - clean_fit.model.coefficients_dph) < se)
    assert any("left out 3 drift_dph reading(s)" in line for line in fit.summary_lines())
    doc = fit.to_json_dict()
    assert [o["row"] for o in doc["outliers_left_out"]] == sorted(glitches)
    kept = fit_drift(log_from_frame(dirty, "dirty"), REGION, FitSettings(outliers="keep"))
    assert kept.outliers == () and kept.model.residual_rms_dph > 10 * fit.model.residual_rms_dph
    # a long block of sentinels is not a few glitches
    block = frame.copy()
    block.loc[inside[:60], "drift_dph"] = 1e6
    with pytest.raises(ParameterError, match="not a few glitches"):
        fit_drift(log_from_frame(block, "block"), REGION)
    with pytest.raises(ParameterError, match="outliers must be one of"):
        FitSettings(outliers="ignore")


@pytest.mark.parametrize("name", ["compensation.csv", "surface.png"])
def test_cli_fit_never_overwrites_its_input(logs_dir, tmp_path, capsys, name):
    """A log in --out under the name of an output (the last one written among them, too)
    is refused before anything is written: the folder keeps what it held (red team:
    coefficients.json and compensation.csv were replaced before residuals.csv refused)."""
    src = tmp_path / name
    src.write_bytes((logs_dir / "run1.csv").read_bytes())
    earlier = tmp_path / "coefficients.json"
    earlier.write_text('{"from": "an earlier fit"}')
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(["fit", str(src), "--region", "-50", "-21", "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_drift_rows_in_a_long_sensor_dropout_are_left_out_and_said(programme):
    """t_int_c blank for 2.8 h while the drift is still logged, no setpoint: the kinematic
    smoother only guesses the temperature across the gap (red team: up to 22 degC off,
    the fit ten times worse than without the gap, and no word). Rows farther than
    FIT_MAX_GAP_S from a reading are left out and counted in a note; the fitted drift
    stays within 0.05 deg/h RMS of the truth over the compensation table."""
    gyro = _gyro(GRAD_COEFS)
    f = gyro_log(programme, gyro, sample_s=20.0, seed=5)
    f = f.drop(columns=["tk_set_c", "tk_air_c"])
    gap = (f["time_s"] > 3.0 * 3600) & (f["time_s"] < 5.8 * 3600)
    f.loc[gap, "t_int_c"] = np.nan
    fit = fit_drift(log_from_frame(f, "dropout"), REGION)
    assert fit.estimator == "kinematic"
    (note,) = [n for n in fit.notes if n.startswith("left out")]
    time = f["time_s"].to_numpy()
    reading = time[~gap.to_numpy()]
    far = gap.to_numpy() & (np.abs(time[:, None] - reading[None, :]).min(axis=1) > 600.0)
    assert far.sum() > 0 and "more than 600 s" in note
    # none of the fitted samples is one of the far rows
    assert not np.isin(fit.samples.time_s, time[far]).any()
    comp = fit.compensation_frame()
    t, g = comp["t_c"].to_numpy(), comp["g_c_per_min"].to_numpy()
    err = comp["drift_dph"].to_numpy() - gyro.drift_dph(t, g)
    assert np.sqrt(np.mean(err**2)) < 0.05, np.sqrt(np.mean(err**2))


def _w3_random_gyro_fit(seed, terms="auto"):
    from schedsyn.gyro import random_gyro

    prog = read_steps("tests/data/plans/w3_steps.csv")
    gyro = random_gyro(np.random.default_rng([seed, 2, ord("3")]), (-2.0, 33.0))
    frame = gyro_log(prog, gyro, sample_s=10.0, seed=seed)
    log = log_from_frame(
        frame.drop(columns=["t_true_c", "g_true_c_per_min", "drift_true_dph", "bias_walk_dph"]),
        f"w3-{seed}",
    )
    return fit_drift(log, (-2.0, 33.0), FitSettings(terms=terms))


def _w3_gyro(seed):
    from schedsyn.gyro import random_gyro

    return random_gyro(np.random.default_rng([seed, 2, ord("3")]), (-2.0, 33.0))


def test_a_fit_that_drops_terms_the_run_cannot_rule_out_says_how_much_they_move_it():
    """Red team: BIC dropped the example gyro's g2 and g3 on W1's plan; t and t3 came out
    5-6 standard errors off and nothing but the BIC table said terms were dropped. The
    note's figures and the widening of the standard errors are checked against a separate
    fit of the larger model: the bias is the difference less its own noise
    (``var_full - var_chosen``)."""
    fit = _w3_random_gyro_fit(0)
    assert fit.terms == parse_terms("g1")
    note = next(n for n in fit.notes if n.startswith("BIC chose g1, but with g2, tg2, g3"))
    full = _w3_random_gyro_fit(0, terms="full")
    comp = fit.compensation_frame()
    t, g = comp["t_c"].to_numpy(), comp["g_c_per_min"].to_numpy()
    k = fit.model.selection_widening
    sd = fit.model.predict_std(t, g) / k  # before the widening
    diff = full.predict(t, g) - fit.predict(t, g)
    bias2 = np.maximum(diff**2 - np.maximum(full.model.predict_std(t, g) ** 2 - sd**2, 0.0), 0.0)
    assert k == pytest.approx(np.sqrt(np.mean((sd**2 + bias2) / sd**2)), rel=1e-9)
    assert k > 1.05 and f"widened {k:.2f}x" in note
    share = np.mean(bias2 > (driftfit.DROPPED_TERMS_SIGMAS * sd) ** 2)
    if share > driftfit.DROPPED_TERMS_SHARE:
        assert f"deviations on {share:.0%} of the compensation table" in note, note
        assert f"up to {np.abs(diff).max():.3g} °/h" in note
    assert "--terms full" in note
    # the widened standard deviations cover the truth better than the chosen model's own
    err = np.abs(fit.predict(t, g) - _w3_gyro(0).drift_dph(t, g))
    assert np.mean(err < 2 * k * sd) > np.mean(err < 2 * sd) + 0.05
    # chosen full: nothing was dropped, no note, no widening
    other = _w3_random_gyro_fit(1)
    assert not any(n.startswith("BIC chose") for n in other.notes)
    assert other.model.selection_widening == 1.0


def test_no_dropped_terms_note_where_the_larger_model_only_adds_noise():
    """Red team: a slow monotone ramp of a gyro with g1 terms only; the full model, ill
    conditioned there (condition number 776), sat 6 standard errors away and the note
    pushed --terms full, which fitted 6x worse. The difference is the full model's own
    noise: no note, and hardly any widening (on the raw difference: a note and 2.9x)."""
    from schedsyn.gyro import Gyro
    from schedsyn.programme import Programme

    gyro = Gyro(
        coefficients_dph={"1": 0.3, "t": 0.015, "t2": -0.0008, "t3": 2e-05, "g": 0.7, "tg": 0.01},
        t_ref_c=15.0,
        white_noise_dph_per_rt_hz=0.3,
        bias_walk_dph_per_rt_h=0.01,
    )
    # down to -5 degC at 1 degC/min, a hold, then 0.1 degC/min up to 39 (the red team's)
    prog = Programme(np.array([25.0, 125.0, 440.0]), np.array([-1.0, 0.0, 0.1]), 20.0)
    frame = gyro_log(prog, gyro, sample_s=10.0, seed=1)
    log = log_from_frame(
        frame.drop(columns=["t_true_c", "g_true_c_per_min", "drift_true_dph", "bias_walk_dph"])
    )
    fit = fit_drift(log, (2.0, 34.0))
    assert not any(n.startswith("BIC chose") for n in fit.notes), fit.notes
    assert fit.model.selection_widening < 1.05


def test_no_dropped_terms_note_on_a_t_only_choice():
    """Adding six free gradient terms moves a T-only gyro's T coefficients by a few of
    their standard errors too: on the T-only cubic (BIC's strong evidence against any
    gradient term) the note would only alarm (it fired on half of such gyros)."""
    from schedsyn.gyro import random_gyro

    prog = read_steps("tests/data/plans/w3_steps.csv")
    for seed in range(4):
        gyro = random_gyro(np.random.default_rng([seed, 9]), (-2.0, 33.0), gradient_terms=False)
        frame = gyro_log(prog, gyro, sample_s=10.0, seed=seed)
        log = log_from_frame(
            frame.drop(columns=["t_true_c", "g_true_c_per_min", "drift_true_dph", "bias_walk_dph"])
        )
        fit = fit_drift(log, (-2.0, 33.0))
        assert fit.terms == parse_terms("t-only")
        assert not any(n.startswith("BIC chose") for n in fit.notes), fit.notes


def test_regressor_error_covariance_matches_repeated_fits(programme, rng):
    """The coefficients' scatter caused by slow errors in T_hat and g_hat alone (an exact
    polynomial drift, no drift noise), over 300 fits, against the covariance
    ``regressor_error_covariance`` predicts from other draws of the same errors."""
    traj = simulate(programme, dt_min=1 / 3)
    m = (traj.t_c >= REGION[0]) & (traj.t_c <= REGION[1])
    t, g = traj.t_c[m], traj.g_c_per_min[m]
    time_s = traj.time_min[m] * 60.0
    coefs = {"1": 0.5, "t": 50.0, "t2": 0.05, "t3": -0.002, "g": 0.8, "g2": -0.2}
    gyro = _gyro(coefs, white=0.0, walk=0.0)
    d = gyro.drift_dph(t, g)
    coding = Coding(CENTRE, 14.5, 1.0)
    terms = TERM_SETS["full"]
    n = t.size

    def errors(k):  # slow errors: a smoothed walk of about 3 mK and its own g error
        walk = np.cumsum(rng.standard_normal((k, n)), axis=1)
        kernel = np.ones(31) / 31
        slow = np.array([np.convolve(w - w.mean(), kernel, mode="same") for w in walk])
        return 3e-3 * slow / slow.std(), 2e-4 * rng.standard_normal((k, n))

    zeros = np.zeros(n)
    e_t, e_g = errors(300)
    fits = np.array([
        fit_coefficients(Samples(time_s, t + a, g + b, d, zeros, zeros, zeros), terms, coding,
                         eiv=False)
        for a, b in zip(e_t, e_g, strict=True)
    ])  # fmt: skip
    p_t, p_g = errors(400)
    s = Samples(time_s, t, g, d, zeros, zeros, zeros, p_t / 20.0, p_g / 20.0)
    x = monomials(*coding.code(t, g), terms)
    coef = np.linalg.solve(x.T @ x, x.T @ d)
    cov = driftfit.regressor_error_covariance(s, coding, terms, coef, x @ np.linalg.inv(x.T @ x))
    measured = np.std(fits, axis=0)
    predicted = np.sqrt(np.diag(cov))
    assert measured[1] > 1e-3, measured  # the errors do move the fit
    np.testing.assert_allclose(predicted, measured, rtol=0.2)


def test_standard_errors_count_the_temperature_estimates_error(programme):
    """A temperature coefficient large against the drift noise (200 °/h/°C, 0.3 °/h/√Hz):
    T_hat's error of about a mK moves the fit by more than the drift noise does, and the
    standard errors count it (T_hat's noise and its identified model's uncertainty)."""
    gyro = Gyro({"1": 5.0, "t": 200.0, "t2": 0.05, "t3": -0.002}, t_ref_c=CENTRE,
                white_noise_dph_per_rt_hz=0.3, bias_walk_dph_per_rt_h=0.01,
                sensor_noise_c=0.02, sensor_quant_c=0.0625)  # fmt: skip
    z = []
    for seed in range(6):
        frame = gyro_log(programme, gyro, sample_s=10.0, seed=seed)
        log = log_from_frame(frame[["time_s", "t_int_c", "tk_set_c", "drift_dph"]], "big tempco")
        fit = fit_drift(log, REGION, FitSettings(terms="t-only"))
        table = fit.compensation_frame()
        t, g = table.t_c.to_numpy(), table.g_c_per_min.to_numpy()
        err = fit.model.predict(t, g) - gyro.drift_dph(t, g)
        z.append(err / fit.model.predict_std(t, g))
        assert fit.model.regressor_share > 0.5
        assert any("temperature and gradient estimates make up" in n for n in fit.notes)
    rms_z = float(np.sqrt(np.mean(np.square(np.concatenate(z)))))
    # six runs of the baseline: 0.80 (2.7 without the regressors' share; 1.3 at 50 °/h/°C)
    assert 0.4 < rms_z < 1.6, rms_z


def _w3_log(gyro, seed, sample_s=10.0, scale=1.0):
    prog = read_steps("tests/data/plans/w3_steps.csv")
    frame = gyro_log(prog, gyro, sample_s=sample_s, seed=seed)
    frame = frame.drop(columns=["t_true_c", "g_true_c_per_min", "drift_true_dph", "bias_walk_dph"])
    frame["drift_dph"] *= scale
    return log_from_frame(frame, f"w3-{seed}")


@pytest.mark.parametrize(
    ("drift_offset_dph", "white_dph", "scale", "refused"),
    [
        (0.5, 0.01, 1.0, False),  # a navigation gyro in deg/h
        (0.5, 0.0, 1.0, False),  # a noiseless simulation: tenths of a deg/h, no noise
        (0.02, 0.001, 1.0, False),  # small drift, plausible noise (ARW 3.7e-5)
        (0.5, 0.01, 1.0 / 3600.0, True),  # the same gyro in deg/s
        (30.0, 1.0, math.pi / 180.0 / 3600.0, True),  # a MEMS gyro in rad/s
        (400.0, 1.0, 1.0 / 3600.0, False),  # 0.11 in deg/s: beyond the magnitude tell
    ],
)
def test_the_drift_unit_check_needs_both_tells(drift_offset_dph, white_dph, scale, refused):
    rng = np.random.default_rng(7)
    t = np.arange(3000) * 5.0
    d = drift_offset_dph + 1e-3 * np.sin(t / 4000.0) + white_dph * rng.standard_normal(t.size)
    if refused:
        with pytest.raises(LogFormatError, match="--trust-drift-units"):
            driftfit.check_drift_units("log", t, d * scale)
    else:
        driftfit.check_drift_units("log", t, d * scale)


def test_a_drift_in_degrees_per_second_is_refused_or_questioned():
    """Red team: drift_dph logged in deg/s (3600x too small) was fitted without a word, then
    with exit 0 and a note. Small and quiet at once is refused; told it is deg/h, the fit
    runs and still says why it doubts it."""
    gyro = _w3_gyro(4)
    assert not any("°/s" in n for n in fit_drift(_w3_log(gyro, 4), (-2.0, 33.0)).notes)
    in_dps = _w3_log(gyro, 4, scale=1.0 / 3600.0)
    with pytest.raises(LogFormatError, match=r"reads like °/s \(multiply by 3600\)"):
        fit_drift(in_dps, (-2.0, 33.0))
    fit = fit_drift(in_dps, (-2.0, 33.0), FitSettings(check_drift_units=False))
    note = next(n for n in fit.notes if "°/s" in n)
    arw = fit.model.white_sigma_dph * math.sqrt(10.0 / 3600.0)
    assert arw < driftfit.MIN_PLAUSIBLE_ARW_DEG_PER_RT_H and f"{arw:.2g} °/√h" in note


def test_the_held_out_check_says_when_another_log_is_fitted_much_worse():
    """Red team: another gyro held out gave 9x the fit's residual and no verdict."""
    gyro = _w3_gyro(5)
    log = _w3_log(gyro, 5)
    same = fit_drift(log, (-2.0, 33.0), holdout=_w3_log(gyro, 6))
    assert not any("held-out log is fitted" in n for n in same.notes), same.notes
    # the same gyro logged every 60 s: more noise per reading, no note (verification red
    # team: "2.4x worse", sqrt 6)
    slow = fit_drift(log, (-2.0, 33.0), holdout=_w3_log(gyro, 6, sample_s=60.0))
    assert not any("held-out log is fitted" in n for n in slow.notes), slow.notes
    other_log = _w3_log(_w3_gyro(7), 6)
    other = fit_drift(log, (-2.0, 33.0), holdout=other_log)
    h = other.holdout
    scale = driftfit._reading_noise_dph(other_log) / driftfit._reading_noise_dph(log)
    ratio = math.sqrt(h.rms_dph**2 - h.mean_dph**2) / (other.model.residual_rms_dph * scale)
    assert ratio > driftfit.HOLDOUT_WORSE
    assert any(f"fitted {ratio:.1f}x worse" in n for n in other.notes), other.notes


def test_a_t_only_request_on_a_gradient_gyro_says_what_it_misses():
    fit = _w3_random_gyro_fit(0, terms="t-only")
    assert fit.terms == parse_terms("t-only")
    row = fit.selection.set_index("candidate")
    gain = row.loc["t-only", "bic"] - row.loc["g1", "bic"]
    assert gain > driftfit.T_ONLY_NOTE_DELTA_BIC
    assert any(f"prefers the first-order gradient terms (g1) by {gain:.0f}" in n for n in fit.notes)


def test_a_region_narrower_than_a_bin_is_said_and_its_far_end_tabled():
    """Red team: --region 10.3 11.2 was fitted without a word and the table stopped at
    10.3 (the grid steps 1 degC from LO)."""
    fit = fit_drift(_w3_log(_w3_gyro(0), 0), (10.3, 11.2))
    assert any("narrower than one 1 °C bin" in n for n in fit.notes)
    assert sorted(set(fit.compensation_frame()["t_c"])) == [10.3, 11.2]


def test_a_sparse_log_is_told_its_sampling_leaves_bins_short():
    """Red team: a 60-s log was told to narrow a region its run had crossed."""
    log = _w3_log(_w3_gyro(0), 0, sample_s=60.0)
    with pytest.raises(
        ParameterError, match=r"passes through \d+ of them, but the log samples every 60 s"
    ):
        fit_drift(log, (-2.0, 33.0), FitSettings(min_points_per_bin=40))


def test_cli_fit_refuses_a_drift_in_degrees_per_second_unless_told(logs_dir, tmp_path, capsys):
    frame = pd.read_csv(logs_dir / "run1.csv")
    frame["drift_dph"] /= 3600.0
    path = tmp_path / "dps.csv"
    frame.to_csv(path, index=False)
    args = ["fit", str(path), "--region", "-50", "-21", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "reads like °/s (multiply by 3600)" in err and err.count("\n") == 1, err
    assert not (tmp_path / "a").exists()
    assert main([*args, "--out", str(tmp_path / "b"), "--trust-drift-units"]) == 0
    assert (tmp_path / "b" / "compensation.csv").exists()
