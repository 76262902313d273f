"""All pictures. matplotlib is imported inside the functions (``import schedsyn`` stays
light) and only its object-oriented API is used (``matplotlib.figure.Figure``), so the
user's backend is left alone; each function draws one thing on ``ax`` (a new figure if
None) and returns the axes. Every axis names its quantity and unit; a legend names every
line that is compared with another.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Colours of the chamber and the device (the same in every picture).
CHAMBER_COLOUR = "tab:blue"
DEVICE_COLOUR = "tab:red"
REGION_COLOUR = "tab:green"


def _figure(figsize=(8, 4.5)):
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained")


def _axes(ax, figsize=(8, 4.5)):
    if ax is not None:
        return ax
    return _figure(figsize).add_subplot()


def save_figure(ax, path: Path | str, inputs=()) -> Path:
    """Save the figure holding ``ax`` (or a Figure) atomically as PNG."""
    from .io import write_atomic

    fig = ax.figure if hasattr(ax, "figure") else ax
    return write_atomic(path, lambda p: fig.savefig(p, dpi=120, format="png"), inputs)


def _break_at_gaps(time, *series, factor: float = 5.0):
    """Insert NaN where the time step exceeds ``factor`` x its median (a logging gap), so
    that no line is drawn across the gap. Returns the new ``(time, *series)``."""
    t = np.asarray(time, dtype=float)
    ys = [np.asarray(y, dtype=float) for y in series]
    if t.size < 3:
        return (t, *ys)
    dt = np.diff(t)
    pos = dt[np.isfinite(dt) & (dt > 0)]
    if pos.size == 0:
        return (t, *ys)
    gaps = np.flatnonzero(dt > factor * float(np.median(pos))) + 1
    if gaps.size == 0:
        return (t, *ys)
    t_mid = 0.5 * (t[gaps - 1] + t[gaps])
    return (np.insert(t, gaps, t_mid), *(np.insert(y, gaps, np.nan) for y in ys))


def _unit_label(column: str) -> str:
    """An axis/colorbar label for a table column: its words and its unit."""
    known = {
        "coverage": "coverage, %",
        "min_levels": "fewest distinct levels of a bin",
        "duration_min": "duration, min",
        "margin_g_c_per_min": "gradient margin, °C/min",
        "margin_t_c": "temperature margin, °C",
        "steps": "steps",
        "solve_s": "solve time, s",
    }
    if column in known:
        return known[column]
    if column.startswith("coverage"):
        return f"{column.replace('_', ' ')}, %"
    for suffix, unit in (("_c_per_min", "°C/min"), ("_min", "min"), ("_c", "°C"), ("_s", "s")):
        if column.endswith(suffix):
            return f"{column[: -len(suffix)].replace('_', ' ')}, {unit}"
    return column.replace("_", " ")


# ---------------------------------------------------------------------------------------
# a programme against time
# ---------------------------------------------------------------------------------------
def programme_plot(
    trajectory,
    ax=None,
    title: str | None = None,
    region=None,
    limits=None,
    programme=None,
):
    """Chamber and internal temperature against time (min), like the paper's figs 2-3.

    ``limits`` (a :class:`~schedsyn.params.Limits`) marks the chamber and device limits
    (a limit far outside the drawn range is named in the legend as off scale);
    ``programme`` marks its step boundaries; ``region`` shades the working region.
    """
    ax = _axes(ax)
    t = np.asarray(trajectory.time_min, dtype=float)
    tk, temp = np.asarray(trajectory.tk_c, float), np.asarray(trajectory.t_c, float)
    ax.plot(t, tk, color=CHAMBER_COLOUR, lw=1.5, label="chamber Tk", zorder=3)
    ax.plot(t, temp, color=DEVICE_COLOUR, lw=1.5, label="device (internal) T", zorder=3)
    if region is not None:
        ax.axhspan(region[0], region[1], color=REGION_COLOUR, alpha=0.12, label="working region")
    data = np.concatenate([tk[np.isfinite(tk)], temp[np.isfinite(temp)]])
    lo, hi = (float(data.min()), float(data.max())) if data.size else (0.0, 1.0)
    if region is not None:
        lo, hi = min(lo, region[0]), max(hi, region[1])
    pad = max(0.05 * (hi - lo), 2.0)
    y0, y1 = lo - pad, hi + pad
    if limits is not None:
        for name, (a, b), colour, ls in (
            ("chamber", (limits.chamber_min_c, limits.chamber_max_c), CHAMBER_COLOUR, "--"),
            ("device", (limits.device_min_c, limits.device_max_c), DEVICE_COLOUR, ":"),
        ):
            near = [v for v in (a, b) if y0 - 12.0 <= v <= y1 + 12.0]
            far = [v for v in (a, b) if v not in near]
            label = f"{name} limits {a:g} .. {b:g} °C"
            if far:
                label += " (" + ", ".join(f"{v:g}" for v in far) + " off scale)"
            for i, v in enumerate(near):
                ax.axhline(
                    v, color=colour, ls=ls, lw=1.0, alpha=0.8, label=label if i == 0 else None
                )
                y0, y1 = min(y0, v - 2.0), max(y1, v + 2.0)
            if not near:
                ax.plot([], [], color=colour, ls=ls, lw=1.0, label=label)
    ax.set_ylim(y0, y1)
    if programme is not None and programme.n_segments > 1:
        starts = np.asarray(programme.starts_min[1:], dtype=float)
        for i, s in enumerate(starts):
            ax.axvline(
                s,
                color="0.55",
                lw=0.5,
                alpha=0.6,
                zorder=1,
                label=f"step boundaries ({programme.n_segments} steps)" if i == 0 else None,
            )
    ax.set_xlim(float(t.min()), float(t.max()))
    ax.set_xlabel("time, min")
    ax.set_ylabel("temperature, °C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


# ---------------------------------------------------------------------------------------
# phase portraits
# ---------------------------------------------------------------------------------------
def sweeps_of(g_c_per_min, min_samples: int | None = None) -> list[tuple[int, int]]:
    """Split a trajectory into sweeps: maximal runs of one sign of the gradient.

    Returns ``[(start, stop), ...]`` sample ranges (stop exclusive) covering every sample;
    runs shorter than ``min_samples`` (default 1 % of the samples) take the sign of the
    run before them (the first: of the next), so that noise around a turning point does
    not make sweeps of its own.
    """
    g = np.asarray(g_c_per_min, dtype=float)
    n = g.size
    if n == 0:
        return []
    sign = np.sign(np.where(np.isfinite(g), g, 0.0))
    # a zero (a hold, a turning point) continues the sign before it
    for i in range(1, n):
        if sign[i] == 0:
            sign[i] = sign[i - 1]
    min_len = max(2, int(0.01 * n)) if min_samples is None else int(min_samples)

    def runs(sg):
        change = np.flatnonzero(np.diff(sg) != 0) + 1
        edges = [0, *change.tolist(), n]
        return list(zip(edges[:-1], edges[1:], strict=True))

    r = runs(sign)
    for i, (a, b) in enumerate(r):  # a short run takes the sign around it
        if b - a < min_len and len(r) > 1:
            sign[a:b] = sign[r[i - 1][0]] if i > 0 else sign[r[1][0]]
    return runs(sign)


def _arrow(ax, x, y, colour, lw):
    """A direction arrow at the middle of the finite part of ``(x, y)``."""
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    if ok.size < 4:
        return
    k = ok[ok.size // 2]
    step = max(1, ok.size // 40)
    k2 = min(k + step, ok[-1])
    if k2 == k:
        return
    ax.annotate(
        "",
        xy=(x[k2], y[k2]),
        xytext=(x[k], y[k]),
        arrowprops={"arrowstyle": "-|>", "color": colour, "lw": lw, "mutation_scale": 14},
        zorder=4,
    )


def phase_plot(
    t_c,
    g_c_per_min,
    ax=None,
    region=None,
    label: str | None = None,
    lw: float = 1.2,
    color: str | None = None,
    title: str | None = None,
    *,
    bins: bool = True,
):
    """Phase portrait: internal temperature on x, gradient (°C/min) on y (paper fig. 4).

    Without ``color`` each sweep (a run of one sign of the gradient, :func:`sweeps_of`)
    gets its own colour and a direction arrow, and the start and end are marked; with
    ``color`` the trajectory is one line (to overlay several, e.g. measured vs
    simulated). ``region`` shades the working region and, with ``bins``, draws its 1 °C
    bin grid.
    """
    ax = _axes(ax, figsize=(8.5, 5))
    t = np.asarray(t_c, dtype=float)
    g = np.asarray(g_c_per_min, dtype=float)
    if region is not None and not getattr(ax, "_schedsyn_region", False):
        ax.axvspan(region[0], region[1], color=REGION_COLOUR, alpha=0.10, label="working region")
        if bins:
            edges = np.arange(region[0], region[1] + 1e-9, 1.0)
            if edges.size <= 200:
                for i, e in enumerate(edges):
                    ax.axvline(
                        e,
                        color=REGION_COLOUR,
                        lw=0.4,
                        alpha=0.5,
                        zorder=0,
                        label="1 °C bins" if i == 0 else None,
                    )
        ax._schedsyn_region = True
    sweeps = sweeps_of(g) if color is None else []
    if color is None and 1 <= len(sweeps) <= 24:
        from matplotlib import colormaps

        cmap = colormaps["tab10"] if len(sweeps) <= 10 else colormaps["tab20"]
        for i, (a, b) in enumerate(sweeps):
            c = cmap(i % cmap.N)
            b_draw = min(b + 1, t.size)  # join the next sweep
            seg_g = g[a:b_draw]
            finite = seg_g[np.isfinite(seg_g)]
            kind = "heating" if finite.size and np.mean(finite) > 0 else "cooling"
            name = f"{label}: " if label else ""
            ax.plot(t[a:b_draw], seg_g, lw=lw, color=c, label=f"{name}sweep {i + 1} ({kind})")
            _arrow(ax, t[a:b_draw], seg_g, c, lw)
        first = np.flatnonzero(np.isfinite(t) & np.isfinite(g))
        if first.size:
            s, e = first[0], first[-1]
            ax.plot(
                t[s],
                g[s],
                "o",
                ms=8,
                mfc="white",
                mec="k",
                mew=1.5,
                zorder=5,
                label=f"start ({t[s]:.1f} °C)",
            )
            ax.plot(t[e], g[e], "s", ms=8, color="k", zorder=5, label=f"end ({t[e]:.1f} °C)")
    else:
        ax.plot(t, g, lw=lw, color=color, label=label)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel("internal temperature T, °C")
    ax.set_ylabel("gradient dT/dt, °C/min")
    ax.grid(True, alpha=0.25)
    handles, _ = ax.get_legend_handles_labels()
    if handles:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


# ---------------------------------------------------------------------------------------
# coverage
# ---------------------------------------------------------------------------------------
def coverage_plot(report, ax=None, title: str | None = None):
    """Distinct gradient levels per bin, coloured by how thin the margin is.

    Bar height: the bin's distinct levels (the requirement is the dashed line). Colour
    and the number above each bar: the widest separation of the required number of its
    passes relative to delta (``CoverageReport.separations_c_per_min / delta``): 1.00 means
    the bin holds its levels with nothing to spare, red bars fall short. The title names
    the tightest bin.
    """
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    ax = _axes(ax, figsize=(9, 4.0))
    lo = report.grid.lower_c
    w = report.grid.bin_c
    delta = report.delta_c_per_min
    ratio = report.separations_c_per_min / delta
    # covered bins: orange (no margin, 1.0 delta) .. yellow .. green (2 delta and more);
    # short bins are red and hatched
    cmap = LinearSegmentedColormap.from_list("margin", ["#e8710a", "#f6d55c", "#3caea3", "#1b7837"])
    norm = Normalize(vmin=1.0, vmax=2.0)
    covered = report.covered
    colours = [
        cmap(norm(min(r, 2.0))) if c and np.isfinite(r) else "#d62728"
        for r, c in zip(ratio, covered, strict=True)
    ]
    ax.bar(lo, report.levels, width=w, align="edge", color=colours, edgecolor="k", lw=0.4)
    short = ~covered
    if short.any():
        ax.bar(
            lo[short],
            report.levels[short],
            width=w,
            align="edge",
            color="none",
            edgecolor="k",
            hatch="///",
            lw=0.4,
            label="short of the requirement",
        )
    for x, n, r, c in zip(lo, report.levels, ratio, covered, strict=True):
        if c and np.isfinite(r):
            ax.text(
                x + 0.5 * w,
                n + 0.15,
                "≥2" if r >= 2 else f"{r:.2f}",
                ha="center",
                va="bottom",
                fontsize=6,
                rotation=90,
            )
    ax.axhline(
        report.levels_required,
        color="k",
        ls="--",
        lw=1,
        label=f"required: {report.levels_required}",
    )
    from matplotlib.cm import ScalarMappable

    sm = ScalarMappable(norm=norm, cmap=cmap)
    ax.figure.colorbar(sm, ax=ax, label="separation of the levels / Δ", pad=0.01, extend="max")
    ax.set_xlabel("internal temperature bin, °C")
    ax.set_ylabel(f"distinct levels (Δ ≥ {delta:g} °C/min)")
    ax.set_ylim(0, max(int(report.levels.max()), report.levels_required) + 2.5)
    ok = covered & np.isfinite(ratio)
    if title is None:
        title = f"coverage {report.coverage:.0%}"
    if ok.any():
        i = int(np.flatnonzero(ok)[np.argmin(ratio[ok])])
        sep = report.separations_c_per_min[i]
        title += (
            f"\ntightest bin [{lo[i]:g}, {lo[i] + w:g}) °C: its {report.levels_required} "
            f"levels are {sep:.4f} °C/min apart = {ratio[i]:.2f} Δ"
        )
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
    ax.grid(True, axis="y", alpha=0.3)
    return ax


# ---------------------------------------------------------------------------------------
# sweeps over tau and dT0
# ---------------------------------------------------------------------------------------
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
    cbar = ax.figure.colorbar(mesh, ax=ax, label=_unit_label(column))
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
    ax.set_title(title or _unit_label(column))
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
    fig = _figure(figsize=(6.5 * len(panels), 5))
    axes = fig.subplots(1, len(panels), squeeze=False)
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
    """Estimated gradient against time (min) with its ±2σ band (and the truth if known);
    no line across a logging gap."""
    ax = _axes(ax)
    t, g, s = _break_at_gaps(estimate.time_min, estimate.g_est_c_per_min, estimate.g_std_c_per_min)
    ax.fill_between(t, g - 2 * s, g + 2 * s, color=DEVICE_COLOUR, alpha=0.25, lw=0, label="±2σ")
    ax.plot(t, g, color=DEVICE_COLOUR, lw=1.0, label=f"estimated ({estimate.method})")
    if truth_c_per_min is not None:
        tt, truth = _break_at_gaps(estimate.time_min, truth_c_per_min)
        ax.plot(tt, truth, color="k", lw=0.6, ls="--", label="truth")
    ax.set_xlabel("time, min")
    ax.set_ylabel("gradient dT/dt, °C/min")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
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
        color=DEVICE_COLOUR,
        title=title,
    )


def temperature_compare_plot(time_min, measured_c, simulated_c, ax=None, title: str | None = None):
    """Measured and simulated internal temperature against time; residual on the right
    axis; no line across a logging gap."""
    ax = _axes(ax)
    t, meas, sim = _break_at_gaps(time_min, measured_c, simulated_c)
    ax.plot(t, sim, color="k", lw=0.8, label="simulated T")
    ax.plot(t, meas, color=DEVICE_COLOUR, lw=1.2, alpha=0.8, label="measured T")
    ax.set_xlabel("time, min")
    ax.set_ylabel("internal temperature, °C")
    ax.grid(True, alpha=0.3)
    right = ax.twinx()
    resid = meas - sim
    right.plot(t, resid, color="tab:purple", lw=0.5, label="measured - simulated")
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
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    return ax


def compare_panels(comparison, region=None, suptitle: str | None = None):
    """Phase overlay, T with residual, gradients and coverage of a
    :class:`~schedsyn.compare.RunComparison` in one 2x2 figure; returns the list of axes.
    Save with ``save_figure(axes[0], path)``."""
    fig = _figure(figsize=(15, 9))
    axes = fig.subplots(2, 2)
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
    t, g = _break_at_gaps(c.simulated.time_min, c.simulated.g_c_per_min)
    ax.plot(t, g, color="k", lw=0.6, label="simulated")
    ax.legend(loc="best", fontsize=8)
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
    """Residuals (model - measured, °C) against time, before and after augmentation.

    The base model's residual is a wide pale band underneath, the augmented one a thin
    dark line on top, so that each stays visible where they overlap; no line is drawn
    across a logging gap.
    """
    ax = _axes(ax)
    if after_c is None:
        t, before = _break_at_gaps(time_min, before_c)
        after = None
    else:
        t, before, after = _break_at_gaps(time_min, before_c, after_c)
    ax.plot(t, before, color="tab:orange", lw=2.4, alpha=0.55, label=labels[0], zorder=2)
    if after is not None:
        ax.plot(t, after, color="tab:blue", lw=0.8, label=labels[1], zorder=3)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("time, min")
    ax.set_ylabel("model - measured, °C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return ax
