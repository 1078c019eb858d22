"""The tag sensor's measurement harness: rendered views of one tag through the real stack.

:func:`run_tag_sweep` scores every cell ``(distance, angle, blur, noise)`` of a
:class:`~tagloc.eval.tag_sweep_config.TagSweepConfig`; for each of the cell's views it

1. draws the view (:func:`sample_wall_view`: a tag on a wall, a nearly level camera), the tag id
   and the orientation prior;
2. renders the camera image of the real tag bitmap (:func:`tagloc.sim.render_tags_scene`, with
   the cell's defocus blur and read noise, shot noise and vignetting as configured);
3. detects tags in it with the configured backend (timed: ``detect``);
4. runs :func:`tagloc.tags.observe_tags` (PnP with both IPPE branches, covariance, gates and the
   ambiguity policy; timed: ``rest``) with the tag's exact map pose;
5. scores the accepted estimate of the true tag against the renderer's ground truth: position
   and rotation error of ``T_cam_tag``, NEES, and whether it is an ambiguity flip
   (:func:`is_ambiguity_flip`).

Per-cell statistics and the issue's checks are in :mod:`tagloc.eval.tag_sweep_stats`; files
(CSV, markdown, plots) in :mod:`tagloc.eval.tag_sweep_report`.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tagloc.camera import CameraModel
from tagloc.eval.summary import Check
from tagloc.eval.tag_sweep_config import TagSweepConfig
from tagloc.eval.tag_sweep_stats import TagSweepRow, ViewOutcome, cell_row, sweep_checks
from tagloc.geometry import SE3, SO3
from tagloc.sim.render import render_tags_scene
from tagloc.sim.render_config import RenderConfig
from tagloc.tags import (
    NoiseModel,
    PosePrior,
    TagDetector,
    family_spec,
    make_detector,
    nees,
    observe_tags,
)
from tagloc.tags.pnp import TagPoseEstimate

__all__ = [
    "FLIP_MARGIN_DEG",
    "FLIP_MIN_ERROR_DEG",
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
#: Map up in a level camera's optical frame; optical axes of a level camera in a z-up map.
_UP_LEVEL_CAM = np.array([0.0, -1.0, 0.0])
_R_MAP_LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_E_Z = np.array([0.0, 0.0, 1.0])

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
    checks : tuple of Check
        The issue's targets (:func:`tagloc.eval.tag_sweep_stats.sweep_checks`).
    nees_per_dof : float
        Mean NEES / 6 over every accepted estimate of the sweep (NaN if none).
    detect_ms, rest_ms : float
        Median per-frame time of detection over every frame of the sweep, and of everything
        after it (``observe_tags``) over the frames with a detection, milliseconds.
    elapsed_s : float
        Wall time of the sweep, rendering included.
    """

    config: TagSweepConfig
    rows: tuple[TagSweepRow, ...]
    checks: tuple[Check, ...]
    nees_per_dof: float
    detect_ms: float
    rest_ms: float
    elapsed_s: float

    @property
    def n_views(self) -> int:
        """Views rendered."""
        return sum(r.n_views for r in self.rows)

    @property
    def flips(self) -> int:
        """Accepted ambiguity flips over the whole sweep."""
        return sum(r.flips for r in self.rows)


def rotation_error_deg(T_true: SE3, T_est: SE3) -> float:
    """Angle of ``R_true^T R_est``, degrees."""
    return float(np.rad2deg(np.linalg.norm((T_true.inverse() @ T_est).rotation.log())))


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


