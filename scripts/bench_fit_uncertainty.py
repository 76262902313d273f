"""Where the drift fit's figures on term selection and the bias walk come from
(docs/drift-fit.md, "How the fit works", steps 3 and 4).

``selection``: per region of the paper's campaign and gyro kind, seeded gyros run
through schedsyn's plan (10-s logs, device tau 2200..2600 s, dT0 2..4 degC), fitted with
``fit_drift`` (default settings), and every candidate term set fitted on the same samples.
Kinds: ``rt-full`` (all ten terms, g2/g3 0.05-0.3 and 0.02-0.2 deg/h per (degC/min)^n, a
red team's generator), ``rt-g1`` (first-order gradient terms only), ``rt-tonly``, and
``random_gyro`` with (``rg``) and without (``rn``) gradient terms. For the rules ``bic``
(schedsyn's), ``aic``, ``bic+aic`` (BIC for "any gradient terms?", then AIC for their
order) and ``bic+full`` it prints, per kind, how often T-only / full is chosen, the median
RMS error against the true polynomial over the working grid (and with the mean offset
removed: "shape"), RMS error/sigma and the share of the grid within +-2 sigma.

``walk``: T-only gyros with a bias walk K of 0, 0.01 and 0.03 deg/h/sqrt(h) on the W1 and
W3 plans, the right terms fitted: the run's estimate of K, the upper K the standard
errors use, and the share of the grid within +-2 sigma with the estimated, the upper and
the true K.

    python scripts/bench_fit_uncertainty.py selection --plans out/campaign [--gyros 12]
    python scripts/bench_fit_uncertainty.py walk --plans out/campaign [--gyros 20]

(``--plans``: a ``schedsyn campaign --out`` folder.) Writes OUT/selection.csv or
OUT/walk.csv (``--out``, default out/bench_fit_uncertainty) and prints the tables.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import zlib
from pathlib import Path

import numpy as np
import pandas as pd

import schedsyn
from schedsyn.design import DesignSpace
from schedsyn.driftfit import FitSettings, fit_drift, fit_samples, noise_fit, walk_covariance
from schedsyn.gyro import Gyro, gyro_log, random_gyro
from schedsyn.io import write_frame_atomic
from schedsyn.terms import EXPONENTS, monomials

ROOT = Path(__file__).resolve().parents[1]
CANDIDATES = ("t-only", "g1", "g2", "full")
N_TERMS = {"t-only": 4, "g1": 7, "g2": 9, "full": 10}


def _specs():
    return {
        s.name: s for s in schedsyn.load_campaign(ROOT / "data" / "paper_campaign.toml").experiments
    }


def rt_gyro(rng: np.random.Generator, approx: tuple[float, float], kind: str) -> Gyro:
    """The red team's generator: coefficients scaled to the region's half-width."""
    lo, hi = approx
    h = 0.5 * (hi - lo)

    def sign() -> float:
        return float(rng.choice([-1.0, 1.0]))

    c = {
        "1": rng.uniform(-1, 1),
        "t": sign() * rng.uniform(0.3, 1.0) / h,
        "t2": sign() * rng.uniform(0.1, 0.5) / h**2,
        "t3": sign() * rng.uniform(0.1, 0.5) / h**3,
    }
    if kind in ("full", "g1"):
        c["g"] = sign() * rng.uniform(0.3, 1.0)
        c["tg"] = sign() * rng.uniform(0.05, 0.3) / h
        c["t2g"] = sign() * rng.uniform(0.05, 0.3) / h**2
    if kind == "full":
        c["g2"] = sign() * rng.uniform(0.05, 0.3)
        c["tg2"] = sign() * rng.uniform(0.02, 0.1) / h
        c["g3"] = sign() * rng.uniform(0.02, 0.2)
    return Gyro(
        coefficients_dph={k: float(c.get(k, 0.0)) for k in EXPONENTS},
        t_ref_c=0.5 * (lo + hi),
        white_noise_dph_per_rt_hz=float(rng.uniform(0.1, 0.5)),
        bias_walk_dph_per_rt_h=0.01,
        sensor_noise_c=0.02,
        sensor_quant_c=0.01,
        name="rt",
    )


def _run(plans: Path, region: str, seed: list[int], gyro_of, tau_dt0=None):
    """One gyro through the region's plan: (fit, gyro, working grid t, g, truth)."""
    spec = _specs()[region]
    approx = (spec.approx_lo_c, spec.approx_hi_c)
    rng = np.random.default_rng(seed)
    gyro = gyro_of(rng, approx)
    if tau_dt0 is None:
        tau_dt0 = (float(rng.uniform(2200, 2600)), float(rng.uniform(2, 4)))
    device = schedsyn.ThermalParams(*tau_dt0)
    plan = schedsyn.read_steps(plans / region / "steps.csv")
    f = gyro_log(plan, gyro, device, sample_s=10.0, seed=int(rng.integers(2**31)))
    t = f["t_true_c"].to_numpy()
    lo = max(approx[0], math.ceil(t.min() * 2) / 2)
    hi = min(approx[1], math.floor(t.max() * 2) / 2)
    return f, gyro, spec, (lo, hi)


