"""Plots of a tag-sensor sweep (matplotlib, Agg; PNG written atomically).

- :func:`plot_tag_sweep_errors`: median position and rotation error of accepted estimates
  against distance, one line per viewing angle, one row of panels per blur/noise condition.
- :func:`plot_tag_sweep_rates`: detection and acceptance rate over distance x angle as
  annotated heatmaps, one row per condition.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from tagloc.eval.report_plots import pyplot, save_png
from tagloc.eval.tag_sweep_stats import TagSweepRow, conditions


def _label(blur: float, noise: float) -> str:
    return f"blur {blur:g} px, read noise {noise:g} DN"


def plot_tag_sweep_errors(rows: Sequence[TagSweepRow], path: str | os.PathLike[str]) -> None:
    """Median errors vs distance per angle (log scale; cells without accepted views omitted).

    Parameters
    ----------
    rows : sequence of TagSweepRow
    path : path-like
        Output PNG, written atomically.
    """
    plt = pyplot()
    conds = conditions(rows)
    angles = sorted({r.angle_deg for r in rows})
    fig, axes = plt.subplots(len(conds), 2, figsize=(11, 3.2 * len(conds)), squeeze=False)
    for i, (blur, noise) in enumerate(conds):
        cell = [r for r in rows if (r.blur_px, r.noise_dn) == (blur, noise)]
        for angle in angles:
            line = sorted((r for r in cell if r.angle_deg == angle), key=lambda r: r.distance_m)
            d = [r.distance_m for r in line]
            for ax, values in (
                (axes[i, 0], [100.0 * r.position_error_median_m for r in line]),
                (axes[i, 1], [r.rotation_error_median_deg for r in line]),
            ):
                ax.plot(d, values, "o-", label=f"{angle:g} deg", markersize=4)
        axes[i, 0].set_ylabel("position error median (cm)")
        axes[i, 1].set_ylabel("rotation error median (deg)")
        for ax in axes[i]:
            ax.set_yscale("log")
            ax.set_xlabel("distance (m)")
            ax.set_title(_label(blur, noise), fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
    axes[0, 1].legend(title="view angle", fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1))
    save_png(fig, path, dpi=100)


def plot_tag_sweep_rates(rows: Sequence[TagSweepRow], path: str | os.PathLike[str]) -> None:
    """Detection and acceptance rate heatmaps (distance x angle), one row per condition of
    ``rows``; the PNG ``path`` is written atomically."""
    conds = conditions(rows)
    distances = sorted({r.distance_m for r in rows})
    angles = sorted({r.angle_deg for r in rows})
    fig, axes = pyplot().subplots(
        len(conds), 2, figsize=(10, 0.5 + 0.45 * len(distances) * len(conds)), squeeze=False
    )
    for i, (blur, noise) in enumerate(conds):
        by_cell = {
            (r.distance_m, r.angle_deg): r for r in rows if (r.blur_px, r.noise_dn) == (blur, noise)
        }
        for ax, name in zip(axes[i], ("detection_rate", "acceptance_rate"), strict=True):
            grid = np.array(
                [[getattr(by_cell[d, a], name) for a in angles] for d in distances], dtype=float
            )
            ax.imshow(grid, vmin=0.0, vmax=1.0, cmap="RdYlGn", aspect="auto")
            for (y, x), value in np.ndenumerate(grid):
                ax.text(x, y, f"{value:.2f}", ha="center", va="center", fontsize=8)
            ax.set_xticks(range(len(angles)), [f"{a:g}" for a in angles])
            ax.set_yticks(range(len(distances)), [f"{d:g}" for d in distances])
            ax.set_xlabel("view angle (deg)")
            ax.set_ylabel("distance (m)")
            ax.set_title(f"{name.replace('_', ' ')}: {_label(blur, noise)}", fontsize=9)
    save_png(fig, path, dpi=100)
