"""All pictures. matplotlib is imported inside the functions (``import schedsyn`` stays
light); each function draws one thing on ``ax`` (created if None) and returns the axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _figure(figsize, nrows: int = 1, ncols: int = 1, **subplots_kw):
    """A new figure and its axes, without pyplot: the user's backend is left alone.

    A :class:`matplotlib.figure.Figure` made directly belongs to no backend and needs
    none to be saved (``savefig`` renders PNG with Agg on its own).
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(nrows, ncols, **subplots_kw)


def _axes(ax, figsize=(8, 4.5)):
    if ax is not None:
        return ax
    return _figure(figsize)[1]


def save_figure(ax, path: Path | str, inputs=()) -> Path:
    """Save the figure holding ``ax`` atomically as PNG (and close it if pyplot made it)."""
    from .io import write_atomic

    fig = ax.figure if hasattr(ax, "figure") else ax
    out = write_atomic(path, lambda p: fig.savefig(p, dpi=120, format="png"), inputs)
    if getattr(fig.canvas, "manager", None) is not None:  # a pyplot figure: free it
        import matplotlib.pyplot as plt

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
    ax.bar(
        lo,
        report.levels,
        width=report.grid.bin_c,
        align="edge",
        color=colors,
        edgecolor="k",
        lw=0.4,
    )
    ax.axhline(
        report.levels_required,
        color="k",
        ls="--",
        lw=1,
        label=f"required: {report.levels_required}",
    )
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
    mesh = ax.pcolormesh(
        _cell_edges(taus),
        _cell_edges(dt0s),
        np.ma.masked_invalid(z),
        cmap="viridis",
        vmin=vmin,
        vmax=vmax,
        shading="flat",
    )
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
            ax.contour(
                taus,
                dt0s,
                full.astype(float),
                levels=[0.5],
                colors="white",
                linewidths=1.2,
                linestyles="--",
            )
    if annotate is None:
        annotate = z.size <= 400
    if annotate:
        for i, d in enumerate(dt0s):
            for j, t in enumerate(taus):
                if np.isfinite(z[i, j]):
                    text = f"{z[i, j]:.0f}" if integer or is_cov else f"{z[i, j]:.3g}"
                    light = mesh.norm(z[i, j]) > 0.6  # dark text on the yellow end
                    ax.text(
                        t,
                        d,
                        text,
                        ha="center",
                        va="center",
                        fontsize=6,
                        color="k" if light else "w",
                    )
    if nominal is not None:
        ax.plot(
            [nominal[0]],
            [nominal[1]],
            marker="*",
            ms=15,
            color="tab:red",
            mec="white",
            ls="none",
            label=f"nominal (tau {nominal[0]:g} s, dT0 {nominal[1]:g} °C)",
        )
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8, frameon=False)
    ax.set_xlabel("time constant tau, s")
    ax.set_ylabel("self-heating offset dT0, °C")
    ax.set_title(title or column)
    return ax


def sweep_panels(
    panels,
    nominal: tuple[float, float] | None = (2400.0, 3.0),
    suptitle: str | None = None,
    box: tuple[tuple[float, float], tuple[float, float]] | None = None,
):
    """Side-by-side :func:`sweep_heatmap` panels in one figure; returns the list of axes.

    ``panels`` is a sequence of ``(frame, column, title)``, e.g. the coverage and the
    minimum levels of one sweep, or the coverage of a nominal and of a robust plan.
    ``box`` = ``((tau_lo_s, tau_hi_s), (dt0_lo_c, dt0_hi_c))`` outlines a robust box on
    every panel. Save with ``save_figure(axes[0], path)``.
    """
    panels = list(panels)
    fig, axes = _figure((6.5 * len(panels), 5), 1, len(panels), squeeze=False)
    for ax, (frame, column, title) in zip(axes[0], panels, strict=True):
        sweep_heatmap(frame, column, ax=ax, nominal=nominal, title=title)
        if box is not None:
            from matplotlib.patches import Rectangle

            (t0, t1), (d0, d1) = box
            ax.add_patch(
                Rectangle(
                    (t0, d0),
                    t1 - t0,
                    d1 - d0,
                    fill=False,
                    ec="red",
                    lw=1.8,
                    ls="-",
                    label="robust box",
                )
            )
            ax.legend(
                loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, fontsize=8, frameon=False
            )
    if suptitle:
        fig.suptitle(suptitle)
    return list(axes[0])


# -- measured runs (estimate / compare) -------------------------------------------------
def gradient_plot(estimate, ax=None, truth_c_per_min=None, title: str | None = None):
    """Estimated gradient against time (min) with its ±2σ band (and the truth if known)."""
    ax = _axes(ax)
    t = estimate.time_min
    g, s = estimate.g_est_c_per_min, estimate.g_std_c_per_min
    ax.fill_between(t, g - 2 * s, g + 2 * s, color="tab:red", alpha=0.25, lw=0, label="±2σ")
    ax.plot(t, g, color="tab:red", lw=1.0, label=f"estimated ({estimate.method})")
    if truth_c_per_min is not None:
        ax.plot(t, truth_c_per_min, color="k", lw=0.6, ls="--", label="truth")
    ax.set_xlabel("time, min")
    ax.set_ylabel("gradient dT/dt, °C/min")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return ax


