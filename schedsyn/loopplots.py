"""Plots of the closed loop: a run in progress against its plan.

matplotlib is imported inside the functions (``import schedsyn`` never loads it); each
function takes ``ax=None``, draws one thing and returns the axes; :func:`monitor_panels`
puts them on one figure.
"""

from __future__ import annotations

import numpy as np


def _axes(ax, figsize=(8, 4.5)):
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=figsize, layout="constrained")
    return ax


def run_vs_plan_plot(report, ax=None, title: str | None = None):
    """Planned chamber and device temperature against time, measured so far, predicted rest."""
    ax = _axes(ax)
    pl = report.planned_dense
    ax.plot(pl["time_min"], pl["tk_c"], color="tab:blue", lw=0.8, label="planned chamber")
    ax.plot(pl["time_min"], pl["t_c"], color="k", lw=1.0, ls="--", label="planned T")
    s = report.series
    ax.plot(s["time_s"] / 60.0, s["t_meas_c"], color="tab:red", lw=1.2, label="measured T")
    d = report.dense[report.dense["predicted"]]
    if len(d):
        ax.plot(
            d["time_min"],
            d["t_c"],
            color="tab:red",
            lw=1.0,
            ls=":",
            label="predicted T (identified model)",
        )
    ax.axvline(report.elapsed_min, color="0.4", lw=0.8)
    ax.axhspan(
        report.plan.working_lo_c,
        report.plan.working_hi_c,
        color="tab:green",
        alpha=0.1,
        label="working region",
    )
    ax.set_xlabel("time, min")
    ax.set_ylabel("temperature, °C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or f"{report.plan.name}: {report.elapsed_min:.0f} min elapsed")
    return ax


def phase_so_far_plot(report, ax=None, title: str | None = None):
    """Phase portrait: the plan (thin), the measured run (smoothed), the predicted rest."""
    ax = _axes(ax)
    pl = report.planned_dense
    ax.plot(pl["t_c"], pl["g_c_per_min"], color="k", lw=0.6, label="planned")
    dense = report.dense
    m = dense[~dense["predicted"]]
    p = dense[dense["predicted"]]
    ax.plot(m["t_c"], m["g_c_per_min"], color="tab:red", lw=1.3, label="measured (smoothed)")
    if len(p):
        ax.plot(p["t_c"], p["g_c_per_min"], color="tab:red", lw=0.8, ls=":", label="predicted")
    edges = report.plan.grid.edges_c
    for e in edges:
        ax.axvline(e, color="0.85", lw=0.4, zorder=0)
    ax.axvspan(edges[0], edges[-1], color="tab:green", alpha=0.08)
    ax.set_xlabel("internal temperature T, °C")
    ax.set_ylabel("gradient dT/dt, °C/min")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "phase portrait: planned vs measured so far")
    return ax


def bin_status_plot(report, ax=None, title: str | None = None):
    """Distinct levels per bin: planned, measured so far, predicted if the plan goes on."""
    ax = _axes(ax)
    lo = report.plan.grid.lower_c
    x = lo + 0.5 * report.plan.grid.bin_c
    w = 0.28 * report.plan.grid.bin_c
    ax.bar(x - w, report.planned.levels, w, color="0.7", label="planned")
    ax.bar(x, report.so_far.levels, w, color="tab:red", label="so far")
    ax.bar(x + w, report.predicted.levels, w, color="tab:orange", label="predicted")
    ax.axhline(report.plan.levels_required, color="k", lw=0.8, ls="--", label="required")
    if report.pass_in_progress is not None:
        op = report.pass_in_progress
        ax.axvspan(op.bin_lo_c, op.bin_lo_c + report.plan.grid.bin_c, color="tab:red", alpha=0.1)
    ax.set_xlabel("bin, °C")
    ax.set_ylabel("distinct gradient levels")
    ax.set_ylim(0, max(int(np.max(report.planned.levels)), report.plan.levels_required) + 1.5)
    ax.legend(loc="best", fontsize=8, ncol=4)
    ax.set_title(title or f"levels per bin (Δ {report.plan.delta_c_per_min:g} °C/min)")
    return ax


def monitor_panels(report, suptitle: str | None = None):
    """The three monitor plots on one figure; returns the axes."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 12), layout="constrained")
    run_vs_plan_plot(report, ax=axes[0])
    phase_so_far_plot(report, ax=axes[1])
    bin_status_plot(report, ax=axes[2])
    if suptitle:
        fig.suptitle(suptitle)
    return axes
