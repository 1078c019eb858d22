"""Plots of a world and of trajectories in it (matplotlib, Agg; written atomically).

The drive picture (:func:`world_figure`, written by :func:`plot_world_and_paths`): a flat world in
one panel; a building in one panel per floor the drive visited, each with that floor's walls and
tags and the part of each path on that floor.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from tagloc._types import FloatArray
from tagloc.fileutil import atomic_path
from tagloc.geometry import SE3
from tagloc.sim import World
from tagloc.sim.world_parts import Tag, Wall
from tagloc.tags.tagmap import TagMap

_MATERIAL_STYLE = {
    "wall": {"color": "0.15", "linewidth": 2.0, "linestyle": "-"},
    "glass": {"color": "tab:cyan", "linewidth": 2.5, "linestyle": "-"},
    "mirror": {"color": "tab:purple", "linewidth": 2.5, "linestyle": "--"},
}


#: A path's sample is on a floor when its z is within this of the floor's height, m (in a
#: moving cab it is on none).
ON_FLOOR_M = 0.05
#: A stretch on a floor moving less than this in x, y (and at neither end of the path) is a cab
#: passing the floor, m.
MIN_STRETCH_M = 0.05
_PATH_COLORS = ["tab:green", "tab:red", "tab:blue", "tab:gray"]


def plot_world_and_paths(
    world: World,
    paths: dict[str, SE3],
    path: str | os.PathLike[str],
    *,
    title: str = "",
    tag_map: TagMap | None = None,
) -> None:
    """Top-down plot of walls (by material), tags (face normal arrows, ids) and base paths:
    :func:`world_figure` written to ``path`` (PNG, atomically)."""
    import matplotlib.pyplot as plt

    fig = world_figure(world, paths, title=title, tag_map=tag_map)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def world_figure(
    world: World,
    paths: dict[str, SE3],
    *,
    title: str = "",
    tag_map: TagMap | None = None,
) -> Any:
    """The top-down picture of a drive: one panel for a flat world, one per floor visited for a
    building (each titled ``floor <name>``, with that floor's walls and tags, the cabs' walls and
    tags, and the samples of each path on that floor).

    Parameters
    ----------
    world : World
        Floor plan and tags (drawn in ``map``).
    paths : dict of label -> SE3 batch
        Trajectories of ``base`` drawn in ``map`` (e.g. ``{"ground truth": T_map_base,
        "odometry": T_odom_base}``), in order; the first is drawn solid, the rest dashed. In a
        building the first path tells the floor of each sample (its z within ``ON_FLOOR_M`` of
        the floor's height; in a moving cab, or passing a floor in one: none), and every path
        must have its length.
    title : str
    tag_map : TagMap, optional
        A built map: its ``map``-frame tags drawn beside the true ones (a line from the truth),
        with the 2-sigma ellipse of each tag's horizontal position where it has a covariance.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        In a building, a path whose length is not the first path's.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xy = {name: np.asarray(T.translation)[:, :2] for name, T in paths.items()}
    if not world.has_floors:
        fig, ax = plt.subplots(figsize=(14, 8), dpi=110)
        _draw_panel(ax, world.walls_in_map(), list(world.tags), world, xy, tag_map, True)
        ax.set_title(title or world.name)
        return fig
    floor_of = _floor_of_samples(world, paths)
    cab_tags = [t for t in world.tags if t.frame != "map"]
    visited = [f for f in world.all_floors() if np.any(floor_of == f.name)]
    n = max(len(visited), 1)
    fig, axes = plt.subplots(1, n, figsize=(7.5 * n, 6.5), dpi=110, squeeze=False)
    for ax, floor in zip(axes[0], visited, strict=False):
        on = floor_of == floor.name
        mine = {name: np.where(on[:, None], v, np.nan) for name, v in xy.items()}
        _draw_panel(ax, world.walls_in_map(floor.name), [*floor.tags, *cab_tags], world, mine,
                    tag_map, False)  # fmt: skip
        ax.set_title(f"floor {floor.name}")
    legend: dict[str, Any] = {}  # every panel's entries, once (the cab's walls: its floor's)
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            legend.setdefault(label, handle)
    axes[0][-1].legend(list(legend.values()), list(legend), loc="upper left",
                       bbox_to_anchor=(1.01, 1.0), fontsize=8)  # fmt: skip
    fig.suptitle(title or world.name)
    return fig


def _floor_of_samples(world: World, paths: dict[str, SE3]) -> np.ndarray:
    """The floor's name of each sample of the first path (``""``: on none). A sample is on a
    floor when its z is within ``ON_FLOOR_M`` of the floor's height; a stretch of such samples
    that does not move in x, y (``MIN_STRETCH_M``) and holds neither end of the path is a cab
    passing the floor, on none."""
    first = next(iter(paths.values()), None)
    if first is None:
        return np.zeros(0, dtype=object)
    for name, T in paths.items():
        if len(T) != len(first):
            raise ValueError(f"path {name!r} has {len(T)} samples, the first path {len(first)}: "
                             "in a building every path needs the first's samples")  # fmt: skip
    p = np.asarray(first.translation)
    out = np.full(len(p), "", dtype=object)
    for floor in world.all_floors():
        out[np.abs(p[:, 2] - floor.height_m) <= ON_FLOOR_M] = floor.name
    cuts = np.flatnonzero(out[1:] != out[:-1]) + 1
    for lo, hi in itertools.pairwise([0, *cuts.tolist(), len(out)]):
        moved = float(np.sum(np.linalg.norm(np.diff(p[lo:hi, :2], axis=0), axis=1)))
        if out[lo] and moved < MIN_STRETCH_M and lo > 0 and hi < len(out):
            out[lo:hi] = ""
    return out


def _draw_panel(
    ax: Any, walls: Sequence[Wall], tags: Sequence[Tag], world: World,
    paths_xy: dict[str, np.ndarray], tag_map: TagMap | None, legend: bool,
) -> None:  # fmt: skip
    """Walls by material, tags (marker, face normal, id), the built map's tags, the paths (NaN
    rows are not drawn), a start dot and an end cross where a path's first or last sample is."""
    seen: set[str] = set()
    for wall in walls:
        style = _MATERIAL_STYLE[wall.material]
        label = wall.material if wall.material not in seen else None
        seen.add(wall.material)
        ax.plot(*np.array([wall.start, wall.end]).T, label=label, **style)
    for tag in tags:
        T_map_tag = world.T_map_tag(tag)
        position = np.asarray(T_map_tag.translation)
        normal = np.asarray(T_map_tag.rotation.as_matrix())[:, 2]
        ax.plot(position[0], position[1], "s", color="tab:orange", markersize=4)
        ax.arrow(position[0], position[1], 0.6 * normal[0], 0.6 * normal[1], width=0.02,
                 color="tab:orange", length_includes_head=True)  # fmt: skip
        label_xy = position[:2] + 0.9 * normal[:2]
        ax.annotate(str(tag.id), (float(label_xy[0]), float(label_xy[1])), fontsize=7,
                    ha="center", va="center", color="tab:orange")  # fmt: skip
    if tag_map is not None:
        _draw_built_tags(ax, tag_map, world, {(t.family, t.id) for t in tags})
    for i, (name, xy) in enumerate(paths_xy.items()):
        color = _PATH_COLORS[i % len(_PATH_COLORS)]
        ax.plot(xy[:, 0], xy[:, 1], color=color, linewidth=1.2,
                linestyle="-" if i == 0 else "--", label=name)  # fmt: skip
        if len(xy) and np.isfinite(xy[0]).all():
            ax.plot(*xy[0], "o", color=color)
        if len(xy) and np.isfinite(xy[-1]).all():
            ax.plot(*xy[-1], "x", color=color, markersize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x in map (m)")
    ax.set_ylabel("y in map (m)")
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)


def ellipse_2sigma(cov_xy: FloatArray) -> tuple[float, float, float]:
    """``(width, height, angle_deg)`` of the 2-sigma ellipse of a ``(2, 2)`` covariance: full
    axes (m), the first along the larger eigenvector, at ``angle_deg`` from x."""
    values, vectors = np.linalg.eigh(np.asarray(cov_xy, dtype=np.float64))
    major = vectors[:, 1]
    width, height = 4.0 * np.sqrt(np.maximum(values[::-1], 0.0))
    return float(width), float(height), float(np.degrees(np.arctan2(major[1], major[0])))


def _draw_built_tags(
    ax: Any, tag_map: TagMap, world: World, keys: set[tuple[str, int]] | None = None
) -> None:
    """Built tags (blue crosses), a line from each true tag, 2-sigma ellipses (``keys``: only
    the built tags of these true tags)."""
    from matplotlib.patches import Ellipse

    truth = {(t.family, t.id): world.T_map_tag(t) for t, _ in world.all_tags()}
    first = True
    for entry in tag_map.in_frame("map"):
        if keys is not None and world.has_floors and entry.key not in keys:
            continue
        T = entry.T_frame_tag()
        p = np.asarray(T.translation)
        label = "built map (2-sigma)" if first else None
        ax.plot(p[0], p[1], "+", color="tab:blue", markersize=7, label=label)
        first = False
        if entry.key in truth:
            q = np.asarray(truth[entry.key].translation)
            ax.plot([q[0], p[0]], [q[1], p[1]], color="tab:blue", linewidth=0.8)
        cov = entry.covariance_matrix()
        if cov is not None:
            R = np.asarray(T.rotation.as_matrix())
            width, height, angle = ellipse_2sigma((R @ cov[:3, :3] @ R.T)[:2, :2])
            ax.add_patch(
                Ellipse((p[0], p[1]), width, height, angle=angle, fill=False, color="tab:blue")
            )
