"""The corner refinement: Gauss-Newton on corners, odometry (with its calibration) and anchors.

Starting from the pose-factor solution, each round

1. linearizes every factor at the current estimate, in numpy: the corners of every observation
   (:mod:`tagloc.mapping.corner_graph`, robust kernel as IRLS weights, false detections left
   out), the odometry steps with the calibration vector ``c`` as a variable
   (:mod:`tagloc.mapping.odometry_factors`), priors on the anchors (:class:`Priors`: each with its
   sigmas), gravity priors (:mod:`tagloc.mapping.gravity`), a broad prior on ``c``, and the
   lidar scan-matching factors if any (:mod:`tagloc.mapping.scan_factors`);
2. solves the sparse normal equations with GTSAM (``GaussianFactorGraph.optimize``: COLAMD
   ordering, multifrontal Cholesky);
3. retracts (``T Exp(delta)``) with a backtracking line search on the robust objective, so it
   never increases;

until no tag moves more than :data:`STEP_TOL_M` / :data:`STEP_TOL_RAD`. Each round is the
exact Gauss-Newton model of the corners (converged in 3-6 rounds on the simulated office). The
last linearization gives the marginal covariances (``gtsam.Marginals`` of the linear graph), with
the calibration's uncertainty included.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.anchors import anchor_default_sigmas, anchor_whitening
from tagloc.mapping.calibration import N_CALIBRATION
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.corner_graph import (
    corner_chi,
    corner_cost,
    corner_jacobians,
    kernel_cost,
    kernel_weights,
    linearize_corners,
)
from tagloc.mapping.flips import flip_stuck_tags
from tagloc.mapping.graph import GraphSolution, L, X
from tagloc.mapping.gravity import gravity_jacobians, gravity_residuals
from tagloc.mapping.gtsam_bridge import solver_errors
from tagloc.mapping.initialize import rotation_angle
from tagloc.mapping.observations import Observations
from tagloc.mapping.odometry_factors import (
    linearize_odometry,
    odometry_residuals,
    prior_residuals,
)
from tagloc.mapping.odometry_noise import odometry_whitening
from tagloc.mapping.scan_factors import RelativePoseFactors, linearize_relative, relative_cost
from tagloc.mapping.whitening import AxisWhitening

logger = logging.getLogger(__name__)
#: Stop when no tag moves more than this (m) or turns more than this (rad) in a round.
STEP_TOL_M, STEP_TOL_RAD = 1e-4, 1e-4
#: Key of the odometry calibration vector.
CAL = int(gtsam.symbol("c", 0))
_LINE_SEARCH_STEPS = 6
#: Corner refinements after which stuck tilts are tested and flipped (then refined again).
MAX_FLIP_PASSES = 2


@dataclass(frozen=True, slots=True)
class Priors:
    """Priors besides the corners and the odometry: each held tag's sigmas ``(6,)`` (m, rad;
    missing: the configuration's defaults), gravity "up" ``(K, 3)`` in each keyframe's base
    (None: no gravity priors, :mod:`tagloc.mapping.gravity`), and "up" ``(K, 3)`` for the
    odometry noise (None: an upright base, :mod:`tagloc.mapping.odometry_noise`)."""

    anchor_sigmas: Mapping[int, FloatArray] = field(default_factory=dict)
    up_base: FloatArray | None = None
    odometry_up: FloatArray | None = None

    def held_whitening(
        self, held: Mapping[int, FloatArray], config: MapBuildConfig
    ) -> dict[int, AxisWhitening]:
        """Each held tag's prior (:func:`~tagloc.mapping.anchors.anchor_whitening`): along
        ``map``'s axes with the tilt free when gravity priors level the map."""
        default = anchor_default_sigmas(config)
        return {
            j: anchor_whitening(
                self.anchor_sigmas.get(j, default), None if self.up_base is None else M
            )
            for j, M in held.items()
        }


@dataclass(frozen=True, slots=True)
class State:
    """Keyframes ``(K, 4, 4)``, tags by index, calibration vector ``(4,)``."""

    M_map_base: FloatArray
    M_map_tag: dict[int, FloatArray]
    c: FloatArray


