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

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from tagloc.camera import CameraModel
from tagloc.eval.engine import Engine, SerialEngine
from tagloc.eval.onsite_pass import (
    HeldOutObservation,
    HeldOutTask,
    StreamFactory,
    held_out_pass,
    observations_of_tag,
)
from tagloc.eval.onsite_stats import ErrorStats, error_stats, fused_pose_at
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.tag_cameras import NodeCamera
from tagloc.messages import NodeTopics
from tagloc.tags import TagMap
from tagloc.tags.covariance import NoiseModel

__all__ = [
    "ErrorStats",
    "HeldOutObservation",
    "HeldOutResult",
    "HeldOutTask",
    "StreamFactory",
    "error_stats",
    "fused_pose_at",
    "held_out_pass",
    "held_out_tags",
    "merge_held_out",
    "observations_of_tag",
]


@dataclass(slots=True)
class HeldOutResult:
    """All held-out views, with per-tag and overall statistics."""

    observations: list[HeldOutObservation] = field(default_factory=list)
    #: Tags held out that were never seen with the fused estimate initialized.
    unseen: list[int] = field(default_factory=list)

    def tag_ids(self) -> list[int]:
        return sorted({o.tag_id for o in self.observations})

    def cameras(self) -> list[str]:
        """The cameras of the views, in the order first seen (``[""]``: one camera)."""
        return list(dict.fromkeys(o.camera for o in self.observations))

    def stats(self, tag_id: int | None = None, camera: str | None = None) -> dict[str, ErrorStats]:
        """Position (m) and absolute yaw (deg) statistics, of one tag, one camera or overall."""
        obs = [
            o for o in self.observations
            if (tag_id is None or o.tag_id == tag_id) and (camera is None or o.camera == camera)
        ]  # fmt: skip
        return {
            "position_m": error_stats([o.position_err_m for o in obs]),
            "yaw_deg": error_stats([abs(o.yaw_err_deg) for o in obs]),
            "base_true_m": error_stats([o.base_err_m for o in obs]),
            "tag_true_m": error_stats([o.tag_err_true_m for o in obs]),
        }

    def to_dict(self) -> dict[str, Any]:
        def pack(s: dict[str, ErrorStats]) -> dict[str, Any]:
            return {k: v.to_dict() for k, v in s.items() if v.n or not k.endswith("true_m")}

        out = {
            "overall": pack(self.stats()),
            "per_tag": {str(i): pack(self.stats(i)) for i in self.tag_ids()},
            "unseen_tags": list(self.unseen),
        }
        cameras = self.cameras()
        if len(cameras) > 1:
            out["per_camera"] = {c: pack(self.stats(camera=c)) for c in cameras}
        return out


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
    cameras: Sequence[NodeCamera] = (),
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
    cameras : sequence of NodeCamera
        A rig: every camera's views of the held-out tag, each through its own model and
        extrinsics (``camera``/``T_base_cam`` then unused; empty: one camera).

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
        HeldOutTask(
            stream,
            tag_map,
            tag_id,
            config,
            camera,
            T_base_cam,
            topics,
            family,
            noise,
            max_range_m,
            tuple(cameras),
        )
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
