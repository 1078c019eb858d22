"""Value types in and out of the localization filter: :class:`TagFix`, :class:`FixQuality`,
:class:`PoseWithCovariance`, :class:`CorrectionUpdate`, and the layer's :class:`LocalizeError`.

A fix is an absolute measurement of the robot's base in the map, ``T_map_base`` at ``stamp_ns``,
with a ``(6, 6)`` covariance in the right tangent of that pose, ordered ``[x, y, z, rx, ry, rz]``:
``T_true = T_map_base @ Exp(d)``, ``d ~ N(0, cov)`` (so the translation block is in the base frame,
as everywhere in tagloc; see :mod:`tagloc.geometry`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import TaglocError
from tagloc.geometry import SE2, SE3

#: Largest accepted ``max |C - C^T|`` relative to ``max |C|`` for a covariance handed in.
SYMMETRY_TOL = 1e-9


class LocalizeError(TaglocError, ValueError):
    """A fix, a query or an argument the localization layer cannot use; the message names it."""


def check_covariance(cov: npt.ArrayLike, dof: int, name: str) -> FloatArray:
    """Return ``cov`` as a read-only ``(dof, dof)`` float64 copy, symmetrized, if it is a finite,
    symmetric, positive-definite matrix.

    Raises
    ------
    LocalizeError
        Naming ``name`` and what is wrong (shape, NaN/inf, asymmetry, not positive definite).
    """
    array = np.array(cov, dtype=np.float64)
    if array.shape != (dof, dof):
        raise LocalizeError(f"{name} must be ({dof}, {dof}), got {array.shape}")
    if not np.isfinite(array).all():
        raise LocalizeError(f"{name} contains NaN or inf")
    scale = max(float(np.abs(array).max()), 1e-300)
    if float(np.abs(array - array.T).max()) > SYMMETRY_TOL * scale:
        raise LocalizeError(f"{name} is not symmetric")
    array = 0.5 * (array + array.T)
    try:
        np.linalg.cholesky(array)
    except np.linalg.LinAlgError:
        raise LocalizeError(f"{name} is not positive definite") from None
    array.flags.writeable = False
    return array


@dataclass(frozen=True, slots=True)
class FixQuality:
    """What the fix source knows about its own quality (gates read it; NaN = unknown).

    Attributes
    ----------
    reproj_err_px : float
        RMS corner reprojection error of the PnP solution, pixels.
    n_tags : int
        Tags in the solution (1 for a single-tag fix, more for a joint multi-tag PnP).
    range_m : float
        Camera-to-tag distance (the nearest tag for a multi-tag fix), metres.
    ambiguity_ratio : float
        ``reproj_err / reproj_err_alt`` of the two IPPE branches (0: unambiguous, near 1:
        the two-fold ambiguity is unresolved).
    view_angle_rad : float
        Angle between the tag normal and the ray to the camera.
    """

    reproj_err_px: float
    n_tags: int = 1
    range_m: float = math.nan
    ambiguity_ratio: float = 0.0
    view_angle_rad: float = math.nan


@dataclass(frozen=True, slots=True, eq=False)
class TagFix:
    """An absolute fix: the pose of the base in the map at one stamp, with its covariance.

    Attributes
    ----------
    stamp_ns : int
        Time of the measurement (the camera exposure), integer nanoseconds.
    T_map_base : SE3
        Maps points from the base frame into the map frame.
    cov : (6, 6) float, read-only
        Right-perturbation covariance of ``T_map_base``, ``[x, y, z, rx, ry, rz]``.
    source : str
        Who measured it: ``"tag:17"``, ``"tags:3,17"`` (joint PnP), ``"amcl"``... Per-source
        statistics and the moved-tag check key on this string.
    quality : FixQuality

    Raises
    ------
    LocalizeError
        On a float or bool stamp, a batch pose, an empty source, or a covariance that is not a
        finite symmetric positive-definite ``(6, 6)`` matrix.
    """

    stamp_ns: int
    T_map_base: SE3
    cov: FloatArray
    source: str
    quality: FixQuality

    def __post_init__(self) -> None:
        if isinstance(self.stamp_ns, bool) or not isinstance(self.stamp_ns, int | np.integer):
            raise LocalizeError(
                f"TagFix from {self.source!r}: stamp_ns must be an integer (ns), got "
                f"{type(self.stamp_ns).__name__}"
            )
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        if not isinstance(self.T_map_base, SE3) or self.T_map_base.is_batch:
            raise LocalizeError(f"TagFix from {self.source!r}: T_map_base must be one SE3")
        if not isinstance(self.source, str) or not self.source:
            raise LocalizeError("TagFix: source must be a non-empty string such as 'tag:17'")
        name = f"TagFix from {self.source!r} at {self.stamp_ns} ns: cov"
        object.__setattr__(self, "cov", check_covariance(self.cov, 6, name))

    def to_planar(self) -> tuple[SE2, FloatArray]:
        """The planar projection ``(x, y, yaw)`` of ``T_map_base`` and its ``(3, 3)`` covariance
        ``J cov J^T`` in the SE(2) right tangent ``[x, y, theta]`` (z, roll, pitch dropped;
        ``J`` from :func:`planar_projection_jacobian`)."""
        J = planar_projection_jacobian(self.T_map_base)
        return SE2.from_se3(self.T_map_base), J @ self.cov @ J.T


@dataclass(frozen=True, slots=True, eq=False)
class PartialFix:
    """An absolute fix that measures ``T_map_base`` only along some directions (a lidar scan
    match in a corridor knows y and yaw, not x): the filter's projected update
    (:mod:`tagloc.localize.projected_update`).

    Attributes
    ----------
    stamp_ns : int
    T_map_base : SE3
    basis : (6, k) float, read-only
        Orthonormal columns spanning the measured directions of the right tangent of
        ``T_map_base``, ``[x, y, z, rx, ry, rz]``; ``1 <= k <= 6``.
    cov : (k, k) float, read-only
        Covariance of ``basis.T @ Log(T_true^-1 T_map_base)``.
    source : str
        E.g. ``"lidar"``.
    quality : FixQuality
        Unused by the filter's quality limits (a partial fix comes with its own checks).

    Raises
    ------
    LocalizeError
        On a bad stamp, pose or source, a basis that is not ``(6, k)`` orthonormal, or a
        covariance that is not ``(k, k)`` symmetric positive definite.
    """

    stamp_ns: int
    T_map_base: SE3
    basis: FloatArray
    cov: FloatArray
    source: str
    quality: FixQuality = FixQuality(float("nan"), 0)

    def __post_init__(self) -> None:
        name = f"PartialFix from {self.source!r} at {self.stamp_ns} ns"
        if isinstance(self.stamp_ns, bool) or not isinstance(self.stamp_ns, int | np.integer):
            raise LocalizeError(f"{name}: stamp_ns must be an integer (ns)")
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        if not isinstance(self.T_map_base, SE3) or self.T_map_base.is_batch:
            raise LocalizeError(f"{name}: T_map_base must be one SE3")
        if not isinstance(self.source, str) or not self.source:
            raise LocalizeError("PartialFix: source must be a non-empty string such as 'lidar'")
        basis = np.array(self.basis, dtype=np.float64)
        k = basis.shape[1] if basis.ndim == 2 else -1
        if basis.ndim != 2 or basis.shape[0] != 6 or not 1 <= k <= 6:
            raise LocalizeError(f"{name}: basis must be (6, k), 1 <= k <= 6, got {basis.shape}")
        if not np.isfinite(basis).all() or not np.allclose(basis.T @ basis, np.eye(k), atol=1e-9):
            raise LocalizeError(f"{name}: basis columns must be orthonormal")
        basis.flags.writeable = False
        object.__setattr__(self, "basis", basis)
        object.__setattr__(self, "cov", check_covariance(self.cov, k, f"{name}: cov"))

    @property
    def k(self) -> int:
        """Number of measured directions."""
        return int(self.basis.shape[1])


def planar_projection_jacobian(T: SE3) -> FloatArray:
    """``J (3, 6)``: right perturbation ``[x, y, z, rx, ry, rz]`` of ``T`` to the right perturbation
    ``[x, y, theta]`` of ``SE2.from_se3(T)`` (yaw ``psi = atan2(R10, R00)``).

    ``T @ Exp(xi)`` moves the position by ``R rho``, i.e. by ``Rz(psi)^T (R rho)[:2]`` in the
    planar body frame; it moves the first column of ``R`` by ``R (phi x e_x)``, hence
    ``dpsi = (R00 dR10 - R10 dR00) / (R00^2 + R10^2)``. For a level pose ``J`` selects
    ``[x, y, rz]``.
    """
    R = T.rotation.matrix
    c, s = R[0, 0], R[1, 0]
    n2 = c * c + s * s
    n = math.sqrt(n2)
    J = np.zeros((3, 6))
    J[:2, :3] = np.array([[c, s], [-s, c]]) / n @ R[:2, :]
    # dR[:, 0] = R @ (0, phi_z, -phi_y): d(R10) = R11 phi_z - R12 phi_y, d(R00) likewise.
    J[2, 4] = (-c * R[1, 2] + s * R[0, 2]) / n2
    J[2, 5] = (c * R[1, 1] - s * R[0, 1]) / n2
    return J


@dataclass(frozen=True, slots=True, eq=False)
class PoseWithCovariance:
    """The base in the map with covariance (ROS ``PoseWithCovarianceStamped``-like).

    Attributes
    ----------
    stamp_ns : int
    frame_id, child_frame_id : str
        E.g. ``"map"`` and ``"base_link"``: ``T_map_base`` maps child into frame.
    T_map_base : SE3
    cov : (6, 6) float
        Right-perturbation covariance of ``T_map_base``, ``[x, y, z, rx, ry, rz]`` (translation
        block in the base frame; :func:`tagloc.geometry.cov_right_to_left` gives the map-frame
        covariance that a ROS message carries).
    """

    stamp_ns: int
    frame_id: str
    child_frame_id: str
    T_map_base: SE3
    cov: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class CorrectionUpdate:
    """One published ``map -> odom`` correction: valid from ``stamp_ns`` until the next one.

    Attributes
    ----------
    stamp_ns : int
    T_map_odom : SE3
    """

    stamp_ns: int
    T_map_odom: SE3
