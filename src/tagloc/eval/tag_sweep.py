"""The tag sensor's measurement harness: rendered views of one tag through the real stack.

:func:`run_tag_sweep` scores every cell ``(distance, angle, blur, noise)`` of a
:class:`~tagloc.eval.tag_sweep_config.TagSweepConfig`; for each of the cell's views it

1. draws the view (:func:`~tagloc.eval.tag_views.sample_wall_view`: a tag on a wall, a nearly
   level camera), the tag id and the orientation prior;
2. renders the camera image of the real tag bitmap (:func:`tagloc.sim.render_tags_scene`, with
   the cell's defocus blur and read noise, shot noise and vignetting as configured);
3. detects tags in it with the configured backend (timed: ``detect``);
4. runs :func:`tagloc.tags.observe_tags` (PnP with both IPPE branches, covariance, gates and the
   ambiguity policy; timed: ``rest``) with the tag's exact map pose;
5. scores the accepted estimate of the true tag against the renderer's ground truth: position
   and rotation error of ``T_cam_tag``, the error of the camera's position in the tag frame
   (what a fix's position error is), NEES, and whether it is an ambiguity flip
   (:func:`is_ambiguity_flip`).

Then, for joint PnP, face-on rows of 2 or more tags (:mod:`tagloc.eval.tag_sweep_joint`).
Views come from :mod:`tagloc.eval.tag_views`; per-cell statistics and the checks are in
:mod:`tagloc.eval.tag_sweep_stats`; files (CSV, markdown, plots) in
:mod:`tagloc.eval.tag_sweep_report`.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tagloc.eval.summary_types import Check
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.eval.tag_sweep_joint import JointRow, joint_cell, joint_checks
from tagloc.eval.tag_sweep_stats import (
    TagSweepRow,
    ViewOutcome,
    cell_row,
    pooled_nees_per_dof,
)
from tagloc.eval.tag_sweep_verdicts import sweep_checks
from tagloc.eval.tag_views import SweepStack, pose_prior, rotation_error_deg, sample_wall_view
from tagloc.geometry import SE3
from tagloc.sim.render import render_tags_scene
from tagloc.sim.render_config import RenderConfig
from tagloc.tags import nees, observe_tags
from tagloc.tags.pnp import TagPoseEstimate

__all__ = [
    "FLIP_MARGIN_DEG",
    "FLIP_MIN_ERROR_DEG",
    "JointRow",
    "TagSweepResult",
    "is_ambiguity_flip",
    "rotation_error_deg",
    "run_tag_sweep",
    "sample_wall_view",
]

#: An accepted estimate is a flip if it is this far off in rotation ...
FLIP_MIN_ERROR_DEG = 10.0
#: ... and its other IPPE branch is closer to the truth by more than this.
FLIP_MARGIN_DEG = 2.0

#: ``progress(views_done, views_total)``, called after every cell.
ProgressFn = Callable[[int, int], None]


@dataclass(frozen=True, slots=True)
class TagSweepResult:
    """Outcome of :func:`run_tag_sweep`.

    Attributes
    ----------
    config : TagSweepConfig
        The sweep that was run.
    rows : tuple of TagSweepRow
        One per cell, ordered by blur, noise, distance, angle.
    joint_rows : tuple of JointRow
        The face-on multi-tag cells (:mod:`tagloc.eval.tag_sweep_joint`), by tag count, distance.
    checks : tuple of Check
        The targets (:func:`tagloc.eval.tag_sweep_stats.sweep_checks`, then
        :func:`tagloc.eval.tag_sweep_joint.joint_checks`).
    detect_ms, rest_ms : float
        Median per-frame time of detection over every frame of the sweep, and of everything
        after it (``observe_tags``) over the frames with a detection, milliseconds.
    elapsed_s : float
        Wall time of the sweep, rendering included.
    """

    config: TagSweepConfig
    rows: tuple[TagSweepRow, ...]
    joint_rows: tuple[JointRow, ...]
    checks: tuple[Check, ...]
    detect_ms: float
    rest_ms: float
    elapsed_s: float

    @property
    def nees_per_dof(self) -> float:
        """Mean NEES / 6 over every accepted single-tag estimate of the sweep (NaN if none)."""
        return pooled_nees_per_dof(self.rows)

    @property
    def n_views(self) -> int:
        """Views rendered (single-tag and joint)."""
        return sum(r.n_views for r in self.rows) + sum(r.n_views for r in self.joint_rows)

    @property
    def flips(self) -> int:
        """Accepted ambiguity flips over the whole sweep."""
        return sum(r.flips for r in self.rows)


def is_ambiguity_flip(T_cam_tag_true: SE3, estimate: TagPoseEstimate) -> bool:
    """Whether an accepted estimate took the wrong IPPE branch.

    True when ``estimate.T_cam_tag`` is more than :data:`FLIP_MIN_ERROR_DEG` off in rotation and
    its other branch is closer to the truth by more than :data:`FLIP_MARGIN_DEG`. When both
    branches are about equally far (a face-on tag at range: the truth on the watershed between
    them) neither is the right one and it is not counted as a flip (the definition of
    ``tests/tags/test_gates.py``).
    """
    error = rotation_error_deg(T_cam_tag_true, estimate.T_cam_tag)
    if error <= FLIP_MIN_ERROR_DEG:
        return False
    return rotation_error_deg(T_cam_tag_true, estimate.T_cam_tag_alt) < error - FLIP_MARGIN_DEG


def _evaluate_view(
    stack: SweepStack, render: RenderConfig, distance_m: float, angle_deg: float, seed: list[int]
) -> ViewOutcome:
    """Steps 1-5 of the module docstring for one view."""
    config = stack.config
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    # 1. view, tag id, prior
    T_cam_tag, T_map_cam = sample_wall_view(distance_m, np.deg2rad(angle_deg), rng, config.tilt_deg)
    tag_id = int(rng.integers(stack.num_ids))
    prior = None if config.prior == "none" else pose_prior(config, T_map_cam, rng)
    # 2. render
    image, truths = render_tags_scene(
        stack.camera,
        [(tag_id, config.tag_size_m, T_cam_tag)],
        render,
        rng,
        background=config.background_albedo,
        family=config.family,
    )
    # 3. detect
    start = time.perf_counter_ns()
    detections = stack.detector.detect(image)
    detect_s = (time.perf_counter_ns() - start) * 1e-9
    # 4. PnP, covariance, gates, ambiguity policy
    start = time.perf_counter_ns()
    result = observe_tags(
        detections,
        stack.camera,
        config.tag_size_m if config.sensor_tag_size_m is None else config.sensor_tag_size_m,
        config.gates,
        tag_poses={tag_id: T_map_cam @ T_cam_tag},
        prior=prior,
        noise=stack.noise,
    )
    rest_s = (time.perf_counter_ns() - start) * 1e-9
    # 5. score against the renderer's truth
    ours = [d for d in detections if d.tag_id == tag_id]
    corner_sq = np.nan
    if ours and truths:
        corner_sq = float(np.mean(np.sum((ours[0].corners_px - truths[0].corners_px) ** 2, 1)))
    accepted = [e for e in result.accepted if e.tag_id == tag_id]
    reasons = [str(r.reason) for r in result.rejections if r.tag_id == tag_id]
    outcome = ViewOutcome(
        detected=bool(ours),
        accepted=bool(accepted),
        corner_sq_px2=corner_sq,
        detect_s=detect_s,
        rest_s=rest_s,
        rejection=reasons[0] if reasons else ("missed" if not ours else None),
        false_detections=len(detections) - len(ours),
    )
    if not accepted:
        return outcome
    est = accepted[0]
    camera_in_tag = est.T_cam_tag.inverse().translation - T_cam_tag.inverse().translation
    return outcome.scored(
        position_error_m=float(np.linalg.norm(est.T_cam_tag.translation - T_cam_tag.translation)),
        rotation_error_deg=rotation_error_deg(T_cam_tag, est.T_cam_tag),
        flip=is_ambiguity_flip(T_cam_tag, est),
        nees=float(nees(T_cam_tag, est.T_cam_tag, est.cov_cam_tag)),
        camera_position_error_m=float(np.linalg.norm(camera_in_tag)),
    )


def _cell_seed(
    seed: int, distance_m: float, angle_deg: float, blur: float, noise: float
) -> list[int]:
    """The cell's entropy: the sweep seed and the cell's values (micro-units)."""
    return [seed, *(round(1e6 * v) for v in (distance_m, angle_deg, blur, noise))]


def run_tag_sweep(config: TagSweepConfig, progress: ProgressFn | None = None) -> TagSweepResult:
    """Render, detect and score every cell of ``config`` (steps in the module docstring).

    Parameters
    ----------
    config : TagSweepConfig
    progress : callable, optional
        ``progress(views_done, views_total)`` after every cell (e.g. a progress bar).

    Returns
    -------
    TagSweepResult

    Raises
    ------
    TagBackendError
        If the backend or family is unknown, or a detector option is bad.
    """
    started = time.perf_counter()
    stack = SweepStack.from_config(config)
    cells = list(
        itertools.product(config.blur_px, config.noise_dn, config.distances_m, config.angles_deg)
    )
    joint_cells = list(itertools.product(config.joint_tag_counts, config.joint_distances_m))
    total = (len(cells) + len(joint_cells)) * config.trials
    # 1. single tags, every cell
    rows: list[TagSweepRow] = []
    views: list[ViewOutcome] = []
    for i, (blur, noise, distance, angle) in enumerate(cells):
        render = config.render.model_copy(update={"defocus_sigma_px": blur, "read_noise_dn": noise})
        seed = _cell_seed(config.seed, distance, angle, blur, noise)
        outcomes = [
            _evaluate_view(stack, render, distance, angle, [*seed, k]) for k in range(config.trials)
        ]
        rows.append(cell_row(distance, angle, blur, noise, outcomes))
        views += outcomes
        if progress is not None:
            progress((i + 1) * config.trials, total)
    # 2. joint PnP over a face-on row of tags (reference condition)
    joint_rows: list[JointRow] = []
    for j, (n_tags, distance) in enumerate(joint_cells):
        seed = [config.seed, 1_000_000_000 + n_tags, round(1e6 * distance)]
        seeds = [[*seed, k] for k in range(config.trials)]
        joint_rows.append(joint_cell(stack, n_tags, distance, seeds))
        if progress is not None:
            progress((len(cells) + j + 1) * config.trials, total)
    targets = config.targets
    checks = sweep_checks(config, rows) + joint_checks(
        joint_rows, targets.joint_rotation_median_deg, targets.joint_rotation_distance_m
    )
    return TagSweepResult(
        config=config,
        rows=tuple(rows),
        joint_rows=tuple(joint_rows),
        checks=tuple(checks),
        detect_ms=1e3 * float(np.median([v.detect_s for v in views])),
        rest_ms=1e3 * float(np.median([v.rest_s for v in views if v.detected] or [np.nan])),
        elapsed_s=time.perf_counter() - started,
    )
