"""Corner-level tag observations of a simulated drive: what a detector reports, without images.

Rendering images (:mod:`tagloc.sim.render`) costs 10-25 ms a frame; surveys, localization
scenarios and their tests need tens of thousands of frames. This module produces the same
:class:`~tagloc.tags.TagDetection` stream analytically: for each camera frame, every tag that

- faces the camera (its printed side toward it) within ``max_view_angle_deg``,
- lies within ``max_range_m``,
- projects with all four corners inside the image (``margin_px``) and at least ``min_side_px``
  on its shortest side,
- is not hidden by an opaque wall (``wall`` or ``mirror``; ``glass`` is transparent): the
  segments from the camera to the tag's centre and corners, on the floor plan, cross no wall,

is detected (with probability ``detection_probability``) with its true corners plus Gaussian
pixel noise ``pixel_sigma_px`` (per coordinate). Injected false detections ("glints", at
``glint_rate`` per frame, Poisson) come in two kinds, both decoding as an id that exists in the
world: ``wrong_id`` (a true tag's corners reported under another id) and ``wrong_corners`` (a
random quad, 20-120 px across, somewhere in the image). Every frame carries its ground truth.

Pure and reproducible: frame ``stamp`` draws from ``SeedSequence([seed, stamp])``, so a frame's
noise does not depend on which other frames are simulated.

Example
-------
>>> from tagloc.sim import load_default_world, simulate_drive, simulate_observations
>>> drive = simulate_drive(load_default_world(), seed=0)                  # doctest: +SKIP
>>> for frame in simulate_observations(drive):                            # doctest: +SKIP
...     frame.stamp_ns, [d.tag_id for d in frame.detections]
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import Field

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.config import StrictModel
from tagloc.geometry import SE3
from tagloc.sim.drive import Drive
from tagloc.sim.floor_scene import SceneCache
from tagloc.sim.people import people_xy
from tagloc.sim.ride import RidePlan
from tagloc.sim.world import Tag, Wall, World
from tagloc.tags.detection import TagDetection, is_convex_clockwise, tag_object_points

__all__ = [
    "ObservationConfig",
    "ObservedFrame",
    "TagSighting",
    "simulate_observations",
    "visible_tags",
]


#: Ground truth is sampled for this many frames at a time.
_CHUNK = 256
#: Sight lines end this far in front of the tag's wall so the tag's own wall does not hide it.
_WALL_CLEARANCE_M = 0.02


class ObservationConfig(StrictModel):
    """How the simulated detector sees tags (see the module docstring)."""

    pixel_sigma_px: float = Field(default=0.3, ge=0.0, description="corner noise, px per axis")
    max_range_m: float = Field(default=8.0, gt=0.0)
    max_view_angle_deg: float = Field(default=75.0, gt=0.0, le=90.0)
    min_side_px: float = Field(default=10.0, ge=0.0)
    margin_px: float = Field(default=2.0, ge=0.0)
    detection_probability: float = Field(default=1.0, ge=0.0, le=1.0)
    glint_rate: float = Field(default=0.0, ge=0.0, description="false detections per frame")
    glint_wrong_id_fraction: float = Field(default=0.5, ge=0.0, le=1.0)
    seed: int = 0


@dataclass(frozen=True, slots=True, eq=False)
class TagSighting:
    """Ground truth of one tag truly in view (detected or missed).

    Attributes
    ----------
    tag_id, family, size :
        The tag (size: black-border edge, m).
    T_cam_tag : SE3
        True pose of the tag in the camera's optical frame.
    corners_px : (4, 2) float
        True corners, tagloc order (top-left, top-right, bottom-right, bottom-left).
    range_m : float
        Camera centre to tag centre, m.
    view_angle_rad : float
        Angle between the tag's normal and the line of sight to the camera (0 = head-on).
    detected : bool
        Whether the simulated detector reported it.
    """

    tag_id: int
    family: str
    size: float
    T_cam_tag: SE3
    corners_px: FloatArray
    range_m: float
    view_angle_rad: float
    detected: bool


@dataclass(frozen=True, slots=True, eq=False)
class ObservedFrame:
    """One camera frame: detections as a detector would report them, and the truth.

    Attributes
    ----------
    stamp_ns : int
    detections : tuple of TagDetection
        True detections (noisy corners) followed by any injected false ones.
    false_detection : tuple of bool
        Per detection: True if it was injected (a glint), False if it is a real tag.
    truth : tuple of TagSighting
        Every tag truly in view by the rules of the module docstring.
    T_map_cam : SE3
        True camera pose.
    T_map_base : SE3
        True base pose.
    """

    stamp_ns: int
    detections: tuple[TagDetection, ...]
    false_detection: tuple[bool, ...]
    truth: tuple[TagSighting, ...]
    T_map_cam: SE3
    T_map_base: SE3


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


def simulate_observations(
    drive: Drive,
    config: ObservationConfig | None = None,
    *,
    camera_model: CameraModel | None = None,
    stamps_ns: npt.ArrayLike | None = None,
    world: World | None = None,
) -> Iterator[ObservedFrame]:
    """The tag detections of every camera frame of ``drive`` (a lazy iterator, stamp order).

    Parameters
    ----------
    drive : Drive
    config : ObservationConfig, optional
    camera_model : CameraModel, optional
        Defaults to the world's robot camera, mounted at ``world.robot.camera.T_base_cam``.
    stamps_ns : (M,) int array_like, optional
        Frame stamps (default ``drive.camera_stamps_ns``).
    world : World, optional
        The world the tags are really in (default ``drive.world``); pass a world with a moved tag
        to simulate a map that is out of date.
    """
    config = config or ObservationConfig()
    world = world if world is not None else drive.world
    camera = camera_model if camera_model is not None else world.robot.camera.camera_model()
    stamps = drive.camera_stamps_ns if stamps_ns is None else np.asarray(stamps_ns, np.int64)
    T_base_cam = world.robot.camera.T_base_cam.T_base_cam()
    if isinstance(drive.plan, RidePlan):
        return _floor_frames(drive, world, camera, config, stamps, T_base_cam)
    return _frames(drive, _world_tags(world), camera, config, stamps, T_base_cam)


def _floor_frames(
    drive: Drive,
    world: World,
    camera: CameraModel,
    config: ObservationConfig,
    stamps: npt.NDArray[np.int64],
    T_base_cam: SE3,
) -> Iterator[ObservedFrame]:
    """:func:`_frames` in a building: each frame sees the scene of its instant
    (:mod:`tagloc.sim.floor_scene`), people included."""
    assert isinstance(drive.plan, RidePlan)
    scenes = SceneCache(world, drive.plan)
    arrays: dict[tuple[object, ...], _WorldTags] = {}
    for start in range(0, len(stamps), _CHUNK):
        chunk = stamps[start : start + _CHUNK]
        truth = drive.ground_truth_at(chunk)
        route_s = drive.route_s(chunk)
        for k, stamp in enumerate(chunk):
            scene = scenes.at(float(route_s[k]), truth.xy_yaw_map_base[k, :2])
            tags = arrays.get(scene.key) if scene.floor is not None else None
            if tags is None:
                tags = _tags_in([t for t, _ in scene.tags], [T for _, T in scene.tags],
                                scene.walls)  # fmt: skip
                if scene.floor is not None:
                    arrays[scene.key] = tags
            occluders = None
            if scene.people:
                xy = people_xy([p.waypoints() for p in scene.people], route_s[k : k + 1])[0]
                radius = np.array([p.radius_m for p in scene.people])
                occluders = np.column_stack([xy, radius])
            T_map_base = truth.T_map_base[k]
            T_map_cam = T_map_base @ T_base_cam
            rng = np.random.default_rng(np.random.SeedSequence([config.seed, int(stamp) % 2**63]))
            yield _frame(int(stamp), tags, camera, config, T_map_base, T_map_cam, rng, occluders)


def _frames(
    drive: Drive,
    tags: _WorldTags,
    camera: CameraModel,
    config: ObservationConfig,
    stamps: npt.NDArray[np.int64],
    T_base_cam: SE3,
) -> Iterator[ObservedFrame]:
    for start in range(0, len(stamps), _CHUNK):
        chunk = stamps[start : start + _CHUNK]
        truth = drive.ground_truth_at(chunk)
        for k, stamp in enumerate(chunk):
            T_map_base = truth.T_map_base[k]
            T_map_cam = T_map_base @ T_base_cam
            rng = np.random.default_rng(np.random.SeedSequence([config.seed, int(stamp) % 2**63]))
            yield _frame(int(stamp), tags, camera, config, T_map_base, T_map_cam, rng)


def _frame(
    stamp: int,
    tags: _WorldTags,
    camera: CameraModel,
    config: ObservationConfig,
    T_map_base: SE3,
    T_map_cam: SE3,
    rng: np.random.Generator,
    occluders: FloatArray | None = None,
) -> ObservedFrame:
    detections: list[TagDetection] = []
    sightings: list[TagSighting] = []
    seen = visible_tags(tags, camera, T_map_cam, config, occluders)
    for i, T_cam_tag, corners, range_m, angle in seen:
        detected = bool(rng.random() < config.detection_probability)
        noisy = corners + rng.normal(0.0, config.pixel_sigma_px, size=(4, 2))
        if detected:
            detections.append(
                TagDetection(
                    tag_id=tags.ids[i],
                    family=tags.families[i],
                    corners_px=noisy,
                    hamming=0,
                    decision_margin=float(rng.uniform(40.0, 120.0)),
                )
            )
        sightings.append(
            TagSighting(
                tags.ids[i],
                tags.families[i],
                float(tags.sizes[i]),
                T_cam_tag,
                corners,
                range_m,
                angle,
                detected,
            )
        )
    n_true = len(detections)
    for _ in range(int(rng.poisson(config.glint_rate)) if len(tags.ids) > 1 else 0):
        detections.append(_glint(detections[:n_true], tags, camera, config, rng))
    flags = (False,) * n_true + (True,) * (len(detections) - n_true)
    return ObservedFrame(stamp, tuple(detections), flags, tuple(sightings), T_map_cam, T_map_base)


def _glint(
    real: list[TagDetection],
    tags: _WorldTags,
    camera: CameraModel,
    config: ObservationConfig,
    rng: np.random.Generator,
) -> TagDetection:
    """A false detection that decodes as an existing id (see the module docstring)."""
    if real and rng.random() < config.glint_wrong_id_fraction:
        source = real[int(rng.integers(len(real)))]
        others = [j for j, tag_id in enumerate(tags.ids) if tag_id != source.tag_id]
        j = others[int(rng.integers(len(others)))]
        corners = source.corners_px
    else:
        j = int(rng.integers(len(tags.ids)))
        side = rng.uniform(20.0, 120.0)
        center = rng.uniform([side, side], [camera.width - side, camera.height - side])
        square = 0.5 * side * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        corners = center + square
        for _ in range(20):  # a detector only reports convex, clockwise quads: draw one
            jittered = corners + rng.normal(0.0, 0.15 * side, size=(4, 2))
            if is_convex_clockwise(jittered):
                corners = jittered
                break
    return TagDetection(
        tag_id=tags.ids[j],
        family=tags.families[j],
        corners_px=np.array(corners, dtype=float),
        hamming=int(rng.integers(0, 3)),
        decision_margin=float(rng.uniform(20.0, 80.0)),
    )
