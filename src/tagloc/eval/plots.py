"""Plots of a world and of trajectories in it (matplotlib, Agg; written atomically)."""

from __future__ import annotations

import os

import numpy as np

from tagloc._types import FloatArray
from tagloc.fileutil import atomic_path
from tagloc.geometry import SE3
from tagloc.sim import World
from tagloc.tags.tagmap import TagMap

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
    tag_map: TagMap | None = None,
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
    title : str
    tag_map : TagMap, optional
        A built map: its ``map``-frame tags drawn beside the true ones (a line from the truth),
        with the 2-sigma ellipse of each tag's horizontal position where it has a covariance.
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
    if tag_map is not None:
        _draw_built_tags(ax, tag_map, world)
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


def ellipse_2sigma(cov_xy: FloatArray) -> tuple[float, float, float]:
    """``(width, height, angle_deg)`` of the 2-sigma ellipse of a ``(2, 2)`` covariance: full
    axes (m), the first along the larger eigenvector, at ``angle_deg`` from x."""
    values, vectors = np.linalg.eigh(np.asarray(cov_xy, dtype=np.float64))
    major = vectors[:, 1]
    width, height = 4.0 * np.sqrt(np.maximum(values[::-1], 0.0))
    return float(width), float(height), float(np.degrees(np.arctan2(major[1], major[0])))


def _draw_built_tags(ax: object, tag_map: TagMap, world: World) -> None:
    """Built tags (blue crosses), a line from each true tag, 2-sigma ellipses."""
    from matplotlib.patches import Ellipse

    truth = {(t.family, t.id): world.T_map_tag(t) for t in world.tags}
    first = True
    for entry in tag_map.in_frame("map"):
        T = entry.T_frame_tag()
        p = np.asarray(T.translation)
        label = "built map (2-sigma)" if first else None
        ax.plot(p[0], p[1], "+", color="tab:blue", markersize=7, label=label)  # type: ignore[attr-defined]
        first = False
        if entry.key in truth:
            q = np.asarray(truth[entry.key].translation)
            ax.plot([q[0], p[0]], [q[1], p[1]], color="tab:blue", linewidth=0.8)  # type: ignore[attr-defined]
        cov = entry.covariance_matrix()
        if cov is not None:
            R = np.asarray(T.rotation.as_matrix())
            width, height, angle = ellipse_2sigma((R @ cov[:3, :3] @ R.T)[:2, :2])
            ax.add_patch(  # type: ignore[attr-defined]
                Ellipse((p[0], p[1]), width, height, angle=angle, fill=False, color="tab:blue")
            )
