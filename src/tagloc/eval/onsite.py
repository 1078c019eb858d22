"""On-site evaluation without motion capture: the held-out-tag protocol.

A building has no ground truth, but it has surveyed tags. Take one tag out of the map, localize
the drive against the others, and wherever the robot sees the held-out tag, predict the tag's
pose from the fused estimate and the camera's own view of it:

``T_map_tag_pred = T_map_base(t) @ T_base_cam @ T_cam_tag``  (``T_cam_tag`` by single-tag PnP)

and compare it with the surveyed ``T_map_tag``. The position error is the localization error
transported to the tag (the base's error plus the heading error times the range) plus the PnP
error of one observation; near tags, where a robot docks or passes a door, that is the error
that matters. Each tag in turn (or a chosen subset) gives per-tag and overall statistics.

:func:`~tagloc.eval.onsite_stats.fused_pose_at` (the recorded run's ``T_map_base`` at any stamp)
and the error statistics live in :mod:`tagloc.eval.onsite_stats`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.eval.engine import Engine, SerialEngine
from tagloc.eval.onsite_stats import ErrorStats, error_stats, fused_pose_at, truth_pose_at
from tagloc.geometry import SE3
from tagloc.localize import driver
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.messages import Message, NodeTopics, TagDetectionsMsg
from tagloc.tags import TagMap
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.pnp import estimate_tag_poses

__all__ = [
    "ErrorStats",
    "HeldOutObservation",
    "HeldOutResult",
    "HeldOutTask",
    "error_stats",
    "fused_pose_at",
    "held_out_pass",
    "held_out_tags",
    "merge_held_out",
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
    """

    tag_id: int
    stamp_ns: int
    range_m: float
    position_err_m: float
    yaw_err_deg: float
    pnp_var_m2: float = math.nan
    base_err_m: float = math.nan
    tag_err_true_m: float = math.nan


@dataclass(slots=True)
class HeldOutResult:
    """All held-out views, with per-tag and overall statistics."""

    observations: list[HeldOutObservation] = field(default_factory=list)
    #: Tags held out that were never seen with the fused estimate initialized.
    unseen: list[int] = field(default_factory=list)

    def tag_ids(self) -> list[int]:
        return sorted({o.tag_id for o in self.observations})

    def stats(self, tag_id: int | None = None) -> dict[str, ErrorStats]:
        """Position (m) and absolute yaw (deg) statistics, of one tag or overall."""
        obs = [o for o in self.observations if tag_id is None or o.tag_id == tag_id]
        return {
            "position_m": error_stats([o.position_err_m for o in obs]),
            "yaw_deg": error_stats([abs(o.yaw_err_deg) for o in obs]),
            "base_true_m": error_stats([o.base_err_m for o in obs]),
            "tag_true_m": error_stats([o.tag_err_true_m for o in obs]),
        }

    def to_dict(self) -> dict[str, Any]:
        def pack(s: dict[str, ErrorStats]) -> dict[str, Any]:
            return {k: v.to_dict() for k, v in s.items() if v.n or not k.endswith("true_m")}

        return {
            "overall": pack(self.stats()),
            "per_tag": {str(i): pack(self.stats(i)) for i in self.tag_ids()},
            "unseen_tags": list(self.unseen),
        }


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
    """Passes a stream through, keeping the detections of one tag (one pass for both)."""

    def __init__(self, topic: str, tag_id: int, family: str) -> None:
        self.topic, self.tag_id, self.family = topic, tag_id, family
        self.seen: list[tuple[int, FloatArray]] = []

    def __call__(self, stream: Iterable[tuple[str, Message]]) -> Iterable[tuple[str, Message]]:
        for topic, msg in stream:
            if topic == self.topic and isinstance(msg, TagDetectionsMsg):
                self.seen.extend(
                    observations_of_tag([(topic, msg)], topic, self.tag_id, self.family)
                )
            yield topic, msg


@dataclass(frozen=True, slots=True)
class HeldOutTask:
    """One localizer pass with one tag held out (picklable when ``stream`` is: an engine may run
    it in another process). Fields as :func:`held_out_tags`'s parameters."""

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