def _grid(spec):
    space = DesignSpace(spec.working_lo_c, spec.working_hi_c, spec.approx_lo_c, spec.approx_hi_c)
    return space.grid("working")


def selection_case(plans: Path, region: str, i: int, kind: str) -> dict:
    def gyro_of(rng, approx):
        if kind.startswith("rt-"):
            return rt_gyro(rng, approx, kind[3:])
        return random_gyro(rng, approx, gradient_terms=kind == "rg")

    seed = [7, i, zlib.crc32(kind.encode()), zlib.crc32(region.encode())]
    f, gyro, spec, region_c = _run(plans, region, seed, gyro_of)
    fit = fit_drift(schedsyn.log_from_frame(f, "bench"), region_c)
    tg, gg = _grid(spec)
    truth = gyro.drift_dph(tg, gg)
    sel = fit.selection
    row = {"region": region, "gyro": i, "kind": kind, "n": fit.samples.n}
    for c, m2 in zip(sel["candidate"], sel["minus2_log_likelihood"], strict=True):
        model = fit_samples(fit.samples, c, fit.model.coding)
        err = model.predict(tg, gg) - truth
        sd = model.predict_std(tg, gg)
        row |= {
            f"m2ll_{c}": float(m2),
            f"rms_{c}": float(np.sqrt(np.mean(err**2))),
            f"shape_{c}": float(np.std(err)),
            f"z_{c}": float(np.sqrt(np.mean((err / sd) ** 2))),
            f"within_2sd_{c}": float(np.mean(np.abs(err) <= 2 * sd)),
        }
    return row


def choose(row: pd.Series, rule: str) -> str:
    bic = {c: row[f"m2ll_{c}"] + (N_TERMS[c] + 2) * math.log(row["n"]) for c in CANDIDATES}
    aic = {c: row[f"m2ll_{c}"] + 2 * (N_TERMS[c] + 2) for c in CANDIDATES}
    if rule == "aic":
        return min(CANDIDATES, key=aic.__getitem__)
    best = min(CANDIDATES, key=bic.__getitem__)
    if rule == "bic" or best == "t-only":
        return best
    if rule == "bic+aic":
        return min(CANDIDATES[1:], key=aic.__getitem__)
    return "full"  # bic+full


