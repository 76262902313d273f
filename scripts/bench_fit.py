"""Benchmark of the drift fit: schedsyn's plans vs paper-like baselines, and term selection.

For every region of the paper's campaign (W1..W4) and every seeded random gyro (with and
without gradient terms; ``schedsyn.gyro.random_gyro`` over the approximation region),
the gyro is run through

* schedsyn's plan (``PLANS/<experiment>/steps.csv`` from ``schedsyn campaign --out PLANS``)
* a paper-like programme of the same duration (``schedsyn.baseline.paper_like_programme``)

with the device's thermal model drawn around the nominal one (tau 2200..2600 s, dT0
2..4 degC; the Kalman estimator assumes the nominal 2400 s / 3 degC), logged every 10 s,
and the drift fitted over the approximation region that both runs reached
(``schedsyn.driftfit.fit_drift``, default settings). Reported per region:

(a) the RMS error of the fitted drift (full model, and the selected one) against the
    true polynomial over the working region x reachable gradients
    (``DesignSpace.grid("working")``), for the plan and the baseline; also with the
    mean offset removed (what is left when the random walk's average level is ignored);
    and the level floor no programme and no fit can beat
    (``schedsyn.design.level_floor_dph``: the walk accumulated before the fastest possible
    entry into the fit's region, plus ``K N``), as a share of the baseline's error;
    and the floor of the full model's error for any programme of the plan's length
    (``schedsyn.design.fit_error_floor_dph``: that level's and the shape's white noise
    leaves at the best distribution of samples over the reachable band);
(b) on gyros with gradient terms: the error of the full model and of the T-only cubic
    fitted on the plan's run, held out on the baseline's run (a different trajectory,
    independent noise), over its samples inside the fit's domain: against the noise-free
    truth at the true (T, g), and as measured residual RMS (noise included); on gyros
    without them: how often term selection picks the T-only model;
(c) the honesty of the stated uncertainty: the share of the grid where the selected
    model's error (plan's run) is within twice the standard deviation the fit states,
    and the RMS of error / standard deviation (1 when the stated one is right).

    python scripts/bench_fit.py --plans out/campaign [--gyros 20] [--regions W1 W2]
        [--workers 2] [--out out/bench_fit] [--seed 0] [--no-walk] [--weighting ols]
        [--estimator kinematic] [--nominal-smoother]

``--no-walk`` drops the bias random walk (white noise only): a diagnostic that shows how
much of (a) the plan's design decides once the walk's offset is gone.

Writes OUT/cases.csv (one row per gyro and region), OUT/summary.csv and OUT/summary.md.
Timings are not the point here; the machine is shared.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

import schedsyn
from schedsyn.baseline import paper_like_programme
from schedsyn.design import (
    DesignSpace,
    every_gradient,
    fastest_entry_min,
    fit_error_floor_dph,
    level_floor_dph,
    programme_design,
)
from schedsyn.driftfit import (
    ESTIMATORS,
    WEIGHTINGS,
    FitSettings,
    estimator_model,
    fit_drift,
    fit_samples,
)
from schedsyn.errors import ParameterError
from schedsyn.gyro import gyro_log, random_gyro
from schedsyn.io import write_frame_atomic, write_text_atomic
from schedsyn.programme import read_step_meta
from schedsyn.sweep import run_map

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_S = 10.0
TAU_RANGE_S = (2200.0, 2600.0)
DT0_RANGE_C = (2.0, 4.0)


@dataclass(frozen=True)
class Case:
    region: str
    region_index: int
    working: tuple[float, float]
    approx: tuple[float, float]
    plan_csv: str
    duration_min: float
    index: int
    gradient: bool
    seed: int
    walk: bool = True
    weighting: str = "gls"
    estimator: str = "auto"
    nominal_smoother: bool = False


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2)))


def _common_region(frames, approx):
    """The approximation region shrunk to whole degrees both runs reached."""
    lo = max(approx[0], max(float(f["t_true_c"].min()) for f in frames))
    hi = min(approx[1], min(float(f["t_true_c"].max()) for f in frames))
    return float(math.ceil(lo * 2) / 2), float(math.floor(hi * 2) / 2)


def _fit(frame, region, source, holdout=None, weighting="gls", estimator="auto", params=None):
    log = schedsyn.log_from_frame(frame, source)
    lo, hi = region
    settings = FitSettings(weighting=weighting, estimator=estimator)
    for _ in range(6):  # shrink by 0.5 degC at an edge with too few samples
        try:
            return fit_drift(log, (lo, hi), settings, params, holdout=holdout), (lo, hi)
        except ParameterError as exc:
            if "too few samples" not in str(exc):
                raise
            mid = 0.5 * (lo + hi)
            t = frame["t_true_c"].to_numpy()
            near_lo = np.sum((t >= lo) & (t < lo + 1))
            near_hi = np.sum((t > hi - 1) & (t <= hi))
            lo, hi = (lo + 0.5, hi) if near_lo <= near_hi and lo + 0.5 < mid else (lo, hi - 0.5)
    raise RuntimeError(f"{source}: could not fit over {region}")


def run_case(case: Case) -> dict:
    rng = np.random.default_rng([case.seed, case.region_index, case.index, int(case.gradient)])
    gyro = random_gyro(rng, case.approx, gradient_terms=case.gradient)
    if not case.walk:  # diagnostic: white noise only
        gyro = dataclasses.replace(gyro, bias_walk_dph_per_rt_h=0.0)
    device = schedsyn.ThermalParams(
        float(rng.uniform(*TAU_RANGE_S)), float(rng.uniform(*DT0_RANGE_C))
    )
    plan = schedsyn.read_steps(case.plan_csv)
    base = paper_like_programme(*case.working, *case.approx, case.duration_min)
    seeds = rng.integers(2**31, size=2)
    f_plan = gyro_log(plan, gyro, device, sample_s=SAMPLE_S, seed=int(seeds[0]))
    f_base = gyro_log(base, gyro, device, sample_s=SAMPLE_S, seed=int(seeds[1]))
    region = _common_region([f_plan, f_base], case.approx)
    log_base = schedsyn.log_from_frame(f_base, "baseline")
    kw = {
        "weighting": case.weighting,
        "estimator": case.estimator,
        "params": schedsyn.ThermalParams() if case.nominal_smoother else None,
    }
    fit_p, region = _fit(f_plan, region, "plan", holdout=log_base, **kw)
    fit_b, _ = _fit(f_base, region, "baseline", **kw)
    space = DesignSpace(*case.working, *case.approx)
    t_grid, g_grid = space.grid("working")
    truth = gyro.drift_dph(t_grid, g_grid)
    row = {
        "region": case.region,
        "gyro": case.index,
        "gradient_terms": case.gradient,
        "fit_lo_c": region[0],
        "fit_hi_c": region[1],
        "tau_s": device.tau_s,
        "dt0_c": device.dt0_c,
        "white_dph_per_rt_hz": gyro.white_noise_dph_per_rt_hz,
        "walk_dph_per_rt_h": gyro.bias_walk_dph_per_rt_h,
        "plan_selected": _name(fit_p),
        "baseline_selected": _name(fit_b),
        **_level_floor(gyro, device, region, (f_plan, f_base), case),
    }
    for tag, fit in (("plan", fit_p), ("baseline", fit_b)):
        full = fit_samples(fit.samples, "full", fit.model.coding, weighting=case.weighting)
        for mname, model in (("full", full), ("selected", fit.model), ("tonly", fit.reference)):
            err = model.predict(t_grid, g_grid) - truth
            row[f"{tag}_{mname}_rms_dph"] = _rms(err)
            row[f"{tag}_{mname}_shape_rms_dph"] = _rms(err - err.mean())
        # honesty of the stated uncertainty: the share of the grid where the selected
        # model's error is within twice its standard deviation (target about 95 %)
        err = fit.model.predict(t_grid, g_grid) - truth
        sd = fit.model.predict_std(t_grid, g_grid)
        row[f"{tag}_selected_within_2sd_share"] = float(np.mean(np.abs(err) <= 2.0 * sd))
        row[f"{tag}_selected_rms_z"] = _rms(err / np.maximum(sd, 1e-12))
    # (b) held out on the baseline's run: inside the plan fit's domain
    full_p = fit_samples(fit_p.samples, "full", fit_p.model.coding, weighting=case.weighting)
    est = schedsyn.estimate_gradient_model(log_base, estimator_model(log_base, "model", None)[0])
    inside = fit_p.in_domain(est.t_est_c, est.g_est_c_per_min)
    t_true = f_base["t_true_c"].to_numpy()[inside]
    g_true = f_base["g_true_c_per_min"].to_numpy()[inside]
    d_true = f_base["drift_true_dph"].to_numpy()[inside]
    d_meas = f_base["drift_dph"].to_numpy()[inside]
    t_est, g_est = est.t_est_c[inside], est.g_est_c_per_min[inside]
    row["holdout_n"] = int(inside.sum())
    for mname, model in (("full", full_p), ("tonly", fit_p.reference)):
        row[f"holdout_{mname}_truth_rms_dph"] = _rms(model.predict(t_true, g_true) - d_true)
        row[f"holdout_{mname}_measured_rms_dph"] = _rms(d_meas - model.predict(t_est, g_est))
    return row


def _level_floor(gyro, device, region, frames, case) -> dict:
    """When the device first reached the fit's region (fastest possible; the plan's and
    the baseline's runs), the level floor no run or fit can beat
    (:func:`schedsyn.design.level_floor_dph`, the walk starting with the log), and the
    floor of the full model's error over target (a)'s grid for a run of the plan's length
    (:func:`schedsyn.design.fit_error_floor_dph`: the level's and the shape's; samples
    anywhere the device can be in the approximation region)."""
    lo, hi = region
    space = DesignSpace(lo, hi, lo, hi, device, max_cool_c_per_min=99.0, max_heat_c_per_min=99.0)
    fastest = fastest_entry_min(space)
    out = {"entry_fastest_min": fastest}
    for tag, f in zip(("plan", "baseline"), frames, strict=True):
        t = f["t_true_c"].to_numpy()
        inside = np.flatnonzero((t >= lo) & (t <= hi))
        out[f"{tag}_entry_min"] = float(f["time_s"].to_numpy()[inside[0]]) / 60.0
    out["level_floor_dph"] = level_floor_dph(
        gyro.bias_walk_dph_per_rt_h, gyro.white_noise_dph_per_rt_hz, fastest
    )
    grid = DesignSpace(*case.working, *case.approx)  # target (a)'s grid
    out["fit_floor_dph"] = fit_error_floor_dph(
        grid,
        gyro.bias_walk_dph_per_rt_h,
        gyro.white_noise_dph_per_rt_hz,
        fastest,
        case.duration_min,
        reach=every_gradient(DesignSpace(*case.working, *case.approx, device)),
    )
    return out


def _name(fit) -> str:
    return str(fit.selection.loc[fit.selection["chosen"], "candidate"].iloc[0])


def summarise(cases: pd.DataFrame, designs: dict) -> pd.DataFrame:
    rows = []
    for region, c in cases.groupby("region", sort=False):
        g = c[c["gradient_terms"]]
        n = c[~c["gradient_terms"]]
        ratio_full = c["plan_full_rms_dph"] / c["baseline_full_rms_dph"]
        ratio_sel = c["plan_selected_rms_dph"] / c["baseline_selected_rms_dph"]
        ho = g["holdout_tonly_truth_rms_dph"] / g["holdout_full_truth_rms_dph"]
        ho_m = g["holdout_tonly_measured_rms_dph"] / g["holdout_full_measured_rms_dph"]
        d = designs[region]
        rows.append(
            {
                "region": region,
                "gyros": int(len(c)),
                "plan_d_eff_pct": d["plan"].d_efficiency_pct,
                "plan_i_eff_pct": d["plan"].i_efficiency_pct,
                "baseline_d_eff_pct": d["baseline"].d_efficiency_pct,
                "baseline_i_eff_pct": d["baseline"].i_efficiency_pct,
                "plan_full_rms_dph_median": c["plan_full_rms_dph"].median(),
                "baseline_full_rms_dph_median": c["baseline_full_rms_dph"].median(),
                "ratio_full_median": ratio_full.median(),
                "ratio_full_le_half_share": float((ratio_full <= 0.5).mean()),
                # the level floor (no programme, no fit beats it in mean square): over the
                # gyros' RMS, what it leaves of target (a)
                "entry_fastest_min_median": c["entry_fastest_min"].median(),
                "plan_entry_min_median": c["plan_entry_min"].median(),
                "baseline_entry_min_median": c["baseline_entry_min"].median(),
                "level_floor_rms_dph": _rms(c["level_floor_dph"]),
                "plan_full_rms_dph_rms": _rms(c["plan_full_rms_dph"]),
                "baseline_full_rms_dph_rms": _rms(c["baseline_full_rms_dph"]),
                "ratio_full_rms": _rms(c["plan_full_rms_dph"]) / _rms(c["baseline_full_rms_dph"]),
                "floor_over_baseline_rms": (
                    _rms(c["level_floor_dph"]) / _rms(c["baseline_full_rms_dph"])
                ),
                "floor_over_baseline_median": (
                    c["level_floor_dph"] / c["baseline_full_rms_dph"]
                ).median(),
                # the level's and the shape's floor together (full model, any programme of
                # the plan's length)
                "fit_floor_rms_dph": _rms(c["fit_floor_dph"]),
                "fit_floor_over_baseline_rms": (
                    _rms(c["fit_floor_dph"]) / _rms(c["baseline_full_rms_dph"])
                ),
                "fit_floor_over_baseline_median": (
                    c["fit_floor_dph"] / c["baseline_full_rms_dph"]
                ).median(),
                "ratio_selected_median": ratio_sel.median(),
                "selected_rms_dph_median_plan": c["plan_selected_rms_dph"].median(),
                "selected_rms_dph_median_baseline": c["baseline_selected_rms_dph"].median(),
                "plan_full_shape_rms_dph_median": c["plan_full_shape_rms_dph"].median(),
                "baseline_full_shape_rms_dph_median": c["baseline_full_shape_rms_dph"].median(),
                "ratio_shape_median": (
                    c["plan_full_shape_rms_dph"] / c["baseline_full_shape_rms_dph"]
                ).median(),
                "holdout_full_truth_rms_dph_median": g["holdout_full_truth_rms_dph"].median(),
                "holdout_tonly_truth_rms_dph_median": g["holdout_tonly_truth_rms_dph"].median(),
                "holdout_tonly_over_full_median": ho.median(),
                "holdout_tonly_over_full_ge_2_share": float((ho >= 2).mean()),
                "holdout_measured_tonly_over_full_median": ho_m.median(),
                "tonly_selected_share_no_gradient": float((n["plan_selected"] == "t-only").mean()),
                "plan_selected_within_2sd_share_mean": c["plan_selected_within_2sd_share"].mean(),
                "plan_selected_rms_z": float(np.sqrt(np.mean(c["plan_selected_rms_z"] ** 2))),
                "tonly_selected_share_gradient": float((g["plan_selected"] == "t-only").mean()),
            }
        )
    return pd.DataFrame(rows)


def markdown(summary: pd.DataFrame) -> str:
    cols = {
        "region": "region",
        "gyros": "gyros",
        "plan_i_eff_pct": "I-eff plan, %",
        "baseline_i_eff_pct": "I-eff baseline, %",
        "plan_full_rms_dph_median": "(a) RMS plan, °/h",
        "baseline_full_rms_dph_median": "(a) RMS baseline, °/h",
        "ratio_full_median": "(a) ratio (target <= 0.5)",
        "ratio_shape_median": "(a) ratio, offset removed",
        "ratio_full_rms": "(a) ratio of RMS over gyros",
        "floor_over_baseline_rms": "level floor / baseline, RMS over gyros (no plan can beat)",
        "fit_floor_over_baseline_rms": "level + shape floor / baseline, RMS over gyros",
        "holdout_tonly_over_full_median": "(b) T-only / full held out (target >= 2)",
        "holdout_measured_tonly_over_full_median": "(b) same, measured residuals",
        "tonly_selected_share_no_gradient": "(b) T-only chosen, no g terms (target >= 90 %)",
        "plan_selected_within_2sd_share_mean": "error within ±2σ (plan, selected)",
        "plan_selected_rms_z": "RMS error/σ (plan, selected)",
    }
    s = summary[list(cols)].rename(columns=cols)
    lines = ["| " + " | ".join(s.columns) + " |", "|" + "---|" * len(s.columns)]
    for _, r in s.iterrows():
        cells = []
        for k, v in r.items():
            if isinstance(v, float):
                cells.append(f"{v:.0%}" if ("chosen" in k or "±2σ" in k) else f"{v:.3g}")
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", default="out/campaign", help="schedsyn campaign output folder")
    ap.add_argument("--gyros", type=int, default=20, help="gyros per region and kind")
    ap.add_argument("--regions", nargs="*", default=None, help="experiments (default all)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/bench_fit")
    ap.add_argument(
        "--no-walk",
        action="store_true",
        help="diagnostic: gyros without the bias random walk (white noise only)",
    )
    ap.add_argument(
        "--weighting",
        choices=WEIGHTINGS,
        default="gls",
        help="the fit's weighting (default gls: white noise + bias walk; ols for comparison)",
    )
    ap.add_argument(
        "--estimator",
        choices=ESTIMATORS,
        default="auto",
        help="the fit's gradient estimator (default auto: model-based, the logs have "
        "tk_set_c; kinematic: as for a log without the chamber setpoint)",
    )
    ap.add_argument(
        "--nominal-smoother",
        action="store_true",
        help="the smoother's model at the nominal 2400 s / 3 degC instead of identified "
        "from each log (for comparison)",
    )
    args = ap.parse_args()
    config = schedsyn.load_campaign(ROOT / "data" / "paper_campaign.toml")
    cases, designs = [], {}
    for k, spec in enumerate(config.experiments):
        if args.regions and spec.name not in args.regions:
            continue
        plan_csv = Path(args.plans) / spec.name / "steps.csv"
        plan = schedsyn.read_steps(plan_csv)
        working = (spec.working_lo_c, spec.working_hi_c)
        approx = (spec.approx_lo_c, spec.approx_hi_c)
        # the regions are the paper campaign's: a table planned for others would be
        # benched against the wrong ones
        meta = read_step_meta(plan_csv)
        if meta is not None and (
            (meta.working_lo_c, meta.working_hi_c) != working
            or (meta.approx_lo_c, meta.approx_hi_c) != approx
        ):
            raise SystemExit(
                f"{plan_csv}: planned for working {meta.working_lo_c:g} .. "
                f"{meta.working_hi_c:g}, approximation {meta.approx_lo_c:g} .. "
                f"{meta.approx_hi_c:g} °C; this benchmark's {spec.name} is {working[0]:g} .. "
                f"{working[1]:g}, {approx[0]:g} .. {approx[1]:g} °C "
                "(data/paper_campaign.toml): plan that campaign's regions"
            )
        base = paper_like_programme(*working, *approx, plan.total_min)
        space = DesignSpace(*working, *approx)
        designs[spec.name] = {
            "plan": programme_design(plan, space),
            "baseline": programme_design(base, space),
        }
        for i in range(args.gyros):
            for gradient in (True, False):
                case = Case(
                    region=spec.name,
                    region_index=k,
                    working=working,
                    approx=approx,
                    plan_csv=str(plan_csv),
                    duration_min=plan.total_min,
                    index=i,
                    gradient=gradient,
                    seed=args.seed,
                    walk=not args.no_walk,
                    weighting=args.weighting,
                    estimator=args.estimator,
                    nominal_smoother=args.nominal_smoother,
                )
                cases.append(case)
    rows = run_map(run_case, cases, "local", workers=args.workers, desc="gyros")
    frame = pd.DataFrame(rows)
    out = Path(args.out)
    write_frame_atomic(out / "cases.csv", frame)
    summary = summarise(frame, designs)
    write_frame_atomic(out / "summary.csv", summary)
    md = markdown(summary)
    write_text_atomic(out / "summary.md", md)
    print(md)
    print(f"wrote {out}/cases.csv, summary.csv, summary.md")


if __name__ == "__main__":
    main()
