"""Long logs: the chunked filter/smoother equals one pass, decimated output, the CLI's
--every / --quiet / progress, and diagnose on a log longer than its row budget."""

import numpy as np
import pandas as pd
import pytest

import schedsyn.estimate as est_mod
from schedsyn.cli import main
from schedsyn.errors import ParameterError
from schedsyn.estimate import (
    decimation_rows,
    estimate_gradient,
    estimate_gradient_model,
    kalman_filter,
    lag_input,
    lag_transition,
    rts_smoother,
)
from schedsyn.logs import log_from_frame, read_log
from schedsyn.model import FirstOrderLag
from schedsyn.params import ThermalParams
from schedsyn.programme import read_steps
from schedsyn.synth import synth_log

STEPS = "data/baseline_exp1_steps.csv"


@pytest.fixture(scope="module")
def messy_log():
    """10 s baseline log with a NaN run, a 15 min gap and an irregular stretch."""
    df = synth_log(read_steps(STEPS), sample_s=10.0, seed=5)
    df.loc[1000:1011, "t_int_c"] = np.nan
    df = df.drop(index=range(2000, 2090)).reset_index(drop=True)
    rng = np.random.default_rng(3)
    t = df["time_s"].to_numpy().copy()
    t[2500:2600] += rng.uniform(-4.0, 4.0, 100)  # jittered clock: irregular steps
    df["time_s"] = t
    return log_from_frame(df)


@pytest.mark.parametrize("method", ["kinematic", "model"])
@pytest.mark.parametrize("chunk_rows", [37, 1000])
def test_chunked_smoother_equals_one_pass(messy_log, monkeypatch, method, chunk_rows):
    """Checkpointed chunks (re-filtered backwards) give the one-pass result."""
    fn = estimate_gradient if method == "kinematic" else estimate_gradient_model
    q = 1e-3 if method == "kinematic" else 1e-7
    one = fn(messy_log, q=q, r=4e-4)
    monkeypatch.setattr(est_mod, "CHUNK_ROWS", chunk_rows)
    chunked = fn(messy_log, q=q, r=4e-4)
    for mean, std in (("t_est_c", "t_std_c"), ("g_est_c_per_min", "g_std_c_per_min")):
        err = (getattr(chunked, mean) - getattr(one, mean)) / getattr(one, std)
        assert np.max(np.abs(err)) < 1e-7
        np.testing.assert_allclose(getattr(chunked, std), getattr(one, std), rtol=1e-7)
    np.testing.assert_allclose(chunked.innovation_c, one.innovation_c, atol=1e-9)
    assert chunked.minus2_log_likelihood == pytest.approx(one.minus2_log_likelihood, rel=1e-9)


def test_chunked_smoother_equals_the_plain_recursions(messy_log, monkeypatch):
    """Independent of the fast path: the chunked run against kalman_filter + rts_smoother
    (row by row over the whole log) on the same transitions."""
    monkeypatch.setattr(est_mod, "CHUNK_ROWS", 500)
    params = ThermalParams(tau_s=2100.0, dt0_c=2.0)
    est = estimate_gradient_model(messy_log, params, q=1e-6, r=4e-4)
    t = messy_log.time_min
    h = np.concatenate(([0.0], np.diff(t)))
    model = FirstOrderLag(params)
    a, b, q11, q12, q22 = lag_transition(h, model, 1e-6)
    tk = messy_log.tk_set_c
    u = np.concatenate(([0.0], lag_input(h[1:], tk[:-1], tk[1:], model)))
    # the steps holding a setpoint corner: the exact input of the two ramps
    corners = est_mod.setpoint_corners_between_samples(messy_log.time_s, tk)
    assert corners[0].size > 0  # the messy log's rate changes fall between samples
    rows, u_corner = est_mod.corner_inputs(messy_log.time_s, tk, corners, model)
    u[rows] = u_corner
    y = messy_log.t_int_c
    x0 = (y[np.isfinite(y)][0], 0.0)
    p0 = (est_mod.PRIOR_T_STD_C**2, 0.0, est_mod.PRIOR_G_STD_C_PER_MIN**2)
    filt, pred, innov, svar, m2ll = kalman_filter(y, a, b, u, q11, q12, q22, 4e-4, x0, p0)
    x1, x2, p11, p12, p22 = rts_smoother(filt, pred, a, b, q11, q12, q22)
    tau = params.tau_min
    g = (tk + params.dt0_c - x1) / tau + x2
    g_std = np.sqrt(p11 / tau**2 - 2 * p12 / tau + p22)
    assert np.max(np.abs(est.g_est_c_per_min - g) / g_std) < 1e-7
    np.testing.assert_allclose(est.g_std_c_per_min, g_std, rtol=1e-6)
    assert est.minus2_log_likelihood == pytest.approx(m2ll, rel=1e-9)


