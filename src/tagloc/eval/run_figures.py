"""Figures of one run from plain series, shared by ``tagloc localize``'s and ``tagloc eval
bag``'s reports (matplotlib, Agg; each returned as PNG bytes).

The estimate is drawn over the truth (it is what the reader checks against the truth), the
odometry under both; colours as :data:`tagloc.eval.report_plots.COLORS`.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

import numpy as np

from tagloc.eval.report_plots import COLORS, pyplot

__all__ = ["Z_ORDER", "decisions_png", "ladder_png", "trajectory_png"]

#: Drawing order (higher on top): the estimate over the truth over the odometry.
Z_ORDER = {"odometry": 1, "baseline": 2, "truth": 3, "fused": 4}
LEVEL_NAMES = {1: "lidar nominal", 2: "markers carry", 3: "markers alone", 4: "odometry only"}


def _png(fig: Any) -> bytes:
    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png")
    pyplot().close(fig)
    return buffer.getvalue()


def trajectory_png(
    paths_xy: Mapping[str, np.ndarray], marks_xy: Mapping[str, np.ndarray] | None = None
) -> bytes:
    """Top-down paths (``name -> (N, 2)`` x, y in the map, m) and optional marks (``label ->
    (M, 2)``, e.g. stops), the estimate on top."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 6.5), dpi=100)
    for name in sorted(paths_xy, key=lambda n: Z_ORDER.get(n, 0)):
        xy = np.asarray(paths_xy[name])
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], color=COLORS.get(name, "k"), label=name,
                    linewidth=1.6 if name == "fused" else 1.0, zorder=Z_ORDER.get(name, 0),
                    linestyle="--" if name == "odometry" else "-")  # fmt: skip
    for label, xy in (marks_xy or {}).items():
        xy = np.asarray(xy)
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], "o", markersize=4, color="k", label=label, zorder=5)
    ax.set_aspect("equal")
    ax.set_xlabel("x in map (m)")
    ax.set_ylabel("y in map (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _png(fig)


def ladder_png(t_s: np.ndarray, level: np.ndarray) -> bytes:
    """The ladder level over stream time, a step function (1 best .. 4 odometry only)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 2.4), dpi=100)
    ax.step(t_s, level, where="post", color="tab:purple")
    ax.set_yticks(list(LEVEL_NAMES), list(LEVEL_NAMES.values()), fontsize=8)
    ax.set_ylim(4.4, 0.6)
    ax.set_xlabel("t (s)")
    ax.grid(True, alpha=0.3)
    return _png(fig)


def decisions_png(decisions: Mapping[str, int]) -> bytes:
    """Fix attempts by decision, accepted first, as horizontal bars."""
    plt = pyplot()
    items = sorted(decisions.items(), key=lambda kv: (kv[0] not in ("accepted", "initialized"),
                                                       -kv[1]))  # fmt: skip
    fig, ax = plt.subplots(figsize=(8, 0.4 * len(items) + 1.0), dpi=100)
    names = [k for k, _ in items]
    colors = ["tab:green" if k in ("accepted", "initialized") else "tab:red" for k in names]
    ax.barh(range(len(items)), [v for _, v in items], color=colors)
    ax.set_yticks(range(len(items)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("fix attempts")
    return _png(fig)
