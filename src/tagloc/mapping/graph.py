"""The factor graph in GTSAM: keyframe and tag poses, odometry and PnP pose factors, anchors.

Variables: ``x_k`` = ``T_map_base`` of keyframe ``k``; ``l_j`` = ``T_map_tag`` of tag ``j``
(both ``Pose3``). Factors:

- odometry ``BetweenFactorPose3(x_{k-1}, x_k, T_odom_base_{k-1}^-1 T_odom_base_k)``, diagonal
  noise from :class:`~tagloc.mapping.config.OdometryNoise` (variance linear in distance and
  rotation travelled, plus a floor), under a Huber kernel (``odometry_robust_k``: convex, so
  the trajectory cannot tear, but a one-frame odometry jump has bounded pull);
- tag observation ``BetweenFactorPose3(x_k, l_j, T_base_tag)`` with the PnP covariance of the
  chosen IPPE branch (right tangent, so the factor's error ``Log(Z^-1 x_k^-1 l_j)`` has exactly
  that covariance), under a Huber or Cauchy kernel so that outliers cannot fold the map;
- ``PriorFactorPose3`` on anchor tags (each with its own sigmas, :mod:`tagloc.mapping.anchors`);
- with a gravity-aligned odometry, an attitude prior on every keyframe
  (:mod:`tagloc.mapping.gravity`).
- scan-matching ``BetweenFactorPose3(x_a, x_b, T_base_a_base_b)`` from lidar registrations, when
  the survey has scans (:mod:`tagloc.mapping.scan_factors`).

Solved with Levenberg-Marquardt; tag covariances from ``gtsam.Marginals``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.anchors import anchor_default_sigmas, anchor_whitening
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.gravity import add_gravity_factors
from tagloc.mapping.gtsam_bridge import PERM, cov_from_gtsam, solver_errors
from tagloc.mapping.odometry_noise import odometry_whitening
from tagloc.mapping.scan_factors import RelativePoseFactors, add_relative_factors

IntArray = npt.NDArray[np.int64]


def X(k: int) -> int:
    """Key of keyframe ``k``'s ``T_map_base``."""
    return int(gtsam.symbol("x", k))


def L(j: int) -> int:
    """Key of tag ``j``'s ``T_map_tag``."""
    return int(gtsam.symbol("l", j))


@dataclass(frozen=True, slots=True, eq=False)
class GraphInput:
    """Everything the graph needs, as arrays (a survey after PnP, or a synthetic benchmark).

    Attributes
    ----------
    M_odom_base : (K, 4, 4) float
        Odometry at the keyframes.
    keyframe, tag : (M,) int
        Keyframe and tag index of each observation.
    M_base_tag : (M, 4, 4) float
        Measured ``T_base_tag`` (the chosen IPPE branch).
    cov_base_tag : (M, 6, 6) float
        Its right-tangent covariance, ``[x, y, z, rx, ry, rz]``.
    M_map_anchor : mapping of int to (4, 4) float
        Anchor tags' surveyed ``T_map_tag``; empty: the first initial tag is held as the origin.
    M_map_base_init : (K, 4, 4) float
    M_map_tag_init : mapping of int to (4, 4) float
    anchor_sigmas : mapping of int to (6,) float
        Prior standard deviations ``[x, y, z, rx, ry, rz]`` of held tags (m, rad); a tag not in
        it gets the configuration's ``anchor_sigma_m``, ``anchor_sigma_rad``.
    up_base : (K, 3) float or None
        Gravity "up" in each keyframe's ``base`` (:mod:`tagloc.mapping.gravity`): one attitude
        prior per keyframe; None: no gravity priors.
    odometry_up : (K, 3) float or None
        "Up" in each keyframe's ``base`` for the odometry noise
        (:mod:`tagloc.mapping.odometry_noise`); None: an upright base.
    relative : RelativePoseFactors, optional
        Scan-matching factors between keyframes (:mod:`tagloc.mapping.scan_factors`).
    """

    M_odom_base: FloatArray
    keyframe: IntArray
    tag: IntArray
    M_base_tag: FloatArray
    cov_base_tag: FloatArray
    M_map_anchor: Mapping[int, FloatArray]
    M_map_base_init: FloatArray
    M_map_tag_init: Mapping[int, FloatArray]
    anchor_sigmas: Mapping[int, FloatArray] = field(default_factory=dict)
    up_base: FloatArray | None = None
    odometry_up: FloatArray | None = None
    relative: RelativePoseFactors | None = None


