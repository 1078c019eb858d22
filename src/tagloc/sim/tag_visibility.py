"""Which tags a camera sees: facing it within the view angle, in range, projecting inside the
image and large enough, and not hidden by an opaque wall or a person (the rules of
:mod:`tagloc.sim.observations`), over the tags of a world as arrays."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.sim.observation_config import ObservationConfig
from tagloc.sim.world import Tag, Wall, World
from tagloc.tags.detection import tag_object_points

__all__ = ["visible_tags"]

#: Sight lines end this far in front of the tag's wall so the tag's own wall does not hide it.
_WALL_CLEARANCE_M = 0.02


@dataclass(frozen=True, slots=True)
class _WorldTags:
    ids: tuple[int, ...]
    families: tuple[str, ...]
    sizes: FloatArray  # (N,)
    T_map_tag: tuple[SE3, ...]
    R: FloatArray  # (N, 3, 3) R_map_tag
    t: FloatArray  # (N, 3) t_map_tag
    corners_map: FloatArray  # (N, 4, 3)
    opaque: FloatArray  # (W, 2, 2) opaque wall segments on the floor plan


def _world_tags(world: World) -> _WorldTags:
    poses = tuple(world.T_map_tag(tag) for tag in world.tags)
    return _tags_in(world.tags, poses, world.walls_in_map())


def _tags_in(tags: Sequence[Tag], poses: Sequence[SE3], all_walls: Sequence[Wall]) -> _WorldTags:
    """The arrays of ``tags`` at ``poses`` (``T_map_tag``) among ``all_walls``."""
    corners = [T.act(tag_object_points(tag.size)) for T, tag in zip(poses, tags, strict=True)]
    walls = [w for w in all_walls if w.material != "glass"]
    return _WorldTags(
        ids=tuple(tag.id for tag in tags),
        families=tuple(tag.family for tag in tags),
        sizes=np.array([tag.size for tag in tags], dtype=float),
        T_map_tag=tuple(poses),
        R=np.array([T.rotation.as_matrix() for T in poses]).reshape(-1, 3, 3),
        t=np.array([T.translation for T in poses], dtype=float).reshape(-1, 3),
        corners_map=np.array(corners, dtype=float).reshape(-1, 4, 3),
        opaque=np.array([[w.start, w.end] for w in walls], dtype=float).reshape(-1, 2, 2),
    )


def _segments_blocked(
    origin: FloatArray, ends: FloatArray, walls: FloatArray
) -> npt.NDArray[np.bool_]:
    """For each end (M, 2): does the segment ``origin -> end`` properly cross any wall (W, 2, 2)?"""
    if len(walls) == 0 or len(ends) == 0:
        return np.zeros(len(ends), dtype=bool)
    p = origin[None, None, :]
    r = ends[:, None, :] - p  # (M, 1, 2)
    q = walls[None, :, 0, :]  # (1, W, 2)
    s = walls[None, :, 1, :] - q
    denom = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]  # (M, W)
    qp = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (qp[..., 0] * s[..., 1] - qp[..., 1] * s[..., 0]) / denom  # along the sight line
        v = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / denom  # along the wall
    hit = (np.abs(denom) > 1e-12) & (u > 0.0) & (u < 1.0) & (v >= 0.0) & (v <= 1.0)
    return np.asarray(hit.any(axis=1))


def _circles_block(origin: FloatArray, ends: FloatArray, circles: FloatArray) -> bool:
    """Does any segment ``origin -> end`` pass through any circle ``[x, y, r]``?"""
    if len(circles) == 0:
        return False
    d = ends - origin  # (M, 2)
    rel = circles[None, :, :2] - origin  # (1, P, 2)
    u = np.clip(np.einsum("mi,mpi->mp", d, rel) / np.maximum((d * d).sum(1), 1e-12)[:, None], 0, 1)
    closest = origin + u[..., None] * d[:, None, :]
    gap = np.linalg.norm(closest - circles[None, :, :2], axis=2)
    return bool((gap < circles[None, :, 2]).any())


def visible_tags(
    world_tags: _WorldTags,
    camera: CameraModel,
    T_map_cam: SE3,
    config: ObservationConfig,
    occluders: FloatArray | None = None,
) -> list[tuple[int, SE3, FloatArray, float, float]]:
    """Tags in view from ``T_map_cam``: ``(index, T_cam_tag, corners_px, range_m, angle_rad)``.

    ``occluders`` (P, 3) ``[x, y, radius]``: upright cylinders (people) that hide a tag when a
    sight line passes through one (planar, as walls)."""
    if len(world_tags.ids) == 0:
        return []
    T_cam_map = T_map_cam.inverse()
    R_cam_map = T_cam_map.rotation.as_matrix()
    t_cam_map = np.asarray(T_cam_map.translation)
    cam_in_map = np.asarray(T_map_cam.translation)
    to_cam = cam_in_map[None, :] - world_tags.t  # (N, 3) tag -> camera, map frame
    rng_m = np.linalg.norm(to_cam, axis=1)
    cos_view = np.einsum("ni,ni->n", world_tags.R[:, :, 2], to_cam) / np.maximum(rng_m, 1e-12)
    candidates = np.flatnonzero(
        (rng_m <= config.max_range_m)
        & (rng_m > 1e-3)
        & (cos_view >= math.cos(math.radians(config.max_view_angle_deg)))
    )
    if len(candidates) == 0:
        return []
    corners_cam = world_tags.corners_map[candidates] @ R_cam_map.T + t_cam_map  # (C, 4, 3)
    in_front = (corners_cam[..., 2] > 0.05).all(axis=1)
    px = camera.project(corners_cam.reshape(-1, 3)).reshape(-1, 4, 2)
    inside = camera.in_image(px.reshape(-1, 2), margin=config.margin_px).reshape(-1, 4).all(axis=1)
    sides = np.linalg.norm(px - np.roll(px, -1, axis=1), axis=2).min(axis=1)
    keep = in_front & inside & np.isfinite(px).all(axis=(1, 2)) & (sides >= config.min_side_px)
    result: list[tuple[int, SE3, FloatArray, float, float]] = []
    for c in np.flatnonzero(keep):
        i = int(candidates[c])
        normal = world_tags.R[i][:, 2]
        ends = np.vstack([world_tags.corners_map[i], world_tags.t[i][None, :]])
        ends = ends + _WALL_CLEARANCE_M * normal[None, :]
        if _segments_blocked(cam_in_map[:2], ends[:, :2], world_tags.opaque).any():
            continue
        if occluders is not None and _circles_block(cam_in_map[:2], ends[:, :2], occluders):
            continue
        T_cam_tag = T_cam_map @ world_tags.T_map_tag[i]
        angle = math.acos(min(1.0, float(cos_view[i])))
        result.append((i, T_cam_tag, px[c], float(rng_m[i]), angle))
    return result
