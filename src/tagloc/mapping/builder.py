"""Build a tag map from a survey drive: PnP observations, a factor graph, QA.

:func:`build_tag_map` reads as its steps:

1. PnP on every detection, keyframes at the frame stamps (:mod:`tagloc.mapping.observations`);
   with lidar sweeps, also keyframes at a sweep every ``lidar.keyframe_distance_m``, their
   consecutive scans registered, and the odometry corrected by them for the initialization
   (:mod:`tagloc.mapping.lidar_survey`);
2. initial keyframe and tag poses, IPPE branch per observation (:mod:`tagloc.mapping.initialize`);
3. pose-factor rounds (:mod:`tagloc.mapping.graph`, GTSAM Levenberg-Marquardt): optimize,
   re-pick each observation's branch at the optimum, again while branches change; optionally
   calibrate the odometry (:mod:`tagloc.mapping.calibration`) between rounds; with lidar, the
   scan-matching factors in every round and loop closures found at the first optimum;
4. corner refinement (:mod:`tagloc.mapping.refine`: Gauss-Newton on the corners, the odometry
   with its calibration, the anchors and the scan factors), then the tilt test of every tag
   (:mod:`tagloc.mapping.flips`) and, if a tag flipped, the refinement again;
5. marginal covariance of every tag; QA (:mod:`tagloc.mapping.report`, with uncertainty flags and
   advice: :mod:`tagloc.mapping.map_qa`) and the TagMap; every factor at the solution as records
   (:mod:`tagloc.mapping.graph_export`). Optional priors: measured anchors with their sigmas
   (:mod:`tagloc.mapping.anchors`), gravity on every keyframe (:mod:`tagloc.mapping.gravity`).

Pose factors or corner factors? Both, for different jobs. PnP pose factors (one
``BetweenFactorPose3`` per observation) converge from drifted odometry and let the IPPE branch be
chosen at the estimate; but the per-view PnP estimate is biased (0.2 % short in range at 0.3 px
noise, measured), that does not average out, and a tag initialized on the wrong tilt stays
there. The corners are unbiased and decide the tilt. Simulated office, one loop (seed 1, every
3rd frame, noise models matching the simulation), *perfect* odometry: pose factors alone 1.9 cm
position RMS and 6.6 deg rotation RMS (1.6 s), with the corner refinement and tilt test 0.84 cm
and 0.51 deg (4.4 s); legged odometry, one anchor: 15.6 cm and 22.7 deg (a tag initialized
from drifted keyframes 130 deg off), then 9.0 cm and 0.84 deg.

What limits the map with one anchor is the odometry between rooms, not the observations: the
tags of a room are seen from inside it, linked to the rest only through the walk through the
door and the turns (legged random walk 0.7 deg/sqrt(m), 1 deg/sqrt(rad) of yaw). The marginal
covariances say so: on the two-lap survey (12 simulated odometry seeds) the tags' position
sigma is 11.5 cm RMS and the errors 7.6 cm RMS (normalized by their sigma 0.88 RMS, the worst
of 432 at 3.6); perfect odometry gives 1.0 cm, and 8 anchors (one per room) 1.6 cm on the
other tags. Rotation: 0.67 deg RMS with one anchor (worst tag 2.2 deg).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

from tagloc.frames import base_tilt_deg
from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.anchors import Anchor, as_anchor
from tagloc.mapping.calibration import (
    OdometryCalibration,
    apply_calibration,
    calibration_from_vector,
    calibration_vector,
    fit_calibration,
)
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.graph import (
    GraphInput,
    GraphSolution,
    build_graph,
    held_tags,
    marginal_covariances,
    solve_graph,
)
from tagloc.mapping.gravity import map_tilt_deg
from tagloc.mapping.gtsam_bridge import SolverError
from tagloc.mapping.initialize import (
    choose_branches,
    initialize_keyframes,
    initialize_tags,
)
from tagloc.mapping.lidar_survey import prepare_lidar, sequential_factors
from tagloc.mapping.map_qa import graph_records, map_and_report
from tagloc.mapping.observations import Observations, collect_observations
from tagloc.mapping.refine import Priors, RefineInputs, State, refine_and_test_tilts
from tagloc.mapping.report import BuildReport
from tagloc.mapping.scan_factors import RelativePoseFactors, scan_scale
from tagloc.mapping.scan_odometry import scan_odometry
from tagloc.mapping.survey import MappingError, Survey, TagKey
from tagloc.tags.tagmap import TagMap
from tagloc.tags.tagmap_checks import DEFAULT_FAMILY

logger = logging.getLogger(__name__)

#: ``progress(stage, done, total)``; stages ``"pnp"``, ``"optimize"``.
ProgressFn = Callable[[str, int, int], None]
Anchors = Mapping[int, SE3 | Anchor] | Mapping[TagKey, SE3 | Anchor]


def _anchor_indices(
    anchors: Anchors, obs: Observations, source: str, config: MapBuildConfig
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Anchor poses and prior sigmas by tag index."""
    index = {key: j for j, key in enumerate(obs.tag_keys)}
    result, sigmas = {}, {}
    for key, value in anchors.items():
        anchor = as_anchor(value)
        tag_key = key if isinstance(key, tuple) else (DEFAULT_FAMILY, int(key))
        if tag_key not in index:
            raise MappingError(
                f"{source}: anchor tag {tag_key[0]}:{tag_key[1]} is never observed "
                f"(observed: {', '.join(str(k[1]) for k in obs.tag_keys)})"
            )
        result[index[tag_key]] = anchor.T_map_tag.as_matrix()
        sigmas[index[tag_key]] = anchor.sigmas(config)
    return result, sigmas


