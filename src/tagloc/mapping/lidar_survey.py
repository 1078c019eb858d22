"""Scan-matching factors of a survey with lidar: keyframe scans, consecutive and loop registrations.

Steps (called by :func:`tagloc.mapping.build_tag_map` when the survey has sweeps):

1. :func:`prepare_lidar`: a sweep every ``keyframe_distance_m`` of odometry becomes a keyframe
   of the graph (:mod:`tagloc.mapping.lidar_keyframes` says why), de-skewed with the odometry
   (:func:`tagloc.lidar.deskew`), cut to ``max_range_m`` and downsampled
   (:mod:`tagloc.mapping.lidar_sweeps`);
2. :meth:`LidarKeyframes.sequential`: each keyframe's scan registered (small_gicp GICP) onto a
   *local map* of the keyframes before it (the last ``local_map_m`` of travel, placed by the
   registrations so far; :mod:`tagloc.lidar.local_map` says why not onto the previous scan
   alone: that is biased by the ring sampling, a scale error of the whole map), from the
   odometry's relative pose;
3. :meth:`LidarKeyframes.loops` (after the first optimization): keyframes within
   ``loop_radius_m`` of each other in the current estimate that the robot reached at least
   ``loop_min_travel_m`` apart along its path are registered too, each onto the local map
   around the earlier visit, from the estimate's relative pose: loop closures.

Each accepted registration (inlier fraction and point-to-plane RMS gated) becomes a relative-pose
factor (:mod:`tagloc.mapping.scan_factors`). Its information is that of the lidar fix
(:mod:`tagloc.lidar.fix`): the point-to-plane Hessian ``H`` (unit noise) over the residual's
robust variance ``s^2``, kept only along the directions the degeneracy analysis finds
constrained (:func:`tagloc.lidar.analyse_hessian`: along a corridor the scan says nothing of the
travel), scaled by ``information_scale`` and floored by ``min_sigma_m`` / ``min_sigma_rad``
(neighbouring points' errors are correlated, and the de-skew carries the odometry's error). It
is moved from the scanner's tangent to the base's by the mount's adjoint: with
``E = T_base_lidar``, ``T_base_a_base_b = E T_lidar_a_lidar_b E^-1`` and
``xi_base = Ad(E) xi_lidar``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.lidar import (
    DegeneracyConfig,
    Registration,
    RegistrationConfig,
    Target,
    analyse_hessian,
    local_map_target,
    register,
)
from tagloc.mapping.initialize import inverse_h
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.mapping.lidar_keyframes import choose_lidar_keyframes, with_keyframes
from tagloc.mapping.lidar_sweeps import keyframe_points, scan_velocity, steady_keyframes
from tagloc.mapping.observations import Observations
from tagloc.mapping.odometry_factors import adjoint
from tagloc.mapping.scan_factors import (
    RelativePoseFactors,
    sqrt_information,
)
from tagloc.mapping.survey import Survey

logger = logging.getLogger(__name__)
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(slots=True)
class LidarStats:
    """What the scan matching did (for the build report's log and the benchmark)."""

    keyframes: int = 0
    sequential: int = 0
    sequential_rejected: int = 0
    loops: int = 0
    loops_rejected: int = 0
    registrations: int = 0
    rejected_reasons: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        """Counts by name; rejected registrations also by reason (``"rejected: <reason>"``)."""
        counts = {
            "keyframes": self.keyframes, "sequential": self.sequential,
            "sequential_rejected": self.sequential_rejected, "loops": self.loops,
            "loops_rejected": self.loops_rejected, "registrations": self.registrations,
        }  # fmt: skip
        return counts | {f"rejected: {k}": v for k, v in self.rejected_reasons.items()}


@dataclass(frozen=True, slots=True, eq=False)
class LidarKeyframes:
    """The keyframe scans of a survey, prepared for scan-to-map registration.

    Attributes
    ----------
    keyframe : (L,) int64
        Graph keyframe index of each lidar keyframe (increasing).
    sweep : (L,) int64
        Index of its sweep in ``survey.lidar``.
    points_lidar : tuple of L (N_i, 3) float
        De-skewed (to the sweep's stamp), in range, downsampled; scanner frame.
    travelled_m : (L,) float
        Odometry path length at each keyframe (to tell loops from neighbours, and to choose the
        keyframes of a local map).
    M_base_lidar : (4, 4) float
    config : LidarSurveyConfig
    stats : LidarStats
    """

    keyframe: IntArray
    sweep: IntArray
    points_lidar: tuple[FloatArray, ...]
    travelled_m: FloatArray
    M_base_lidar: FloatArray
    config: LidarSurveyConfig
    stats: LidarStats

    def __len__(self) -> int:
        return len(self.keyframe)

    def registration_config(self) -> RegistrationConfig:
        c = self.config
        return RegistrationConfig(voxel_m=c.voxel_m, max_correspondence_m=c.max_correspondence_m)

    def sequential(self, M_map_base: FloatArray) -> RelativePoseFactors:
        """Each keyframe's scan onto the local map of the keyframes before it (step 2 of the
        module docstring), from ``M_map_base``'s relative poses (the odometry's, at the start).

        The map is built every ``local_map_every`` keyframes, in the frame of its newest
        keyframe ``r``, from the keyframes up to ``local_map_m`` of travel before ``r``, placed
        at their scan-matched poses so far; keyframes ``r + 1 .. r + local_map_every`` are
        registered onto it (factors ``(r, i)``) and placed by it.
        """
        factors, _ = self.chain(M_map_base)
        self.stats.sequential += len(factors)
        self.stats.sequential_rejected += len(self) - 1 - len(factors)
        return factors

    def chain(self, M_map_base: FloatArray) -> tuple[RelativePoseFactors, FloatArray]:
        """:meth:`sequential`'s factors and the scanner poses they place the keyframes at
        (``(L, 4, 4)``, in ``M_map_base``'s frame; a rejected registration leaves the guess);
        no counts in :attr:`stats` but the registrations."""
        c, E = self.config, self.M_base_lidar
        M_lidar = M_map_base[self.keyframe] @ E  # initial guesses (map frame, scanner)
        placed = M_lidar.copy()  # scan-matched chain, in the same frame
        steps = inverse_h(M_lidar[:-1]) @ M_lidar[1:]
        found = _Found()
        r, target = -1, None
        for i in range(1, len(self)):
            if target is None or i - r > c.local_map_every:
                r = i - 1
                window = np.flatnonzero(
                    (self.travelled_m <= self.travelled_m[r])
                    & (self.travelled_m >= self.travelled_m[r] - c.local_map_m)
                    & (np.arange(len(self)) <= r)
                )
                target = self._map(inverse_h(placed[r]) @ placed[window], window)
            guess = placed[i - 1] @ steps[i - 1]
            M_r_i = self._register(i, target, inverse_h(placed[r]) @ guess, False, found, r)
            placed[i] = guess if M_r_i is None else placed[r] @ M_r_i
        return found.factors(self.config, loop=False), placed

    def loops(self, M_map_base: FloatArray) -> RelativePoseFactors:
        """Loop closures at the estimate ``M_map_base`` (step 3 of the module docstring): each
        onto the local map around the earlier visit (the keyframes within ``local_map_m / 2``
        of travel of it, at the estimate), in the frame of a keyframe on a grid of
        ``2 * local_map_every`` keyframes (so neighbouring closures share one map)."""
        c = self.config
        xy = M_map_base[self.keyframe, :2, 3]
        M_lidar = M_map_base[self.keyframe] @ self.M_base_lidar
        found, maps, pairs = _Found(), {}, 0
        for j in range(0, len(self), c.loop_stride):
            far = self.travelled_m[j] - self.travelled_m >= c.loop_min_travel_m
            dist = np.linalg.norm(xy - xy[j], axis=1)
            candidates = np.flatnonzero(far & (dist <= c.loop_radius_m))
            for i in candidates[np.argsort(dist[candidates])][: c.loops_per_keyframe]:
                r = int(i) - int(i) % (2 * c.local_map_every)
                if r not in maps:
                    near = np.abs(self.travelled_m - self.travelled_m[r]) <= 0.5 * c.local_map_m
                    near &= self.travelled_m[j] - self.travelled_m >= 0.5 * c.loop_min_travel_m
                    window = np.flatnonzero(near)
                    maps[r] = self._map(inverse_h(M_lidar[r]) @ M_lidar[window], window)
                pairs += 1
                self._register(j, maps[r], inverse_h(M_lidar[r]) @ M_lidar[j], True, found, r)
        factors = found.factors(self.config, loop=True)
        self.stats.loops += len(factors)
        self.stats.loops_rejected += pairs - len(factors)
        logger.info("loop closures: %d of %d candidates accepted", len(factors), pairs)
        return factors

    def _map(self, M_r_lidar: FloatArray, window: IntArray) -> Target:
        return local_map_target(M_r_lidar, [self.points_lidar[k] for k in window],
                                self.registration_config())  # fmt: skip

    def _register(
        self, i: int, target: Target, M_init: FloatArray, loop: bool, found: _Found, r: int
    ) -> FloatArray | None:
        """Keyframe ``i``'s scan onto ``target`` (in keyframe ``r``'s scanner frame) from
        ``M_init``; an accepted registration is added to ``found`` as a factor ``(r, i)`` in the
        bases' frames, and its ``T_lidar_r_lidar_i`` returned (None: rejected)."""
        E, E_inv = self.M_base_lidar, inverse_h(self.M_base_lidar)
        reg = register(self.points_lidar[i], target, SE3.from_matrix(M_init, normalize=True),
                       self.registration_config())  # fmt: skip
        self.stats.registrations += 1
        info_lidar, reason = self._information(reg, DegeneracyConfig())
        M_found = reg.T_target_source.as_matrix()
        if loop and reason is None:
            reason = self._moved_too_far(M_init, M_found)
        if reason is not None:
            self.stats.rejected_reasons[reason] = self.stats.rejected_reasons.get(reason, 0) + 1
            return None
        # xi_base = Ad(E) xi_lidar: Lambda_base = Ad(E)^-T Lambda_lidar Ad(E)^-1
        Ad_E_inv = adjoint(E_inv[None])[0]
        info_base = Ad_E_inv.T @ info_lidar @ Ad_E_inv
        found.add(int(self.keyframe[r]), int(self.keyframe[i]), E @ M_found @ E_inv,
                  sqrt_information(info_base))  # fmt: skip
        return M_found

    def _moved_too_far(self, M_init: FloatArray, M_found: FloatArray) -> str | None:
        """A loop registration that moved far from the estimate's guess may have slid to the
        next look-alike place (a corridor's niches repeat): not used."""
        delta = inverse_h(M_init) @ M_found
        angle = np.degrees(np.arccos(np.clip((np.trace(delta[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
        if np.linalg.norm(delta[:3, 3]) > self.config.loop_max_correction_m:
            return "loop moved too far"
        if angle > self.config.loop_max_correction_deg:
            return "loop turned too far"
        return None

    def _information(
        self, reg: Registration, degeneracy: DegeneracyConfig
    ) -> tuple[FloatArray, str | None]:
        """The registration's information (scanner tangent), or the reason it is not used."""
        c = self.config
        if reg.num_plane_inliers <= 6 or not np.isfinite(reg.sigma_m):
            return np.zeros((6, 6)), "too few inliers"
        if reg.inlier_fraction < c.min_inlier_fraction:
            return np.zeros((6, 6)), "low inlier fraction"
        if not reg.rmse_m <= c.max_rmse_m:
            return np.zeros((6, 6)), "high rmse"
        analysis = analyse_hessian(reg.plane_hessian, degeneracy)
        if analysis.num_constrained == 0:
            return np.zeros((6, 6)), "degenerate"
        basis = analysis.basis()
        n = reg.num_plane_inliers
        variance = max(reg.sigma_m, 1e-4) ** 2 * n / (n - 6)
        cov_k = np.linalg.inv(basis.T @ reg.plane_hessian @ basis) * variance
        cov_k /= c.information_scale
        # floors: what a flat Hessian claims is not believed
        floor = np.diag(
            [c.min_sigma_m**2] * 3 + [c.min_sigma_tilt_rad**2] * 2 + [c.min_sigma_rad**2]
        )
        cov_k = cov_k + basis.T @ floor @ basis
        info = basis @ np.linalg.inv(cov_k) @ basis.T
        return 0.5 * (info + info.T), None


@dataclass(slots=True)
class _Found:
    """Accepted registrations, gathered into :class:`RelativePoseFactors`."""

    a: list[int] = field(default_factory=list)
    b: list[int] = field(default_factory=list)
    M_a_b: list[FloatArray] = field(default_factory=list)
    R: list[FloatArray] = field(default_factory=list)

    def add(self, a: int, b: int, M_a_b: FloatArray, R: FloatArray) -> None:
        self.a.append(a)
        self.b.append(b)
        self.M_a_b.append(M_a_b)
        self.R.append(R)

    def factors(self, config: LidarSurveyConfig, loop: bool) -> RelativePoseFactors:
        if not self.a:
            return RelativePoseFactors.empty(config.kernel, config.robust_k)
        return RelativePoseFactors(
            np.array(self.a, dtype=np.int64), np.array(self.b, dtype=np.int64),
            np.array(self.M_a_b), np.array(self.R), np.full(len(self.a), loop), config.kernel,
            config.robust_k,
        )  # fmt: skip


def sequential_factors(
    survey: Survey, scans: LidarKeyframes, M_map_base: FloatArray
) -> tuple[LidarKeyframes, RelativePoseFactors]:
    """Step 2 of the module docstring, de-skewed twice: the keyframes (their scans de-skewed
    again) and their consecutive registrations.

    The first pass de-skews each sweep with the odometry's velocity: its systematic errors
    (0.3 deg/m of yaw drift is 4 mrad/s at 0.8 m/s, a distance scale of a few %) skew every
    sweep the same way, and the registrations inherit it as a bias (simulated loop corridor:
    0.27 mrad of yaw per 0.75 m step, a bend of the map; 0.15 with the true motion). With
    ``deskew_passes`` 2, each sweep where the robot goes straight
    (:func:`~tagloc.mapping.lidar_sweeps.steady_keyframes`) is de-skewed again with the
    scanner's velocity from the scan-matched poses of its neighbours
    (:func:`~tagloc.mapping.lidar_sweeps.scan_velocity`: a mean over two steps, too coarse for a
    turn, where the odometry's own velocity stays), and all are registered again
    (the loop corridor: 0.04 mrad of yaw per step).
    """
    factors, placed = scans.chain(M_map_base)
    if scans.config.deskew_passes > 1 and len(scans) > 2 and survey.lidar is not None:
        stamps_s = survey.lidar.stamps_ns[scans.sweep].astype(np.float64) / 1e9
        velocity = scan_velocity(placed, stamps_s)
        steady = steady_keyframes(placed)
        points = tuple(
            keyframe_points(survey, int(s), scans.config, velocity[i] if steady[i] else None)
            for i, s in enumerate(scans.sweep)
        )
        scans = replace(scans, points_lidar=points)
        factors, _ = scans.chain(M_map_base)
    scans.stats.sequential += len(factors)
    scans.stats.sequential_rejected += len(scans) - 1 - len(factors)
    return scans, factors


def prepare_lidar(
    survey: Survey, obs: Observations, config: LidarSurveyConfig
) -> tuple[Observations, LidarKeyframes] | None:
    """Step 1 of the module docstring: ``obs`` with the lidar keyframes added, and their scans.

    None when the survey has no sweeps, lidar is disabled, or fewer than two sweeps fall inside
    the odometry's span.
    """
    scans = survey.lidar
    if scans is None or not config.enabled:
        return None
    chosen = choose_lidar_keyframes(survey, config.keyframe_distance_m,
                                    np.radians(config.keyframe_turn_deg))  # fmt: skip
    if len(chosen) < 2:
        return None
    obs, keyframe = with_keyframes(obs, survey, scans.stamps_ns[chosen])
    M_base_lidar = scans.T_base_lidar.as_matrix()
    points = [keyframe_points(survey, int(s), config) for s in chosen]
    T_odom = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)[keyframe]
    steps = np.linalg.norm(np.diff(T_odom[:, :3, 3], axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    stats = LidarStats(keyframes=len(chosen))
    return obs, LidarKeyframes(keyframe, np.asarray(chosen), tuple(points),
                               travelled, M_base_lidar, config, stats)  # fmt: skip
