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


def _cell_edges(values) -> np.ndarray:
    """Edges of heatmap cells centred on ``values`` (sorted, 1-D)."""
    v = np.asarray(values, dtype=float)
    if v.size == 1:
        w = max(abs(float(v[0])) * 0.05, 0.5)
        return np.array([v[0] - w, v[0] + w])
    mid = 0.5 * (v[1:] + v[:-1])
    return np.concatenate(([v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]))


def sweep_heatmap(
    frame,
    column: str = "coverage",
    ax=None,
    nominal: tuple[float, float] | None = (2400.0, 3.0),
    title: str | None = None,
    annotate: bool | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
):
    """Heatmap of one column of a sweep table over tau (x, s) and dT0 (y, °C).

    ``frame`` has columns ``tau_s``, ``dt0_c`` and ``column`` (e.g.
    ``SweepResult.to_frame()`` or ``ReplanResult.to_frame()``). Coverage columns are drawn
    on 0..100 % with the boundary of full coverage outlined; ``nominal`` (tau_s, dt0_c) is
    marked with a star. Cells are annotated when the grid has at most 400 points.
    """
    ax = _axes(ax, figsize=(7, 5))
    table = frame.pivot(index="dt0_c", columns="tau_s", values=column).sort_index()
    table = table.reindex(sorted(table.columns), axis=1)
    taus = table.columns.to_numpy(dtype=float)
    dt0s = table.index.to_numpy(dtype=float)
    z = table.to_numpy(dtype=float)
    is_cov = column.startswith("coverage")
    if is_cov:
        z = 100.0 * z
        vmin = 0.0 if vmin is None else 100.0 * vmin
        vmax = 100.0 if vmax is None else 100.0 * vmax
    mesh = ax.pcolormesh(_cell_edges(taus), _cell_edges(dt0s), np.ma.masked_invalid(z),
                         cmap="viridis", vmin=vmin, vmax=vmax, shading="flat")
    label = f"{column}, %" if is_cov else column
    cbar = ax.figure.colorbar(mesh, ax=ax, label=label)
    integer = bool(np.all(np.isnan(z) | (z == np.round(z))))
    if integer and not is_cov:
        from matplotlib.ticker import MaxNLocator

        cbar.locator = MaxNLocator(integer=True)
        cbar.update_ticks()
    if is_cov and taus.size > 1 and dt0s.size > 1:
        full = z >= 100.0 - 1e-9
        if full.any() and not full.all():
            ax.contour(taus, dt0s, full.astype(float), levels=[0.5], colors="white",
                       linewidths=1.2, linestyles="--")
    if annotate is None:
        annotate = z.size <= 400
    if annotate:
        for i, d in enumerate(dt0s):
            for j, t in enumerate(taus):
                if np.isfinite(z[i, j]):
                    text = f"{z[i, j]:.0f}" if integer or is_cov else f"{z[i, j]:.3g}"
                    light = mesh.norm(z[i, j]) > 0.6  # dark text on the yellow end
                    ax.text(t, d, text, ha="center", va="center", fontsize=6,
                            color="k" if light else "w")
    if nominal is not None:
        ax.plot([nominal[0]], [nominal[1]], marker="*", ms=15, color="tab:red", mec="white",
                ls="none", label=f"nominal (tau {nominal[0]:g} s, dT0 {nominal[1]:g} °C)")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8,
                  frameon=False)
    ax.set_xlabel("time constant tau, s")
    ax.set_ylabel("self-heating offset dT0, °C")
    ax.set_title(title or column)
    return ax


def sweep_panels(panels, nominal: tuple[float, float] | None = (2400.0, 3.0),
                 suptitle: str | None = None):
    """Side-by-side :func:`sweep_heatmap` panels in one figure; returns the list of axes.

    ``panels`` is a sequence of ``(frame, column, title)``, e.g. the coverage and the
    minimum levels of one sweep, or the coverage of a nominal and of a robust plan.
    Save with ``save_figure(axes[0], path)``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    panels = list(panels)
    fig, axes = plt.subplots(1, len(panels), figsize=(6.5 * len(panels), 5),
                             constrained_layout=True, squeeze=False)
    for ax, (frame, column, title) in zip(axes[0], panels, strict=True):
        sweep_heatmap(frame, column, ax=ax, nominal=nominal, title=title)
    if suptitle:
        fig.suptitle(suptitle)
    return list(axes[0])