def _graph_input(
    obs: Observations,
    M_odom_base: np.ndarray,
    branch: np.ndarray,
    anchors: Mapping[int, np.ndarray],
    M_map_base: np.ndarray,
    M_map_tag: Mapping[int, np.ndarray],
    priors: Priors,
    relative: RelativePoseFactors | None = None,
) -> GraphInput:
    rows = np.arange(len(obs))
    return GraphInput(
        M_odom_base=M_odom_base,
        keyframe=obs.keyframe,
        tag=obs.tag,
        M_base_tag=obs.T_base_tag[rows, branch],
        cov_base_tag=obs.cov[rows, branch],
        M_map_anchor=anchors,
        M_map_base_init=M_map_base,
        M_map_tag_init=M_map_tag,
        anchor_sigmas=priors.anchor_sigmas,
        up_base=priors.up_base,
        odometry_up=priors.odometry_up,
        relative=relative,
    )


def build_tag_map(
    survey: Survey,
    anchors: Anchors | None = None,
    config: MapBuildConfig | None = None,
    progress: ProgressFn | None = None,
) -> tuple[TagMap, BuildReport]:
    """Build the tag map of ``survey`` (steps in the module docstring).

    Parameters
    ----------
    survey : Survey
    anchors : mapping of tag id (or (family, id)) to SE3 or Anchor, optional
        Surveyed ``T_map_tag`` of anchor tags, held by priors with their sigmas
        (:class:`~tagloc.mapping.anchors.Anchor`; a bare SE3: the configuration's sigmas). None
        or empty: the first tag seen defines ``map`` (identity pose).
    config : MapBuildConfig, optional
    progress : callable, optional
        ``progress(stage, done, total)`` for a progress bar.

    Returns
    -------
    (TagMap, BuildReport)
        Every observed tag in frame ``map`` with its marginal covariance ``[x, y, z, rx, ry, rz]``
        (right perturbation, m and rad) and observation count; the QA report.

    Raises
    ------
    MappingError
        No odometry, a tag of unknown size, an anchor never observed, no usable detection, a
        graph GTSAM cannot solve (:class:`~tagloc.mapping.gtsam_bridge.SolverError`).
    """
    config = config or MapBuildConfig()
    anchors = anchors or {}
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    # 1. observations
    pnp_progress = None if progress is None else (lambda d, n: progress("pnp", d, n))
    obs = collect_observations(
        survey, config.pnp_noise, config.max_range_m, pnp_progress, config.observation_covariance
    )
    timings["observations"] = time.perf_counter() - t_start
    # 1b. lidar keyframes: pose variables at sweeps, their scans prepared for registration
    t = time.perf_counter()
    lidar = prepare_lidar(survey, obs, config.lidar)
    relative: RelativePoseFactors | None = None
    obs_init = obs
    if lidar is not None:
        obs, scans = lidar
        timings["lidar_keyframes"] = time.perf_counter() - t
        # consecutive registrations from the odometry; the scan-corrected odometry initializes
        t = time.perf_counter()
        scans, relative = sequential_factors(
            survey, scans, obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
        )
        obs_init = replace(obs, T_odom_base=scan_odometry(obs, relative, config))
        timings["scan_matching"] = time.perf_counter() - t
    # 2. initial values
    t = time.perf_counter()
    M_anchor, anchor_sigmas = _anchor_indices(anchors, obs, survey.source, config)
    R_odom_base = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)[:, :3, :3]
    frame_warning = None
    if not config.odometry_frame.knows_up:  # no vertical to split the odometry noise about
        logger.info("%s: the odometry frame knows no up: no vertical noise split", survey.source)
        config = config.model_copy(
            update={"odometry": config.odometry.model_copy(update={"vertical_factor": 1.0})}
        )
        odometry_up = np.tile([0.0, 0.0, 1.0], (len(R_odom_base), 1))
    else:
        odometry_up = config.odometry_frame.up_in_base(R_odom_base)
        frame_warning = _check_odometry_frame(R_odom_base, odometry_up, config, survey.source)
    gravity = config.odometry_frame.gravity_aligned and config.gravity.priors
    priors = Priors(anchor_sigmas, odometry_up if gravity else None, odometry_up)
    M_map_base = initialize_keyframes(obs_init, M_anchor, config.max_ambiguity_for_init)
    M_map_tag = initialize_tags(obs, M_map_base, M_anchor)
    branch = choose_branches(obs, M_map_base, M_map_tag)
    timings["initialize"] = time.perf_counter() - t
    # 3. and 4.: GTSAM names a tag by its index: name it by family and id
    tag_names = [f"{family}:{tag_id}" for family, tag_id in obs.tag_keys]
    try:
        # 3. optimize, re-pick branches, repeat
        t = time.perf_counter()
        M_map_base_odometry = _odometry_in_map(obs, M_map_base)
        M_odom_raw = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
        M_odom_base, calibration = M_odom_raw, OdometryCalibration.identity()
        scan_s = 0.0
        solution: GraphSolution | None = None
        iterations, optimize_s, error_initial = 0, 0.0, float("nan")
        n_rounds = config.rounds + config.calibration_rounds
        for round_ in range(n_rounds):
            if progress is not None:
                progress("optimize", round_, n_rounds)
            data = _graph_input(
                obs, M_odom_base, branch, M_anchor, M_map_base, M_map_tag, priors, relative
            )
            solution = solve_graph(data, config)
            iterations += solution.iterations
            optimize_s += solution.optimize_s
            error_initial = solution.error_initial if round_ == 0 else error_initial
            M_map_base, M_map_tag = solution.M_map_base, solution.M_map_tag
            new_branch = choose_branches(obs, M_map_base, M_map_tag)
            changed = int((new_branch != branch).sum())
            branch = new_branch
            calibrate = round_ + 1 >= config.rounds and round_ + 1 < n_rounds
            closed = 0
            if lidar is not None and relative is not None and round_ == 0:
                t_scan = time.perf_counter()  # loop closures at the first estimate
                loops = scans.loops(M_map_base)
                relative, closed = relative.concat(loops), len(loops)
                scan_s += time.perf_counter() - t_scan
            logger.info(
                "round %d: %d iterations, %d branches changed", round_, solution.iterations, changed
            )
            if calibrate:
                calibration = fit_calibration(M_odom_raw, M_map_base)
                M_odom_base = apply_calibration(M_odom_raw, calibration)
                logger.info("odometry calibration: %s", calibration)
            elif not changed and not closed:
                break
        assert solution is not None
        timings["pose_rounds"] = time.perf_counter() - t - scan_s
        timings["scan_matching"] = timings.get("scan_matching", 0.0) + scan_s
        t_refine = time.perf_counter()
        ambiguous: list[int] = []
        held = held_tags(M_anchor, obs.tag, M_map_tag)
        state = State(M_map_base, M_map_tag, calibration_vector(calibration))
        if config.factors == "corners":
            inputs = RefineInputs(obs, M_odom_raw, held, survey.cameras, survey.T_base_cam,
                                  config, priors, relative)  # fmt: skip
            solution, state, ambiguous = refine_and_test_tilts(inputs, state, set(M_anchor))
            iterations += solution.iterations
            optimize_s += solution.optimize_s
            logger.info("odometry calibration: %s", calibration_from_vector(state.c))
        if progress is not None:
            progress("optimize", config.rounds, config.rounds)
        timings["corner_refinement"] = time.perf_counter() - t_refine
        timings["optimize"] = optimize_s
        timings["graph"] = time.perf_counter() - t - optimize_s
        # 4. covariances
        t = time.perf_counter()
        if config.compute_covariance and config.factors == "corners":
            # the last linearization of the refinement: the corners' Gauss-Newton information
            solution = marginal_covariances(solution)
        elif config.compute_covariance:
            data = _graph_input(
                obs, M_odom_base, branch, M_anchor, solution.M_map_base, solution.M_map_tag,
                priors, relative,
            )  # fmt: skip
            graph, values = build_graph(data, config)
            at = replace(solution, graph=graph, values=values)
            solution = replace(solution, cov_map_tag=marginal_covariances(at).cov_map_tag)
            solution = replace(solution, marginals_s=time.perf_counter() - t)
        timings["covariance"] = solution.marginals_s if config.compute_covariance else 0.0
    except SolverError as exc:
        raise exc.naming(tag_names) from None
    # 5. QA and the map
    t = time.perf_counter()
    tag_map, report = map_and_report(
        survey, obs, solution, set(M_anchor), M_map_base_odometry, config, set(ambiguous)
    )
    odometry_z = config.odometry_frame.model_copy(update={"gravity_aligned": True})
    up_odom = odometry_z.up_in_base(R_odom_base)  # the odometry frame's up, in each base
    object.__setattr__(report, "tilt_deg", map_tilt_deg(solution.M_map_base, up_odom))
    if frame_warning is not None:
        object.__setattr__(report, "warnings", (frame_warning,))
    factors = graph_records(
        survey, obs, solution, M_odom_raw, state.c, held, priors, config, relative
    )
    object.__setattr__(report, "factors", factors)
    timings["report"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start
    object.__setattr__(report, "timings_s", timings)
    object.__setattr__(report, "iterations", iterations)
    object.__setattr__(report, "error_initial", error_initial)
    scale = {"odometry": float(state.c[0])}
    if lidar is not None:
        object.__setattr__(report, "scan_matching", scans.stats.as_dict())
        if relative is not None:
            s, sigma = scan_scale(solution.M_map_base, relative)
            scale |= {"scan_matching": s, "scan_matching_sigma": sigma}
    object.__setattr__(report, "scale", scale)
    return tag_map, report


def _odometry_in_map(obs: Observations, M_map_base_init: np.ndarray) -> np.ndarray:
    """Keyframe odometry, aligned to ``map`` at the first keyframe (the 'before' trajectory)."""
    M_odom_base = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
    return np.asarray((M_map_base_init[0] @ inverse_h(M_odom_base[0])) @ M_odom_base)


#: Median angle (deg) between the body's configured "up" and the odometry frame's z above which
#: the odometry frame's configuration is probably wrong (a camera frame taken for an upright
#: base: about 90).
BASE_TILT_WARN_DEG = 30.0


def _check_odometry_frame(
    R_odom_base: np.ndarray, odometry_up: np.ndarray, config: MapBuildConfig, source: str
) -> str | None:
    """The warning (for the QA report) when the body's "up" is far from the odometry frame's z."""
    if config.odometry_frame.gravity_aligned:
        return None
    tilt = base_tilt_deg(R_odom_base, odometry_up)
    if tilt <= BASE_TILT_WARN_DEG:
        return None
    message = (
        f"{source}: the body's up axis ({config.odometry_frame.base_up_axis}) is {tilt:.0f} deg "
        "from the odometry frame's z (median over keyframes): the odometry noise is split about "
        "the wrong vertical; if the odometry is gravity-aligned (VIO) set "
        "odometry_frame.gravity_aligned, otherwise odometry_frame.base_up_axis"
    )
    logger.info("%s", message)
    return message

