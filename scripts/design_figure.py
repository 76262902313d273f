"""Prediction-variance maps of schedsyn's W1 plan and a paper-like programme of the same
length (docs/img/drift_design_W1.png).

    schedsyn campaign --out out/campaign
    python scripts/design_figure.py [--plans out/campaign] [--out docs/img/drift_design_W1.png]
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import schedsyn  # noqa: E402
from schedsyn.baseline import paper_like_programme  # noqa: E402
from schedsyn.design import DesignSpace, programme_design  # noqa: E402
from schedsyn.fitplots import save_figure, variance_map_plot  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plans", default="out/campaign")
    ap.add_argument("--out", default="docs/img/drift_design_W1.png")
    args = ap.parse_args()
    plan = schedsyn.read_steps(f"{args.plans}/W1/steps.csv")
    base = paper_like_programme(-50, -30, -52, -20, plan.total_min)
    space = DesignSpace(-50, -30, -52, -20)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), constrained_layout=True, sharey=True)
    for ax, (name, prog) in zip(
        axes, (("schedsyn W1 plan", plan), ("paper-like programme", base)), strict=True
    ):
        rep = programme_design(prog, space)
        traj = schedsyn.simulate(prog, dt_min=0.5)
        variance_map_plot(
            rep,
            ax=ax,
            samples=(traj.t_c, traj.g_c_per_min),
            title=f"{name}: D-eff {rep.d_efficiency_pct:.1f} %, I-eff {rep.i_efficiency_pct:.0f} %",
            vlim=(0.5, 1.8),
        )
        ax.set_ylim(-0.9, 1.05)
    save_figure(axes[0], args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
