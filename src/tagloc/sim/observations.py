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
noise does not depend on which other frames are simulated. The visibility rules are
:mod:`tagloc.sim.tag_visibility`'s, the configuration :mod:`tagloc.sim.observation_config`'s.

Example
-------
>>> from tagloc.sim import load_default_world, simulate_drive, simulate_observations
>>> drive = simulate_drive(load_default_world(), seed=0)                  # doctest: +SKIP
>>> for frame in simulate_observations(drive):                            # doctest: +SKIP
...     frame.stamp_ns, [d.tag_id for d in frame.detections]
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.sim.drive import Drive
from tagloc.sim.floor_scene import SceneCache
from tagloc.sim.observation_config import ObservationConfig
from tagloc.sim.people import people_xy
from tagloc.sim.ride import RidePlan
from tagloc.sim.tag_visibility import _tags_in, _world_tags, _WorldTags, visible_tags
from tagloc.sim.world import World
from tagloc.tags.detection import TagDetection, is_convex_clockwise

__all__ = [
    "ObservationConfig",
    "ObservedFrame",
    "TagSighting",
    "simulate_observations",
    "visible_tags",
]


#: Ground truth is sampled for this many frames at a time.
_CHUNK = 256


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
        return _frames(drive, _FloorTags(world, drive.plan), camera, config, stamps, T_base_cam)
    return _frames(drive, _world_tags(world), camera, config, stamps, T_base_cam)


class _FloorTags:
    """The tags a frame sees in a building: the scene of its instant
    (:mod:`tagloc.sim.floor_scene`), people included; each floor's arrays made once."""

    def __init__(self, world: World, plan: RidePlan) -> None:
        self.scenes = SceneCache(world, plan)
        self.arrays: dict[tuple[object, ...], _WorldTags] = {}

    def at(
        self, route_s: npt.NDArray[np.float64], xy_map_base: FloatArray
    ) -> tuple[_WorldTags, FloatArray | None]:
        """The tags and the occluders (``[x, y, radius]`` rows, or None) at route time
        ``route_s`` (1,), the robot at ``xy_map_base``."""
        scene = self.scenes.at(float(route_s[0]), xy_map_base)
        tags = self.arrays.get(scene.key) if scene.floor is not None else None
        if tags is None:
            tags = _tags_in([t for t, _ in scene.tags], [T for _, T in scene.tags],
                            scene.walls)  # fmt: skip
            if scene.floor is not None:
                self.arrays[scene.key] = tags
        occluders = None
        if scene.people:
            xy = people_xy([p.waypoints() for p in scene.people], route_s)[0]
            radius = np.array([p.radius_m for p in scene.people])
            occluders = np.column_stack([xy, radius])
        return tags, occluders


def _frames(
    drive: Drive,
    tags: _WorldTags | _FloorTags,
    camera: CameraModel,
    config: ObservationConfig,
    stamps: npt.NDArray[np.int64],
    T_base_cam: SE3,
) -> Iterator[ObservedFrame]:
    """The frames at ``stamps``, seeing the world's ``tags`` or, in a building, those of the
    frame's instant."""
    for start in range(0, len(stamps), _CHUNK):
        chunk = stamps[start : start + _CHUNK]
        truth = drive.ground_truth_at(chunk)
        route_s = drive.route_s(chunk) if isinstance(tags, _FloorTags) else None
        for k, stamp in enumerate(chunk):
            if isinstance(tags, _FloorTags):
                assert route_s is not None
                seen, occluders = tags.at(route_s[k : k + 1], truth.xy_yaw_map_base[k, :2])
            else:
                seen, occluders = tags, None
            T_map_base = truth.T_map_base[k]
            T_map_cam = T_map_base @ T_base_cam
            rng = np.random.default_rng(np.random.SeedSequence([config.seed, int(stamp) % 2**63]))
            yield _frame(int(stamp), seen, camera, config, T_map_base, T_map_cam, rng, occluders)


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
