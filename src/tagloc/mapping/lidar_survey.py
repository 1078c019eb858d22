"""Scan-matching factors of a survey with lidar: keyframe scans, consecutive and loop registrations.

Steps (called by :func:`tagloc.mapping.build_tag_map` when the survey has sweeps):

1. :func:`prepare_lidar`: a sweep every ``keyframe_distance_m`` of odometry becomes a keyframe
   of the graph (:mod:`tagloc.mapping.lidar_keyframes` says why), de-skewed with the odometry
   (:func:`tagloc.lidar.deskew`), cut to ``max_range_m``, downsampled, and prepared once as a
   registration target (:class:`tagloc.lidar.Target`: covariances, KD-tree);
2. :meth:`LidarKeyframes.sequential`: each keyframe's scan registered (small_gicp GICP) onto the
   previous one's, from the odometry's relative pose;
3. :meth:`LidarKeyframes.loops` (after the first optimization): keyframes within
   ``loop_radius_m`` of each other in the current estimate that the robot reached at least
   ``loop_min_travel_m`` apart along its path are registered too, from the estimate's relative
   pose: loop closures.

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
from collections.abc import Callable
from dataclasses import dataclass, field

import gtsam
import numpy as np
import numpy.typing as npt

from tagloc.geometry import SE3
from tagloc.lidar import (
    DegeneracyConfig,
    Registration,
    RegistrationConfig,
    Target,
    analyse_hessian,
    deskew,
    finite_points,
    register,
    voxel_downsample,
)
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.graph import X, lm_params
from tagloc.mapping.gtsam_bridge import solver_errors
from tagloc.mapping.initialize import inverse_h
from tagloc.mapping.lidar_config import LidarSurveyConfig
from tagloc.mapping.lidar_keyframes import choose_lidar_keyframes, with_keyframes
from tagloc.mapping.observations import Observations, interpolate_odometry
from tagloc.mapping.odometry_factors import adjoint
from tagloc.mapping.odometry_noise import odometry_whitening
from tagloc.mapping.scan_factors import (
    RelativePoseFactors,
    add_relative_factors,
    sqrt_information,
)
from tagloc.mapping.survey import Survey

logger = logging.getLogger(__name__)
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
S_NS = 1_000_000_000


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
    """The keyframe scans of a survey, prepared for registration.

    Attributes
    ----------
    keyframe : (L,) int64
        Graph keyframe index of each lidar keyframe (increasing).
    sweep : (L,) int64
        Index of its sweep in ``survey.lidar``.
    points_lidar : tuple of L (N_i, 3) float
        De-skewed (to the sweep's stamp), in range, downsampled; scanner frame.
    targets : tuple of L Target
    travelled_m : (L,) float
        Odometry path length at each keyframe (to tell loops from neighbours).
    M_base_lidar : (4, 4) float
    config : LidarSurveyConfig
    stats : LidarStats
    """

    keyframe: IntArray
    sweep: IntArray
    points_lidar: tuple[FloatArray, ...]
    targets: tuple[Target, ...]
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
        """Each keyframe's scan onto the previous one's, from ``M_map_base``'s relative pose
        (the odometry's, at the start)."""
        pairs = [(i - 1, i) for i in range(1, len(self))]
        factors = self._register_pairs(pairs, M_map_base, loop=False)
        self.stats.sequential += len(factors)
        self.stats.sequential_rejected += len(pairs) - len(factors)
        return factors

    def loops(self, M_map_base: FloatArray) -> RelativePoseFactors:
        """Loop closures at the estimate ``M_map_base`` (step 3 of the module docstring)."""
        c = self.config
        xy = M_map_base[self.keyframe, :2, 3]
        pairs: list[tuple[int, int]] = []
        for j in range(0, len(self), c.loop_stride):
            far = self.travelled_m[j] - self.travelled_m >= c.loop_min_travel_m
            dist = np.linalg.norm(xy - xy[j], axis=1)
            candidates = np.flatnonzero(far & (dist <= c.loop_radius_m))
            nearest = candidates[np.argsort(dist[candidates])][: c.loops_per_keyframe]
            pairs += [(int(i), j) for i in nearest]
        factors = self._register_pairs(pairs, M_map_base, loop=True)
        self.stats.loops += len(factors)
        self.stats.loops_rejected += len(pairs) - len(factors)
        logger.info("loop closures: %d of %d candidates accepted", len(factors), len(pairs))
        return factors

    def _register_pairs(
        self, pairs: list[tuple[int, int]], M_map_base: FloatArray, loop: bool
    ) -> RelativePoseFactors:
        E, E_inv = self.M_base_lidar, inverse_h(self.M_base_lidar)
        Ad_E_inv = adjoint(E_inv[None])[0]
        reg_config = self.registration_config()
        degeneracy = DegeneracyConfig()
        a, b, M_ab, R = [], [], [], []
        for i, j in pairs:
            ka, kb = int(self.keyframe[i]), int(self.keyframe[j])
            M_la_lb = E_inv @ inverse_h(M_map_base[ka]) @ M_map_base[kb] @ E
            reg = register(
                self.points_lidar[j], self.targets[i], SE3.from_matrix(M_la_lb, normalize=True),
                reg_config,
            )  # fmt: skip
            self.stats.registrations += 1
            info_lidar, reason = self._information(reg, degeneracy)
            if loop and reason is None:
                reason = self._moved_too_far(M_la_lb, reg.T_target_source.as_matrix())
            if reason is not None:
                self.stats.rejected_reasons[reason] = self.stats.rejected_reasons.get(reason, 0) + 1
                continue
            # xi_base = Ad(E) xi_lidar: Lambda_base = Ad(E)^-T Lambda_lidar Ad(E)^-1
            info_base = Ad_E_inv.T @ info_lidar @ Ad_E_inv
            a.append(ka)
            b.append(kb)
            M_ab.append(E @ reg.T_target_source.as_matrix() @ E_inv)
            R.append(sqrt_information(info_base))
        if not a:
            return RelativePoseFactors.empty(self.config.kernel, self.config.robust_k)
        return RelativePoseFactors(
            np.array(a, dtype=np.int64), np.array(b, dtype=np.int64), np.array(M_ab),
            np.array(R), np.full(len(a), loop), self.config.kernel, self.config.robust_k,
        )  # fmt: skip

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
        floor = np.diag([c.min_sigma_m**2] * 3 + [c.min_sigma_rad**2] * 3)
        cov_k = cov_k + basis.T @ floor @ basis
        info = basis @ np.linalg.inv(cov_k) @ basis.T
        return 0.5 * (info + info.T), None


def scan_odometry(
    obs: Observations, sequential: RelativePoseFactors, config: MapBuildConfig
) -> SE3:
    """The keyframes' odometry corrected by the consecutive registrations (``T_odom_base``, batch
    of K): odometry and scan factors alone, optimized from the odometry (a chain: GTSAM solves
    it in one or two iterations). The builder initializes from it instead of the raw odometry:
    a scan-matched chain drifts far less (0.3 deg/m of odometry yaw drift is 36 deg over 120 m,
    enough for the tag-based initialization to seat keyframes on the wrong tags)."""
    M_odom = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for k, M in enumerate(M_odom):
        values.insert(X(k), gtsam.Pose3(gtsam.Rot3(M[:3, :3]), M[:3, 3]))
    graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(M_odom[0, :3, :3]),
                                                       M_odom[0, :3, 3]),
                                     gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))  # fmt: skip
    steps = inverse_h(M_odom[:-1]) @ M_odom[1:]
    up = (
        config.odometry_frame.up_in_base(M_odom[:, :3, :3])
        if config.odometry_frame.knows_up
        else None
    )
    noise = odometry_whitening(M_odom, config.odometry, up)
    for k, M in enumerate(steps):
        Z = gtsam.Pose3(gtsam.Rot3(M[:3, :3]), M[:3, 3])
        graph.add(gtsam.BetweenFactorPose3(X(k), X(k + 1), Z, noise.gtsam_model(k)))
    add_relative_factors(graph, sequential, X)
    with solver_errors("the scan-matched odometry"):
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(config)).optimize()
    M = np.array([result.atPose3(X(k)).matrix() for k in range(len(M_odom))])
    return SE3.from_matrix(M, normalize=True)


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
    reg_config = RegistrationConfig(voxel_m=config.voxel_m,
                                    max_correspondence_m=config.max_correspondence_m)  # fmt: skip
    points, targets = [], []
    for s in chosen:
        p = keyframe_points(survey, int(s), config)
        points.append(p)
        targets.append(Target.from_points(p, reg_config))
    T_odom = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)[keyframe]
    steps = np.linalg.norm(np.diff(T_odom[:, :3, 3], axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    stats = LidarStats(keyframes=len(chosen))
    return obs, LidarKeyframes(keyframe, np.asarray(chosen), tuple(points), tuple(targets),
                               travelled, M_base_lidar, config, stats)  # fmt: skip


def keyframe_points(survey: Survey, sweep: int, config: LidarSurveyConfig) -> FloatArray:
    """Sweep ``sweep`` of ``survey.lidar`` de-skewed to its stamp with the odometry, cut to
    ``max_range_m`` and downsampled to ``voxel_m / 2``; ``(N, 3)`` in the scanner frame."""
    points = deskewed_points(survey, sweep, config.deskew_window_s)
    dist = np.linalg.norm(points, axis=1)
    keep = dist <= config.max_range_m
    if config.min_height_m is not None:  # the floor left out (see LidarSurveyConfig)
        assert survey.lidar is not None
        z_base = survey.lidar.T_base_lidar.act(points)[:, 2]
        keep &= z_base >= config.min_height_m
    return voxel_downsample(points[keep], 0.5 * config.voxel_m)


def deskewed_points(survey: Survey, sweep: int, window_s: float) -> FloatArray:
    """Sweep ``sweep`` de-skewed to its stamp with the survey's odometry (scanner frame), at the
    odometry's mean velocity over ``window_s`` around the sweep (:func:`sweep_motion`)."""
    scans = survey.lidar
    assert scans is not None
    offsets = scans.time_offset_s[sweep]
    if offsets is None:
        return finite_points(scans.points_lidar[sweep])
    period_s = float(np.nanmax(offsets)) if len(offsets) else 0.0
    motion = sweep_motion(survey, int(scans.stamps_ns[sweep]), period_s, window_s)
    return deskew(scans.points_lidar[sweep], offsets, motion)


def sweep_motion(
    survey: Survey, stamp_ns: int, period_s: float, window_s: float
) -> Callable[[np.ndarray], SE3]:
    """``offsets (K,) -> T_lidar0_lidart``: constant body velocity, the odometry's mean over
    ``window_s`` centred on the sweep (clamped to the odometry's span).

    Why a mean: odometry's own noise is white at the sample rate (legged odometry's yaw random
    walk is 2.7 mrad over one 0.1 s sweep), and following it sample by sample de-skews the
    sweep with that error (simulated office: 3.7 mrad RMS yaw error per registration, against
    0.25 mrad with the true motion); the mean over 1 s leaves about a tenth of it.
    """
    scans = survey.lidar
    assert scans is not None
    E = scans.T_base_lidar
    t0, t1 = int(survey.odom_stamps_ns[0]), int(survey.odom_stamps_ns[-1])
    centre = stamp_ns + round(0.5 * period_s * S_NS)
    half = round(0.5 * window_s * S_NS)
    begin, end = max(t0, centre - half), min(t1, centre + half)
    T = interpolate_odometry(survey, np.array([begin, end], dtype=np.int64))
    twist = (T[0].inverse() @ T[1]).log() / max((end - begin) / S_NS, 1e-9)  # body, per s

    def motion(offsets_s: np.ndarray) -> SE3:
        step = SE3.exp(np.asarray(offsets_s, dtype=np.float64)[:, None] * twist[None])
        return E.inverse() @ step @ E

    return motion
