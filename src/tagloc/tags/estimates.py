"""What PnP returns: :class:`TagPoseEstimate` (one tag, both branches) and
:class:`JointPoseEstimate` (the camera in the map from several tags), with their covariances.

Computed by :mod:`tagloc.tags.pnp` (which re-exports both); frames and covariance conventions
are stated in the attributes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.geometry.small_batch import row_norms


def _range_and_view_angle(R: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Range ``|t|`` and the angle between the tag normal ``R[:, 2]`` and the ray ``-t``."""
    range_m = row_norms(t)
    with np.errstate(all="ignore"):
        cos_angle = -np.einsum("...i,...i->...", R[..., :, 2], t) / range_m
    return range_m, np.arccos(np.clip(cos_angle, -1.0, 1.0))


@dataclass(frozen=True, slots=True, eq=False)
class TagPoseEstimate:
    """Pose of one tag in the camera optical frame, both IPPE branches, with covariance.

    Attributes
    ----------
    tag_id : int
    size : float
        Black-border edge length used, metres.
    T_cam_tag, T_cam_tag_alt : SE3
        Chosen pose (lowest refined reprojection error, unless a policy swapped them) and the
        other branch of the two-fold ambiguity (refined; the raw IPPE one if refinement took it
        into the chosen minimum).
    reproj_err_px, reproj_err_alt_px : float
        RMS corner reprojection error (pixels, through the real camera model) of each.
    ambiguity_ratio : float
        ``reproj_err_px / reproj_err_alt_px``: <= 1 from PnP (0 if there is no alternative);
        > 1 only after a policy chose the alternative (:meth:`swapped`).
    cov_cam_tag, cov_cam_tag_alt : (6, 6) float
        Covariance in the right tangent of each pose, ``[x, y, z, rx, ry, rz]``:
        ``T_true = T_cam_tag @ Exp(d)``, ``d ~ N(0, cov)`` (so the translation block is in the tag
        frame), given that branch (:func:`tagloc.tags.covariance.pose_covariance`). Estimates
        accepted by :func:`tagloc.tags.observation.observe_tags` also carry the other branch's
        posterior weight (:func:`tagloc.tags.covariance.ambiguity_mixture`). For ``T_map_cam`` /
        ``T_map_base`` use :func:`tagloc.tags.covariance.map_cam_from_tag`.
    range_m : float
        Distance camera center to tag center.
    view_angle_rad : float
        Angle between the tag normal (its +z) and the ray from the tag to the camera.
    cov_rot_laplace, cov_rot_laplace_alt : (3, 3) float
        Rotation block of each branch's likelihood lobe: ``sigma^2 (J^T J)^-1`` plus the valley
        term towards the other branch (no other inflation). The ambiguity policy weighs a prior
        with it (:func:`tagloc.tags.gates.prior_evidence`).
    """

    tag_id: int
    size: float
    T_cam_tag: SE3
    T_cam_tag_alt: SE3
    reproj_err_px: float
    reproj_err_alt_px: float
    ambiguity_ratio: float
    cov_cam_tag: FloatArray
    cov_cam_tag_alt: FloatArray
    range_m: float
    view_angle_rad: float
    cov_rot_laplace: FloatArray
    cov_rot_laplace_alt: FloatArray

    @property
    def sse_px2(self) -> float:
        """Sum of squared pixel residuals of ``T_cam_tag`` (8 components)."""
        return 4.0 * self.reproj_err_px**2

    @property
    def sse_alt_px2(self) -> float:
        """Sum of squared pixel residuals of ``T_cam_tag_alt``."""
        return 4.0 * self.reproj_err_alt_px**2

    def with_covariance(self, cov_cam_tag: FloatArray) -> TagPoseEstimate:
        """The same estimate with ``cov_cam_tag`` replaced (``dataclasses.replace``, faster)."""
        return TagPoseEstimate(
            self.tag_id,
            self.size,
            self.T_cam_tag,
            self.T_cam_tag_alt,
            self.reproj_err_px,
            self.reproj_err_alt_px,
            self.ambiguity_ratio,
            cov_cam_tag,
            self.cov_cam_tag_alt,
            self.range_m,
            self.view_angle_rad,
            self.cov_rot_laplace,
            self.cov_rot_laplace_alt,
        )

    def swapped(self) -> TagPoseEstimate:
        """The same estimate with the alternative branch chosen (range, angle recomputed)."""
        alt = self.T_cam_tag_alt
        range_m, angle = _range_and_view_angle(alt.rotation.matrix, alt.translation)
        return TagPoseEstimate(
            self.tag_id,
            self.size,
            alt,
            self.T_cam_tag,
            self.reproj_err_alt_px,
            self.reproj_err_px,
            _ratio(self.reproj_err_alt_px, self.reproj_err_px),
            self.cov_cam_tag_alt,
            self.cov_cam_tag,
            float(range_m),
            float(angle),
            self.cov_rot_laplace_alt,
            self.cov_rot_laplace,
        )


