"""Where each mapped tag should appear in a camera frame, and how sure that is.

From the node's estimate of the base in the map (``T_map_odom`` composed with the odometry) and
its covariance, the extrinsics ``T_base_cam``, the tag map and the camera model,
:func:`predict_tags` projects every mapped tag's corners into the image. Each corner's
uncertainty is the pose covariance pushed through the projection by central differences over
the covariance's square-root columns (``(P(+L_i) - P(-L_i)) / 2``, summed in quadrature: the
linearized projected covariance's diagonal, with the projection's curvature over one sigma
included); floors on the pose's sigma cover what a planar filter does not estimate. A tag's
region is the box of its corners widened by ``margin_sigma`` of those sigmas plus a fixed and a
side-proportional margin (its quiet zone and the detector's threshold tiles), aligned to the
detector's grid (:func:`tagloc.tags.regions.region_around`). :func:`plan_regions` merges the
regions that overlap and gives each the decimation its smallest tag allows.

Configuration: :class:`~tagloc.localize.config_roi.RegionConfig`; what the node does with the
regions (the fallback to the full frame and the counts): :mod:`tagloc.localize.roi_detector`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.localize.config_roi import RegionConfig
from tagloc.tags import TagMap
from tagloc.tags.detection import tag_object_points
from tagloc.tags.regions import PixelRegion, merge_regions, region_around

__all__ = ["MappedTag", "PredictedTag", "mapped_tags", "plan_regions", "predict_tags"]


@dataclass(frozen=True, slots=True, eq=False)
class MappedTag:
    """A tag of the map as the prediction needs it: id, corners ``(4, 3)`` in the map (the
    detection corner order), the face normal ``(3,)`` in the map."""

    tag_id: int
    corners_map: FloatArray
    normal_map: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class PredictedTag:
    """One mapped tag's predicted appearance.

    Attributes
    ----------
    tag_id : int
    corners_px : (4, 2) float
        Projected corners at the estimate (detection order, OpenCV pixel centers).
    sigma_px : (4, 2) float
        1-sigma of each corner's ``u`` and ``v`` from the pose covariance.
    side_px : float
        The shortest projected edge.
    region : PixelRegion
        The grid-aligned box the tag should be found in (clipped to the image).
    """

    tag_id: int
    corners_px: FloatArray
    sigma_px: FloatArray
    side_px: float
    region: PixelRegion


def mapped_tags(tag_map: TagMap, family: str, map_frame: str) -> tuple[MappedTag, ...]:
    """The tags of ``family`` placed in ``map_frame`` (tags in other frames, e.g. a moving cab,
    are not predicted from the map pose)."""
    out = []
    for entry in tag_map:
        if entry.family != family or entry.frame != map_frame:
            continue
        T_map_tag = entry.T_frame_tag()
        corners = T_map_tag.act(tag_object_points(float(entry.size)))
        normal = T_map_tag.rotation.as_matrix()[:, 2]
        out.append(MappedTag(int(entry.id), np.asarray(corners), np.asarray(normal)))
    return tuple(out)


def predict_tags(
    camera: CameraModel, T_map_base: SE3, cov_base: FloatArray, T_base_cam: SE3,
    tags: Sequence[MappedTag], config: RegionConfig, min_decimate: float = 1.0,
) -> list[PredictedTag]:  # fmt: skip
    """Project each tag with its uncertainty (module docstring).

    Parameters
    ----------
    camera : CameraModel
    T_map_base : SE3
        The estimate at the frame's stamp.
    cov_base : (6, 6) float
        Its right-perturbation covariance ``[x, y, z, rx, ry, rz]`` (base frame); the floors of
        ``config`` are added.
    T_base_cam : SE3
    tags : sequence of MappedTag
    config : RegionConfig
    min_decimate : float
        No region is searched at a smaller decimation (the full frame's: a smaller one would
        find other quads, and so other corners, than the full frame).

    Returns
    -------
    list of PredictedTag
        The tags in front of the camera, facing it within ``max_view_angle_deg``, at least
        ``min_tag_px`` on a side and with every corner in the image (``edge_tolerance_px``
        outside at most); in the order of ``tags``.
    """
    if not tags:
        return []
    cov = _floored(cov_base, config)
    L = np.linalg.cholesky(cov)
    deltas = np.vstack([np.zeros(6), L.T, -L.T])  # (13, 6): nominal, +columns, -columns
    T_cam_map = (T_map_base.plus(deltas) @ T_base_cam).inverse().as_matrix()  # (13, 4, 4)
    corners_map = np.stack([t.corners_map for t in tags])  # (N, 4, 3)
    points = corners_map.reshape(-1, 3)
    points_cam = np.einsum("kij,nj->kni", T_cam_map[:, :3, :3], points) + T_cam_map[:, None, :3, 3]
    pixels = camera.project(points_cam.reshape(-1, 3)).reshape(13, len(tags), 4, 2)
    nominal = pixels[0]
    spread = 0.5 * (pixels[1:7] - pixels[7:13])  # (6, N, 4, 2)
    sigma = np.sqrt(np.sum(spread**2, axis=0))
    # visibility at the estimate: in front, facing the camera
    R_cam_map, t_cam_map = T_cam_map[0, :3, :3], T_cam_map[0, :3, 3]
    centers_cam = corners_map.mean(axis=1) @ R_cam_map.T + t_cam_map
    normals_cam = np.stack([t.normal_map for t in tags]) @ R_cam_map.T
    distance = np.linalg.norm(centers_cam, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_view = -np.sum(normals_cam * centers_cam, axis=1) / distance
    min_cos = math.cos(math.radians(config.max_view_angle_deg))
    width, height = camera.width, camera.height
    edge = config.edge_tolerance_px
    far_edge = np.array([width - 1 + edge, height - 1 + edge])
    out = []
    for i, tag in enumerate(tags):
        corners = nominal[i]
        if not np.isfinite(corners).all() or not cos_view[i] >= min_cos:
            continue
        if (points_cam[0, 4 * i : 4 * i + 4, 2] <= 0.0).any():
            continue
        if (corners < -edge).any() or (corners > far_edge).any():
            continue
        side = float(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1).min())
        if side < config.min_tag_px:
            continue
        tag_sigma = np.where(np.isfinite(sigma[i]), sigma[i], side)
        margin = (
            config.margin_sigma * tag_sigma + config.min_margin_px
            + config.margin_side_fraction * side
        )  # fmt: skip
        low, high = (corners - margin).min(axis=0), (corners + margin).max(axis=0)
        region = region_around(
            float(low[0]), float(low[1]), float(high[0]), float(high[1]), width, height,
            max(quad_decimate(side, config), min_decimate),
        )  # fmt: skip
        if region is not None:
            out.append(PredictedTag(tag.tag_id, corners, tag_sigma, side, region))
    return out


def quad_decimate(side_px: float, config: RegionConfig) -> float:
    """The largest integer decimation up to ``max_quad_decimate`` leaving ``side_px`` at least
    ``min_decimated_side_px`` decimated pixels (at least 1)."""
    d = math.floor(side_px / config.min_decimated_side_px)
    return float(min(max(d, 1), config.max_quad_decimate))


def plan_regions(
    predicted: Iterable[PredictedTag], width: int, height: int
) -> list[PixelRegion]:
    """The predicted tags' regions merged where they overlap (the smaller decimation)."""
    return merge_regions((p.region for p in predicted), width, height)


def _floored(cov_base: FloatArray, config: RegionConfig) -> FloatArray:
    """``cov_base`` (symmetrized, NaN-free) plus the floors' variances on the diagonal."""
    cov = np.nan_to_num(0.5 * (cov_base + cov_base.T), nan=0.0, posinf=0.0, neginf=0.0)
    floors = np.array(
        [config.min_translation_sigma_m] * 3 + [config.min_rotation_sigma_rad] * 3
    )
    cov = cov + np.diag(floors**2 + 1e-12)
    # a covariance that is not positive definite (rounding of a near-singular one) is lifted
    eig = np.linalg.eigvalsh(cov)
    if eig[0] <= 0.0:
        cov = cov + np.eye(6) * (1e-9 - eig[0])
    return cov
