"""The map and its QA from a solved survey graph, and the graph's records at the solution.

Split from :mod:`tagloc.mapping.builder` (step 5 of :func:`~tagloc.mapping.build_tag_map`):
:func:`map_and_report` turns the solution into ``TagMap`` entries and :class:`BuildReport` rows
(sigmas, uncertainty flags with advice); :func:`graph_records` assembles every factor's residual
(:mod:`tagloc.mapping.graph_export`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from tagloc.geometry import SE3, inverse_h
from tagloc.mapping.advice import coverage_gaps, uncertainty_advice
from tagloc.mapping.config import MapBuildConfig
from tagloc.mapping.exclude import survey_start_ns
from tagloc.mapping.graph import GraphSolution
from tagloc.mapping.graph_export import GraphAtSolution, factor_records
from tagloc.mapping.observations import Observations
from tagloc.mapping.odometry_noise import odometry_whitening
from tagloc.mapping.refine import Priors
from tagloc.mapping.report import BuildReport, TagQA, tag_sigmas
from tagloc.mapping.residuals import corner_residuals_px, observation_rms_px, rms
from tagloc.mapping.scan_factors import RelativePoseFactors
from tagloc.mapping.survey import Survey
from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap import TagMap


def graph_records(
    survey: Survey,
    obs: Observations,
    solution: GraphSolution,
    M_odom_raw: np.ndarray,
    c: np.ndarray,
    held: Mapping[int, np.ndarray],
    priors: Priors,
    config: MapBuildConfig,
    relative: RelativePoseFactors | None = None,
) -> tuple[dict[str, Any], ...]:
    """Every factor with its residual at ``solution`` (:mod:`tagloc.mapping.graph_export`)."""
    at_solution = GraphAtSolution(
        survey.source, survey_start_ns(survey), obs.keyframe_stamps_ns, solution.M_map_base,
        solution.M_map_tag, obs.tag_keys, obs.keyframe, obs.tag, obs.camera,
        corner_residuals_px(
            obs, solution.M_map_base, solution.M_map_tag, survey.cameras, survey.T_base_cam
        ),
        solution.mahalanobis, config.outlier_sigma, inverse_h(M_odom_raw[:-1]) @ M_odom_raw[1:],
        c, odometry_whitening(M_odom_raw, config.odometry, priors.odometry_up), held,
        priors.held_whitening(held, config),
        priors.up_base, float(np.radians(config.gravity.sigma_deg)), relative,
    )  # fmt: skip
    return tuple(factor_records(at_solution))


def map_and_report(
    survey: Survey,
    obs: Observations,
    solution: GraphSolution,
    anchor_indices: set[int],
    M_map_base_odometry: np.ndarray,
    config: MapBuildConfig,
    ambiguous: set[int],
) -> tuple[TagMap, BuildReport]:
    """The tag map (every tag with its marginal covariance and a note) and the QA report
    (per-tag numbers, uncertain tags with advice: :mod:`tagloc.mapping.advice`)."""
    residual = observation_rms_px(corner_residuals_px(
        obs, solution.M_map_base, solution.M_map_tag, survey.cameras, survey.T_base_cam
    ))  # fmt: skip
    outlier = solution.mahalanobis > config.outlier_sigma
    cams = np.array(obs.camera)
    entries, qa = [], []
    sigma_m, sigma_deg = tag_sigmas(solution.cov_map_tag)
    flagged = sorted(j for j, s in sigma_m.items() if s > config.uncertainty_flag_m)
    advice = uncertainty_advice(
        flagged,
        coverage_gaps(
            solution.M_map_base[:, :3, 3],
            obs.keyframe_stamps_ns,
            obs.keyframe,
            obs.tag,
            survey_start_ns(survey),
        ),
        {j: M[:3, 3] for j, M in solution.M_map_tag.items()},
        sorted(anchor_indices),
        [str(key[1]) for key in obs.tag_keys],
    )
    for j in sorted(solution.M_map_tag):
        family, tag_id = obs.tag_keys[j]
        idx = np.flatnonzero(obs.tag == j)
        n_out = int(outlier[idx].sum())
        disagreeing = n_out >= 3 and n_out > config.disagreeing_fraction * len(idx)
        cov = solution.cov_map_tag.get(j)
        sigma = sigma_m.get(j, float("nan"))
        T_map_tag = SE3.from_matrix(solution.M_map_tag[j], normalize=True)
        note = (
            f"built from {len(idx)} observations"
            + (f"; sigma {100 * sigma:.1f} cm, {sigma_deg[j]:.2f} deg" if j in sigma_m else "")
            + (f"; {n_out} disagree (moved or duplicated?)" if disagreeing else "")
            + ("; tilt ambiguous (seen only face-on or far)" if j in ambiguous else "")
            + ("; uncertain" if j in advice else "")
        )
        entries.append(
            TagEntry.from_pose(
                tag_id,
                T_map_tag,
                float(obs.tag_sizes[j]),
                family=family,
                anchor=j in anchor_indices,
                observations=len(idx),
                covariance=cov,
                note=note,
            )
        )
        qa.append(
            TagQA(
                family,
                tag_id,
                len(idx),
                n_out,
                rms(residual[idx[~outlier[idx]]]),
                sigma,
                tuple(sorted(set(cams[idx].tolist()))),
                j in anchor_indices,
                disagreeing,
                j in ambiguous,
                sigma_deg.get(j, float("nan")),
                j in advice,
                advice.get(j, ""),
            )
        )
    inlier = ~outlier
    report = BuildReport(
        source=survey.source,
        tags=tuple(qa),
        reproj_rms_px=rms(residual[inlier]),
        reproj_rms_px_per_camera={
            str(c): rms(residual[inlier & (cams == c)]) for c in sorted(set(obs.camera))
        },
        observations=len(obs),
        outliers=int(outlier.sum()),
        keyframes=len(obs.keyframe_stamps_ns),
        dropped=dict(obs.dropped),
        disagreeing_tags=tuple(t.tag_id for t in qa if t.disagreeing),
        keyframe_stamps_ns=obs.keyframe_stamps_ns,
        T_map_base_odometry=SE3.from_matrix(M_map_base_odometry, normalize=True),
        T_map_base_optimized=SE3.from_matrix(solution.M_map_base, normalize=True),
        iterations=solution.iterations,
        error_initial=solution.error_initial,
        error_final=solution.error_final,
        gravity_priors=config.odometry_frame.gravity_aligned and config.gravity.priors,
        uncertainty_flag_m=config.uncertainty_flag_m,
    )
    return TagMap.from_entries(entries), report
