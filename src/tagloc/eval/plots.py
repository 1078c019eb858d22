"""Plots of a world and of trajectories in it (matplotlib, Agg; written atomically)."""

from __future__ import annotations

import os

import numpy as np

from tagloc.fileutil import atomic_path
from tagloc.geometry import SE3
from tagloc.sim import World

_MATERIAL_STYLE = {
    "wall": {"color": "0.15", "linewidth": 2.0, "linestyle": "-"},
    "glass": {"color": "tab:cyan", "linewidth": 2.5, "linestyle": "-"},
    "mirror": {"color": "tab:purple", "linewidth": 2.5, "linestyle": "--"},
}


def plot_world_and_paths(
    world: World,
    paths: dict[str, SE3],
    path: str | os.PathLike[str],
    *,
    title: str = "",
) -> None:
    """Top-down plot of walls (by material), tags (face normal arrows, ids) and base paths.

    Parameters
    ----------
    world : World
        Floor plan and tags (drawn in ``map``).
    paths : dict of label -> SE3 batch
        Trajectories of ``base`` drawn in ``map`` (e.g. ``{"ground truth": T_map_base,
        "odometry": T_odom_base}``), in order; the first is drawn solid, the rest dashed.
    path : path-like
        Output image (PNG); written atomically.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(14, 8), dpi=110)
    # 1. walls, styled by material (one legend entry each)
    seen: set[str] = set()
    for wall in world.walls_in_map():
        style = _MATERIAL_STYLE[wall.material]
        label = wall.material if wall.material not in seen else None
        seen.add(wall.material)
        ax.plot(*np.array([wall.start, wall.end]).T, label=label, **style)  # type: ignore[arg-type]
    # 2. tags: a marker, the face normal, and the id
    for tag in world.tags:
        T_map_tag = world.T_map_tag(tag)
        position = np.asarray(T_map_tag.translation)
        normal = np.asarray(T_map_tag.rotation.as_matrix())[:, 2]
        ax.plot(position[0], position[1], "s", color="tab:orange", markersize=4)
        ax.arrow(
            position[0],
            position[1],
            0.6 * normal[0],
            0.6 * normal[1],
            width=0.02,
            color="tab:orange",
            length_includes_head=True,
        )
        label_xy = position[:2] + 0.9 * normal[:2]
        ax.annotate(
            str(tag.id),
            (float(label_xy[0]), float(label_xy[1])),
            fontsize=7,
            ha="center",
            va="center",
            color="tab:orange",
        )
    # 3. paths
    colors = ["tab:green", "tab:red", "tab:blue", "tab:gray"]
    for i, (name, T_map_base) in enumerate(paths.items()):
        xy = np.asarray(T_map_base.translation)[:, :2]
        ax.plot(
            xy[:, 0],
            xy[:, 1],
            color=colors[i % len(colors)],
            linewidth=1.2,
            linestyle="-" if i == 0 else "--",
            label=name,
        )
        ax.plot(*xy[0], "o", color=colors[i % len(colors)])
        ax.plot(*xy[-1], "x", color=colors[i % len(colors)], markersize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x in map (m)")
    ax.set_ylabel("y in map (m)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_title(title or world.name)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
