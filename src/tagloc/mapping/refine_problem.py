"""The corner refinement's problem: its state, inputs, robust objective and linearization.

:class:`RefineProblem` evaluates, at a :class:`State`, the robust cost that the refinement
(:mod:`tagloc.mapping.refine`) never lets increase and the Gauss-Newton factors of one round:
the corners of every observation (:mod:`tagloc.mapping.corner_graph`, robust kernel as IRLS
weights), the odometry steps with the calibration vector ``c`` as a variable
(:mod:`tagloc.mapping.odometry_factors`), priors on the anchors (:class:`Priors`), gravity priors
(:mod:`tagloc.mapping.gravity`), a broad prior on ``c``, and the lidar scan-matching factors if
any (:mod:`tagloc.mapping.scan_factors`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import gtsam
import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.anchors import anchor_default_sigmas, anchor_whitening
from tagloc.mapping.calibration import N_CALIBRATION
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.corner_graph import (
    corner_cost,
    corner_jacobians,
    kernel_cost,
    kernel_weights,
    linearize_corners,
)
from tagloc.mapping.graph import L, X
from tagloc.mapping.gravity import gravity_jacobians, gravity_residuals
from tagloc.mapping.observations import Observations
from tagloc.mapping.odometry_factors import (
    linearize_odometry,
    odometry_residuals,
    prior_residuals,
)
from tagloc.mapping.odometry_noise import odometry_whitening
from tagloc.mapping.scan_factors import RelativePoseFactors, linearize_relative, relative_cost
from tagloc.mapping.whitening import AxisWhitening

__all__ = ["CAL", "Priors", "RefineInputs", "RefineProblem", "State"]

#: Key of the odometry calibration vector.
CAL = int(gtsam.symbol("c", 0))


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


@dataclass(frozen=True, slots=True)
class RefineInputs:
    """What the refinement holds fixed: the observations, the raw odometry ``(K, 4, 4)`` at the
    keyframes, the tags held by priors (anchors, or the origin tag; ``(4, 4)`` each), the
    cameras and their ``T_base_cam``, the configuration (``joint_calibration``: estimate the
    odometry calibration vector jointly), the priors (default: configuration sigmas, no
    gravity) and the lidar scan-matching factors between keyframes, if any."""

    obs: Observations
    M_odom_raw: FloatArray
    held: Mapping[int, FloatArray]
    cameras: Mapping[str, CameraModel]
    T_base_cam: Mapping[str, SE3]
    config: MapBuildConfig
    priors: Priors = field(default_factory=Priors)
    relative: RelativePoseFactors | None = None


class RefineProblem:
    """The refinement's robust objective and its linearization, for fixed inputs."""

    def __init__(self, inputs: RefineInputs) -> None:
        obs, config, priors = inputs.obs, inputs.config, inputs.priors
        M_odom_raw = inputs.M_odom_raw
        self.obs, self.held, self.config = obs, dict(inputs.held), config
        self.relative = inputs.relative
        self.calibrate = config.joint_calibration
        self.cameras, self.T_base_cam = inputs.cameras, inputs.T_base_cam
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
