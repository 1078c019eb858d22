"""Joint PnP in the tag-sensor sweep: a face-on row of tags, rendered, against the best single.

For every ``(n_tags, distance)`` of ``joint_tag_counts x joint_distances_m`` (reference
condition), each of ``trials`` views (:func:`~tagloc.eval.tag_views.sample_board_view`) is
rendered, detected and run through :func:`tagloc.tags.observe_tags` with every tag's map pose,
which solves joint PnP over them. Scored against the true ``T_map_cam``: the accepted joint
estimate, and the *best single tag* of the frame, i.e. the one whose own PnP estimate
(:func:`tagloc.tags.estimate_tag_poses`, lowest-reprojection branch, before any gate: face-on
single tags are mostly refused as ambiguous) implies the camera rotation nearest the truth, as
in the corner-level test of ``tests/tags/test_pnp.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tagloc.eval.summary_types import Check
from tagloc.eval.tag_sweep_stats import percentile_or_nan
from tagloc.eval.tag_views import SweepStack, pose_prior, rotation_error_deg, sample_board_view
from tagloc.sim.render import render_tags_scene
from tagloc.tags import estimate_tag_poses, nees, observe_tags


@dataclass(frozen=True, slots=True)
class JointRow:
    """One ``(n_tags, distance)`` cell of the joint part.

    Attributes
    ----------
    n_tags : int
    distance_m : float
        Camera to the wall.
    n_views : int
    joint_rate : float
        Fraction of views with an accepted joint estimate.
    rotation_error_median_deg, rotation_error_p95_deg : float
        Of the accepted joint ``T_map_cam``.
    position_error_median_m : float
    best_single_rotation_median_deg : float
        Median over views of the best single tag's rotation error (NaN if none solved).
    nees_per_dof : float
        Mean NEES / 6 of the accepted joint estimates.
    """

    n_tags: int
    distance_m: float
    n_views: int
    joint_rate: float
    rotation_error_median_deg: float
    rotation_error_p95_deg: float
    position_error_median_m: float
    best_single_rotation_median_deg: float
    nees_per_dof: float


def joint_cell(
    stack: SweepStack, n_tags: int, distance_m: float, seeds: Sequence[list[int]]
) -> JointRow:
    """Render, detect and score the views of one cell (module docstring); one seed a view."""
    config = stack.config
    render = config.render.model_copy(
        update={"defocus_sigma_px": config.blur_px[0], "read_noise_dn": config.noise_dn[0]}
    )
    joint_rot, joint_pos, joint_nees, single_rot = [], [], [], []
    for seed in seeds:
        rng = np.random.default_rng(np.random.SeedSequence(seed))
        T_map_tags, T_map_cam = sample_board_view(
            distance_m, n_tags, config.joint_spacing_m, rng, config.tilt_deg
        )
        ids = [int(i) for i in rng.choice(stack.num_ids, n_tags, replace=False)]
        prior = None if config.prior == "none" else pose_prior(config, T_map_cam, rng)
        T_cam_map = T_map_cam.inverse()
        scene = [
            (i, config.tag_size_m, T_cam_map @ T) for i, T in zip(ids, T_map_tags, strict=True)
        ]
        image, _ = render_tags_scene(
            stack.camera, scene, render, rng,
            background=config.background_albedo, family=config.family,
        )  # fmt: skip
        poses = dict(zip(ids, T_map_tags, strict=True))
        all_detections = stack.detector.detect(image)
        result = observe_tags(
            all_detections, stack.camera, config.tag_size_m, config.gates,
            tag_poses=poses, prior=prior, noise=stack.noise,
        )  # fmt: skip
        detections = [d for d in all_detections if d.tag_id in poses]
        if result.joint is not None:
            joint_rot.append(rotation_error_deg(T_map_cam, result.joint.T_map_cam))
            joint_pos.append(
                float(np.linalg.norm(result.joint.T_map_cam.translation - T_map_cam.translation))
            )
            joint_nees.append(float(nees(T_map_cam, result.joint.T_map_cam,
                                         result.joint.cov_map_cam)))  # fmt: skip
        if detections:
            singles = estimate_tag_poses(
                [d.tag_id for d in detections],
                np.array([d.corners_px for d in detections]),
                [config.tag_size_m] * len(detections),
                stack.camera,
                stack.noise,
            )
            errors = [
                rotation_error_deg(T_map_cam, poses[e.tag_id] @ e.T_cam_tag.inverse())
                for e in singles
                if e is not None
            ]
            if errors:
                single_rot.append(min(errors))
    return JointRow(
        n_tags=n_tags,
        distance_m=distance_m,
        n_views=len(seeds),
        joint_rate=len(joint_rot) / len(seeds) if seeds else math.nan,
        rotation_error_median_deg=percentile_or_nan(joint_rot, 50),
        rotation_error_p95_deg=percentile_or_nan(joint_rot, 95),
        position_error_median_m=percentile_or_nan(joint_pos, 50),
        best_single_rotation_median_deg=percentile_or_nan(single_rot, 50),
        nees_per_dof=float(np.mean(joint_nees)) / 6.0 if joint_nees else math.nan,
    )


def joint_checks(
    rows: Sequence[JointRow], max_rotation_deg: float, at_distance_m: float
) -> list[Check]:
    """Joint PnP within ``max_rotation_deg`` face-on at ``at_distance_m`` (worst tag count), and
    no worse than the best single tag in any cell (NaN / None without such cells)."""
    rotation = [
        r.rotation_error_median_deg
        for r in rows
        if math.isclose(r.distance_m, at_distance_m) and math.isfinite(r.rotation_error_median_deg)
    ]
    margin = [
        r.rotation_error_median_deg - r.best_single_rotation_median_deg
        for r in rows
        if math.isfinite(r.rotation_error_median_deg - r.best_single_rotation_median_deg)
    ]
    worst_rotation = max(rotation) if rotation else math.nan
    worst_margin = max(margin) if margin else math.nan
    return [
        Check(
            f"joint PnP rotation error median, face-on at {at_distance_m:g} m (worst count)",
            worst_rotation,
            f"<= {max_rotation_deg:g} deg",
            None if math.isnan(worst_rotation) else worst_rotation <= max_rotation_deg,
        ),
        Check(
            "joint minus best single tag, rotation median (worst cell)",
            worst_margin,
            "<= 0 deg",
            None if math.isnan(worst_margin) else worst_margin <= 0.0,
        ),
    ]