@dataclass(frozen=True, slots=True, eq=False)
class JointPoseEstimate:
    """Camera pose in the map from all corners of several tags (:func:`estimate_joint_pose`).

    Attributes
    ----------
    tag_ids : tuple of int
    T_map_cam, T_map_cam_alt : SE3
        Best minimum and the best other one (the worst start if there is no other minimum).
    cov_map_cam, cov_map_cam_alt : (6, 6) float
        Right-tangent covariances of each, ``[x, y, z, rx, ry, rz]`` (camera frame).
    reproj_err_px, reproj_err_alt_px : float
        RMS corner reprojection errors (``inf``: no alternative).
    cov_rot_laplace, cov_rot_laplace_alt : (3, 3) float
        Laplace rotation covariances in the right tangent of ``T_cam_map`` (map frame axes).
    n_corners : int
    T_map_base : SE3 or None
        ``T_map_cam @ T_base_cam^-1`` if extrinsics were given.
    cov_map_base : (6, 6) float or None
        Its right-tangent covariance.
    """

    tag_ids: tuple[int, ...]
    T_map_cam: SE3
    cov_map_cam: FloatArray
    reproj_err_px: float
    T_map_cam_alt: SE3
    cov_map_cam_alt: FloatArray
    reproj_err_alt_px: float
    cov_rot_laplace: FloatArray
    cov_rot_laplace_alt: FloatArray
    n_corners: int
    T_map_base: SE3 | None = None
    cov_map_base: FloatArray | None = None

    @property
    def sse_px2(self) -> float:
        """Sum of squared pixel residuals (``2 n_corners`` components)."""
        return self.n_corners * self.reproj_err_px**2

    @property
    def sse_alt_px2(self) -> float:
        """The same for the alternative."""
        return self.n_corners * self.reproj_err_alt_px**2

    @property
    def ambiguity_ratio(self) -> float:
        """``reproj_err_px / reproj_err_alt_px`` (0 without alternative)."""
        return _ratio(self.reproj_err_px, self.reproj_err_alt_px)

    def swapped(self) -> JointPoseEstimate:
        """The alternative chosen instead (``T_map_base`` is dropped: recompute it)."""
        return JointPoseEstimate(
            self.tag_ids,
            self.T_map_cam_alt,
            self.cov_map_cam_alt,
            self.reproj_err_alt_px,
            self.T_map_cam,
            self.cov_map_cam,
            self.reproj_err_px,
            self.cov_rot_laplace_alt,
            self.cov_rot_laplace,
            self.n_corners,
        )


def _ratio(err: float, err_alt: float) -> float:
    """``err / err_alt`` with ``0 / 0 = 1`` (two exact fits) and ``x / inf = 0``."""
    if err_alt == 0.0:
        return 1.0 if err == 0.0 else float("inf")
    return float(err / err_alt)