def phase_overlay_plot(
    sim_t_c,
    sim_g_c_per_min,
    run_t_c,
    run_g_c_per_min,
    ax=None,
    region=None,
    title: str | None = None,
):
    """Measured phase trajectory over the simulated one (thin line), as in paper figs 5-6."""
    ax = phase_plot(
        sim_t_c, sim_g_c_per_min, ax=ax, region=region, label="simulated plan", lw=0.7, color="k"
    )
    return phase_plot(
        run_t_c,
        run_g_c_per_min,
        ax=ax,
        label="measured (smoothed)",
        lw=1.4,
        color="tab:red",
        title=title,
    )


def temperature_compare_plot(time_min, measured_c, simulated_c, ax=None, title: str | None = None):
    """Measured and simulated internal temperature against time; residual on the right axis."""
    ax = _axes(ax)
    ax.plot(time_min, simulated_c, color="k", lw=0.8, label="simulated T")
    ax.plot(time_min, measured_c, color="tab:red", lw=1.2, alpha=0.8, label="measured T")
    ax.set_xlabel("time, min")
    ax.set_ylabel("internal temperature, °C")
    ax.grid(True, alpha=0.3)
    right = ax.twinx()
    resid = np.asarray(measured_c, dtype=float) - np.asarray(simulated_c, dtype=float)
    right.plot(time_min, resid, color="tab:purple", lw=0.5, label="measured - simulated")
    right.axhline(0.0, color="tab:purple", lw=0.4, ls=":")
    right.set_ylabel("residual, °C", color="tab:purple")
    lim = max(float(np.nanmax(np.abs(resid))) if np.isfinite(resid).any() else 1.0, 1e-3)
    right.set_ylim(-1.2 * lim, 4 * lim)  # keep the residual in the lower part of the axes
    lines = ax.get_lines()[:2] + right.get_lines()[:1]
    ax.legend(lines, [ln.get_label() for ln in lines], loc="upper center", framealpha=0.9)
    if title:
        ax.set_title(title)
    return ax


def coverage_compare_plot(planned, run, ax=None, title: str | None = None):
    """Distinct gradient levels per bin: planned (hatched) next to achieved by the run."""
    ax = _axes(ax, figsize=(8, 3.5))
    lo = planned.grid.lower_c
    w = planned.grid.bin_c
    ax.bar(
        lo,
        planned.levels,
        width=0.45 * w,
        align="edge",
        color="0.85",
        edgecolor="k",
        lw=0.4,
        hatch="//",
        label=f"planned ({planned.coverage:.0%})",
    )
    colors = np.where(run.covered, "tab:green", "tab:red")
    ax.bar(
        lo + 0.5 * w,
        run.levels,
        width=0.45 * w,
        align="edge",
        color=colors,
        edgecolor="k",
        lw=0.4,
        label=f"run ({run.coverage:.0%})",
    )
    ax.axhline(
        planned.levels_required,
        color="k",
        ls="--",
        lw=1,
        label=f"required: {planned.levels_required}",
    )
    ax.set_xlabel("internal temperature bin, °C")
    ax.set_ylabel(f"distinct levels (Δ ≥ {planned.delta_c_per_min:g} °C/min)")
    ax.set_title(title or f"coverage: planned {planned.coverage:.0%}, run {run.coverage:.0%}")
    ax.legend(loc="best")
    ax.grid(True, axis="y", alpha=0.3)
    return ax


def compare_panels(comparison, region=None, suptitle: str | None = None):
    """Phase overlay, T with residual, gradients and coverage of a
    :class:`~schedsyn.compare.RunComparison` in one 2x2 figure; returns the list of axes.
    Save with ``save_figure(axes[0], path)``."""
    fig, axes = _figure((14, 9), 2, 2)
    c = comparison
    phase_overlay_plot(
        c.planned.t_c,
        c.planned.g_c_per_min,
        c.run_dense.t_c,
        c.run_dense.g_c_per_min,
        ax=axes[0, 0],
        region=region,
        title="phase portrait: measured over simulated",
    )
    temperature_compare_plot(
        c.log.time_min,
        c.log.t_int_c,
        c.simulated.t_c,
        ax=axes[0, 1],
        title=f"internal temperature (RMS residual {c.rms_residual_c:.2f} °C)",
    )
    ax = gradient_plot(c.estimate, ax=axes[1, 0], title="gradient: estimated vs simulated")
    ax.plot(c.simulated.time_min, c.simulated.g_c_per_min, color="k", lw=0.6, label="simulated")
    ax.legend(loc="best")
    coverage_compare_plot(c.planned_coverage, c.run_coverage, ax=axes[1, 1])
    if suptitle:
        fig.suptitle(suptitle)
    return list(axes.ravel())


def residual_plot(
    time_min,
    before_c,
    after_c=None,
    ax=None,
    title: str | None = None,
    labels=("base model", "augmented model"),
):
    """Residuals (model - measured, °C) against time, before and after augmentation."""
    ax = _axes(ax)
    ax.plot(time_min, before_c, color="tab:red", lw=0.8, alpha=0.8, label=labels[0])
    if after_c is not None:
        ax.plot(time_min, after_c, color="tab:blue", lw=0.8, alpha=0.8, label=labels[1])
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("time, min")
    ax.set_ylabel("model - measured, °C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    if title:
        ax.set_title(title)
    return ax
