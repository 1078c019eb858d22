"""Tag sizes against each other: a tag printed at another size than the map's (``tagloc detect``).

PnP with a wrong size puts the tag at the right bearing and the wrong depth, by exactly the
ratio of the sizes; a second mapped tag in view (and the map) says where it really is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from tagloc.geometry import SE3


class _CheckedTag(Protocol):
    """What the size check reads of a :class:`~tagloc.eval.tag_check.TagCheck`."""

    @property
    def accepted(self) -> Any: ...
    @property
    def estimate(self) -> Any: ...
    @property
    def in_map(self) -> bool: ...
    @property
    def detection(self) -> Any: ...
    @property
    def size_m(self) -> float | None: ...
    @property
    def notes(self) -> list[str]: ...

__all__ = ["SIZE_TOLERANCE", "size_notes", "size_ratios"]

#: A tag's apparent size off the others' by more than this fraction is named.
SIZE_TOLERANCE = 0.05


def size_ratios(
    T_cam_tag: dict[int, SE3], T_map_tag: dict[int, SE3]
) -> dict[tuple[int, int], float]:
    """``r[i, j]``: tag ``i``'s printed size over its assumed one, if tag ``j``'s is right.

    Tag ``j``'s PnP pose and the map give the camera (``T_map_cam = T_map_tag_j @
    T_cam_tag_j^-1``), which predicts tag ``i`` at ``p = T_map_cam^-1 @ t_map_tag_i``. PnP with a
    size off by a factor puts the tag at ``t_cam_tag_i`` scaled by its inverse along the ray, so
    ``r = (p . t) / (t . t)``.
    """
    out: dict[tuple[int, int], float] = {}
    for j, T_cj in T_cam_tag.items():
        T_map_cam = T_map_tag[j] @ T_cj.inverse()
        for i, T_ci in T_cam_tag.items():
            if i == j:
                continue
            predicted = T_map_cam.inverse().act(T_map_tag[i].translation)
            t = T_ci.translation
            out[i, j] = float(np.dot(predicted, t) / np.dot(t, t))
    return out


def size_notes(tags: Sequence[_CheckedTag], tag_poses: dict[int, SE3]) -> list[str]:
    """Step 6: name tags whose size disagrees with the consensus of the others."""
    poses = {}
    for tag in tags:
        est = tag.accepted or tag.estimate
        if tag.in_map and est is not None and tag.detection.tag_id not in poses:
            poses[tag.detection.tag_id] = est.T_cam_tag
    if len(poses) < 2:
        return []
    ratios = size_ratios(poses, tag_poses)
    ids = list(poses)
    consistent = {
        i: {j for j in ids if j == i or abs(ratios[i, j] - 1) <= SIZE_TOLERANCE} for i in ids
    }
    core = max(consistent.values(), key=len)
    if len(core) * 2 <= len(ids):  # no majority: say which disagree, not which is wrong
        return [
            f"tags {', '.join(map(str, ids))} disagree on scale (by up to "
            f"{100 * max(abs(r - 1) for r in ratios.values()):.0f} %): one of them is "
            "printed at another size than the map's, or the map is wrong"
        ]
    notes = []
    by_id = {t.detection.tag_id: t for t in tags}
    for i in ids:
        if i in core:
            continue
        ratio = float(np.median([ratios[i, j] for j in core]))
        size = by_id[i].size_m or math.nan
        notes.append(
            f"tag {i} looks {ratio * size:.3g} m, not the map's {size:g} m "
            f"({100 * (ratio - 1):+.0f} % against tags {', '.join(map(str, sorted(core)))}): "
            "printed at another size?"
        )
        by_id[i].notes.append(notes[-1])
    return notes
