"""Corner reprojection residuals of a map's observations, through the real camera models.

The QA report (:mod:`tagloc.mapping.report`) and the factor export
(:mod:`tagloc.mapping.graph_export`) show them at the optimized poses; NaN where a corner does
not project.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.observations import Observations
from tagloc.tags.detection import tag_object_points

__all__ = ["corner_residuals_px", "observation_rms_px", "rms"]


def observation_rms_px(residuals_px: FloatArray) -> FloatArray:
    """``(M,)`` RMS over its four corners of each observation's ``(M, 4, 2)`` residuals, px."""
    err = np.linalg.norm(residuals_px, axis=2)
    return np.asarray(np.sqrt(np.mean(err**2, axis=1)))


def corner_residuals_px(
    obs: Observations,
    M_map_base: FloatArray,
    M_map_tag: Mapping[int, FloatArray],
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
) -> FloatArray:
    """``(M, 4, 2)`` projected minus detected corners of each observation at the given poses, px
    (NaN where a corner does not project)."""
    out = np.full((len(obs), 4, 2), np.nan)
    cams = np.array(obs.camera)
    tags = np.array([M_map_tag[int(j)] for j in obs.tag])
    M_base_tag = inverse_h(M_map_base[obs.keyframe]) @ tags
    for name in np.unique(cams):
        idx = np.flatnonzero(cams == name)
        M_cam_tag = inverse_h(T_base_cam[str(name)].as_matrix())[None] @ M_base_tag[idx]
        points_tag = tag_object_points(1.0)[None] * obs.tag_sizes[obs.tag[idx]][:, None, None]
        points_cam = (
            np.einsum("mij,mnj->mni", M_cam_tag[:, :3, :3], points_tag) + M_cam_tag[:, None, :3, 3]
        )
        with np.errstate(all="ignore"):
            px = cameras[str(name)].project(points_cam.reshape(-1, 3)).reshape(-1, 4, 2)
        out[idx] = px - obs.corners_px[idx]
    return out


def rms(values: FloatArray) -> float:
    """Root mean square of the finite values (NaN if none)."""
    v = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(v**2))) if len(v) else float("nan")