def held_out_pass(task: HeldOutTask) -> list[HeldOutObservation] | None:
    """Localize ``task.stream()`` against the map without ``task.tag_id``; the views of that tag
    within ``max_range_m`` (None: the tag was never seen with the estimate initialized)."""
    entry = task.tag_map.get(task.tag_id, task.family)
    if entry is None:
        raise KeyError(f"tag {task.family}:{task.tag_id} is not in the map")
    reduced = TagMap.from_entries(
        (e for e in task.tag_map if e.key != entry.key), frames=task.tag_map.frames
    )
    node = partial(
        LocalizerNode, reduced, task.config, camera=task.camera, T_base_cam=task.T_base_cam,
        topics=task.topics,
    )  # fmt: skip
    tap = _Tap(task.topics.detections, task.tag_id, task.family)
    recorder = RunRecorder(f"held_out:{task.tag_id}")
    done = driver.run(node, tap(task.stream()), [recorder])
    run = recorder.run(done.node.metadata())
    cam, X = done.node.camera, done.node.T_base_cam
    if cam is None or X is None or not tap.seen:
        return None
    views = _views(run, tap.seen, cam, X, entry.T_frame_tag(), entry.size, task.tag_id, task.noise)
    views = [v for v in views if v.range_m <= task.max_range_m]
    return views or None


def held_out_tags(
    stream: StreamFactory,
    tag_map: TagMap,
    config: LocalizerConfig | None = None,
    *,
    tag_ids: Sequence[int] | None = None,
    camera: CameraModel | None = None,
    T_base_cam: SE3 | None = None,
    topics: NodeTopics | None = None,
    family: str = "tag36h11",
    noise: NoiseModel | None = None,
    max_range_m: float = 4.0,
    progress: Callable[[int, int], None] | None = None,
    engine: Engine | None = None,
) -> HeldOutResult:
    """Localize ``stream()`` once per held-out tag against ``tag_map`` without it.

    Parameters
    ----------
    stream : callable
        Returns the message stream afresh (it is replayed once per tag); picklable (e.g. a
        bag's path and topics) when ``engine`` runs passes in other processes.
    tag_map : TagMap
        The surveyed map (tags in frame ``map``).
    config : LocalizerConfig, optional
    tag_ids : sequence of int, optional
        Tags to hold out (default: every tag of ``family`` in the map).
    camera, T_base_cam : optional
        As for the node (default: the stream's CameraInfo and static transform).
    topics : NodeTopics, optional
    family : str
    noise : NoiseModel, optional
        Pixel noise for PnP (only its refinement is used here).
    max_range_m : float
        Views farther than this (PnP range, m) are left out: beyond about 4 m one view's PnP
        error is as large as the localization error it should measure.
    progress : callable, optional
        ``progress(done, total)`` after each pass.
    engine : Engine, optional
        Where the passes run (:mod:`tagloc.eval.engine`; default: in series, here).

    Returns
    -------
    HeldOutResult
        One observation per detection of a held-out tag at a stamp where the fused estimate is
        initialized (with truth errors when the stream carries ground truth); the same for any
        engine.

    Raises
    ------
    KeyError
        If a tag of ``tag_ids`` is not in the map.
    """
    topics = topics or NodeTopics()
    ids = list(tag_ids) if tag_ids is not None else list(tag_map.ids(family))
    for tag_id in ids:
        if tag_map.get(tag_id, family) is None:
            raise KeyError(f"tag {family}:{tag_id} is not in the map")
    tasks = [
        HeldOutTask(stream, tag_map, tag_id, config, camera, T_base_cam, topics, family, noise,
                    max_range_m)
        for tag_id in ids
    ]
    passes = (engine or SerialEngine()).map(held_out_pass, tasks, progress)
    return merge_held_out(ids, passes)


def merge_held_out(
    tag_ids: Sequence[int], passes: Sequence[list[HeldOutObservation] | None]
) -> HeldOutResult:
    """The :class:`HeldOutResult` of one pass per tag (:func:`held_out_pass`), in tag order."""
    result = HeldOutResult()
    for tag_id, views in zip(tag_ids, passes, strict=True):
        if views is None:
            result.unseen.append(tag_id)
        else:
            result.observations.extend(views)
    return result


def _views(
    run: LocalizationRun, seen: list[tuple[int, FloatArray]], camera: CameraModel,
    T_base_cam: SE3, T_map_tag: SE3, size: float, tag_id: int, noise: NoiseModel | None,
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
            )
        )  # fmt: skip
    return out


def _angle(T_a: SE3, T_b: SE3) -> float:
    return float(np.linalg.norm((T_a.rotation.inverse() @ T_b.rotation).log()))


def _trace3(cov: FloatArray) -> float:
    return float(np.trace(np.asarray(cov)[:3, :3]))
