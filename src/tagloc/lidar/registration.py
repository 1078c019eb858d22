"""Scan registration with small_gicp: a prepared :class:`Target`, one :func:`register` call.

small_gicp (K. Koide, "small_gicp: Efficient and parallel algorithms for point cloud
registration", JOSS 2024) minimises ``E(T) = 1/2 sum_i r_i^T M_i r_i`` over ``T_target_source``
with Gauss-Newton, where ``r_i = q_i - T p_i`` pairs each source point with its nearest target
point and, for GICP, ``M_i = (C_q + R C_p R^T)^-1`` fuses the two points' local covariances
(regularised to planes: eigenvalues ``(1e-3, 1, 1)``). Each step updates
``T <- T Exp(delta)`` with ``delta = [rx, ry, rz, x, y, z]``: a *right* (body) perturbation with
rotation first. :func:`register` returns the Hessian ``H = sum J^T M J`` permuted to tagloc's
``[x, y, z, rx, ry, rz]``; the perturbation side is already tagloc's (``T (+) xi = T Exp(xi)``).
At ``xi = 0`` both Exp maps have identity derivative, so the permutation is exact
(``tests/lidar/test_registration.py`` checks it by finite differences of small_gicp's own
gradient ``b``).

small_gicp's ``H`` is not the point-to-plane information the lidar fix needs, so
:func:`register` searches each source point's nearest target point once more at the final pose
(about a tenth of the registration's time): for GICP, ``M_i`` keeps the regularised in-plane
terms (a straight corridor's axis reads as constrained); its ``PLANE_ICP`` factor takes the
residual ``n * r`` element by element, not ``n^T r`` (a wall askew to the axes pulls along
itself); ``H`` is taken one step before the final pose; and the fix's covariance needs each
pair's distance, not only their sum (``error``).

The target (a premap or a keyframe) is downsampled, its covariances estimated and its KD-tree
built ONCE, in :meth:`Target.from_points`; each scan then pays only for its own preprocessing
and the optimisation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import small_gicp
from pydantic import Field

from tagloc.config import MAX_THREADS, StrictModel
from tagloc.geometry import SE3
from tagloc.lidar.cloud import finite_points

__all__ = ["Registration", "RegistrationConfig", "Target", "register"]

#: small_gicp's tangent [rx, ry, rz, x, y, z] -> tagloc's [x, y, z, rx, ry, rz].
SMALL_GICP_TO_TAGLOC = np.array([3, 4, 5, 0, 1, 2])


class RegistrationConfig(StrictModel):
    """How a scan is registered against a target (small_gicp)."""

    voxel_m: float = Field(0.25, ge=0.01, le=10.0)
    """Voxel edge (m) both clouds are downsampled to before registration."""
    max_correspondence_m: float = Field(1.0, gt=0.0, le=100.0)
    """Pairs farther apart than this (m) are outliers (not in the cost, not inliers)."""
    max_iterations: int = Field(30, ge=1, le=1000)
    """Gauss-Newton iterations at most."""
    num_threads: int = Field(1, ge=1, le=MAX_THREADS)
    """Threads small_gicp may use (1: the node shares its core with the other fix sources)."""
    kernel: Literal["GICP", "PLANE_ICP", "ICP"] = "GICP"
    """The per-pair cost: ``GICP`` (distribution to distribution, default), ``PLANE_ICP``
    (point to plane) or ``ICP`` (point to point: biased between two differently sampled clouds,
    1 deg off in the room of ``tests/lidar/test_registration.py`` where the others are within
    0.1 deg; for comparison only)."""
    num_neighbors: int = Field(10, ge=5, le=100)
    """Neighbours used to estimate each point's covariance / normal."""
    rotation_epsilon_rad: float = Field(1e-4, gt=0.0, le=1.0)
    """Converged when a step rotates less than this (rad) ..."""
    translation_epsilon_m: float = Field(1e-4, gt=0.0, le=1.0)
    """... and moves less than this (m)."""


