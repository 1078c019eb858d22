"""The report's figures (matplotlib, Agg), each returned as PNG bytes for embedding.

Colours are fixed per estimate across figures: truth green, odometry red, fused blue,
baseline grey.
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np

from tagloc.eval.fixstats import AcceptanceBin
from tagloc.eval.summary_types import Evaluation
from tagloc.fileutil import atomic_path

COLORS = {"truth": "tab:green", "odometry": "tab:red", "fused": "tab:blue", "baseline": "0.45"}
_MAX_POINTS = 6000  # plotted samples per series (decimated evenly)


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig: Any) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    pyplot().close(fig)
    return buffer.getvalue()


def save_png(fig: Any, path: str | os.PathLike[str], dpi: float | None = None) -> None:
    """Lay ``fig`` out tightly, write it to the PNG ``path`` atomically, and close it."""
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    pyplot().close(fig)


def _finish(fig: Any, ax: Any, xlabel: str, ylabel: str) -> bytes:
    """Label the axes, add the legend and grid, and return the figure as PNG bytes."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return _png(fig)


def _every(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def trajectories_png(ev: Evaluation) -> bytes:
    """Top-down ``x, y`` in ``map`` of truth, odometry, fused and baseline, m."""
    plt = pyplot()
    traj = ev.trajectories
    paths = {"truth": traj.T_map_base_truth, **traj.estimates()}
    fig, ax = plt.subplots(figsize=(10, 6.5), dpi=100)
    step = _every(len(traj.stamps_ns))
    for z, name in enumerate(("truth", "odometry", "baseline", "fused")):  # the estimate on top
        T_map_base = paths[name]
        if T_map_base is None:
            continue
        xy = np.asarray(T_map_base.translation)[step, :2]
        ax.plot(xy[:, 0], xy[:, 1], color=COLORS[name], label=name, linewidth=1.0, zorder=2 + z,
                linestyle="-" if name in ("truth", "fused") else "--")  # fmt: skip
    ax.set_aspect("equal")
    ax.set_xlabel("x in map (m)")
    ax.set_ylabel("y in map (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{ev.summary.name}: base trajectories, top-down")
    fig.tight_layout()
    return _png(fig)


def errors_over_time_png(ev: Evaluation) -> bytes:
    """Position error (m, log scale) and rotation error (deg) against time, per estimate."""
    plt = pyplot()
    traj = ev.trajectories
    t_s = (traj.stamps_ns - traj.stamps_ns[0]) * 1e-9
    step = _every(len(t_s))
    fig, (ax_m, ax_deg) = plt.subplots(2, 1, figsize=(10, 6.5), dpi=100, sharex=True)
    for name in ("odometry", "baseline", "fused"):
        errors = ev.errors[name]
        ax_m.semilogy(t_s[step], np.maximum(errors.translation_m[step], 1e-4),
                      color=COLORS[name], label=name, linewidth=0.8)  # fmt: skip
        ax_deg.plot(t_s[step], errors.rotation_deg[step], color=COLORS[name], linewidth=0.8)
    cfg = ev.summary.config
    ax_m.axhline(cfg.position_tol_m, color="k", linestyle=":", linewidth=0.8, label="X tolerance")
    ax_deg.axhline(cfg.rotation_tol_deg, color="k", linestyle=":", linewidth=0.8)
    for kidnap in ev.summary.kidnaps:
        for ax in (ax_m, ax_deg):
            ax.axvline((kidnap.kidnap_ns - traj.stamps_ns[0]) * 1e-9, color="tab:orange")
    ax_m.set_ylabel("position error (m)")
    ax_deg.set_ylabel("rotation error (deg)")
    ax_deg.set_xlabel("time (s)")
    ax_deg.set_yscale("symlog", linthresh=1.0)
    ax_deg.set_ylim(bottom=0.0)
    ax_m.legend(loc="upper left", fontsize=8)
    for ax in (ax_m, ax_deg):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return _png(fig)


def error_histogram_png(ev: Evaluation) -> bytes:
    """Histograms (log-spaced bins) of the fused and baseline position error, m."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 4), dpi=100)
    bins = np.logspace(-4, 1.5, 56)
    for name in ("baseline", "fused"):
        values = np.clip(ev.errors[name].translation_m, bins[0], bins[-1])
        ax.hist(values, bins=bins, color=COLORS[name], alpha=0.6, label=name)
    ax.axvline(ev.summary.config.position_tol_m, color="k", linestyle=":", label="X tolerance")
    ax.set_xscale("log")
    return _finish(fig, ax, "position error (m)", "odometry stamps")


def acceptance_png(ev: Evaluation) -> bytes:
    """Fraction of fix attempts accepted against range (m) and viewing angle (deg)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), dpi=100)
    tables = (
        (ev.summary.acceptance_vs_range, "range to tag (m)"),
        (ev.summary.acceptance_vs_angle, "viewing angle (deg)"),
    )
    for ax, (bins, label) in zip(axes, tables, strict=True):
        _acceptance_bars(ax, bins, label)
    fig.tight_layout()
    return _png(fig)


def _acceptance_bars(ax: Any, bins: list[AcceptanceBin], label: str) -> None:
    names = [f"{b.low:g}-{b.high:g}" if np.isfinite(b.high) else f">{b.low:g}" for b in bins]
    values = [0.0 if b.n_attempts == 0 else b.acceptance for b in bins]
    bars = ax.bar(names, values, color="tab:blue")
    for bar, b in zip(bars, bins, strict=True):
        ax.annotate(f"{b.n_accepted}/{b.n_attempts}", (bar.get_x() + bar.get_width() / 2,
                    bar.get_height()), ha="center", va="bottom", fontsize=7)  # fmt: skip
    ax.set_ylim(0, 1.12)
    ax.set_xlabel(label)
    ax.set_ylabel("accepted / attempts")
    ax.tick_params(axis="x", labelsize=7)
    ax.grid(True, axis="y", alpha=0.3)


def jumps_png(ev: Evaluation) -> bytes:
    """Per-step change of ``T_map_base`` caused by the correction (m), fused vs baseline."""
    plt = pyplot()
    traj = ev.trajectories
    t_s = (traj.stamps_ns[1:] - traj.stamps_ns[0]) * 1e-9
    fig, ax = plt.subplots(figsize=(10, 3.5), dpi=100)
    for name in ("baseline", "fused"):
        jump_m = ev.jumps[name].translation_m
        shown = jump_m > 1e-6
        ax.semilogy(t_s[shown], jump_m[shown], ".", markersize=2, color=COLORS[name], label=name)
    cap = ev.summary.cap_translation_m
    if np.isfinite(cap):
        ax.axhline(cap, color="k", linestyle=":", label="cap per update")
    return _finish(fig, ax, "time (s)", "correction jump (m)")


def ladder_png(ev: Evaluation) -> bytes:
    """The degradation ladder's level over the drive (1 best, 4 odometry only)."""
    assert ev.ladder_steps is not None
    t_s, level = ev.ladder_steps
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 2.2))
    ax.step(t_s, level, where="post", color="k")
    ax.set_ylim(4.5, 0.5)
    ax.set_yticks([1, 2, 3, 4], ["1 lidar", "2 markers carry", "3 markers alone", "4 odometry"])
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.17, bottom=0.25)
    return _png(fig)