def sample_wall_view(
    distance_m: float, angle_rad: float, rng: np.random.Generator, tilt_deg: float = 1.0
) -> tuple[SE3, SE3]:
    """An upright tag on a vertical wall seen by a nearly level camera at the map origin.

    The tag center is ``distance_m`` away along a ray up to 25 deg off-axis horizontally and up
    to ``min(15 deg, angle)`` vertically; the tag normal is horizontal and makes ``angle_rad``
    with the ray to the camera (to either side); the camera is rolled and pitched by
    ``N(0, tilt_deg)`` each. The same draws, in the same order, as the corner-level tests'
    ``wall_view`` (``tests/tags/test_pnp.py``), so both see the same views for the same seed.

    Parameters
    ----------
    distance_m : float
    angle_rad : float
        Viewing angle, ``[0, pi/2)``.
    rng : numpy.random.Generator
    tilt_deg : float

    Returns
    -------
    T_cam_tag, T_map_cam : SE3
        The map has z up; ``T_map_tag = T_map_cam @ T_cam_tag`` has its y axis up.
    """
    el = np.deg2rad(rng.uniform(-1.0, 1.0) * min(15.0, np.rad2deg(angle_rad)))
    az = np.deg2rad(rng.uniform(-25.0, 25.0))
    ray = np.array([np.sin(az) * np.cos(el), -np.sin(el), np.cos(az) * np.cos(el)])
    psi = np.arccos(np.clip(np.cos(angle_rad) / np.cos(el), -1.0, 1.0)) * rng.choice([-1, 1])
    h = -np.array([ray[0], 0.0, ray[2]]) / np.hypot(ray[0], ray[2])
    c, s = np.cos(psi), np.sin(psi)
    normal = np.array([c * h[0] + s * h[2], 0.0, -s * h[0] + c * h[2]])
    R_level_tag = np.stack([np.cross(_UP_LEVEL_CAM, normal), _UP_LEVEL_CAM, normal], axis=1)
    tilt = np.deg2rad(tilt_deg) * rng.normal(size=3) * np.array([1.0, 0.0, 1.0])
    R_cam_level = SO3.from_rotvec(tilt).matrix
    T_cam_tag = SE3(
        rotation=SO3.from_matrix(R_cam_level @ R_level_tag),
        translation=R_cam_level @ (distance_m * ray),
    )
    T_map_cam = SE3(rotation=SO3.from_matrix(_R_MAP_LEVEL @ R_cam_level.T), translation=np.zeros(3))
    return T_cam_tag, T_map_cam


def _pose_prior(config: TagSweepConfig, T_map_cam: SE3, rng: np.random.Generator) -> PosePrior:
    """Gravity off by ``gravity_error_deg`` per axis, plus (``"rotation"``) a predicted camera
    rotation off by ``prior_rotation_error_deg`` per axis; both with ``prior_sigma_deg``."""
    measured = T_map_cam.rotation @ SO3.from_rotvec(
        np.deg2rad(config.gravity_error_deg) * rng.normal(size=3)
    )
    up_cam = measured.inverse().act(_E_Z)
    predicted = None
    if config.prior == "rotation":
        turn = np.deg2rad(config.prior_rotation_error_deg) * rng.normal(size=3)
        predicted = T_map_cam.plus(np.r_[0.0, 0.0, 0.0, turn])
    sigma = np.deg2rad(config.prior_sigma_deg)
    return PosePrior(predicted, sigma, up_cam, sigma)


@dataclass(frozen=True, slots=True)
class _Stack:
    """What every view of a sweep shares."""

    config: TagSweepConfig
    camera: CameraModel
    detector: TagDetector
    noise: NoiseModel
    num_ids: int


def _evaluate_view(
    stack: _Stack, render: RenderConfig, distance_m: float, angle_deg: float, seed: list[int]
) -> ViewOutcome:
    """Steps 1-5 of the module docstring for one view."""
    config = stack.config
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    # 1. view, tag id, prior
    T_cam_tag, T_map_cam = sample_wall_view(distance_m, np.deg2rad(angle_deg), rng, config.tilt_deg)
    tag_id = int(rng.integers(stack.num_ids))
    prior = None if config.prior == "none" else _pose_prior(config, T_map_cam, rng)
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
        config.tag_size_m,
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
    return outcome.scored(
        position_error_m=float(np.linalg.norm(est.T_cam_tag.translation - T_cam_tag.translation)),
        rotation_error_deg=rotation_error_deg(T_cam_tag, est.T_cam_tag),
        flip=is_ambiguity_flip(T_cam_tag, est),
        nees=float(nees(T_cam_tag, est.T_cam_tag, est.cov_cam_tag)),
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
    stack = _Stack(
        config,
        config.camera_model(),
        make_detector(config.backend, config.family, **config.detector_options),
        config.noise_model(),
        family_spec(config.family).num_ids,
    )
    cells = list(
        itertools.product(config.blur_px, config.noise_dn, config.distances_m, config.angles_deg)
    )
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
            progress((i + 1) * config.trials, len(cells) * config.trials)
    accepted_nees = [v.nees for v in views if v.accepted]
    return TagSweepResult(
        config=config,
        rows=tuple(rows),
        checks=tuple(sweep_checks(config, rows)),
        nees_per_dof=float(np.mean(accepted_nees)) / 6.0 if accepted_nees else float("nan"),
        detect_ms=1e3 * float(np.median([v.detect_s for v in views])),
        rest_ms=1e3 * float(np.median([v.rest_s for v in views if v.detected] or [np.nan])),
        elapsed_s=time.perf_counter() - started,
    )