@dataclass(frozen=True, slots=True, eq=False)
class GraphSolution:
    """Optimized poses, tag covariances and per-observation whitened errors.

    Attributes
    ----------
    M_map_base : (K, 4, 4) float
    M_map_tag : dict of int to (4, 4) float
    cov_map_tag : dict of int to (6, 6) float
        Marginal covariance of each tag, right tangent, ``[x, y, z, rx, ry, rz]`` (empty if not
        computed).
    mahalanobis : (M,) float
        ``sqrt(e^T C^-1 e)`` of each tag factor at the solution (no kernel).
    iterations : int
    error_initial, error_final : float
        Graph error (robust) before and after.
    optimize_s, marginals_s : float
        Wall time in GTSAM's optimizer and in ``Marginals``.
    graph, values : gtsam.NonlinearFactorGraph, gtsam.Values
        The graph and its optimum (for :func:`marginal_covariances`).
    linear : gtsam.GaussianFactorGraph or None
        Instead, the graph linearized at the optimum, in tagloc's tangent order (the corner
        refinement, :mod:`tagloc.mapping.refine`).
    """

    M_map_base: FloatArray
    M_map_tag: dict[int, FloatArray]
    cov_map_tag: dict[int, FloatArray]
    mahalanobis: FloatArray
    iterations: int
    error_initial: float
    error_final: float
    optimize_s: float
    marginals_s: float
    graph: gtsam.NonlinearFactorGraph
    values: gtsam.Values
    linear: gtsam.GaussianFactorGraph | None = None


def _kernel(config: MapBuildConfig, k: float) -> gtsam.noiseModel.mEstimator.Base:
    if config.robust == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(k)
    return gtsam.noiseModel.mEstimator.Cauchy.Create(k)


def _pose3(M: FloatArray) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3(M[:3, :3]), M[:3, 3])


def held_tags(
    anchors: Mapping[int, FloatArray], tag: IntArray, M_map_tag: Mapping[int, FloatArray]
) -> dict[int, FloatArray]:
    """Tags held by priors: the anchors, or without anchors the first observed tag (``tag[0]``,
    at ``M_map_tag``) as the origin."""
    if anchors:
        return dict(anchors)
    first = int(tag[0])
    return {first: M_map_tag[first]}


def add_odometry_and_anchors(
    graph: gtsam.NonlinearFactorGraph, data: GraphInput, config: MapBuildConfig
) -> None:
    """Odometry between consecutive keyframes, priors on anchors (or the origin tag)."""
    steps = inverse_h(data.M_odom_base[:-1]) @ data.M_odom_base[1:]
    k_odo = config.odometry_robust_k
    odo_kernel = None if k_odo is None else gtsam.noiseModel.mEstimator.Huber.Create(k_odo)
    whitening = odometry_whitening(data.M_odom_base, config.odometry, data.odometry_up)
    for k, M in enumerate(steps):
        model = whitening.gtsam_model(k)
        if odo_kernel is not None:
            model = gtsam.noiseModel.Robust.Create(odo_kernel, model)
        graph.add(gtsam.BetweenFactorPose3(X(k), X(k + 1), _pose3(M), model))
    default = anchor_default_sigmas(config)
    for j, M in held_tags(data.M_map_anchor, data.tag, data.M_map_tag_init).items():
        level = None if data.up_base is None else M  # gravity priors: the tilt is theirs
        noise = anchor_whitening(data.anchor_sigmas.get(j, default), level)
        graph.add(gtsam.PriorFactorPose3(L(j), _pose3(M), noise.gtsam_model(0)))
    if data.up_base is not None:  # gravity priors (mapping.gravity)
        keys = [X(k) for k in range(len(data.up_base))]
        add_gravity_factors(graph, keys, data.up_base, np.radians(config.gravity.sigma_deg))