def test_decimation_rows_one_per_bin():
    t = np.array([0.0, 0.5, 1.0, 2.9, 3.0, 3.1, 10.0, 10.5, 20.0])
    np.testing.assert_array_equal(decimation_rows(t, 1.0), [0, 2, 3, 4, 6, 8])
    np.testing.assert_array_equal(decimation_rows(t, 5.0), [0, 6, 8])
    np.testing.assert_array_equal(decimation_rows(t, 0.1), np.arange(t.size))
    with pytest.raises(ParameterError, match="every_s"):
        decimation_rows(t, 0.0)


@pytest.mark.parametrize("every_s", [30.0, 95.0])
def test_decimated_estimate_is_the_full_one_at_the_kept_rows(messy_log, monkeypatch, every_s):
    monkeypatch.setattr(est_mod, "CHUNK_ROWS", 700)
    full = estimate_gradient(messy_log, q=1e-3, r=4e-4)
    dec = estimate_gradient(messy_log, q=1e-3, r=4e-4, every_s=every_s)
    # independent count: the first row in each every_s-wide bin
    bins = np.floor((messy_log.time_s - messy_log.time_s[0]) / every_s)
    kept = np.flatnonzero(np.r_[True, np.diff(bins) > 0])
    np.testing.assert_array_equal(dec.time_s, messy_log.time_s[kept])
    assert dec.every_s == every_s and dec.n_rows == kept.size
    for name in ("t_est_c", "g_est_c_per_min", "g_std_c_per_min", "innovation_c"):
        np.testing.assert_allclose(getattr(dec, name), getattr(full, name)[kept], rtol=1e-12)
    assert dec.minus2_log_likelihood == pytest.approx(full.minus2_log_likelihood, rel=1e-12)
    assert "one row every" in dec.summary()


