"""The figures docs/drift-fit.md gives for the ``informative`` objective's pull.

For each experiment of a planned campaign folder (``schedsyn campaign ... --out DIR``):
the minutes of the planning model's 1-min samples inside the approximation region, and
the walk-aware prediction of the fitted drift's error, computed before anything is run
(``schedsyn.design.predicted_fit_error``: the generalised-least-squares error of the full
cubic over the working grid under a bias walk of ``K`` deg/h/sqrt(h) started at
switch-on and white noise of ``N`` deg/h/sqrt(Hz), on 1-min samples), total and shape
(offset removed); the same for a paper-like programme of the same duration. With
``--cases``, the RMS over gyros of the selected model's total and shape error from
``scripts/bench_fit.py``'s ``cases.csv`` files (and, for two of them, the per-gyro shape
ratio of the second to the first).

    python scripts/informative_figures.py out/informative [--config data/paper_campaign.toml]
        [--k 0.0125] [--n 0.3] [--cases A/cases.csv B/cases.csv]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn.baseline import paper_like_programme
from schedsyn.campaign import load_campaign
from schedsyn.design import DesignSpace, predicted_fit_error
from schedsyn.programme import read_steps
from schedsyn.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]


def walk_aware(programme, space: DesignSpace, k: float, n: float) -> tuple[int, float, float]:
    """(minutes in the region, predicted RMS error total, shape), deg/h."""
    traj = simulate(programme, space.params, dt_min=1.0, t0_c=space.limits.t_init_c)
    pred = predicted_fit_error(traj.time_min, traj.t_c, traj.g_c_per_min, space, n, k)
    return pred.n_samples, pred.total_dph, pred.shape_dph


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plans", type=Path, nargs="*", help="campaign output folders")
    ap.add_argument("--config", type=Path, default=ROOT / "data" / "paper_campaign.toml")
    ap.add_argument("--k", type=float, default=0.0125, help="bias walk, deg/h/sqrt(h)")
    ap.add_argument("--n", type=float, default=0.3, help="white noise, deg/h/sqrt(Hz)")
    ap.add_argument("--cases", type=Path, nargs="*", default=[], help="bench_fit cases.csv")
    args = ap.parse_args()
    missing = [str(p) for p in [*args.plans, *args.cases] if not p.exists()]
    if missing:
        ap.error(f"not found: {', '.join(missing)}")
    cfg = load_campaign(args.config)
    for folder in args.plans:
        print(f"== {folder}")
        for exp in cfg.experiments:
            steps = folder / exp.name / "steps.csv"
            if not steps.is_file():
                continue
            prog = read_steps(steps)
            space = DesignSpace(
                exp.working_lo_c, exp.working_hi_c, exp.approx_lo_c, exp.approx_hi_c,
                cfg.params, cfg.limits, exp.max_cool_c_per_min, exp.max_heat_c_per_min,
            )  # fmt: skip
            base = paper_like_programme(
                exp.working_lo_c, exp.working_hi_c, exp.approx_lo_c, exp.approx_hi_c,
                prog.total_min, cfg.params, cfg.limits,
            )  # fmt: skip
            n_in, tot, shp = walk_aware(prog, space, args.k, args.n)
            b_in, b_tot, b_shp = walk_aware(base, space, args.k, args.n)
            print(
                f"{exp.name}: {prog.total_min:g} min, {n_in} in the region, predicted total "
                f"{tot:.4f} shape {shp:.4f} deg/h | paper-like: {b_in} in the region, "
                f"total {b_tot:.4f} shape {b_shp:.4f}"
            )
    frames = [pd.read_csv(c) for c in args.cases]
    for c, f in zip(args.cases, frames, strict=True):
        print(f"== {c}: selected model, RMS over gyros, deg/h")
        for region, d in f.groupby("region"):

            def rms(col: str, d: pd.DataFrame = d) -> float:
                return math.sqrt(float(np.mean(np.square(d[col]))))

            print(
                f"{region}: plan total {rms('plan_selected_rms_dph'):.4f} shape "
                f"{rms('plan_selected_shape_rms_dph'):.4f} | baseline total "
                f"{rms('baseline_selected_rms_dph'):.4f} shape "
                f"{rms('baseline_selected_shape_rms_dph'):.4f}"
            )
    if len(frames) == 2:
        a, b = frames
        print(f"== per gyro, shape {args.cases[1]} / {args.cases[0]}")
        for region in sorted(set(a.region)):
            sa = a[a.region == region].plan_selected_shape_rms_dph.to_numpy()
            sb = b[b.region == region].plan_selected_shape_rms_dph.to_numpy()
            if sa.size != sb.size:
                raise SystemExit(f"{region}: the two benches ran different gyros")
            ratio = np.median(sb / sa)
            print(f"{region}: median {ratio:.2f}, better on {(sb < sa).sum()} of {sa.size}")


if __name__ == "__main__":
    main()