class Target:
    """A point cloud prepared for registration: downsampled, covariances, KD-tree (built once).

    Build with :meth:`from_points`; reuse for every scan (a premap at node start, not per scan).
    """

    __slots__ = ("_cloud", "_normals", "_points", "_tree", "voxel_m")

    def __init__(self, cloud: Any, tree: Any, voxel_m: float) -> None:
        self._cloud = cloud
        self._tree = tree
        self.voxel_m = voxel_m
        self._points = np.array(np.asarray(cloud.points())[:, :3])
        self._normals = np.array(np.asarray(cloud.normals())[:, :3])
        self._points.flags.writeable = self._normals.flags.writeable = False

    @classmethod
    def from_points(cls, points: npt.ArrayLike, config: RegistrationConfig) -> Target:
        """Prepare ``points`` (``(N, 3)`` metres, in the target frame; NaN rows dropped)."""
        cloud, tree = small_gicp.preprocess_points(
            finite_points(points),
            downsampling_resolution=config.voxel_m,
            num_neighbors=config.num_neighbors,
            num_threads=config.num_threads,
        )
        return cls(cloud, tree, config.voxel_m)

    def __len__(self) -> int:
        return int(self._points.shape[0])

    @property
    def points(self) -> np.ndarray:
        """``(M, 3)`` the downsampled target points (metres)."""
        return self._points

    @property
    def normals(self) -> np.ndarray:
        """``(M, 3)`` unit normals of the downsampled target points."""
        return self._normals


@dataclass(frozen=True, slots=True, eq=False)
class Registration:
    """The result of :func:`register`.

    Attributes
    ----------
    T_target_source : SE3
        Maps source points into the target frame.
    hessian : (6, 6) float
        small_gicp's Gauss-Newton ``H = sum J^T M J`` at the last linearisation, in tagloc's
        order ``[x, y, z, rx, ry, rz]``, body tangent of ``T_target_source``. Units follow
        ``M`` (for GICP: the regularised covariances, not metres^-2; see :mod:`tagloc.lidar.fix`
        for the scale).
    error : float
        small_gicp's reported final cost ``1/2 sum r^T M r`` (it is evaluated after the last
        step, not at the last linearisation; for information only).
    plane_hessian : (6, 6) float
        ``sum_i g_i g_i^T`` over the inliers at ``T_target_source``, ``g_i`` the gradient of the
        point-to-plane distance ``n_i^T (T p_i - q_i)`` (m) with respect to the body tangent
        ``[x, y, z, rx, ry, rz]``: the information of the pose for unit point-to-plane noise,
        free of GICP's covariance regularisation (its in-plane terms). The lidar fix uses it.
    rmse_m : float
        RMS point-to-plane distance (m) of the inlier source points to their nearest target
        point's plane, at ``T_target_source``.
    sigma_m : float
        Robust scale of those distances: ``1.4826 * median(|d|)`` (m; a normal distribution's
        standard deviation, unmoved by the few pairs that straddle an edge or a corner).
    num_plane_inliers : int
        The points behind ``rmse_m``, ``sigma_m`` and ``plane_hessian``.
    inlier_fraction : float
        ``num_inliers`` over the downsampled source points.
    num_inliers, num_points : int
        Pairs within ``max_correspondence_m``; downsampled source points.
    converged : bool
    iterations : int
    """

    T_target_source: SE3
    hessian: np.ndarray
    error: float
    plane_hessian: np.ndarray
    plane_scatter: np.ndarray
    rmse_m: float
    sigma_m: float
    num_plane_inliers: int
    inlier_fraction: float
    num_inliers: int
    num_points: int
    converged: bool
    iterations: int


