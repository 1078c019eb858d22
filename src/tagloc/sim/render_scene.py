"""What the renderer draws: a :class:`Scene` built from a world (or from bare tag poses), and its
walls expressed in one camera view (:class:`ViewWalls`).

Walls are vertical rectangles over the floor segment ``start -> end`` up to ``height``; a ray
``t r`` (unit ``r``, optical frame) meets wall ``j`` where ``t = d_j / (n_j . r)``, at
``w = t (e_j . r) - w0_j`` along the wall and ``z = cam_z + t (up . r)`` above the floor; it hits
the wall when ``t > 0``, ``0 <= w <= length_j`` and ``0 <= z <= height_j``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.sim.render_geometry import Float32Array, polygon_bboxes
from tagloc.sim.world import World

#: Material codes.
WALL, GLASS, MIRROR = 0, 1, 2
_MATERIALS = {"wall": WALL, "glass": GLASS, "mirror": MIRROR}


@dataclass(frozen=True, slots=True)
class SceneTag:
    """One tag to draw: ``family``, ``tag_id``, black-border ``size`` (m) and pose in ``map``."""

    tag_id: int
    family: str
    size: float
    T_map_tag: SE3


@dataclass(frozen=True, slots=True)
class Scene:
    """Walls (M, as arrays), tags, and the floor/ceiling heights.

    Attributes
    ----------
    start_xy, end_xy : (M, 2) float
        Wall floor segments in ``map``.
    height : (M,) float
        Wall heights, m.
    material : (M,) int
        ``WALL``, ``GLASS`` or ``MIRROR``.
    tags : tuple of SceneTag
    ceiling_z : float or None
        Ceiling height (m); None for a scene without floor and ceiling (a flat backdrop).
    tag_rotation, tag_translation : (N, 3, 3), (N, 3) float
        ``T_map_tag`` of every tag as arrays (derived from ``tags``).
    """

    start_xy: FloatArray
    end_xy: FloatArray
    height: FloatArray
    material: npt.NDArray[np.int64]
    tags: tuple[SceneTag, ...]
    ceiling_z: float | None
    tag_rotation: FloatArray = field(init=False)
    tag_translation: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        rotation = [tag.T_map_tag.rotation.as_matrix() for tag in self.tags]
        translation = [tag.T_map_tag.translation for tag in self.tags]
        object.__setattr__(self, "tag_rotation", np.array(rotation).reshape(-1, 3, 3))
        object.__setattr__(self, "tag_translation", np.array(translation).reshape(-1, 3))

    @property
    def num_walls(self) -> int:
        """M."""
        return len(self.height)


def scene_from_world(world: World, ceiling_height_m: float | None = None) -> Scene:
    """The walls (building and elevator cab) and tags of ``world``, in ``map``.

    Parameters
    ----------
    world : World
    ceiling_height_m : float, optional
        Ceiling height; defaults to the tallest wall (2.5 m without walls).
    """
    walls = world.walls_in_map()
    heights = np.array([w.height for w in walls], dtype=np.float64)
    tags = tuple(SceneTag(tag.id, tag.family, tag.size, world.T_map_tag(tag)) for tag in world.tags)
    ceiling = ceiling_height_m if ceiling_height_m is not None else float(heights.max(initial=2.5))
    return Scene(
        start_xy=np.array([w.start for w in walls], dtype=np.float64).reshape(-1, 2),
        end_xy=np.array([w.end for w in walls], dtype=np.float64).reshape(-1, 2),
        height=heights,
        material=np.array([_MATERIALS[w.material] for w in walls], dtype=np.int64),
        tags=tags,
        ceiling_z=ceiling,
    )


def scene_of_tags(tags: list[tuple[int, float, SE3]], family: str) -> Scene:
    """Tags at given poses and nothing else (the frame ``map`` is the camera's frame here)."""
    return Scene(
        start_xy=np.zeros((0, 2)),
        end_xy=np.zeros((0, 2)),
        height=np.zeros(0),
        material=np.zeros(0, dtype=np.int64),
        tags=tuple(SceneTag(int(i), family, float(s), T) for i, s, T in tags),
        ceiling_z=None,
    )


@dataclass(frozen=True, slots=True)
class ViewWalls:
    """The walls of a scene seen from one camera pose (only those that can appear).

    Attributes
    ----------
    index : (K,) int
        Indices into the scene's walls, nearest first.
    normal, along : (K, 3) float32
        Wall normal and unit direction ``start -> end`` in the optical frame.
    d, w0 : (K,) float
        ``n . p`` and ``e . p`` of the wall's start point ``p`` in the optical frame.
    length, height : (K,) float
    material : (K,) int
    min_dist : (K,) float
        Distance from the camera to the nearest point of each wall, m.
    bbox : list of (x0, y0, x1, y1)
        Image pixels each wall can cover (end-exclusive).
    up : (3,) float32
        Map ``z`` in the optical frame; ``cam_z``: the camera's height above the floor.
    """

    index: npt.NDArray[np.int64]
    normal: Float32Array
    along: Float32Array
    d: FloatArray
    w0: FloatArray
    length: FloatArray
    height: FloatArray
    material: npt.NDArray[np.int64]
    min_dist: FloatArray
    bbox: list[tuple[int, int, int, int]]
    up: Float32Array
    cam_z: float

    def hits(self, k: int, r: Float32Array, rz_up: Float32Array) -> Float32Array:
        """Distance along unit rays ``r`` (3, ...) to wall ``k``; ``inf`` where they miss it.

        ``rz_up`` is ``up . r`` (passed in: every wall uses it).
        """
        n, e = self.normal[k], self.along[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.float32(self.d[k]) / (n[0] * r[0] + n[1] * r[1] + n[2] * r[2])
            w = t * (e[0] * r[0] + e[1] * r[1] + e[2] * r[2]) - np.float32(self.w0[k])
            z = np.float32(self.cam_z) + t * rz_up
            hit = (t > 0) & (w >= 0) & (w <= self.length[k]) & (z >= 0) & (z <= self.height[k])
        return np.asarray(np.where(hit, t, np.float32(np.inf)), dtype=np.float32)

    def along_wall(self, k: int, t: Float32Array, r: Float32Array) -> Float32Array:
        """Position along wall ``k`` (m from its start) of the points ``t r``."""
        e = self.along[k]
        w = t * (e[0] * r[0] + e[1] * r[1] + e[2] * r[2]) - np.float32(self.w0[k])
        return np.asarray(w, dtype=np.float32)


def view_walls(scene: Scene, camera: CameraModel, T_map_cam: SE3) -> ViewWalls:
    """Express the scene's walls in the camera frame; drop those that cannot appear in the image.

    Parameters
    ----------
    scene : Scene
    camera : CameraModel
    T_map_cam : SE3
        Camera pose.
    """
    T_cam_map = T_map_cam.inverse()
    R_cam_map = T_cam_map.rotation.as_matrix()
    cam_xyz = np.asarray(T_map_cam.translation, dtype=np.float64)
    # 1. cull: only walls whose rectangle projects into the image
    floor = np.zeros((scene.num_walls, 1))
    corners_map = np.stack(
        [
            np.hstack([scene.start_xy, floor]),
            np.hstack([scene.end_xy, floor]),
            np.hstack([scene.end_xy, scene.height[:, None]]),
            np.hstack([scene.start_xy, scene.height[:, None]]),
        ],
        axis=1,
    )  # (M, 4, 3)
    corners_cam = T_cam_map.act(corners_map.reshape(-1, 3)).reshape(-1, 4, 3)
    all_boxes = polygon_bboxes(camera, list(corners_cam))
    index = np.array([j for j, box in enumerate(all_boxes) if box is not None], dtype=np.int64)
    boxes = [box for box in all_boxes if box is not None]
    # 2. wall planes in the camera frame
    a, b = scene.start_xy[index], scene.end_xy[index]
    length = np.linalg.norm(b - a, axis=1)
    e_map = np.zeros((len(index), 3))
    e_map[:, :2] = (b - a) / length[:, None]
    n_map = np.stack([-e_map[:, 1], e_map[:, 0], np.zeros(len(index))], axis=1)
    start_cam = T_cam_map.act(np.column_stack([a, np.zeros(len(index))]).reshape(-1, 3))
    normal, along = n_map @ R_cam_map.T, e_map @ R_cam_map.T
    # Nearest point of each wall rectangle to the camera (clamp in wall coordinates).
    rel = cam_xyz[:2] - a
    s = np.clip(np.einsum("ij,ij->i", rel, e_map[:, :2]), 0.0, length)
    closest = np.column_stack(
        [a + s[:, None] * e_map[:, :2], np.clip(cam_xyz[2], 0.0, scene.height[index])]
    )
    min_dist = np.linalg.norm(closest - cam_xyz, axis=1)
    order = np.argsort(min_dist, kind="stable")
    return ViewWalls(
        index=index[order],
        normal=normal[order].astype(np.float32),
        along=along[order].astype(np.float32),
        d=np.einsum("ij,ij->i", normal, start_cam)[order],
        w0=np.einsum("ij,ij->i", along, start_cam)[order],
        length=length[order],
        height=scene.height[index][order],
        material=scene.material[index][order],
        min_dist=min_dist[order],
        bbox=[boxes[i] for i in order],
        up=R_cam_map[:, 2].astype(np.float32),
        cam_z=float(cam_xyz[2]),
    )
