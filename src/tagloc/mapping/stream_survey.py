"""Surveys from a recorded message stream (a bag read by :class:`tagloc.io.BagSource`).

The parsers of a tagSLAM-style rig description (``camera_poses.yaml``, ``tagslam.yaml``) are in
:mod:`tagloc.mapping.rig_config` (re-exported here).

Corner order of recorded detections: a source that is not AprilTag 3 may list corners in another
order. Every cyclic rotation of a clockwise order is also clockwise, so the winding check cannot
tell them apart and the reprojection error is the same for all four (the tag frame just turns
by 90 degrees about its normal). What tells them apart is an absolute reference:
:func:`corner_rotation_by_gravity` compares, for each rotation, the camera's "up" implied by the
anchor tag's surveyed pose with the "up" of a gravity-aware odometry (VIO): only the right one
agrees. On the dupont bag, read with ``corner_order="bl_br_tr_tl"`` (tagSLAM's object corners
``(-s/2,-s/2), (s/2,-s/2), (s/2,s/2), (-s/2,s/2)``), rotation 0 agrees to 2 degrees; the others
are off by 88, 178 and 91 degrees.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.mapping.rig_config import RigConfig, TagRemap, parse_camera_poses, parse_tagslam
from tagloc.mapping.survey import CameraFrame, MappingError, Survey, TagKey
from tagloc.mapping.survey_scans import SurveyScans
from tagloc.messages import Message, OdometryMsg, PointCloudMsg, TagDetectionsMsg, TransformMsg
from tagloc.tags.detection import TagDetection
from tagloc.tags.pnp import estimate_tag_poses
from tagloc.tags.tagmap_checks import DEFAULT_FAMILY

__all__ = [
    "RigConfig", "TagRemap", "corner_rotation_by_gravity", "parse_camera_poses", "parse_tagslam",
    "survey_from_messages", "survey_from_tagslam",
]  # fmt: skip


def survey_from_messages(
    items: Iterable[tuple[str, Message]],
    camera_topics: Mapping[str, str],
    odom_topic: str,
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    *,
    T_child_base: SE3 | None = None,
    tag_sizes: Mapping[TagKey, float] | None = None,
    default_tag_size: float | None = None,
    ignore_tags: Iterable[int] = (),
    tag_remaps: Iterable[TagRemap] = (),
    source: str = "stream",
    lidar_topic: str | None = None,
    base_frame: str = "base_link",
    lidar_keep_distance_m: float = 0.5,
) -> Survey:
    """A survey from ``(topic, record)`` items.

    Parameters
    ----------
    camera_topics : mapping of topic to camera name
        Which :class:`TagDetectionsMsg` topic is which camera.
    odom_topic : str
        The :class:`OdometryMsg` topic; ``T_odom_base = T_parent_child @ T_child_base``.
    T_child_base : SE3, optional
        The base in the odometry's child frame (tagSLAM's ``T_body_odom`` inverted).
    tag_remaps : iterable of TagRemap
        Detections re-labelled by stamp (a printed id used twice in the building).
    lidar_topic : str, optional
        The :class:`PointCloudMsg` topic (None: a tags-only survey). Sweeps are kept as they
        stream, the first and then each one after ``lidar_keep_distance_m`` of odometry (the
        builder uses one per ``keyframe_distance_m``; memory stays small), raw, with their time
        offsets. The mount ``T_base_lidar`` is the static transform ``base_frame -> <the
        sweeps' frame_id>`` of the stream (``/tf_static``).

    Raises
    ------
    MappingError
        If the stream has no odometry on ``odom_topic`` or no detections on the camera topics,
        or sweeps but no static transform from ``base_frame`` to their frame.
    """
    stamps: list[int] = []
    poses: list[SE3] = []
    frames: list[CameraFrame] = []
    remaps = tuple(tag_remaps)
    sweeps: list[PointCloudMsg] = []
    statics: dict[tuple[str, str], SE3] = {}
    kept_at: npt.NDArray[np.float64] | None = None
    for topic, msg in items:
        if isinstance(msg, TransformMsg) and msg.static:
            statics[(msg.parent, msg.child)] = msg.T_parent_child
        elif topic == lidar_topic and isinstance(msg, PointCloudMsg) and poses:
            position = np.asarray(poses[-1].translation)
            if kept_at is None or np.linalg.norm(position - kept_at) >= lidar_keep_distance_m:
                sweeps.append(msg)
                kept_at = position
        if topic == odom_topic and isinstance(msg, OdometryMsg):
            stamps.append(msg.stamp_ns)
            poses.append(msg.T_parent_child)
        elif topic in camera_topics and isinstance(msg, TagDetectionsMsg):
            detections = tuple(_remapped(d, msg.stamp_ns, remaps) for d in msg.detections)
            frames.append(CameraFrame(msg.stamp_ns, camera_topics[topic], detections))
    if len(stamps) < 2:
        raise MappingError(
            f"{source}: no odometry on topic {odom_topic!r} (found {len(stamps)} messages)"
        )
    if not frames:
        raise MappingError(f"{source}: no tag detections on topics {sorted(camera_topics)}")
    T_odom_child = SE3.stack(poses)
    T_odom_base = T_odom_child if T_child_base is None else T_odom_child @ T_child_base
    lidar = _survey_scans(sweeps, statics, base_frame, source) if sweeps else None
    return Survey(
        odom_stamps_ns=np.array(stamps, dtype=np.int64),
        T_odom_base=T_odom_base,
        frames=tuple(frames),
        cameras=dict(cameras),
        T_base_cam=dict(T_base_cam),
        tag_sizes=dict(tag_sizes or {}),
        default_tag_size=default_tag_size,
        ignore_tags=frozenset(int(i) for i in ignore_tags),
        source=source,
        lidar=lidar,
    )


def _survey_scans(
    sweeps: list[PointCloudMsg], statics: Mapping[tuple[str, str], SE3], base: str, source: str
) -> SurveyScans:
    frame = sweeps[0].frame_id
    T_base_lidar = statics.get((base, frame))
    if T_base_lidar is None:
        raise MappingError(
            f"{source}: lidar sweeps in frame {frame!r} but no static transform {base} -> "
            f"{frame} (/tf_static)"
        )
    order = np.argsort([m.stamp_ns for m in sweeps], kind="stable")
    unique = [sweeps[i] for k, i in enumerate(order)
              if k == 0 or sweeps[i].stamp_ns != sweeps[order[k - 1]].stamp_ns]  # fmt: skip
    return SurveyScans(
        stamps_ns=np.array([m.stamp_ns for m in unique], dtype=np.int64),
        points_lidar=tuple(m.points for m in unique),
        time_offset_s=tuple(m.time_offset_s for m in unique),
        T_base_lidar=T_base_lidar,
    )


def survey_from_tagslam(
    items: Iterable[tuple[str, Message]],
    camera_topics: Mapping[str, str],
    odom_topic: str,
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    rig: RigConfig | None,
    *,
    tag_sizes: Mapping[int, float] | None = None,
    default_tag_size: float | None = None,
    family: str = DEFAULT_FAMILY,
    source: str = "stream",
    lidar_topic: str | None = None,
) -> Survey:
    """:func:`survey_from_messages` with a tagSLAM rig's settings (:func:`parse_tagslam`): the
    base in the odometry's child frame (``T_body_odom`` inverted), tag sizes, ignored ids and
    id remaps (``rig=None``: none of them).

    ``tag_sizes`` (edge by id, tags of ``family``) and ``default_tag_size`` override the rig's;
    ``lidar_topic``: the sweeps, as :func:`survey_from_messages`.
    """
    sizes = {**(rig.tag_sizes if rig is not None else {}), **(tag_sizes or {})}
    if default_tag_size is None and rig is not None:
        default_tag_size = rig.default_tag_size
    return survey_from_messages(
        items,
        camera_topics,
        odom_topic,
        cameras,
        T_base_cam,
        T_child_base=None if rig is None or rig.T_body_odom is None else rig.T_body_odom.inverse(),
        tag_sizes={(family, i): s for i, s in sizes.items()},
        default_tag_size=default_tag_size,
        ignore_tags=rig.ignore_tags if rig is not None else (),
        tag_remaps=rig.tag_remaps if rig is not None else (),
        source=source,
        lidar_topic=lidar_topic,
    )


def _remapped(det: TagDetection, stamp_ns: int, remaps: tuple[TagRemap, ...]) -> TagDetection:
    for r in remaps:
        if det.tag_id == r.tag_id and r.start_ns <= stamp_ns <= r.end_ns:
            return dataclasses.replace(det, tag_id=r.remap_id)
    return det


def corner_rotation_by_gravity(
    survey: Survey,
    anchor_id: int,
    T_map_anchor: SE3,
    family: str = "tag36h11",
    max_frames: int = 20,
) -> npt.NDArray[np.float64]:
    """``(4,)`` median angle (deg) between map "up" and odometry "up" per corner rotation ``k``.

    For frames that see the anchor, ``T_map_base = T_map_anchor @ T_base_tag^-1`` under each
    rotation; the odometry at the nearest sample gives ``R_odom_base``. With a gravity-aligned
    ``map`` and odometry (z up), the right rotation gives a small angle between their z axes
    expressed in ``base`` (module docstring). Pick ``argmin``.
    """
    seen = [
        f
        for f in sorted(survey.frames, key=lambda f: f.stamp_ns)
        if any(d.tag_id == anchor_id and d.family == family for d in f.detections)
    ]
    if not seen:
        raise MappingError(f"{survey.source}: anchor tag {anchor_id} is never observed")
    seen = seen[:: max(1, len(seen) // max_frames)][:max_frames]
    angles = np.full((4, len(seen)), np.nan)
    size = survey.tag_size((family, anchor_id))
    for n, frame in enumerate(seen):
        det = next(d for d in frame.detections if d.tag_id == anchor_id and d.family == family)
        i = int(np.argmin(np.abs(survey.odom_stamps_ns - frame.stamp_ns)))
        up_odom = survey.T_odom_base[i].rotation.as_matrix().T @ [0.0, 0.0, 1.0]
        corners = np.array([np.roll(det.corners_px, k, axis=0) for k in range(4)])
        estimates = estimate_tag_poses(
            [anchor_id] * 4, corners, [size] * 4, survey.cameras[frame.camera]
        )
        for k, e in enumerate(estimates):
            if e is None:
                continue
            T_map_base = T_map_anchor @ (survey.T_base_cam[frame.camera] @ e.T_cam_tag).inverse()
            up_map = T_map_base.rotation.as_matrix().T @ [0.0, 0.0, 1.0]
            angles[k, n] = np.degrees(np.arccos(np.clip(up_map @ up_odom, -1.0, 1.0)))
    return np.asarray(np.nanmedian(angles, axis=1))
