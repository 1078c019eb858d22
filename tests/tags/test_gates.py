"""Gates, the ambiguity policy and :func:`observe_tags` on streams of good and bad detections.

Oracles: hand-computed limits and chi-squares for the pure functions; simulator ground truth for
the flip sweep (see :func:`_outcomes` for what counts as a flip).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from pydantic import ValidationError
from test_pnp import (
    CAMERA,
    SIZE,
    corners_of,
    level_camera,
    observe_cell,
    rotation_error_deg,
    wall_tags,
    wall_view,
)

from tagloc.geometry import SE3, SO3
from tagloc.tags.detection import TagDetection
from tagloc.tags.gates import (
    GateConfig,
    OrientationPrior,
    PriorEvidence,
    RejectReason,
    check_detection,
    check_estimate,
    resolve_ambiguity,
)
from tagloc.tags.observation import ObservationResult, PosePrior, observe_tags
from tagloc.tags.pnp import estimate_tag_pose

MIN_ODDS = GateConfig().ambiguity_log_odds


def _outcomes(results: list[tuple[SE3, ObservationResult]]) -> tuple[float, int, int]:
    """Acceptance rate, wrong-branch flips and accepted rotation errors > 10 deg.

    A wrong-branch flip is an accepted estimate more than 10 deg off whose other branch is
    closer to the truth by more than 2 deg; when both branches are about equally far (a face-on
    tag at range, the truth on the watershed between them) neither was the right one, and the
    error is counted only among the > 10 deg errors.
    """
    accepted = [(T, r.accepted[0]) for T, r in results if r.accepted]
    big = [(T, e) for T, e in accepted if rotation_error_deg(T, e.T_cam_tag) > 10.0]
    wrong = [
        1
        for T, e in big
        if rotation_error_deg(T, e.T_cam_tag_alt) < rotation_error_deg(T, e.T_cam_tag) - 2.0
    ]
    return len(accepted) / len(results), len(wrong), len(big)


# ----- config, reasons, single gates -----------------------------------------------------------


def test_reject_reasons_are_stable_strings() -> None:
    assert str(RejectReason.AMBIGUOUS) == "ambiguous" and isinstance(RejectReason.RANGE, str)
    assert {r.value for r in RejectReason} >= {
        "reprojection",
        "range",
        "view_angle",
        "decision_margin",
        "hamming",
        "ambiguous",
        "unknown_tag",
        "degenerate",
        "prior_conflict",
    }


def test_gate_config_forbids_unknown_fields_and_names_them() -> None:
    with pytest.raises(ValidationError, match="max_range"):
        GateConfig(max_range=3.0)  # type: ignore[call-arg]
    with pytest.raises(ValidationError, match="max_view_angle_deg"):
        GateConfig(max_view_angle_deg=120.0)
    assert GateConfig(max_hamming=0).max_hamming == 0


def test_detection_gates_hamming_then_margin_and_skip_nan_margins() -> None:
    corners = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 50.0], [10.0, 50.0]])
    config = GateConfig(max_hamming=1, min_decision_margin=30.0)
    hamming = check_detection(TagDetection(3, "tag36h11", corners, 2, 10.0), config)
    assert hamming is not None and hamming.reason is RejectReason.HAMMING and hamming.tag_id == 3
    margin = check_detection(TagDetection(3, "tag36h11", corners, 0, 10.0), config)
    assert margin is not None and margin.reason is RejectReason.DECISION_MARGIN
    assert margin.value == 10.0 and margin.limit == 30.0 and "decision margin" in margin.detail
    assert check_detection(TagDetection(3, "aruco_4x4_50", corners), config) is None


def test_estimate_gates_reprojection_range_and_view_angle() -> None:
    T, _ = wall_view(3.0, np.deg2rad(50.0), np.random.default_rng(30))
    est = estimate_tag_pose(TagDetection(4, "tag36h11", corners_of(T)), CAMERA, SIZE)
    assert check_estimate(est, GateConfig()) is None
    bad = dataclasses.replace(est, reproj_err_px=3.0)
    assert check_estimate(bad, GateConfig()).reason is RejectReason.REPROJECTION  # type: ignore[union-attr]
    assert check_estimate(est, GateConfig(max_range_m=2.5)).reason is RejectReason.RANGE  # type: ignore[union-attr]
    view = check_estimate(est, GateConfig(max_view_angle_deg=45.0))
    assert view is not None and view.reason is RejectReason.VIEW_ANGLE
    assert view.value == pytest.approx(50.0, abs=0.1)


# ----- the ambiguity policy (pure) -------------------------------------------------------------


def test_policy_accepts_on_data_rejects_when_ambiguous_and_without_alternative_accepts() -> None:
    sigma = 0.5
    strong = resolve_ambiguity(0.5, 0.5 + 20.0 * sigma**2, sigma, MIN_ODDS)
    assert (
        strong.reason is None and not strong.choose_alt and strong.log_odds == pytest.approx(20.0)
    )
    weak = resolve_ambiguity(0.5, 0.5 + 3.0 * sigma**2, sigma, MIN_ODDS)
    assert weak.reason is RejectReason.AMBIGUOUS and "log-odds" in weak.detail
    assert resolve_ambiguity(0.5, math.inf, sigma, MIN_ODDS).reason is None


def test_policy_lets_a_prior_choose_the_alternative_and_rejects_conflicts() -> None:
    sigma = 0.5
    # pixels slightly prefer the best (2), prior strongly the alternative (40 - 0.5)
    prior = PriorEvidence(chi2=40.0, chi2_alt=0.5, innovation_chi2=30.0, innovation_chi2_alt=0.4)
    flipped = resolve_ambiguity(1.0, 1.0 + 2.0 * sigma**2, sigma, MIN_ODDS, prior, 16.3)
    assert flipped.reason is None and flipped.choose_alt
    assert flipped.log_odds == pytest.approx(37.5)
    assert flipped.data_log_odds == pytest.approx(2.0) and flipped.prior_log_odds == -39.5
    # pixels decisive for the best, but the best is far from the prior
    conflict = PriorEvidence(chi2=60.0, chi2_alt=80.0, innovation_chi2=50.0, innovation_chi2_alt=70)
    out = resolve_ambiguity(1.0, 1.0 + 100.0 * sigma**2, sigma, MIN_ODDS, conflict, 16.3)
    assert out.reason is RejectReason.PRIOR_CONFLICT


def test_orientation_prior_chi2_values() -> None:
    R = SO3.from_rotvec([0.0, 0.3, 0.0]).matrix
    off = SO3.from_rotvec([0.0, 0.3 + 0.06, 0.0]).matrix
    prior = OrientationPrior(R_cam_obj=R, sigma_rad=0.02)
    assert prior.chi2(R) == pytest.approx(0.0, abs=1e-12)
    assert prior.chi2(off) == pytest.approx(9.0)
    assert prior.chi2(off, np.eye(3) * 0.02**2 * 2.0) == pytest.approx(3.0)
    # gravity: tag +y should be the camera's up (-y for a level camera); a 0.1 rad roll
    gravity = OrientationPrior(up_cam=np.array([0.0, -1.0, 0.0]), up_sigma_rad=0.05)
    face_on = np.diag([1.0, -1.0, -1.0])
    rolled = SO3.from_rotvec([0.0, 0.0, 0.1]).matrix @ face_on
    assert gravity.chi2(face_on) == pytest.approx(0.0, abs=1e-12)
    assert gravity.chi2(rolled) == pytest.approx((np.sin(0.1) / 0.05) ** 2)  # |u x Ra| = sin


# ----- observe_tags on streams -----------------------------------------------------------------


def test_observe_tags_never_raises_and_counts_every_rejection() -> None:
    rng = np.random.default_rng(31)
    T, T_map_cam = wall_view(1.5, np.deg2rad(40.0), rng)
    good = corners_of(T) + rng.normal(0.0, 0.3, (4, 2))
    outside = np.array([[-9e4, -9e4], [9e4, -9e4], [9e4, 9e4], [-9e4, 9e4]])
    tag_poses = {1: T_map_cam @ T, 2: T_map_cam @ T}
    stream = [
        TagDetection(1, "tag36h11", good, 0, 60.0),  # accepted
        TagDetection(9, "tag36h11", good, 0, 60.0),  # not in the map
        TagDetection(1, "tag36h11", good, 3, 60.0),  # hamming
        TagDetection(1, "tag36h11", good, 0, 5.0),  # decision margin
        TagDetection(2, "tag36h11", outside, 0, 60.0),  # corners outside the camera model
    ]
    weird = CAMERA.__class__(
        width=1280, height=720, fx=640.0, fy=640.0, cx=639.5, cy=359.5, k1=-0.3
    )  # folds: the far-out corners cannot be undistorted
    result = observe_tags(stream, weird, {1: SIZE, 2: SIZE, 9: SIZE}, tag_poses=tag_poses)
    assert [e.tag_id for e in result.accepted] == [1]
    counts = result.counts()
    assert counts[RejectReason.UNKNOWN_TAG] == 1
    assert counts[RejectReason.HAMMING] == 1
    assert counts[RejectReason.DECISION_MARGIN] == 1
    assert counts[RejectReason.DEGENERATE] == 1
    assert result.joint is None  # one usable known tag
    assert observe_tags([], CAMERA, SIZE).accepted == ()
    # a size map without the id is also an unknown tag
    assert observe_tags(stream[:1], CAMERA, {7: SIZE}).counts()[RejectReason.UNKNOWN_TAG] == 1


def test_observe_tags_survives_random_quads_without_warnings() -> None:
    # Any convex clockwise quad, anywhere, of any size (1e-3 to 3000 px): a result, no
    # exception and no numpy warning (warnings are errors here).
    rng = np.random.default_rng(35)
    tag_poses = {0: SE3.identity(), 1: SE3.from_rotvec([0.0, 0.0, 1.0], [1.0, 2.0, 3.0])}
    prior = PosePrior(SE3.identity(), up_cam=np.array([0.0, -1.0, 0.0]))
    square = 0.5 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    seen = 0
    for _ in range(300):
        side, angle = 10 ** rng.uniform(-3.0, 3.5), rng.uniform(0.0, 2.0 * np.pi)
        turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        quad = side * square @ turn.T + rng.uniform(-2000, 3000, 2)
        quad += rng.normal(0.0, 0.3 * side, (4, 2))
        try:
            det = TagDetection(int(rng.integers(0, 3)), "tag36h11", quad, 0, 50.0)
        except ValueError:
            continue  # not convex and clockwise: TagDetection refuses it
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            result = observe_tags([det, det], CAMERA, SIZE, tag_poses=tag_poses, prior=prior)
        assert len(result.accepted) + len(result.rejections) >= 2
        seen += 1
    assert seen > 200


def test_observe_tags_gives_a_joint_map_pose_with_base() -> None:
    tags = wall_tags([-0.5, 0.0, 0.5], [1.0, 1.3, 1.1])
    T_map_cam = level_camera(0.2, 2.5, 1.1, 0.0)  # 2.5 m, face-on: single tags are ambiguous
    T_base_cam = SE3.from_rotvec([-np.pi / 2, 0.0, -np.pi / 2], [0.1, 0.0, 1.1])
    rng = np.random.default_rng(32)
    dets = [
        TagDetection(
            i,
            "tag36h11",
            corners_of(T_map_cam.inverse() @ T) + rng.normal(0.0, 0.3, (4, 2)),
            0,
            60.0,
        )
        for i, T in tags.items()
    ]
    result = observe_tags(dets, CAMERA, SIZE, tag_poses=tags, T_base_cam=T_base_cam)
    assert result.joint is not None
    assert result.joint.tag_ids == (0, 1, 2)
    assert rotation_error_deg(T_map_cam, result.joint.T_map_cam) < 3.0
    assert result.joint.T_map_base is not None and result.joint.cov_map_base is not None
    assert result.joint.T_map_base.allclose(result.joint.T_map_cam @ T_base_cam.inverse())


def test_gravity_resolves_flips_of_tags_above_or_below_the_camera() -> None:
    # At 2 m and 30 deg the pixels alone separate the branches in few views; a tag up to 15 deg
    # above or below the camera's horizon tilts the mirrored normal out of the vertical, which
    # the camera's known up direction sees.
    none = observe_cell(2.0, 30.0, 0.5, 60, "none", seed=33)
    gravity = observe_cell(2.0, 30.0, 0.5, 60, "gravity", seed=33)
    acc_none, wrong_none, _ = _outcomes(none)
    acc_gravity, wrong_gravity, _ = _outcomes(gravity)
    assert wrong_none == 0 and wrong_gravity == 0
    assert acc_gravity >= acc_none + 0.2


def test_no_flips_and_most_views_within_3_m_accepted() -> None:
    # Subsample of the slow sweep below (0.3 px, rotation prior of 3 deg).
    for distance in (1.0, 2.0, 3.0):
        for angle in (15.0, 30.0, 60.0):
            acceptance, wrong, _ = _outcomes(
                observe_cell(distance, angle, 0.3, 40, "rotation", seed=int(10 * distance + angle))
            )
            assert wrong == 0
            assert acceptance >= 0.9, (distance, angle, acceptance)
    for distance in (0.5, 4.0, 6.0):
        for angle in (0.0, 10.0, 45.0, 75.0):
            for prior in ("none", "rotation"):
                _, wrong, _ = _outcomes(observe_cell(distance, angle, 0.5, 25, prior, seed=34))
                assert wrong == 0, (distance, angle, prior)


@pytest.mark.slow
@pytest.mark.parametrize("sigma", [0.3, 0.5])
@pytest.mark.parametrize("prior", ["none", "gravity", "rotation"])
def test_flip_sweep_full(sigma: float, prior: str) -> None:
    for distance in (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0):
        for angle in (0.0, 10.0, 15.0, 30.0, 45.0, 60.0, 75.0):
            results = observe_cell(
                distance, angle, sigma, 200, prior, seed=int(1000 * sigma + 10 * distance + angle)
            )
            acceptance, wrong, _ = _outcomes(results)
            assert wrong == 0, (distance, angle)
            if sigma == 0.3 and prior == "rotation" and distance <= 3.0 and 15 <= angle <= 60:
                assert acceptance >= 0.9, (distance, angle, acceptance)


def test_pose_prior_upright_points_up_in_the_camera() -> None:
    T_base_cam = SE3(
        rotation=SO3.from_matrix([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
        translation=np.array([0.2, 0.0, 0.5]),
    )
    prior = PosePrior.upright(T_base_cam)
    assert prior.up_cam is not None
    np.testing.assert_allclose(prior.up_cam, [0.0, -1.0, 0.0], atol=1e-12)
