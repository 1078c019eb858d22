"""Is the camera model the one that took these detections? Evidence from the start of a stream.

A camera file for another camera (another lens, another resolution, a focal length off by a
factor) still gives PnP poses, and the filter may accept them: they are consistent with each
other, just wrong. Before any fix is applied, :func:`check_camera` reads the first frames of the
stream and compares three things with the model:

1. the stream's ``CameraInfo`` (when it has one): image size and focal lengths;
2. the size of the first image (when it has images);
3. the depth scale of PnP against the odometry: a mapped tag seen in two frames a few tenths of
   a metre of travel apart is at two PnP positions ``p_a``, ``p_b`` in the camera, and the
   odometry (through ``T_base_cam``) gives the camera's motion ``T_ab`` between them. A focal
   length off by a factor ``k`` scales PnP's depths by about ``k`` and leaves the lateral
   offsets, so ``D^-1 p_a = T_ab D^-1 p_b`` with ``D = diag(1, 1, k)``; the ``k`` that fits best
   (median residual) is 1 for a correct model, within the odometry's scale error (a few %).

A problem is one line naming what disagrees; a model that passes is never refused for lack of
evidence (too few tag pairs leave the scale unchecked).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel, from_camera_info
from tagloc.errors import TaglocError
from tagloc.geometry import SE3
from tagloc.messages import (
    CameraInfoMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.tags import TagEntry, TagMap
from tagloc.tags.pnp import estimate_tag_poses

__all__ = ["CameraCheck", "check_camera"]


@dataclass(slots=True)
class CameraCheck:
    """What :func:`check_camera` found.

    Attributes
    ----------
    scale : float
        Median ratio of the camera's motion by PnP to the odometry's (NaN without pairs).
    n_pairs : int
    frames_read : int
        Camera frames read.
    problems : list of str
        One line each; empty when the model fits.
    """

    scale: float = math.nan
    n_pairs: int = 0
    frames_read: int = 0
    problems: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, object]:
        return {"pnp_scale": self.scale, "n_pairs": self.n_pairs,
                "frames_read": self.frames_read, "problems": list(self.problems)}  # fmt: skip


def check_camera(
    stream: Iterable[tuple[str, Message]],
    camera: CameraModel,
    tag_map: TagMap,
    *,
    detections_topic: str,
    odom_topic: str,
    T_base_cam: SE3 | None = None,
    camera_info_topic: str | None = None,
    image_topic: str | None = None,
    family: str = "tag36h11",
    max_frames: int = 600,
    stride: int = 3,
    min_pairs: int = 5,
    scale_tolerance: float = 0.2,
    focal_tolerance: float = 0.05,
    min_motion_m: float = 0.3,
    max_gap_s: float = 3.0,
) -> CameraCheck:
    """Compare ``camera`` with the first frames of ``stream`` (module docstring).

    Parameters
    ----------
    stream : iterable of (topic, message)
        Read for ``max_frames`` camera frames (then left).
    camera : CameraModel
        The model to check.
    tag_map : TagMap
        Tags in frame ``map`` of ``family`` (their sizes; only mapped tags are used).
    detections_topic, odom_topic, camera_info_topic, image_topic : str
    T_base_cam : SE3, optional
        Default: the stream's static transform to the detections' frame.
    max_frames, stride : int
        Frames read; PnP on every ``stride``-th.
    min_pairs : int
        Fewer pairs of views leave the scale unchecked.
    scale_tolerance : float
        The motion ratio must be within ``[1 / (1 + tol), 1 + tol]``.
    focal_tolerance : float
        Relative difference of focal lengths allowed against the stream's CameraInfo.
    min_motion_m, max_gap_s : float
        A pair of views of one tag: at least this far apart (odometry), at most this long.
    """
    entries = {e.id: e for e in tag_map.in_frame("map") if e.family == family}
    out = CameraCheck()
    statics: dict[str, SE3] = {}
    info_seen = image_seen = False
    seen: dict[int, list[tuple[int, SE3]]] = {}  # tag id -> (stamp, T_cam_tag)
    odom: list[tuple[int, SE3]] = []
    for topic, msg in stream:
        if isinstance(msg, OdometryMsg) and topic == odom_topic:
            odom.append((msg.stamp_ns, msg.T_parent_child))
        elif isinstance(msg, TransformMsg) and msg.static and T_base_cam is None:
            statics[msg.child] = msg.T_parent_child
        elif isinstance(msg, CameraInfoMsg) and topic == camera_info_topic and not info_seen:
            info_seen = True
            out.problems += _info_problems(camera, msg, topic, focal_tolerance)
        elif isinstance(msg, ImageMsg) and topic == image_topic and not image_seen:
            image_seen = True
            h, w = msg.image.shape[:2]
            if (w, h) != (camera.width, camera.height):
                out.problems.append(
                    f"the images on {topic} are {w}x{h}, the camera model is "
                    f"{camera.width}x{camera.height}"
                )
        elif isinstance(msg, TagDetectionsMsg) and topic == detections_topic:
            out.frames_read += 1
            if T_base_cam is None:
                T_base_cam = statics.get(msg.frame_id)
            if out.frames_read % stride == 0:
                _observe(msg, camera, entries, family, seen)
            if out.frames_read >= max_frames:
                break
    pairs = _motion_pairs(seen, odom, T_base_cam, min_motion_m, max_gap_s)
    out.n_pairs = len(pairs)
    if pairs:
        out.scale = _depth_scale(pairs)
        if len(pairs) >= min_pairs and not (
            1.0 / (1.0 + scale_tolerance) <= out.scale <= 1.0 + scale_tolerance
        ):
            out.problems.append(
                f"PnP with this camera model puts the tags at {out.scale:.2f} x the depth the "
                f"odometry's motion implies ({len(pairs)} pairs of views of a tag): wrong focal "
                "length, or another camera's file"
            )
    return out


def _observe(
    msg: TagDetectionsMsg, camera: CameraModel, entries: dict[int, TagEntry], family: str,
    seen: dict[int, list[tuple[int, SE3]]],
) -> None:  # fmt: skip
    dets = [d for d in msg.detections if d.family == family and d.tag_id in entries]
    if not dets:
        return
    ids = [d.tag_id for d in dets]
    corners = np.stack([np.asarray(d.corners_px) for d in dets])
    estimates = estimate_tag_poses(ids, corners, [entries[i].size for i in ids], camera)
    for tag_id, est in zip(ids, estimates, strict=True):
        if est is not None and ids.count(tag_id) == 1:
            seen.setdefault(tag_id, []).append((msg.stamp_ns, est.T_cam_tag))


def _motion_pairs(
    seen: dict[int, list[tuple[int, SE3]]], odom: list[tuple[int, SE3]],
    T_base_cam: SE3 | None, min_motion_m: float, max_gap_s: float,
) -> list[tuple[FloatArray, FloatArray, SE3]]:  # fmt: skip
    """``(p_a, p_b, T_cam_a_cam_b)``: a tag's PnP positions in two frames and the odometry's
    camera motion between them."""
    if T_base_cam is None or len(odom) < 2:
        return []
    stamps = np.array([s for s, _ in odom], dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    stamps = stamps[order]
    T_odom_base = SE3.stack([odom[k][1] for k in order])
    out = []
    for views in seen.values():
        t = np.array([s for s, _ in views], dtype=np.int64)
        inside = (t >= stamps[0]) & (t <= stamps[-1])
        if inside.sum() < 2:
            continue
        t = t[inside]
        p = np.array([v.translation for (_, v), ok in zip(views, inside, strict=True) if ok])
        i = np.clip(np.searchsorted(stamps, t, side="right") - 1, 0, len(stamps) - 1)
        j = np.minimum(i + 1, len(stamps) - 1)
        alpha = np.clip((t - stamps[i]) / np.maximum(stamps[j] - stamps[i], 1), 0.0, 1.0)
        T_odom_cam = T_odom_base[i].interpolate_rt(T_odom_base[j], alpha) @ T_base_cam
        last = 0
        for b in range(1, len(t)):
            if (t[b] - t[last]) / 1e9 > max_gap_s:
                last = b
                continue
            T_ab = T_odom_cam[last].inverse() @ T_odom_cam[b]
            if float(np.linalg.norm(T_ab.translation)) < min_motion_m:
                continue
            out.append((p[last], p[b], T_ab))
            last = b
    return out


def _depth_scale(pairs: list[tuple[FloatArray, FloatArray, SE3]]) -> float:
    """The factor ``k`` on PnP depths that best explains the pairs: with ``D = diag(1, 1, k)``,
    ``D^-1 p_a = T_ab D^-1 p_b`` (median residual, searched on a log grid 1/4 .. 4)."""
    p_a = np.array([a for a, _, _ in pairs])
    p_b = np.array([b for _, b, _ in pairs])
    T_ab = SE3.stack([T for _, _, T in pairs])
    grid = np.geomspace(0.25, 4.0, 241)
    cost = []
    for k in grid:
        d = np.array([1.0, 1.0, 1.0 / k])
        r = np.linalg.norm(p_a * d - T_ab.act(p_b * d), axis=1)
        cost.append(float(np.median(r)))
    return float(grid[int(np.argmin(cost))])


def _info_problems(
    camera: CameraModel, msg: CameraInfoMsg, topic: str, tolerance: float
) -> list[str]:
    try:
        info = from_camera_info(msg.info, f"{topic} CameraInfo")
    except TaglocError:  # a CameraInfo tagloc cannot read is evidence of nothing
        return []
    problems = []
    if (info.width, info.height) != (camera.width, camera.height):
        problems.append(
            f"{topic} says {info.width}x{info.height}, the camera model "
            f"{camera.width}x{camera.height}"
        )
    for k, name in ((0, "fx"), (1, "fy")):
        a, b = float(camera.K[k, k]), float(info.K[k, k])
        if b > 0 and abs(a - b) > tolerance * b:
            problems.append(f"{topic} says {name} = {b:.1f} px, the camera model {a:.1f} px")
    return problems