def selection_table(cases: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for rule in ("bic", "aic", "bic+aic", "bic+full"):
        for kind, g in cases.groupby("kind"):
            ch = [choose(r, rule) for _, r in g.iterrows()]
            picked = {
                col: np.array([r[f"{col}_{c}"] for (_, r), c in zip(g.iterrows(), ch, strict=True)])
                for col in ("rms", "shape", "z", "within_2sd")
            }
            z = picked["z"]
            rows.append(
                {
                    "rule": rule,
                    "kind": kind,
                    "t_only_share": float(np.mean(np.array(ch) == "t-only")),
                    "full_share": float(np.mean(np.array(ch) == "full")),
                    "median_rms_dph": float(np.median(picked["rms"])),
                    "median_shape_rms_dph": float(np.median(picked["shape"])),
                    "rms_error_over_sigma": float(np.sqrt(np.mean(z**2))),
                    "within_2sd_share": float(np.mean(picked["within_2sd"])),
                }
            )
    return pd.DataFrame(rows)


def walk_case(plans: Path, region: str, i: int, walk: float) -> dict:
    def gyro_of(rng, approx):
        return dataclasses.replace(rt_gyro(rng, approx, "tonly"), bias_walk_dph_per_rt_h=walk)

    seed = [11, i, int(walk * 1e4), zlib.crc32(region.encode())]
    f, gyro, spec, region_c = _run(plans, region, seed, gyro_of, (2400.0, 3.0))
    fit = fit_drift(schedsyn.log_from_frame(f, "bench"), region_c, FitSettings(terms="t-only"))
    m, s = fit.model, fit.samples
    tg, gg = _grid(spec)
    err = m.predict(tg, gg) - gyro.drift_dph(tg, gg)
    x = monomials(*m.coding.code(s.t_c, s.g_c_per_min), m.terms)
    grid = monomials(*m.coding.code(tg, gg), m.terms)
    a_inv = np.linalg.inv(x.T @ x)
    nf = noise_fit(s.time_s, s.drift_dph, x)
    row = {"region": region, "gyro": i, "walk_true": walk, "walk_estimated": nf.walk_dph_per_rt_h,
           "walk_upper": nf.walk_upper_dph_per_rt_h}  # fmt: skip
    for tag, k in (("estimated", nf.walk_dph_per_rt_h), ("upper", nf.walk_upper_dph_per_rt_h),
                   ("true", walk)):  # fmt: skip
        cov = a_inv @ (nf.sigma_dph**2 * x.T @ x + k**2 * walk_covariance(s.time_s, x)) @ a_inv
        sd = np.sqrt(np.einsum("ij,jk,ik->i", grid, cov, grid))
        row[f"within_2sd_{tag}_walk"] = float(np.mean(np.abs(err) <= 2 * sd))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("selection", "walk"))
    ap.add_argument("--plans", default="out/campaign", help="schedsyn campaign output folder")
    ap.add_argument("--gyros", type=int, default=None, help="gyros per region and kind")
    ap.add_argument("--out", default="out/bench_fit_uncertainty")
    args = ap.parse_args()
    plans = Path(args.plans)
    if args.what == "selection":
        n = args.gyros or 12
        kinds = ("rt-full", "rt-g1", "rt-tonly", "rg", "rn")
        cases = pd.DataFrame(
            [
                selection_case(plans, r, i, k)
                for r in ("W1", "W2", "W3", "W4")
                for k in kinds
                for i in range(n)
            ]  # fmt: skip
        )
        table = selection_table(cases)
    else:
        n = args.gyros or 20
        cases = pd.DataFrame(
            [
                walk_case(plans, r, i, k)
                for r in ("W1", "W3")
                for k in (0.0, 0.01, 0.03)
                for i in range(n)
            ]  # fmt: skip
        )
        table = cases.groupby(["region", "walk_true"]).agg(
            walk_estimated_q10=("walk_estimated", lambda v: v.quantile(0.1)),
            walk_estimated_q90=("walk_estimated", lambda v: v.quantile(0.9)),
            walk_upper_median=("walk_upper", "median"),
            within_2sd_estimated=("within_2sd_estimated_walk", "mean"),
            within_2sd_upper=("within_2sd_upper_walk", "mean"),
            within_2sd_true=("within_2sd_true_walk", "mean"),
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_frame_atomic(out / f"{args.what}.csv", cases)
    print(table.to_string())


if __name__ == "__main__":
    main()