class _Problem:
    """The refinement's fixed inputs, its robust objective and its linearization."""

    def __init__(
        self,
        obs: Observations,
        M_odom_raw: FloatArray,
        held: Mapping[int, FloatArray],
        cameras: Mapping[str, CameraModel],
        T_base_cam: Mapping[str, SE3],
        config: MapBuildConfig,
        priors: Priors | None = None,
        relative: RelativePoseFactors | None = None,
    ) -> None:
        self.obs, self.held, self.config = obs, dict(held), config
        priors = priors or Priors()
        self.relative = relative
        self.calibrate = config.joint_calibration
        self.cameras, self.T_base_cam = cameras, T_base_cam
        self.step_raw = inverse_h(M_odom_raw[:-1]) @ M_odom_raw[1:]
        self.noise = odometry_whitening(M_odom_raw, config.odometry, priors.odometry_up)
        self.held_noise = priors.held_whitening(self.held, config)
        self.up_base = priors.up_base
        self.gravity_sigma = float(np.radians(config.gravity.sigma_deg))
        self.kind, self.k = config.robust, config.robust_k
        # the corners of the last state asked for: the objective of the line search's accepted
        # step is evaluated there, and the next round linearizes there
        self._corners: tuple[State, tuple[FloatArray, FloatArray, FloatArray]] | None = None

    def corners(self, state: State) -> tuple[FloatArray, FloatArray, FloatArray]:
        if self._corners is not None and self._corners[0] is state:
            return self._corners[1]
        tags = np.array([state.M_map_tag[int(j)] for j in self.obs.tag])
        out = linearize_corners(
            self.obs, np.arange(len(self.obs)), state.M_map_base, tags, self.cameras,
            self.T_base_cam, self.config.pnp_noise.sigma_px,
        )  # fmt: skip
        self._corners = (state, out)
        return out

    def _odometry_weights(self, e: FloatArray) -> FloatArray:
        k = self.config.odometry_robust_k
        if k is None:
            return np.ones(len(e))
        return kernel_weights(np.sum(e**2, axis=1), "huber", k)

    def objective(self, state: State) -> float:
        """The robust cost (corners capped, Huber or Gaussian odometry, priors)."""
        r, _, _ = self.corners(state)
        total = float(np.sum(corner_cost(r, self.kind, self.k)))
        e = odometry_residuals(state.M_map_base, self.step_raw, state.c, self.noise)
        s = np.sum(e**2, axis=1)
        k = self.config.odometry_robust_k
        total += float(np.sum(0.5 * s if k is None else kernel_cost(s, "huber", k)))
        for j, M in self.held.items():
            total += 0.5 * float(
                np.sum(prior_residuals(state.M_map_tag[j][None], M[None], self.held_noise[j]) ** 2)
            )
        if self.up_base is not None:
            g = gravity_residuals(state.M_map_base, self.up_base, self.gravity_sigma)
            total += 0.5 * float(np.sum(g**2))
        if self.calibrate:
            total += 0.5 * float(np.sum((state.c / self.config.calibration_sigma) ** 2))
        if self.relative is not None:
            total += relative_cost(state.M_map_base, self.relative)
        return total

    def linearize(self, state: State) -> tuple[gtsam.GaussianFactorGraph, FloatArray]:
        """The Gauss-Newton factors at ``state`` (module docstring) and the corner residuals."""
        obs, graph = self.obs, gtsam.GaussianFactorGraph()
        r, J, M_base_tag = self.corners(state)
        A_base, A_tag, b = corner_jacobians(r, J, M_base_tag, obs.tag, self.kind, self.k)
        unit6, unit8 = gtsam.noiseModel.Unit.Create(6), gtsam.noiseModel.Unit.Create(8)
        for m in range(len(obs)):
            graph.add(gtsam.JacobianFactor(
                X(int(obs.keyframe[m])), A_base[m], L(int(obs.tag[m])), A_tag[m], b[m], unit8
            ))  # fmt: skip
        e, A_prev, A_next, A_c = linearize_odometry(
            state.M_map_base, self.step_raw, state.c, self.noise, self.calibrate
        )
        sqrt_w = np.sqrt(self._odometry_weights(e))[:, None]
        e, A_prev, A_next = e * sqrt_w, A_prev * sqrt_w[..., None], A_next * sqrt_w[..., None]
        for k in range(len(e)):
            if A_c is None:
                graph.add(gtsam.JacobianFactor(X(k), A_prev[k], X(k + 1), A_next[k], -e[k], unit6))
            else:
                graph.add(gtsam.JacobianFactor(
                    X(k), A_prev[k], X(k + 1), A_next[k], CAL, A_c[k] * sqrt_w[k, :, None],
                    -e[k], unit6,
                ))  # fmt: skip
        for j, M in self.held.items():
            noise = self.held_noise[j]
            e_held = prior_residuals(state.M_map_tag[j][None], M[None], noise)[0]
            W = noise.whiten_jacobian(np.eye(6)[None])[0]
            graph.add(gtsam.JacobianFactor(L(j), W, -e_held, unit6))
        if self.up_base is not None:  # gravity priors (mapping.gravity)
            g = gravity_residuals(state.M_map_base, self.up_base, self.gravity_sigma)
            A_g = gravity_jacobians(state.M_map_base, self.gravity_sigma)
            unit3 = gtsam.noiseModel.Unit.Create(3)
            for k in range(len(g)):
                graph.add(gtsam.JacobianFactor(X(k), A_g[k], -g[k], unit3))
        if self.relative is not None:  # lidar scan matching, IRLS-weighted
            e_rel, A_a, A_b = linearize_relative(state.M_map_base, self.relative)
            for a, b, e_i, A_ai, A_bi in zip(self.relative.a, self.relative.b, e_rel, A_a, A_b,
                                             strict=True):  # fmt: skip
                graph.add(gtsam.JacobianFactor(X(int(a)), A_ai, X(int(b)), A_bi, -e_i, unit6))
        if self.calibrate:
            s = self.config.calibration_sigma
            graph.add(gtsam.JacobianFactor(
                CAL, np.eye(N_CALIBRATION) / s, -state.c / s,
                gtsam.noiseModel.Unit.Create(N_CALIBRATION),
            ))  # fmt: skip
        return graph, r


