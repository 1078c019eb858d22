"""Keyframes and PnP tag observations of a survey (the measurements of the factor graph).

1. Frames are sorted by stamp; ignored ids are dropped; frames outside the odometry's span are
   dropped (counted); every stamp with at least one detection becomes a keyframe, shared by all
   cameras that saw tags at that stamp (a stereo pair is one keyframe).
2. Odometry is interpolated to each keyframe stamp (slerp on rotation, linear on translation).
3. Each detection gives both IPPE branches of ``T_cam_tag`` (:func:`tagloc.tags.estimate_tag_poses`)
   with their covariances (:func:`pixel_covariance` by default, or the PnP module's inflated
   ones), moved to ``T_base_tag = T_base_cam @ T_cam_tag``.
   The right-tangent covariance of ``T_cam_tag`` is also that of ``T_base_tag`` (a left
   multiplication by a constant does not change the right tangent).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, hat
from tagloc.mapping.survey import MappingError, Survey, TagKey
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.pnp import estimate_tag_poses

logger = logging.getLogger(__name__)

IntArray = npt.NDArray[np.int64]
Progress = Callable[[int, int], None]
#: Detections per call of :func:`estimate_tag_poses`.
_CHUNK = 512


@dataclass(frozen=True, slots=True, eq=False)
class Observations:
    """``M`` tag observations from ``K`` keyframes (structure of arrays).

    Attributes
    ----------
    keyframe_stamps_ns : (K,) int64
    T_odom_base : SE3 batch of K
        Odometry interpolated at the keyframe stamps.
    tag_keys : tuple of (family, id)
        The tags observed, sorted; ``tag`` indexes it.
    tag_sizes : (T,) float
        Edge length of each tag, m.
    keyframe, tag : (M,) int64
    camera : tuple of M str
    T_base_tag : (M, 2, 4, 4) float
        Both IPPE branches (``[:, 0]`` the lower reprojection error).
    cov : (M, 2, 6, 6) float
        Right-tangent covariance of each branch, ``[x, y, z, rx, ry, rz]``.
    ambiguity : (M,) float
        IPPE ambiguity ratio (lower is less ambiguous).
    range_m : (M,) float
    corners_px : (M, 4, 2) float
        The detected corners (tagloc order), for reprojection residuals.
    dropped : dict of str to int
        Inputs left out, by reason.
    """

    keyframe_stamps_ns: IntArray
    T_odom_base: SE3
    tag_keys: tuple[TagKey, ...]
    tag_sizes: FloatArray
    keyframe: IntArray
    tag: IntArray
    camera: tuple[str, ...]
    T_base_tag: FloatArray
    cov: FloatArray
    ambiguity: FloatArray
    range_m: FloatArray
    corners_px: FloatArray
    dropped: dict[str, int]

    def __len__(self) -> int:
        return len(self.keyframe)


def interpolate_odometry(survey: Survey, stamps_ns: IntArray) -> SE3:
    """``T_odom_base`` at ``stamps_ns`` (inside the odometry span), interpolated."""
    t = survey.odom_stamps_ns
    idx = np.clip(np.searchsorted(t, stamps_ns, side="right") - 1, 0, len(t) - 2)
    alpha = (stamps_ns - t[idx]) / (t[idx + 1] - t[idx]).astype(np.float64)
    T = survey.T_odom_base
    return T[idx].interpolate_rt(T[idx + 1], np.clip(alpha, 0.0, 1.0))


def pixel_covariance(
    M_cam_tag: FloatArray, sizes: FloatArray, camera: CameraModel, noise: NoiseModel
) -> FloatArray:
    """``(M, 6, 6)`` Gauss-Newton covariance of ``T_cam_tag`` from its corners' pixel noise.

    ``sigma_px^2 (J^T J)^-1`` with ``J`` the ``(8, 6)`` reprojection Jacobian for a right
    perturbation ``[x, y, z, rx, ry, rz]`` (the Cramer-Rao bound at the given branch), plus the
    noise model's floor. Unlike :func:`tagloc.tags.pose_covariance` it has no valley term towards
    the other IPPE branch: in the graph the branch is chosen at the estimate, so the ambiguity
    is resolved by all the other observations instead of being spread over this one.
    """
    m = len(M_cam_tag)
    R, t = M_cam_tag[:, :3, :3], M_cam_tag[:, :3, 3]
    points_tag = tag_object_points(1.0)[None] * sizes[:, None, None]  # (M, 4, 3)
    points_cam = np.einsum("mij,mnj->mni", R, points_tag) + t[:, None]
    _, J_px_p = camera.project_with_jacobian(points_cam.reshape(-1, 3))
    J_p_xi = np.empty((m, 4, 3, 6))
    J_p_xi[..., :3] = R[:, None]
    J_p_xi[..., 3:] = -np.einsum("mij,mnjl->mnil", R, hat(points_tag))
    J = (J_px_p.reshape(m, 4, 2, 3) @ J_p_xi).reshape(m, 8, 6)
    info = np.einsum("mki,mkj->mij", J, J) / noise.sigma_px**2
    floor = [noise.floor_translation_m**2] * 3 + [noise.floor_rotation_rad**2] * 3
    with np.errstate(all="ignore"):
        cov = np.linalg.inv(info) + np.diag(floor)
    return np.asarray(0.5 * (cov + np.swapaxes(cov, 1, 2)))


def collect_observations(
    survey: Survey,
    noise: NoiseModel,
    max_range_m: float,
    progress: Progress | None = None,
    covariance: str = "pixel",
) -> Observations:
    """Keyframes and PnP observations of ``survey`` (steps 1-3 of the module docstring).

    Raises
    ------
    MappingError
        If a tag is observed whose size is unknown, or no frame has a usable detection.
    """
    dropped = {"ignored_tag": 0, "outside_odometry": 0, "no_pnp_pose": 0, "beyond_range": 0}
    t0, t1 = int(survey.odom_stamps_ns[0]), int(survey.odom_stamps_ns[-1])
    frames = sorted(survey.frames, key=lambda f: (f.stamp_ns, f.camera))
    usable: list[tuple[int, str, list[TagDetection]]] = []
    for frame in frames:
        dets = [d for d in frame.detections if d.tag_id not in survey.ignore_tags]
        dropped["ignored_tag"] += len(frame.detections) - len(dets)
        if dets and not t0 <= frame.stamp_ns <= t1:
            dropped["outside_odometry"] += len(dets)
        elif dets:
            usable.append((frame.stamp_ns, frame.camera, dets))
    if not usable:
        raise MappingError(f"{survey.source}: no tag detection inside the odometry's time span")
    keys = sorted({(d.family, d.tag_id) for _, _, dets in usable for d in dets})
    tag_index = {key: j for j, key in enumerate(keys)}
    sizes = np.array([survey.tag_size(key) for key in keys])
    stamps = np.array(sorted({s for s, _, _ in usable}), dtype=np.int64)
    kf_index = {int(s): k for k, s in enumerate(stamps)}
    # 3. PnP, batched per camera over frames (estimate_tag_poses is vectorized over tags)
    flat = [(stamp, cam, d) for stamp, cam, dets in usable for d in dets]
    kf = np.array([kf_index[s] for s, _, _ in flat], dtype=np.int64)
    tag = np.array([tag_index[(d.family, d.tag_id)] for _, _, d in flat], dtype=np.int64)
    cams = np.array([c for _, c, _ in flat])
    corners = np.array([d.corners_px for _, _, d in flat], dtype=np.float64)
    T = np.full((len(flat), 2, 4, 4), np.nan)
    cov = np.full((len(flat), 2, 6, 6), np.nan)
    amb, rng = np.full(len(flat), np.nan), np.full(len(flat), np.nan)
    done = 0
    for cam in sorted(set(cams.tolist())):
        M_base_cam = survey.T_base_cam[cam].as_matrix()
        idx_cam = np.flatnonzero(cams == cam)
        for chunk in np.array_split(idx_cam, max(1, len(idx_cam) // _CHUNK)):
            camera = survey.cameras[cam]
            est = estimate_tag_poses(
                tag[chunk].tolist(), corners[chunk], sizes[tag[chunk]], camera, noise
            )
            for i, e in zip(chunk, est, strict=True):
                if e is None:
                    continue
                M_cam_tag = np.array([e.T_cam_tag.as_matrix(), e.T_cam_tag_alt.as_matrix()])
                T[i] = M_base_cam @ M_cam_tag
                if covariance == "pixel":
                    cov[i] = pixel_covariance(M_cam_tag, np.full(2, e.size), camera, noise)
                else:
                    cov[i] = (e.cov_cam_tag, e.cov_cam_tag_alt)
                amb[i], rng[i] = e.ambiguity_ratio, e.range_m
            done += len(chunk)
            if progress is not None:
                progress(done, len(flat))
    ok = np.isfinite(rng) & np.isfinite(cov).all(axis=(1, 2, 3))
    dropped["no_pnp_pose"] = int((~ok).sum())
    dropped["beyond_range"] = int((ok & (rng > max_range_m)).sum())
    keep = np.flatnonzero(ok & (rng <= max_range_m))
    if len(keep) == 0:
        raise MappingError(f"{survey.source}: no detection gave a usable tag pose")
    logger.info("%d observations from %d keyframes; dropped %s", len(keep), len(stamps), dropped)
    return Observations(
        keyframe_stamps_ns=stamps,
        T_odom_base=interpolate_odometry(survey, stamps),
        tag_keys=tuple(keys),
        tag_sizes=sizes,
        keyframe=kf[keep],
        tag=tag[keep],
        camera=tuple(str(c) for c in cams[keep]),
        T_base_tag=T[keep],
        cov=cov[keep],
        ambiguity=amb[keep],
        range_m=rng[keep],
        corners_px=corners[keep],
        dropped=dropped,
    )
