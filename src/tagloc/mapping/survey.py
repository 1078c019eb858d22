"""The input of the map builder: a survey drive (odometry + tag detections per camera frame).

A :class:`Survey` is plain data, independent of where it came from (the simulator,
:mod:`tagloc.sim.survey`; a recorded bag, :mod:`tagloc.mapping.stream_survey`):

- odometry ``T_odom_base`` at ``odom_stamps_ns`` (strictly increasing), interpolated to every
  camera frame's stamp by the builder (odometry and camera are never sampled at the same instants);
- camera frames: ``(stamp_ns, camera name, detections)``; a camera name keys both its model and its
  extrinsic ``T_base_cam`` (a stereo rig has two);
- tag sizes: black-border edge per ``(family, id)``, or ``default_tag_size`` for the rest;
- ``ignore_tags``: ids dropped on input (known bad detections);
- ``lidar``: optional lidar sweeps and the scanner's mount (:class:`~tagloc.mapping.survey_scans.
  SurveyScans`); with them the builder adds scan-matching factors and builds the premap and the
  occupancy grid (:mod:`tagloc.mapping.lidar_survey`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.mapping.survey_scans import SurveyScans
from tagloc.tags.detection import TagDetection

TagKey = tuple[str, int]  # (family, id)


class MappingError(TaglocError, ValueError):
    """A survey or map-build request that cannot be used; the message names the field at fault."""


@dataclass(frozen=True, slots=True, eq=False)
class CameraFrame:
    """The tags one camera saw in one image (possibly none)."""

    stamp_ns: int
    camera: str
    detections: tuple[TagDetection, ...]


@dataclass(frozen=True, slots=True, eq=False)
class Survey:
    """A survey drive (see the module docstring).

    Attributes
    ----------
    odom_stamps_ns : (N,) int64
        Strictly increasing odometry stamps, ns.
    T_odom_base : SE3 batch of N
        Odometry pose of ``base`` in ``odom`` at each stamp.
    frames : tuple of CameraFrame
        Camera frames in any order (the builder sorts them).
    cameras : mapping of str to CameraModel
    T_base_cam : mapping of str to SE3
        Extrinsic of each camera's optical frame in ``base``.
    tag_sizes : mapping of (family, id) to float
        Black-border edge lengths, m.
    default_tag_size : float or None
        Edge of tags not in ``tag_sizes`` (None: such a tag is an error).
    ignore_tags : frozenset of int
        Tag ids dropped on input.
    source : str
        Where the survey came from, for messages.
    lidar : SurveyScans or None
        Lidar sweeps (None: a tags-only survey).
    """

    odom_stamps_ns: npt.NDArray[np.int64]
    T_odom_base: SE3
    frames: tuple[CameraFrame, ...]
    cameras: Mapping[str, CameraModel]
    T_base_cam: Mapping[str, SE3]
    tag_sizes: Mapping[TagKey, float] = field(default_factory=dict)
    default_tag_size: float | None = None
    ignore_tags: frozenset[int] = frozenset()
    source: str = "survey"
    lidar: SurveyScans | None = None

    def __post_init__(self) -> None:
        stamps = np.asarray(self.odom_stamps_ns, dtype=np.int64).reshape(-1)
        if len(stamps) < 2:
            raise MappingError(
                f"{self.source}: odometry: need at least 2 samples, got {len(stamps)} "
                "(a survey without odometry cannot be mapped)"
            )
        if not (np.diff(stamps) > 0).all():
            raise MappingError(f"{self.source}: odometry: stamps must increase strictly")
        if not self.T_odom_base.is_batch or len(self.T_odom_base) != len(stamps):
            raise MappingError(
                f"{self.source}: odometry: T_odom_base must be a batch of {len(stamps)} poses"
            )
        for frame in self.frames:
            if frame.camera not in self.cameras or frame.camera not in self.T_base_cam:
                raise MappingError(
                    f"{self.source}: frame at {frame.stamp_ns} ns: camera {frame.camera!r} has "
                    f"no model or no T_base_cam (known: {sorted(self.cameras)})"
                )
        for key, size in self.tag_sizes.items():
            if not (np.isfinite(size) and size > 0.0):
                raise MappingError(f"{self.source}: tag_sizes[{key}]: must be > 0, got {size}")
        if self.default_tag_size is not None and not self.default_tag_size > 0.0:
            raise MappingError(f"{self.source}: default_tag_size: must be > 0")
        object.__setattr__(self, "odom_stamps_ns", stamps)

    def tag_size(self, key: TagKey) -> float:
        """Edge length of tag ``key`` (m). Raises :class:`MappingError` if it is unknown."""
        size = self.tag_sizes.get(key, self.default_tag_size)
        if size is None:
            raise MappingError(
                f"{self.source}: tag {key[0]}:{key[1]} is observed but has no known size "
                "(give a default tag size or a size for this id)"
            )
        return float(size)


def only_cameras(survey: Survey, cameras: Sequence[str]) -> Survey:
    """The survey restricted to the frames of ``cameras`` (e.g. one side of a stereo rig)."""
    keep = set(cameras)
    return Survey(
        survey.odom_stamps_ns,
        survey.T_odom_base,
        tuple(f for f in survey.frames if f.camera in keep),
        survey.cameras,
        survey.T_base_cam,
        survey.tag_sizes,
        survey.default_tag_size,
        survey.ignore_tags,
        f"{survey.source} ({', '.join(sorted(keep))})",
        survey.lidar,
    )
