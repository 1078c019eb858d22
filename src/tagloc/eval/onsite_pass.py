"""One pass of the held-out-tag protocol (:mod:`tagloc.eval.onsite`): the drive localized
without one tag, and every camera's views of that tag predicted from the fused estimate.

On a rig (``cameras``) each camera's views of the held-out tag are predicted through that
camera's model and extrinsics, so the protocol judges the fused estimate through every camera
the node takes fixes from, and a camera whose views disagree with the others stands out in the
per-camera statistics.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.eval.onsite_stats import fused_pose_at, truth_pose_at
from tagloc.geometry import SE3
from tagloc.localize import driver
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.localize.tag_cameras import NodeCamera
from tagloc.messages import Message, NodeTopics, TagDetectionsMsg
from tagloc.tags import TagMap
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.pnp import estimate_tag_poses

__all__ = [
    "HeldOutObservation",
    "HeldOutTask",
    "StreamFactory",
    "held_out_pass",
    "observations_of_tag",
]

#: A stream that can be iterated more than once (a bag source, a scenario source, a list).
StreamFactory = Callable[[], Iterable[tuple[str, Message]]]


@dataclass(frozen=True, slots=True)
class HeldOutObservation:
    """One view of a held-out tag.

    Attributes
    ----------
    tag_id : int
    stamp_ns : int
    range_m : float
        Camera to tag by PnP, m.
    position_err_m : float
        ``|t(T_map_tag_pred) - t(T_map_tag_surveyed)|``, m.
    yaw_err_deg : float
        Heading of the predicted tag's normal about the map's z against the surveyed one,
        signed, degrees.
    pnp_var_m2 : float
        Trace of the PnP position covariance (the observation's own noise), m^2.
    base_err_m : float
        With ground truth (simulation) only: the fused base's position error at the stamp, m
        (NaN without truth).
    tag_err_true_m : float
        With ground truth only: the fused pose's error transported to the tag (the prediction
        with the true camera-to-tag pose), m (NaN without truth).
    camera : str
        The camera of the view (``""``: the node's only camera).
    """

    tag_id: int
    stamp_ns: int
    range_m: float
    position_err_m: float
    yaw_err_deg: float
    pnp_var_m2: float = math.nan
    base_err_m: float = math.nan
    tag_err_true_m: float = math.nan
    camera: str = ""


def observations_of_tag(
    stream: Iterable[tuple[str, Message]], detections_topic: str, tag_id: int, family: str
) -> list[tuple[int, FloatArray]]:
    """``(stamp_ns, corners_px)`` of every detection of one tag on ``detections_topic``."""
    out = []
    for topic, msg in stream:
        if topic == detections_topic and isinstance(msg, TagDetectionsMsg):
            for d in msg.detections:
                if d.tag_id == tag_id and d.family == family:
                    out.append((msg.stamp_ns, np.asarray(d.corners_px, dtype=np.float64)))
    return out


class _Tap:
    """Passes a stream through, keeping the detections of one tag on each camera's topic (one
    pass for both): ``seen[camera]``."""

    def __init__(self, topics: dict[str, str], tag_id: int, family: str) -> None:
        self.topics, self.tag_id, self.family = topics, tag_id, family
        self.seen: dict[str, list[tuple[int, FloatArray]]] = {c: [] for c in topics.values()}

    def __call__(self, stream: Iterable[tuple[str, Message]]) -> Iterable[tuple[str, Message]]:
        for topic, msg in stream:
            camera = self.topics.get(topic)
            if camera is not None and isinstance(msg, TagDetectionsMsg):
                self.seen[camera].extend(
                    observations_of_tag([(topic, msg)], topic, self.tag_id, self.family)
                )
            yield topic, msg


@dataclass(frozen=True, slots=True)
class HeldOutTask:
    """One localizer pass with one tag held out (picklable when ``stream`` is: an engine may run
    it in another process). Fields as :func:`~tagloc.eval.onsite.held_out_tags`'s parameters;
    ``cameras``: the rig (empty: the one camera of ``camera`` / the stream)."""

    stream: StreamFactory
    tag_map: TagMap
    tag_id: int
    config: LocalizerConfig | None = None
    camera: CameraModel | None = None
    T_base_cam: SE3 | None = None
    topics: NodeTopics = field(default_factory=NodeTopics)
    family: str = "tag36h11"
    noise: NoiseModel | None = None
    max_range_m: float = 4.0
    cameras: tuple[NodeCamera, ...] = ()


def held_out_pass(task: HeldOutTask) -> list[HeldOutObservation] | None:
    """Localize ``task.stream()`` against the map without ``task.tag_id``; every camera's views
    of that tag within ``max_range_m`` (None: the tag was never seen with the estimate
    initialized)."""
    entry = task.tag_map.get(task.tag_id, task.family)
    if entry is None:
        raise KeyError(f"tag {task.family}:{task.tag_id} is not in the map")
    reduced = TagMap.from_entries(
        (e for e in task.tag_map if e.key != entry.key), frames=task.tag_map.frames
    )
    node = partial(
        LocalizerNode, reduced, task.config, camera=task.camera, T_base_cam=task.T_base_cam,
        topics=task.topics, cameras=task.cameras,
    )  # fmt: skip
    topics = {c.detections_topic: c.name for c in task.cameras} or {task.topics.detections: ""}
    tap = _Tap(topics, task.tag_id, task.family)
    recorder = RunRecorder(f"held_out:{task.tag_id}")
    done = driver.run(node, tap(task.stream()), [recorder])
    run = recorder.run(done.node.metadata())
    models = {c.name: c.camera for c in task.cameras} or {"": done.node.camera}
    mounts = done.node.T_base_cam_by_camera if task.cameras else {"": done.node.T_base_cam}
    views: list[HeldOutObservation] = []
    for name, seen in tap.seen.items():
        cam, X = models.get(name), mounts.get(name)
        if cam is None or X is None or not seen:
            continue
        views += _views(run, seen, cam, X, entry.T_frame_tag(), entry.size, task.tag_id,
                        task.noise, name)  # fmt: skip
    views = [v for v in views if v.range_m <= task.max_range_m]
    return views or None


def _views(
    run: LocalizationRun, seen: list[tuple[int, FloatArray]], camera: CameraModel,
    T_base_cam: SE3, T_map_tag: SE3, size: float, tag_id: int, noise: NoiseModel | None,
    camera_name: str = "",
) -> list[HeldOutObservation]:  # fmt: skip
    stamps = np.array([s for s, _ in seen], dtype=np.int64)
    corners = np.stack([c for _, c in seen])
    estimates = estimate_tag_poses([tag_id] * len(seen), corners, [size] * len(seen), camera, noise)
    T_map_base, valid = fused_pose_at(run, stamps)
    truth = truth_pose_at(run, stamps)
    normal_surveyed = T_map_tag.rotation.matrix[:, 2]
    yaw_surveyed = math.atan2(normal_surveyed[1], normal_surveyed[0])
    out = []
    for i, est in enumerate(estimates):
        if est is None or not valid[i]:
            continue
        T_map_cam = T_map_base[i] @ T_base_cam
        # of the two IPPE branches, the one nearer the map's orientation (the localizer's own
        # disambiguation with a prior); the position barely depends on the branch
        T_cam_tag, cov = est.T_cam_tag, est.cov_cam_tag
        if _angle(T_map_cam @ est.T_cam_tag_alt, T_map_tag) < _angle(
            T_map_cam @ T_cam_tag, T_map_tag
        ):
            T_cam_tag, cov = est.T_cam_tag_alt, est.cov_cam_tag_alt
        T_map_tag_pred = T_map_cam @ T_cam_tag
        normal = T_map_tag_pred.rotation.matrix[:, 2]
        dyaw = math.atan2(normal[1], normal[0]) - yaw_surveyed
        base_err = tag_true = math.nan
        if truth is not None:
            base_err = float(np.linalg.norm(T_map_base[i].translation - truth[i].translation))
            T_base_tag_true = truth[i].inverse() @ T_map_tag
            tag_true = float(
                np.linalg.norm(
                    (T_map_base[i] @ T_base_tag_true).translation - T_map_tag.translation
                )
            )
        out.append(
            HeldOutObservation(
                tag_id, int(stamps[i]), float(est.range_m),
                float(np.linalg.norm(T_map_tag_pred.translation - T_map_tag.translation)),
                math.degrees(math.remainder(dyaw, math.tau)), _trace3(cov), base_err, tag_true,
                camera_name,
            )
        )  # fmt: skip
    return out


def _angle(T_a: SE3, T_b: SE3) -> float:
    return float(np.linalg.norm((T_a.rotation.inverse() @ T_b.rotation).log()))


def _trace3(cov: FloatArray) -> float:
    return float(np.trace(np.asarray(cov)[:3, :3]))
