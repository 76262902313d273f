"""Drift fit: errors-in-variables maths, noise model and standard errors against dense
computation, recovery of known polynomials from synthetic gyro logs, term selection,
compensation table, bad input and the `schedsyn fit` command."""

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from schedsyn.cli import main
from schedsyn.driftfit import (
    WALK_UPPER_DELTA_M2LL,
    Coding,
    FitSettings,
    Samples,
    cross_validate,
    estimation_errors,
    fit_coefficients,
    fit_drift,
    fit_samples,
    noise_fit,
    pass_blocks,
    walk_covariance,
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
def test_adjusted_least_squares_removes_classical_error_bias(rng):
    """Regressors with known Gaussian errors: plain least squares attenuates and shifts
    the gradient terms; adjusted least squares does not (mean over replicates)."""
    n = 3000
    t = rng.uniform(-50, -20, n)
    g = rng.uniform(-0.8, 1.0, n)
    d = 0.2 + 0.01 * (t + 35) + 1.0 * g + 0.5 * g**3
    coding = Coding(-35.0, 15.0, 1.0)
    sd_t, sd_g = 0.05, 0.15
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
            errs[eiv].append(fit_coefficients(s, "full", coding, eiv=eiv) - truth)
    plain = np.mean(errs[False], axis=0)
    adjusted = np.mean(errs[True], axis=0)
    se = np.std(errs[False], axis=0, ddof=1) / math.sqrt(30)
    for k in (2, 9):  # g and g3
        assert abs(plain[k]) > 10 * se[k]  # a real bias ...
        assert abs(adjusted[k]) < 0.2 * abs(plain[k])  # ... removed


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
    """z = (estimate - truth)/std error over replicates has unit spread; standard errors
    that ignore the walk are several times too small."""
    traj = simulate(programme, dt_min=1 / 3)
    m = (traj.t_c >= REGION[0]) & (traj.t_c <= REGION[1])
    time_s = traj.time_min * 60.0
    gyro = _gyro(GRAD_COEFS, white=0.3, walk=0.02)
    true = gyro.drift_dph(traj.t_c, traj.g_c_per_min)
    truth = gyro.coefficient_vector
    coding = Coding(CENTRE, 14.5, 1.0)
    zeros = np.zeros(int(m.sum()))
    rng = np.random.default_rng(11)
    z, z_iid = [], []
    for _ in range(40):
        white, walk = drift_noise(time_s, gyro, rng)
        s = Samples(time_s[m], traj.t_c[m], traj.g_c_per_min[m], (true + white + walk)[m],
                    zeros, zeros, zeros)  # fmt: skip
        fit = fit_samples(s, "full", coding, eiv=False)
        z.append((fit.coefficients_dph - truth) / fit.std_errors)
        x = monomials(*coding.code(s.t_c, s.g_c_per_min), TERMS)
        resid = s.drift_dph - x @ fit.coef_coded
        cov_iid = np.linalg.inv(x.T @ x) * np.mean(resid**2)
        j = np.diag(np.diag(coded_to_physical(TERMS, CENTRE, 14.5, 0.0, 1.0)))
        z_iid.append((fit.coefficients_dph - truth) / np.sqrt(np.diag(j @ cov_iid @ j)))
    spread = np.std(z, axis=0)
    # the standard errors allow for the largest walk the run cannot rule out (profile
    # likelihood): about a fifth conservative on the terms; the constant, the walk's mean
    # level over one run, had a spread of 1.9 with the run's own estimate of the walk
    assert np.all(spread > 0.6) and np.all(spread < 1.3), spread
    iid = np.std(z_iid, axis=0)
    assert np.median(iid) > 1.5 and iid.max() > 3.0, iid


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
    with pytest.raises(ParameterError, match="never enters the region 30 .. 60"):
        fit_drift(log_from_frame(f), (30.0, 60.0))
    with pytest.raises(ParameterError, match=r"bins -54 .. -52 °C have fewer than 5"):
        fit_drift(log_from_frame(f), (-54.0, -21.0))
    with pytest.raises(ParameterError, match="lo < hi"):
        fit_drift(log_from_frame(f), (-20.0, -30.0))
    with pytest.raises(ParameterError, match="unknown drift term"):
        FitSettings(terms="1,t,tt")
    with pytest.raises(ParameterError, match="n_error_draws"):
        FitSettings(n_error_draws=1)


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
    comp = pd.read_csv(out / "compensation.csv")
    assert list(comp.columns) == ["t_c", "g_c_per_min", "drift_dph"]


def test_cli_fit_terms_option_and_errors(logs_dir, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["fit", str(logs_dir / "run1.csv"), "--region", "-50", "-21", "--terms",
                 "t-only", "--out", str(out)]) == 0  # fmt: skip
    doc = json.loads((out / "coefficients.json").read_text())
    assert [c["term"] for c in doc["coefficients"]] == list(TERM_SETS["t-only"])
    capsys.readouterr()
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


def test_cli_fit_never_overwrites_its_input(logs_dir, tmp_path, capsys):
    src = tmp_path / "compensation.csv"
    src.write_bytes((logs_dir / "run1.csv").read_bytes())
    before = src.read_bytes()
    assert main(["fit", str(src), "--region", "-50", "-21", "--out", str(tmp_path)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert src.read_bytes() == before