def register(
    source_points: npt.ArrayLike,
    target: Target,
    T_target_source_init: SE3,
    config: RegistrationConfig,
) -> Registration:
    """Register ``source_points`` (``(N, 3)`` metres, source frame) against ``target``.

    Steps: preprocess the source (downsample to ``voxel_m``, covariances); Gauss-Newton from
    ``T_target_source_init``; permute the Hessian to tagloc's order; measure the inliers'
    point-to-plane RMS. An empty source (or target) gives a non-converged result with
    0 inliers and a zero Hessian.
    """
    source = finite_points(source_points)
    if source.shape[0] == 0 or len(target) == 0:
        return _empty(T_target_source_init)
    cloud, _ = small_gicp.preprocess_points(
        source,
        downsampling_resolution=config.voxel_m,
        num_neighbors=config.num_neighbors,
        num_threads=config.num_threads,
    )
    result = small_gicp.align(
        target._cloud,
        cloud,
        target._tree,
        init_T_target_source=T_target_source_init.as_matrix(),
        registration_type=config.kernel,
        max_correspondence_distance=config.max_correspondence_m,
        num_threads=config.num_threads,
        max_iterations=config.max_iterations,
        rotation_epsilon=config.rotation_epsilon_rad,
        translation_epsilon=config.translation_epsilon_m,
    )
    T_target_source = SE3.from_matrix(result.T_target_source, normalize=True)
    points = np.asarray(cloud.points())[:, :3]
    order = SMALL_GICP_TO_TAGLOC
    hessian = np.asarray(result.H)[np.ix_(order, order)]
    plane = _point_to_plane(points, target, T_target_source, config)
    return Registration(
        T_target_source=T_target_source,
        hessian=0.5 * (hessian + hessian.T),
        error=float(result.error),
        plane_hessian=plane[0],
        plane_scatter=plane[1],
        rmse_m=plane[2],
        sigma_m=plane[3],
        num_plane_inliers=plane[4],
        inlier_fraction=result.num_inliers / points.shape[0],
        num_inliers=int(result.num_inliers),
        num_points=int(points.shape[0]),
        converged=bool(result.converged),
        iterations=int(result.iterations) + 1,
    )


def _point_to_plane(
    points_source: np.ndarray, target: Target, T_target_source: SE3, config: RegistrationConfig
) -> tuple[np.ndarray, np.ndarray, float, float, int]:
    """Point-to-plane information, RMS and robust sigma (m, ``nan`` when no inlier) and count
    of the moved source points within the correspondence radius of their nearest target point.

    The distance of ``T p`` to the plane ``(q, n)`` is ``d = n^T (R p + t - q)``; under a body
    perturbation ``T Exp(xi)`` its gradient is ``g = [R^T n, p x (R^T n)]`` (Sola et al. 2018,
    App. D: ``d(T p)/d xi = [R, -R [p]x]``).
    """
    moved = T_target_source.act(points_source)
    # k-NN with k = 1 is the nearest-neighbour search returning arrays (not Python lists)
    index, sq_dist = target._tree.batch_knn_search(moved, 1, config.num_threads)
    inlier = sq_dist[:, 0] <= config.max_correspondence_m**2  # none found: an infinite distance
    count = int(np.count_nonzero(inlier))
    if count == 0:
        return np.zeros((6, 6)), np.zeros((6, 6)), float("nan"), float("nan"), 0
    nearest, p = index[:, 0], points_source
    if count < inlier.shape[0]:  # most scans: every point paired, no boolean gathers
        nearest, moved, p = nearest[inlier], moved[inlier], p[inlier]
    normals_target = target.normals[nearest]
    offset = moved - target.points[nearest]
    distance = offset[:, 0] * normals_target[:, 0]
    distance += offset[:, 1] * normals_target[:, 1]
    distance += offset[:, 2] * normals_target[:, 2]
    n = normals_target @ T_target_source.rotation.matrix  # R^T n, row by row
    gradient = np.empty((count, 6))
    gradient[:, :3] = n
    gradient[:, 3] = p[:, 1] * n[:, 2] - p[:, 2] * n[:, 1]
    gradient[:, 4] = p[:, 2] * n[:, 0] - p[:, 0] * n[:, 2]
    gradient[:, 5] = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]  # [n, p x n]
    absolute = np.abs(distance)
    rmse = float(np.sqrt(distance @ distance / count))
    sigma = float(1.4826 * np.median(absolute))
    weighted = gradient * np.minimum(absolute, 3.0 * sigma)[:, None]
    return gradient.T @ gradient, weighted.T @ weighted, rmse, sigma, count


def _empty(T_target_source: SE3) -> Registration:
    return Registration(
        T_target_source=T_target_source,
        hessian=np.zeros((6, 6)),
        error=0.0,
        plane_hessian=np.zeros((6, 6)),
        plane_scatter=np.zeros((6, 6)),
        rmse_m=float("nan"),
        sigma_m=float("nan"),
        num_plane_inliers=0,
        inlier_fraction=0.0,
        num_inliers=0,
        num_points=0,
        converged=False,
        iterations=0,
    )
