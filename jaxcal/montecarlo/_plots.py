"""Plots of Monte-Carlo studies (matplotlib, imported lazily): histograms of the
estimates against the analytic normal density, and the error against the noise level."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ._stats import MonteCarloResult

__all__ = ["plot_histograms", "plot_error_vs_noise"]


def _select(result: MonteCarloResult, names: Sequence[str] | None) -> list[int]:
    if names is None:
        return list(range(len(result.names)))
    out = []
    for n in names:
        hits = [i for i, m in enumerate(result.names) if n in (m, m.split("_")[0])]
        if not hits:
            raise ValueError(f"unknown parameter {n!r}; the study has {result.names}")
        out.append(hits[0])
    return out


def plot_histograms(
    result: MonteCarloResult,
    names: Sequence[str] | None = None,
    *,
    bins: int = 60,
    axes=None,
):
    """Histogram of each parameter's estimates (from `keep_estimates=True`, else the
    streamed `histogram_bins` counts), with the true value, the noise-free estimate and
    the normal density of the predicted standard error around it. Returns the figure."""
    import matplotlib.pyplot as plt

    idx = _select(result, names)
    if axes is None:
        cols = min(4, len(idx))
        rows = math.ceil(len(idx) / cols)
        fig, axs = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), squeeze=False)
        axes = axs.ravel()
    else:
        axes = np.ravel(axes)
        fig = axes[0].figure
    for ax, i in zip(axes, idx, strict=False):
        if result.estimates is not None:
            x = result.estimates[:, i]
            ax.hist(x, bins=bins, density=True, color="0.75", label="estimates")
        elif result.histogram is not None and result.histogram_edges is not None:
            e = result.histogram_edges[i]
            c = result.histogram[i, 1:-1]
            n = max(result.histogram[i].sum(), 1)
            ax.stairs(c / (n * np.diff(e)), e, fill=True, color="0.75", label="estimates")
        else:
            raise ValueError("the study kept neither estimates nor histograms")
        m, s = result.noise_free[i], result.predicted_std[i]
        if s > 0:
            t = np.linspace(m - 4 * s, m + 4 * s, 200)
            ax.plot(t, np.exp(-0.5 * ((t - m) / s) ** 2) / (s * math.sqrt(2 * math.pi)), "C0-")
        ax.axvline(result.true[i], color="C3", lw=1.2, label="true")
        ax.axvline(m, color="C0", lw=0.8, ls="--", label="noise-free fit")
        ax.set_title(result.names[i], fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes[len(idx) :]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_error_vs_noise(
    results: Sequence[MonteCarloResult],
    names: Sequence[str] | None = None,
    *,
    relative: bool = True,
    ax=None,
):
    """RMSE (markers) and predicted standard error (lines) of each parameter against
    the noise σ (mm) of a sweep (`noise_sweep`), relative to the true values by
    default, log–log. Returns the axes."""
    import matplotlib.pyplot as plt

    if not results:
        raise ValueError("no results to plot")
    idx = _select(results[0], names)
    if ax is None:
        _, ax = plt.subplots(figsize=(5.5, 3.8))
    sig = np.array([r.noise_std * 1e3 for r in results])
    for j, i in enumerate(idx):
        scale = abs(results[0].true[i]) if relative else 1.0
        rmse = np.array([r.rmse[i] for r in results]) / scale
        pred = np.array([r.predicted_std[i] for r in results]) / scale
        ax.loglog(sig, rmse, "o", color=f"C{j}", label=results[0].names[i].split("_")[0])
        ax.loglog(sig, pred, "-", color=f"C{j}", lw=0.8)
    ax.set_xlabel("noise σ per coordinate (mm)")
    ax.set_ylabel("relative RMSE" if relative else "RMSE (user units)")
    ax.set_title("markers: Monte-Carlo RMSE; lines: predicted standard error", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    return ax