def _retract(state: State, delta: gtsam.VectorValues, alpha: float, calibrate: bool) -> State:
    """``state`` moved by ``alpha delta`` (``c`` too if ``calibrate``)."""
    n_kf = len(state.M_map_base)
    d_base = np.array([delta.at(X(k)) for k in range(n_kf)])
    M_map_base = state.M_map_base @ SE3.exp(alpha * d_base).as_matrix()
    keys = sorted(state.M_map_tag)
    d_tag = np.array([delta.at(L(j)) for j in keys])
    M_tags = np.array([state.M_map_tag[j] for j in keys]) @ SE3.exp(alpha * d_tag).as_matrix()
    c = state.c + alpha * delta.at(CAL) if calibrate else state.c
    return State(M_map_base, dict(zip(keys, M_tags, strict=True)), c)


def _moved(a: State, b: State) -> tuple[float, float]:
    moved = max(
        float(np.linalg.norm(b.M_map_tag[j][:3, 3] - M[:3, 3])) for j, M in a.M_map_tag.items()
    )
    turned = max(
        float(rotation_angle(b.M_map_tag[j][:3, :3], M[:3, :3])) for j, M in a.M_map_tag.items()
    )
    return moved, turned


def refine_with_corners(
    obs: Observations,
    M_odom_raw: FloatArray,
    start: State,
    held: Mapping[int, FloatArray],
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    config: MapBuildConfig,
    priors: Priors | None = None,
    relative: RelativePoseFactors | None = None,
) -> tuple[GraphSolution, State]:
    """Refine ``start`` with the corners (module docstring).

    Parameters
    ----------
    obs : Observations
    M_odom_raw : (K, 4, 4) float
        Raw odometry at the keyframes.
    start : State
        Keyframes, tags and the calibration vector to start from.
    held : mapping of int to (4, 4) float
        Tags held by priors (anchors, or the origin tag).
    cameras, T_base_cam : mapping of str
    config : MapBuildConfig
        ``joint_calibration``: estimate the odometry calibration vector jointly (else it stays
        at ``start.c``).
    priors : Priors, optional
        Anchor sigmas and gravity (default: configuration sigmas, no gravity).
    relative : RelativePoseFactors, optional
        Lidar scan-matching factors between keyframes.

    Returns
    -------
    (GraphSolution, State)
        ``mahalanobis`` is the corners' whitened norm per observation; ``linear`` the last
        linearization (for :func:`tagloc.mapping.graph.marginal_covariances`).
    """
    problem = _Problem(obs, M_odom_raw, held, cameras, T_base_cam, config, priors, relative)
    calibrate = problem.calibrate
    state, cost = start, problem.objective(start)
    cost_initial, rounds, solve_s = cost, 0, 0.0
    linear: tuple[gtsam.GaussianFactorGraph, FloatArray] | None = None  # at ``state``
    while rounds < config.corner_max_iterations:
        rounds += 1
        linear = problem.linearize(state)
        graph = linear[0]
        t = time.perf_counter()
        with solver_errors("the corner refinement"):
            delta = graph.optimize()
        solve_s += time.perf_counter() - t
        alpha, new, new_cost = 1.0, state, cost
        for _ in range(_LINE_SEARCH_STEPS):
            new = _retract(state, delta, alpha, calibrate)
            new_cost = problem.objective(new)
            if new_cost <= cost:
                break
            alpha *= 0.5
        if new_cost > cost:
            break
        moved, turned = _moved(state, new)
        state, cost, linear = new, new_cost, None
        if moved < STEP_TOL_M and turned < STEP_TOL_RAD:
            break
    graph, r = problem.linearize(state) if linear is None else linear
    solution = GraphSolution(
        M_map_base=state.M_map_base,
        M_map_tag=state.M_map_tag,
        cov_map_tag={},
        mahalanobis=corner_chi(r),
        iterations=rounds,
        error_initial=cost_initial,
        error_final=cost,
        optimize_s=solve_s,
        marginals_s=0.0,
        graph=gtsam.NonlinearFactorGraph(),
        values=gtsam.Values(),
        linear=graph,
    )
    return solution, state


