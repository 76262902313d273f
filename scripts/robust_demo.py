"""Nominal vs robust plan: the price of robustness and the two coverage heatmaps.

Plans one experiment twice -- at the nominal (tau, dT0) and robustly for a box -- then
sweeps both plans over a wider (tau, dT0) grid with the same coverage metric, writes
out/robust/{nominal,robust}_steps.csv, out/robust/price.csv and the side-by-side heatmap
out/robust/robust_vs_nominal.png.

Run: python scripts/robust_demo.py [--working LO HI] [--approx LO HI]
         [--robust-tau-s LO:HI] [--robust-dt0-c LO:HI]
"""

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from schedsyn import plan_experiment, sweep_fixed
from schedsyn.io import write_frame_atomic
from schedsyn.planner import ExperimentSpec
from schedsyn.sweep import parse_range


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--working", nargs=2, type=float, default=(-30.0, -10.0))
    ap.add_argument("--approx", nargs=2, type=float, default=(-40.0, 0.0))
    ap.add_argument("--robust-tau-s", default="2200:2600")
    ap.add_argument("--robust-dt0-c", default="2:4")
    ap.add_argument("--out", default="out/robust")
    ap.add_argument("--figure", default="out/robust/robust_vs_nominal.png")
    args = ap.parse_args()
    tau_box = parse_range(args.robust_tau_s, "--robust-tau-s")
    dt0_box = parse_range(args.robust_dt0_c, "--robust-dt0-c")
    spec = ExperimentSpec("robust_demo", *args.working, *args.approx)
    out = Path(args.out)
    plans = {
        "nominal": plan_experiment(spec),
        "robust": plan_experiment(spec, robust_tau_s=tau_box, robust_dt0_c=dt0_box),
    }
    taus = np.linspace(1800, 3000, 13)
    dt0s = np.linspace(0, 6, 13)
    frames, rows = {}, []
    for name, plan in plans.items():
        plan.programme.to_csv(out / f"{name}_steps.csv")
        sweep = sweep_fixed(
            plan.programme,
            (spec.working_lo_c, spec.working_hi_c),
            taus,
            dt0s,
            levels_required=spec.levels_required,
        )
        frames[name] = sweep.to_frame()
        in_box = frames[name][
            frames[name].tau_s.between(*tau_box) & frames[name].dt0_c.between(*dt0_box)
        ]
        rows.append(
            {
                "plan": name,
                "duration_min": plan.duration_min,
                "steps": plan.steps,
                "coverage_at_scenarios": plan.coverage.coverage,
                "coverage_delta_0p1": plan.coverage_0p1.coverage,
                "margin_g_c_per_min": plan.margin_g_c_per_min,
                "box_min_coverage": float(in_box.coverage.min()),
                "box_min_levels": int(in_box.min_levels.min()),
                "box_full_share": float((in_box.coverage >= 1).mean()),
                "grid_full_share": float((frames[name].coverage >= 1).mean()),
                "complete": plan.complete,
                "notes": " | ".join(plan.notes),
            }
        )
    price = pd.DataFrame(rows)
    write_frame_atomic(out / "price.csv", price)
    print(price.drop(columns=["notes"]).to_string(index=False))
    from schedsyn import plots

    axes = plots.sweep_panels(
        [
            (
                frames["nominal"],
                "coverage",
                f"nominal plan ({plans['nominal'].duration_min:g} min)",
            ),
            (
                frames["robust"],
                "coverage",
                f"robust plan, box tau {tau_box[0]:g}-{tau_box[1]:g} s, dT0 {dt0_box[0]:g}-"
                f"{dt0_box[1]:g} °C ({plans['robust'].duration_min:g} min"
                f"{'' if plans['robust'].complete else ', NOT complete'})",
            ),
        ],
        suptitle=f"coverage of [{spec.working_lo_c:g}, {spec.working_hi_c:g}] °C",
        box=(tau_box, dt0_box),
    )
    plots.save_figure(axes[0], args.figure)
    print(f"wrote {out}/price.csv and {args.figure}")


if __name__ == "__main__":
    main()
