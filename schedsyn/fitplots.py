"""Pictures of a drift fit and of a plan's information (kept apart from ``plots``).

matplotlib is imported inside the functions (``import schedsyn`` stays light); each
function draws one thing on ``ax`` (created if None) and returns the axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _axes(ax, figsize=(7, 4.5)):
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


def fit_residual_plot(fit, against: str = "t", ax=None, title: str | None = None):
    """Residuals (°/h) of a :class:`~schedsyn.driftfit.DriftFit` against T or g.

    ``against`` is ``"t"`` (internal temperature, °C) or ``"g"`` (gradient, °C/min).
    The chosen model's residuals are dots; the T-only reference's are faint.
    """
    if against not in ("t", "g"):
        raise ValueError(f"against must be 't' or 'g', got {against!r}")
    ax = _axes(ax)
    frame = fit.residual_frame()
    x = frame["t_est_c"] if against == "t" else frame["g_est_c_per_min"]
    ref = frame["drift_dph"] - frame["reference_fitted_dph"]
    if tuple(fit.terms) != tuple(fit.reference.terms):
        ax.plot(x, ref, ".", ms=2, color="0.7", label="T-only cubic")
    ax.plot(x, frame["residual_dph"], ".", ms=2, color="tab:blue", label="fitted model")
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.set_xlabel("internal temperature T, °C" if against == "t" else "gradient g, °C/min")
    ax.set_ylabel("residual, °/h")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", markerscale=4)
    if title:
        ax.set_title(title)
    return ax


def fit_surface_plot(fit, ax=None, title: str | None = None):
    """The fitted drift (°/h) over (T, g) where the run went, with the measured points.

    Filled contours of the fitted model inside the reached gradients; the regression
    samples on top, coloured by their measured drift on the same scale.
    """
    ax = _axes(ax, figsize=(7.5, 5))
    d = fit.domain
    t = np.asarray(d["t_c"], dtype=float)
    g_min = np.asarray(d["g_min_c_per_min"], dtype=float)
    g_max = np.asarray(d["g_max_c_per_min"], dtype=float)
    if t.size < 2:  # a region narrower than the table's step: contour over its two edges
        t = np.asarray(fit.region_c, dtype=float)
        g_min, g_max = np.full(2, g_min.min()), np.full(2, g_max.max())
    g = np.linspace(float(g_min.min()), float(g_max.max()), 81)
    tt, gg = np.meshgrid(t, g, indexing="ij")
    z = fit.predict(tt.ravel(), gg.ravel()).reshape(tt.shape)
    inside = (gg >= g_min[:, None]) & (gg <= g_max[:, None])
    z = np.where(inside, z, np.nan)
    s = fit.samples
    lo = float(np.nanmin([np.nanmin(z), np.percentile(s.drift_dph, 1)]))
    hi = float(np.nanmax([np.nanmax(z), np.percentile(s.drift_dph, 99)]))
    levels = np.linspace(lo, hi, 21) if hi > lo else 21
    cs = ax.contourf(tt, gg, z, levels=levels, cmap="viridis", extend="both")
    ax.scatter(
        s.t_c,
        s.g_c_per_min,
        c=s.drift_dph,
        s=5,
        cmap="viridis",
        vmin=lo,
        vmax=hi,
        edgecolors="0.15",
        linewidths=0.15,
    )
    ax.figure.colorbar(cs, ax=ax, label="drift, °/h")
    ax.set_xlabel("internal temperature T, °C")
    ax.set_ylabel("gradient g, °C/min")
    ax.set_title(title or "fitted drift (contours) and measured drift (points)")
    return ax


def variance_map_plot(report, ax=None, title: str | None = None, samples=None, vlim=None):
    """Prediction variance of a :class:`~schedsyn.design.DesignReport` over (T, g).

    ``samples``: optional ``(t_c, g_c_per_min)`` of the run, drawn as a thin line;
    ``vlim``: optional ``(lo, hi)`` of the colour scale in log10 units (to compare maps).
    """
    ax = _axes(ax, figsize=(7.5, 5))
    m = report.variance_map
    v = np.asarray(m["prediction_variance"], dtype=float)
    sc = ax.scatter(
        m["t_c"],
        m["g_c_per_min"],
        c=np.log10(np.where(np.isfinite(v), v, np.nan)),
        s=8,
        marker="s",
        cmap="magma_r",
        vmin=None if vlim is None else vlim[0],
        vmax=None if vlim is None else vlim[1],
        edgecolors="none",
    )
    ax.figure.colorbar(sc, ax=ax, label="log10 prediction variance (σ²/n)")
    if samples is not None:
        ax.plot(samples[0], samples[1], color="tab:blue", lw=0.6, alpha=0.7, label="run")
        ax.legend(loc="best")
    ax.set_xlim(report.space.working_lo_c, report.space.working_hi_c)
    ax.set_xlabel("internal temperature T, °C")
    ax.set_ylabel("gradient g, °C/min")
    ax.set_title(title or f"prediction variance; I-efficiency {report.i_efficiency_pct:.0f} %")
    return ax
