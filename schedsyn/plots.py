"""All pictures. matplotlib is imported inside the functions (``import schedsyn`` stays
light); each function draws one thing on ``ax`` (created if None) and returns the axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _axes(ax, figsize=(8, 4.5)):
    if ax is not None:
        return ax
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    _, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return ax


def save_figure(ax, path: Path | str, inputs=()) -> Path:
    """Save the figure holding ``ax`` atomically as PNG and close it."""
    import matplotlib.pyplot as plt

    from .io import write_atomic

    fig = ax.figure if hasattr(ax, "figure") else ax
    out = write_atomic(path, lambda p: fig.savefig(p, dpi=120, format="png"), inputs)
    plt.close(fig)
    return out


def programme_plot(trajectory, ax=None, title: str | None = None, region=None):
    """Chamber and internal temperature against time (min), like the paper's figs 2-3."""
    ax = _axes(ax)
    ax.plot(trajectory.time_min, trajectory.tk_c, color="tab:blue", lw=1.5, label="chamber Tk")
    ax.plot(trajectory.time_min, trajectory.t_c, color="tab:red", lw=1.5, label="internal T")
    if region is not None:
        ax.axhspan(region[0], region[1], color="tab:green", alpha=0.12, label="working region")
    ax.set_xlabel("time, min")
    ax.set_ylabel("temperature, °C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return ax


def phase_plot(
    t_c,
    g_c_per_min,
    ax=None,
    region=None,
    label: str | None = None,
    lw: float = 1.2,
    color: str | None = None,
    title: str | None = None,
):
    """Phase portrait: internal temperature on x, gradient (°C/min) on y (paper fig. 4)."""
    ax = _axes(ax, figsize=(7, 5))
    if region is not None and not getattr(ax, "_schedsyn_region", False):
        ax.axvspan(region[0], region[1], color="tab:green", alpha=0.12, label="working region")
        ax._schedsyn_region = True
    ax.plot(t_c, g_c_per_min, lw=lw, color=color, label=label)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel("internal temperature T, °C")
    ax.set_ylabel("gradient dT/dt, °C/min")
    ax.grid(True, alpha=0.3)
    if label or region is not None:
        ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return ax


def coverage_plot(report, ax=None, title: str | None = None):
    """Distinct gradient levels per bin, with the requirement as a line."""
    ax = _axes(ax, figsize=(8, 3.5))
    lo = report.grid.lower_c
    colors = np.where(report.covered, "tab:green", "tab:red")
    ax.bar(lo, report.levels, width=report.grid.bin_c, align="edge", color=colors,
           edgecolor="k", lw=0.4)
    ax.axhline(report.levels_required, color="k", ls="--", lw=1,
               label=f"required: {report.levels_required}")
    ax.set_xlabel("internal temperature bin, °C")
    ax.set_ylabel(f"distinct levels (Δ ≥ {report.delta_c_per_min:g} °C/min)")
    ax.set_title(title or f"coverage {report.coverage:.0%}")
    ax.legend(loc="best")
    ax.grid(True, axis="y", alpha=0.3)
    return ax