def build_graph(
    data: GraphInput, config: MapBuildConfig
) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """The factor graph and initial values (module docstring)."""
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for k, M in enumerate(data.M_map_base_init):
        values.insert(X(k), _pose3(M))
    for j, M in data.M_map_tag_init.items():
        values.insert(L(j), _pose3(M))
    add_odometry_and_anchors(graph, data, config)
    # tag observations
    kernel = _kernel(config, config.robust_k)
    covs = data.cov_base_tag[:, PERM][:, :, PERM]
    for k, j, M, cov in zip(data.keyframe, data.tag, data.M_base_tag, covs, strict=True):
        model = gtsam.noiseModel.Robust.Create(kernel, gtsam.noiseModel.Gaussian.Covariance(cov))
        graph.add(gtsam.BetweenFactorPose3(X(int(k)), L(int(j)), _pose3(M), model))
    if data.relative is not None:  # lidar scan matching
        add_relative_factors(graph, data.relative, X)
    return graph, values


def lm_params(config: MapBuildConfig) -> gtsam.LevenbergMarquardtParams:
    """Levenberg-Marquardt settings used by :func:`solve_graph` (and the benchmark)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(1e-7)
    params.setAbsoluteErrorTol(1e-9)
    return params


def mahalanobis(
    M_map_base: FloatArray,
    M_map_tag: Mapping[int, FloatArray],
    data: GraphInput,
) -> FloatArray:
    """``(M,)`` Mahalanobis norm of each tag factor's error ``Log(Z^-1 x_k^-1 l_j)``."""
    tags = np.array([M_map_tag[int(j)] for j in data.tag])
    M_pred = inverse_h(M_map_base[data.keyframe]) @ tags
    err = SE3.from_matrix(inverse_h(data.M_base_tag) @ M_pred, normalize=True).log()
    sol = np.linalg.solve(data.cov_base_tag, err[..., None])[..., 0]
    return np.asarray(np.sqrt(np.maximum(np.einsum("mi,mi->m", err, sol), 0.0)))


def marginal_covariances(solution: GraphSolution) -> GraphSolution:
    """``solution`` with the marginal covariance of every tag (``gtsam.Marginals``)."""
    start = time.perf_counter()
    if solution.linear is not None:  # already in tagloc order
        # the solution only labels the variables: elimination does not need it
        with solver_errors("the tag covariances"):
            marginals = gtsam.Marginals(solution.linear, gtsam.VectorValues())
            cov = {j: marginals.marginalCovariance(L(j)) for j in solution.M_map_tag}
    else:
        with solver_errors("the tag covariances"):
            marginals = gtsam.Marginals(solution.graph, solution.values)
            cov = {
                j: cov_from_gtsam(marginals.marginalCovariance(L(j))) for j in solution.M_map_tag
            }
    return replace(solution, cov_map_tag=cov, marginals_s=time.perf_counter() - start)


def solve_graph(data: GraphInput, config: MapBuildConfig) -> GraphSolution:
    """Build, optimize and read back the graph (no covariances: :func:`marginal_covariances`)."""
    graph, values = build_graph(data, config)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(config))
    start = time.perf_counter()
    with solver_errors("the survey graph"):
        result = optimizer.optimize()
    optimize_s = time.perf_counter() - start
    n_kf = len(data.M_map_base_init)
    M_map_base = np.array([result.atPose3(X(k)).matrix() for k in range(n_kf)])
    M_map_tag = {j: result.atPose3(L(j)).matrix() for j in data.M_map_tag_init}
    return GraphSolution(
        M_map_base=M_map_base,
        M_map_tag=M_map_tag,
        cov_map_tag={},
        mahalanobis=mahalanobis(M_map_base, M_map_tag, data),
        iterations=int(optimizer.iterations()),
        error_initial=float(graph.error(values)),
        error_final=float(graph.error(result)),
        optimize_s=optimize_s,
        marginals_s=0.0,
        graph=graph,
        values=result,
    )
