"""Tags stuck on the wrong tilt: the planar ambiguity, resolved with all of a tag's corners.

A tag seen only face-on and far away has two tilts that both fit each view (the IPPE
ambiguity); when most views start on the wrong one, the joint optimum can stay there (measured:
2 of 30 simulated tags at ~19 degrees). After optimizing, each tag's alternative is the tilt its
observations' *other* branches agree on (:func:`~tagloc.mapping.initialize.consensus_rotation`);
if the tag's corners, seen from the optimized keyframes, fit the alternative better (robust
cost lower by :data:`MIN_GAIN`), the tag is flipped and the builder optimizes again.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.mapping.initialize import consensus_rotation, inverse_h, rotation_angle
from tagloc.mapping.observations import Observations
from tagloc.tags.detection import tag_object_points

FloatArray = npt.NDArray[np.float64]
MIN_GAIN = 0.8
#: An alternative tilt within this factor of the chosen one's cost is reported as ambiguous.
AMBIGUOUS_RATIO = 1.25


def _cost(
    obs: Observations,
    idx: npt.NDArray[np.int64],
    M_map_base: FloatArray,
    M_map_tag: FloatArray,
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    sigma_px: float,
) -> float:
    """Cauchy cost of the corners of observations ``idx`` of one tag at ``M_map_tag``."""
    total = 0.0
    cams = np.array(obs.camera)[idx]
    for name in np.unique(cams):
        sel = idx[cams == name]
        M_cam_tag = (
            inverse_h(M_map_base[obs.keyframe[sel]] @ T_base_cam[str(name)].as_matrix()) @ M_map_tag
        )
        points = tag_object_points(float(obs.tag_sizes[obs.tag[sel[0]]]))
        p = np.einsum("mij,nj->mni", M_cam_tag[:, :3, :3], points) + M_cam_tag[:, None, :3, 3]
        with np.errstate(all="ignore"):
            px = cameras[str(name)].project(p.reshape(-1, 3)).reshape(-1, 4, 2)
        r2 = np.sum((px - obs.corners_px[sel]) ** 2, axis=2) / sigma_px**2
        total += float(np.sum(np.log1p(np.where(np.isfinite(r2), r2, 1e6) / 9.0)))
    return total


def flip_stuck_tags(
    obs: Observations,
    M_map_base: FloatArray,
    M_map_tag: Mapping[int, FloatArray],
    fixed: set[int],
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    sigma_px: float,
) -> tuple[dict[int, FloatArray], list[int], list[int]]:
    """``M_map_tag`` with stuck tags flipped to their better tilt; flipped and ambiguous indices.

    Ambiguous: the alternative tilt fits the corners almost as well (within
    :data:`AMBIGUOUS_RATIO`): the views do not determine the tag's tilt (seen only face-on or
    far); the reviewer should know (measured: 3 of 30 simulated tags, ~20 degrees off).
    """
    result = {j: np.array(M) for j, M in M_map_tag.items()}
    flipped, ambiguous = [], []
    implied = M_map_base[obs.keyframe, None] @ obs.T_base_tag  # (M, 2, 4, 4)
    for j, M in M_map_tag.items():
        if j in fixed:
            continue
        idx = np.flatnonzero(obs.tag == j)
        R = implied[idx, :, :3, :3]
        angle = rotation_angle(np.broadcast_to(M[:3, :3], R.shape), R)  # (n, 2)
        other = R[np.arange(len(idx)), np.argmax(angle, axis=1)]
        R_alt = consensus_rotation(other[:, None])
        if float(rotation_angle(M[:3, :3], R_alt)) < np.radians(3.0):
            continue
        M_alt = np.array(M)
        M_alt[:3, :3] = R_alt
        now = _cost(obs, idx, M_map_base, M, cameras, T_base_cam, sigma_px)
        alt = _cost(obs, idx, M_map_base, M_alt, cameras, T_base_cam, sigma_px)
        if alt < MIN_GAIN * now:
            result[j] = M_alt
            flipped.append(j)
        elif alt < AMBIGUOUS_RATIO * now:
            ambiguous.append(j)
    return result, flipped, ambiguous