def test_cli_every_quiet_and_progress(tmp_path, capsys, monkeypatch):
    import schedsyn.cli.estimate as cli_est

    monkeypatch.setattr(cli_est, "WRITE_ROWS", 100)  # gradient.csv written in pieces
    df = synth_log(read_steps(STEPS), sample_s=5.0, seed=2)
    log_path = tmp_path / "run.csv"
    df.to_csv(log_path, index=False)
    out = tmp_path / "full"
    assert main(["estimate", str(log_path), "--out", str(out), "--q", "1e-3", "--r", "4e-4"]) == 0
    cap = capsys.readouterr()
    # progress goes to stderr as plain lines (not a terminal), per stage, ending at 100 %
    for stage in ("reading", "filter", "smoother", "writing"):
        assert f"estimate: {stage} 100 %" in cap.err
    full = pd.read_csv(out / "gradient.csv")
    est = estimate_gradient(read_log(log_path), q=1e-3, r=4e-4)
    pd.testing.assert_frame_equal(full, est.to_frame(), check_exact=False, rtol=1e-12)
    dec_out = tmp_path / "dec"
    args = ["estimate", str(log_path), "--out", str(dec_out), "--q", "1e-3", "--r", "4e-4"]
    assert main([*args, "--every", "60", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.err == ""
    assert "one every 60 s" in cap.out
    dec = pd.read_csv(dec_out / "gradient.csv")
    np.testing.assert_array_equal(dec["time_s"], full["time_s"][::12])  # 5 s rows, 60 s bins
    pd.testing.assert_frame_equal(dec, full.iloc[::12].reset_index(drop=True), rtol=1e-12)
    assert (dec_out / "phase.png").stat().st_size > 0
    assert main([*args, "--every", "-5"]) == 2
    assert "every_s must be" in capsys.readouterr().err


def test_diagnose_thins_a_log_longer_than_its_budget(tmp_path, capsys, monkeypatch):
    """Over DIAGNOSE_MAX_ROWS rows, diagnose works on every k-th row: the same answer as
    diagnosing that thinned log directly, and the CLI says so."""
    import schedsyn.cli.diagnose as cli_diag
    import schedsyn.discrepancy as disc

    monkeypatch.setattr(disc, "DIAGNOSE_MAX_ROWS", 1000)
    monkeypatch.setattr(cli_diag, "DIAGNOSE_MAX_ROWS", 1000)
    params = ThermalParams(tau_s=2700.0, dt0_c=2.0)
    df = synth_log(read_steps(STEPS), params, sample_s=2.0, seed=4)
    n = len(df)
    stride = -(-n // 1000)
    settings = disc.DiagnoseSettings(effects=("dead_time",))
    d = disc.diagnose(log_from_frame(df), settings)
    assert d.info["row_stride"] == stride > 1
    direct = disc.diagnose(log_from_frame(df.iloc[::stride].reset_index(drop=True)), settings)
    assert direct.info["row_stride"] == 1
    assert d.base.tau_s == direct.base.tau_s and d.base.dt0_c == direct.base.dt0_c
    assert d.base.tau_s == pytest.approx(2700.0, rel=0.02)
    assert d.base.dt0_c == pytest.approx(2.0, abs=0.1)
    assert d.time_min.size == int(np.isfinite(df["t_int_c"].to_numpy()[::stride]).sum())
    path = tmp_path / "long.csv"
    df.to_csv(path, index=False)
    rc = main(["diagnose", str(path), "--out", str(tmp_path / "d"), "--effects", "dead_time"])
    assert rc == 0
    kept = len(range(0, n, stride))
    note = f"note: the log has {n} rows; diagnosed on every {stride}th row ({kept} rows)"
    assert note in capsys.readouterr().out


def test_cli_order_option(tmp_path, capsys):
    df = synth_log(read_steps(STEPS), sample_s=20.0, seed=3)
    path = tmp_path / "run.csv"
    df.to_csv(path, index=False)
    for order in (2, 3):
        out = tmp_path / f"o{order}"
        assert (
            main(["estimate", str(path), "--out", str(out), "--order", str(order), "--quiet"]) == 0
        )
        got = pd.read_csv(out / "gradient.csv")
        want = estimate_gradient(read_log(path), order=order)
        np.testing.assert_allclose(got["g_est_c_per_min"], want.g_est_c_per_min, rtol=1e-12)
    capsys.readouterr()
    assert main(["estimate", str(path), "--order", "4"]) == 2


def test_progress_reporter_lines_and_bar():
    """Plain lines (not a terminal): each stage's first and last report, 10 % steps in
    between at most every LINE_MIN_INTERVAL_S; a terminal gets a tqdm bar instead."""
    import io

    from schedsyn.cli._progress import StderrProgress

    plain = io.StringIO()
    rep = StderrProgress("estimate", stream=plain, tty=False)
    for done in range(0, 1001, 50):
        rep("filter", done, 1000)
    rep("noise levels", 3, 0)
    rep.close()
    lines = plain.getvalue().splitlines()
    assert lines[0] == "estimate: filter 0 % (0 rows of 1 000 rows)"
    assert "estimate: filter 100 % (1 000 rows of 1 000 rows)" in lines
    assert lines[-1] == "estimate: noise levels ..."
    assert len(lines) <= 13
    term = io.StringIO()
    bar = StderrProgress("estimate", stream=term, tty=True)
    for done in (0, 10_000_000, 20_000_000):
        bar("reading", done, 20_000_000)
    bar.close()
    assert "estimate: reading" in term.getvalue() and "\n" not in term.getvalue().strip("\n")