def refine_and_test_tilts(
    obs: Observations,
    M_odom_raw: FloatArray,
    start: State,
    held: Mapping[int, FloatArray],
    fixed: set[int],
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    config: MapBuildConfig,
    priors: Priors | None = None,
    relative: RelativePoseFactors | None = None,
) -> tuple[GraphSolution, State, list[int]]:
    """Refine, test every tag's tilt (:mod:`tagloc.mapping.flips`), refine again while tags
    flip (at most :data:`MAX_FLIP_PASSES` tests).

    ``fixed``: tags not tested (anchors). Returns the last solution (iterations and solver time
    summed over the passes), its state, and the tags whose tilt is ambiguous.
    """
    state, rounds, solve_s = start, 0, 0.0
    ambiguous: list[int] = []
    for pass_ in range(MAX_FLIP_PASSES + 1):
        solution, state = refine_with_corners(
            obs, M_odom_raw, state, held, cameras, T_base_cam, config, priors, relative
        )
        rounds += solution.iterations
        solve_s += solution.optimize_s
        if pass_ == MAX_FLIP_PASSES:
            break
        M_map_tag, flipped, ambiguous = flip_stuck_tags(
            obs, state.M_map_base, state.M_map_tag, fixed, cameras, T_base_cam,
            config.pnp_noise.sigma_px,
        )  # fmt: skip
        logger.info("tilt test: flipped tags %s", [obs.tag_keys[j][1] for j in flipped])
        if not flipped:
            break
        state = State(state.M_map_base, M_map_tag, state.c)
    return replace(solution, iterations=rounds, optimize_s=solve_s), state, ambiguous
