"""Batched fast paths of the per-frame pipeline against the computations they replace.

Oracles: one formula written out here (:meth:`OrientationPrior.chi2` as its docstring states
it, one rotation at a time; the prior evidences agree with it and with the per-tag calls to
1e-9), the :class:`SE3` methods the geometry fast paths stand in for (bit for bit), and for the
frame's shared PnP pass (:func:`estimate_frame`, :func:`observe_tags`) the public calls it
replaces, :func:`estimate_tag_poses` then :func:`estimate_joint_pose` (bit for bit; these are
the same solver, not an independent one), with ``T_map_base`` checked against
``T_map_cam T_base_cam^-1`` and the adjoint of ``T_base_cam`` written out here.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from test_pnp import CAMERA, corners_of, level_camera, wall_tags, wall_view

from tagloc.geometry import SE3, SO3
from tagloc.geometry.small_batch import row_norms, se3_minus, se3_plus
from tagloc.tags import _frame, observation
from tagloc.tags._frame import estimate_frame
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection
from tagloc.tags.gates import (
    OrientationPrior,
    RejectReason,
    tag_prior_evidence,
    tag_prior_evidences,
)
from tagloc.tags.observation import observe_tags
from tagloc.tags.pnp import (
    JointPoseEstimate,
    TagPoseEstimate,
    estimate_joint_pose,
    estimate_tag_poses,
)

FloatArray = npt.NDArray[np.float64]


def _hat(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _reference_chi2(prior: OrientationPrior, R: FloatArray, C: FloatArray) -> float:
    """:meth:`OrientationPrior.chi2` as its docstring states it, one rotation at a time."""
    total = 0.0
    if prior.R_cam_obj is not None:
        e = np.ravel(cv2.Rodrigues(np.asarray(prior.R_cam_obj).T @ R)[0])
        total += float(e @ np.linalg.solve(prior.sigma_rad**2 * np.eye(3) + C, e))
    if prior.up_cam is not None:
        a = np.asarray(prior.up_obj, dtype=np.float64)
        u = np.asarray(prior.up_cam, dtype=np.float64)
        a, u = a / np.linalg.norm(a), u / np.linalg.norm(u)
        e1 = _hat(u) @ np.eye(3)[int(np.argmin(np.abs(u)))]
        e1 /= np.linalg.norm(e1)
        B = np.stack([e1, _hat(u) @ e1])
        BJ = B @ _hat(u) @ R @ _hat(a)
        g = B @ (_hat(u) @ (R @ a))
        S = prior.up_sigma_rad**2 * np.eye(2) + BJ @ C @ BJ.T
        total += float(g @ np.linalg.solve(S, g))
    return total


def _frame_estimates(seed: int, n: int) -> tuple[list[TagPoseEstimate], list[SE3]]:
    """``n`` tags of one frame (noisy corners) and each one's true ``T_map_tag``."""
    rng = np.random.default_rng(seed)
    views = [
        wall_view(rng.uniform(0.7, 5.0), np.deg2rad(rng.uniform(5, 70)), rng) for _ in range(n)
    ]
    corners = np.array([corners_of(T) + rng.normal(0, 0.4, (4, 2)) for T, _ in views])
    estimates = estimate_tag_poses(list(range(n)), corners, [0.16] * n, CAMERA, NoiseModel())
    assert all(e is not None for e in estimates)
    return [e for e in estimates if e is not None], [T_map_cam @ T for T, T_map_cam in views]


def _priors(kind: str, T_map_tags: list[SE3], rng: np.random.Generator) -> list[OrientationPrior]:
    R_map_cam = SO3.from_rotvec(0.05 * rng.normal(size=3)).matrix @ np.array(
        [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
    )
    up_cam = None if kind == "rotation" else R_map_cam.T @ np.array([0.0, 0.0, 1.0])
    out = []
    for T in T_map_tags:
        R_cam_tag = None if kind == "gravity" else R_map_cam.T @ T.rotation.matrix
        up_tag = T.rotation.matrix.T @ np.array([0.0, 0.0, 1.0])
        out.append(OrientationPrior(R_cam_tag, 0.05, up_cam, up_tag, 0.04))
    return out


@pytest.mark.parametrize("kind", ["rotation", "gravity", "both"])
def test_chi2_equals_the_per_rotation_formula(kind: str) -> None:
    rng = np.random.default_rng(3)
    estimates, T_map_tags = _frame_estimates(11, 5)
    for prior, est in zip(_priors(kind, T_map_tags, rng), estimates, strict=True):
        for T, C in (
            (est.T_cam_tag, est.cov_rot_laplace),
            (est.T_cam_tag_alt, est.cov_cam_tag_alt[3:, 3:]),
            (SE3.random(rng), np.zeros((3, 3))),
        ):
            R = T.rotation.matrix
            expected = _reference_chi2(prior, R, C)
            assert prior.chi2(R, C) == pytest.approx(expected, rel=1e-12, abs=1e-12)
            if not C.any():
                assert prior.chi2(R) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("kind", ["rotation", "gravity", "both"])
@pytest.mark.parametrize("n", [1, 2, 6])
def test_tag_prior_evidences_equal_per_tag(kind: str, n: int) -> None:
    rng = np.random.default_rng(n)
    estimates, T_map_tags = _frame_estimates(20 + n, n)
    priors = _priors(kind, T_map_tags, rng)
    batched = tag_prior_evidences(priors, estimates)
    for prior, est, got in zip(priors, estimates, batched, strict=True):
        one = tag_prior_evidence(prior, est)
        for name in ("chi2", "chi2_alt", "innovation_chi2", "innovation_chi2_alt"):
            assert getattr(got, name) == pytest.approx(getattr(one, name), rel=1e-9, abs=1e-12)
            expected = _reference_chi2(
                prior,
                (est.T_cam_tag_alt if name.endswith("alt") else est.T_cam_tag).rotation.matrix,
                {
                    "chi2": est.cov_rot_laplace,
                    "chi2_alt": est.cov_rot_laplace_alt,
                    "innovation_chi2": est.cov_cam_tag[3:, 3:],
                    "innovation_chi2_alt": est.cov_cam_tag_alt[3:, 3:],
                }[name],
            )
            assert getattr(got, name) == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_tag_prior_evidences_with_mixed_priors_fall_back_per_tag() -> None:
    rng = np.random.default_rng(5)
    estimates, T_map_tags = _frame_estimates(31, 3)
    priors = _priors("both", T_map_tags, rng)
    priors[1] = OrientationPrior(None, 0.1, priors[0].up_cam, priors[1].up_obj, 0.02)
    batched = tag_prior_evidences(priors, estimates)
    for prior, est, got in zip(priors, estimates, batched, strict=True):
        assert got == tag_prior_evidence(prior, est)
        for name, R, C in (
            ("chi2", est.T_cam_tag, est.cov_rot_laplace),
            ("chi2_alt", est.T_cam_tag_alt, est.cov_rot_laplace_alt),
            ("innovation_chi2", est.T_cam_tag, est.cov_cam_tag[3:, 3:]),
            ("innovation_chi2_alt", est.T_cam_tag_alt, est.cov_cam_tag_alt[3:, 3:]),
        ):
            expected = _reference_chi2(prior, R.rotation.matrix, C)
            assert getattr(got, name) == pytest.approx(expected, rel=1e-9, abs=1e-12)
    with pytest.raises(ValueError, match="2 priors for 3 estimates"):
        tag_prior_evidences(priors[:2], estimates)


# ----- geometry fast paths the solver uses -------------------------------------------------------


@pytest.mark.parametrize("scale", [0.0, 1e-9, 1e-3, 0.3, 1.2, 3.0])
@pytest.mark.parametrize("n", [1, 4, 40])
def test_small_batch_minus_and_plus_are_bit_identical_to_se3(scale: float, n: int) -> None:
    rng = np.random.default_rng(int(1000 * scale) + n)
    for _ in range(20):
        T = SE3.random(rng, n, translation_scale=2.0)
        tau = scale * rng.normal(size=(n, 6))
        tau[0, 3:] = 0.0  # a pure translation among them
        other = SE3.random(rng, n) if scale == 0.0 else T.plus(tau)
        np.testing.assert_array_equal(se3_minus(other, T), other.minus(T))
        fast, slow = se3_plus(T, tau), T.plus(tau)
        np.testing.assert_array_equal(fast.rotation.matrix, slow.rotation.matrix)
        np.testing.assert_array_equal(fast.translation, slow.translation)


@pytest.mark.parametrize("shape", [(3,), (7, 3), (4, 2, 3), (5, 2)])
def test_row_norms_are_numpys_norms_bit_for_bit(shape: tuple[int, ...]) -> None:
    v = np.random.default_rng(len(shape)).normal(size=shape) * 10.0 ** np.arange(shape[-1])
    np.testing.assert_array_equal(row_norms(v), np.linalg.norm(v, axis=-1))


def test_from_trusted_equals_the_checked_constructor_and_owns_its_arrays() -> None:
    rng = np.random.default_rng(8)
    T = SE3.random(rng, 5)
    R, t = T.rotation.matrix.copy(), T.translation.copy()
    trusted = SE3.from_trusted(R, t)
    assert trusted.allclose(SE3(rotation=SO3.from_matrix(R), translation=t), atol=0.0)
    R[0] = 0.0  # the caller's arrays stay the caller's
    assert trusted.allclose(T, atol=0.0)
    assert not trusted.rotation.matrix.flags.writeable
    single = SE3.from_trusted(T.rotation.matrix[2], T.translation[2])
    assert not single.is_batch and single.allclose(T[2], atol=0.0)


# ----- one frame: tags and joint PnP finished together ------------------------------------------


def _frame_detections(seed: int, n: int) -> tuple[list[tuple[TagDetection, float]], dict[int, SE3]]:
    """``n`` upright tags on a wall 1-4 m in front of a level camera, noisy corners."""
    rng = np.random.default_rng(seed)
    T_map_cam = level_camera(0.0, 0.0, 1.2, 0.0)
    xs = list(rng.uniform(-1.5, 1.5, n))
    tag_poses = wall_tags(xs, list(rng.uniform(0.8, 1.6, n)))
    tags = []
    for tag_id, T_map_tag in tag_poses.items():
        corners = corners_of(T_map_cam.inverse() @ T_map_tag) + rng.normal(0, 0.3, (4, 2))
        tags.append((TagDetection(tag_id, "tag36h11", corners, 0, 60.0), 0.16))
    return tags, tag_poses


def _assert_same_estimate(a: TagPoseEstimate | None, b: TagPoseEstimate | None) -> None:
    assert (a is None) == (b is None)
    if a is None or b is None:
        return
    assert (a.tag_id, a.size, a.reproj_err_px, a.reproj_err_alt_px) == (
        b.tag_id,
        b.size,
        b.reproj_err_px,
        b.reproj_err_alt_px,
    )
    for name in ("T_cam_tag", "T_cam_tag_alt"):
        assert getattr(a, name).allclose(getattr(b, name), atol=0.0)
    for name in ("cov_cam_tag", "cov_cam_tag_alt", "cov_rot_laplace", "cov_rot_laplace_alt"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def _assert_same_joint(a: JointPoseEstimate | None, b: JointPoseEstimate | None) -> None:
    assert (a is None) == (b is None)
    if a is None or b is None:
        return
    assert (a.tag_ids, a.reproj_err_px, a.reproj_err_alt_px) == (
        b.tag_ids,
        b.reproj_err_px,
        b.reproj_err_alt_px,
    )
    assert a.T_map_cam.allclose(b.T_map_cam, atol=0.0)
    assert a.T_map_cam_alt.allclose(b.T_map_cam_alt, atol=0.0)
    for name in ("cov_map_cam", "cov_map_cam_alt", "cov_rot_laplace", "cov_rot_laplace_alt"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("seed", range(6))
def test_estimate_frame_equals_tag_then_joint_pnp_bit_for_bit(seed: int) -> None:
    n = 2 + seed % 4
    tags, tag_poses = _frame_detections(seed, n)
    noise = NoiseModel(sigma_px=0.3)
    estimates, guess = estimate_frame(tags, CAMERA, noise, 2.0, tag_poses, None)
    ids = [det.tag_id for det, _ in tags]
    corners = np.array([det.corners_px for det, _ in tags])
    reference = estimate_tag_poses(ids, corners, [0.16] * n, CAMERA, noise)
    for got, want in zip(estimates, reference, strict=True):
        _assert_same_estimate(got, want)
    assert guess is not None and guess.rows == tuple(range(n))
    joint = estimate_joint_pose(
        [e for e in reference if e is not None], corners, list(tag_poses.values()), CAMERA, noise
    )
    _assert_same_joint(guess.estimate, joint)


def test_observe_tags_recomputes_the_joint_when_a_tag_it_guessed_drops_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the guess takes every tag whose refined error fits; a tag whose covariance then comes out
    # non-finite has no estimate, so the joint estimate must be the one over the others
    tags, tag_poses = _frame_detections(3, 4)
    noise = NoiseModel(sigma_px=0.3)
    real = _frame.tag_estimates

    def drop_second(*args: object, **kwargs: object) -> list[TagPoseEstimate | None]:
        out = real(*args, **kwargs)  # type: ignore[arg-type]
        out[1] = None
        return out

    monkeypatch.setattr(_frame, "tag_estimates", drop_second)
    result = observe_tags([det for det, _ in tags], CAMERA, 0.16, tag_poses=tag_poses, noise=noise)
    assert result.counts()[RejectReason.DEGENERATE] == 1
    kept = [0, 2, 3]
    ids = [tags[i][0].tag_id for i in kept]
    corners = np.array([tags[i][0].corners_px for i in kept])
    estimates = [e for e in estimate_tag_poses(ids, corners, [0.16] * 3, CAMERA, noise) if e]
    joint = estimate_joint_pose(estimates, corners, [tag_poses[i] for i in ids], CAMERA, noise)
    assert result.joint is not None and result.joint.tag_ids == tuple(ids)
    _assert_same_joint(result.joint, joint)  # no prior: the policy keeps the best branch


def _spy(monkeypatch: pytest.MonkeyPatch, module: object, name: str) -> list[tuple[object, ...]]:
    """Record the positional arguments of every call of ``module.name`` (still called)."""
    real = getattr(module, name)
    calls: list[tuple[object, ...]] = []

    def spy(*args: object, **kwargs: object) -> object:
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, spy)
    return calls


def _adjoint(T: SE3) -> FloatArray:
    """``Ad_T`` for tangents ``[x, y, z, rx, ry, rz]``: ``[[R, [t]x R], [0, R]]``."""
    R, t = T.rotation.matrix, np.asarray(T.translation)
    out = np.zeros((6, 6))
    out[:3, :3], out[:3, 3:], out[3:, 3:] = R, _hat(t) @ R, R
    return out


@pytest.mark.parametrize("seed", [0, 4])
def test_estimate_frame_with_extrinsics_gives_the_base_pose_of_the_camera_pose(seed: int) -> None:
    n = 3 + seed % 2
    tags, tag_poses = _frame_detections(seed, n)
    noise = NoiseModel(sigma_px=0.3)
    T_base_cam = SE3(
        rotation=SO3.from_matrix([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        @ SO3.from_rotvec(np.array([0.02, -0.01, 0.03])),
        translation=np.array([0.25, -0.04, 0.9]),
    )
    _, guess = estimate_frame(tags, CAMERA, noise, 2.0, tag_poses, T_base_cam)
    assert guess is not None and guess.estimate is not None
    got = guess.estimate
    assert got.T_map_base is not None and got.cov_map_base is not None
    # independent: T_map_base = T_map_cam T_cam_base; its right tangent is Ad_{T_base_cam} of
    # the camera's (T_map_cam Exp(d) T_cam_base = T_map_base Exp(Ad_{T_base_cam} d))
    want = got.T_map_cam @ T_base_cam.inverse()
    assert got.T_map_base.allclose(want, atol=1e-12)
    Ad = _adjoint(T_base_cam)
    np.testing.assert_allclose(got.cov_map_base, Ad @ got.cov_map_cam @ Ad.T, rtol=1e-9, atol=1e-15)
    # and the joint PnP alone with the extrinsics, bit for bit
    ids = [det.tag_id for det, _ in tags]
    corners = np.array([det.corners_px for det, _ in tags])
    reference = [e for e in estimate_tag_poses(ids, corners, [0.16] * n, CAMERA, noise) if e]
    joint = estimate_joint_pose(
        reference, corners, list(tag_poses.values()), CAMERA, noise, T_base_cam
    )
    assert joint is not None and joint.T_map_base is not None
    _assert_same_joint(got, joint)
    assert got.T_map_base.allclose(joint.T_map_base, atol=0.0)
    np.testing.assert_array_equal(got.cov_map_base, joint.cov_map_base)


def test_observe_tags_takes_the_early_joint_estimate_on_a_normal_frame(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tags, tag_poses = _frame_detections(2, 4)
    noise = NoiseModel(sigma_px=0.3)
    calls = _spy(monkeypatch, observation, "estimate_joint_pose")
    result = observe_tags([det for det, _ in tags], CAMERA, 0.16, tag_poses=tag_poses, noise=noise)
    # face-on tags: single-tag poses ambiguous, but all four fit and the joint takes them
    assert set(result.counts()) <= {RejectReason.AMBIGUOUS}
    assert result.joint is not None and result.joint.tag_ids == tuple(tag_poses)
    assert calls == []  # step 2's guess was these tags: no second joint PnP


def test_estimate_frame_goes_per_tag_at_once_when_the_batched_tag_stage_fails(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tags, tag_poses = _frame_detections(1, 3)
    noise = NoiseModel(sigma_px=0.3)

    def fail(*args: object, **kwargs: object) -> None:
        raise np.linalg.LinAlgError("batched tag stage")

    monkeypatch.setattr(_frame, "refine_tag_problems", fail)
    calls = _spy(monkeypatch, _frame, "estimate_tag_poses")
    estimates, guess = estimate_frame(tags, CAMERA, noise, 2.0, tag_poses, None)
    assert guess is None
    assert [c[0] for c in calls] == [[det.tag_id] for det, _ in tags]  # no batch retried
    for (det, size), got in zip(tags, estimates, strict=True):
        (want,) = estimate_tag_poses([det.tag_id], det.corners_px[None], [size], CAMERA, noise)
        _assert_same_estimate(got, want)


def test_estimate_frame_per_tag_fallback_costs_a_bad_tag_only_itself(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tags, tag_poses = _frame_detections(1, 3)
    noise = NoiseModel(sigma_px=0.3)
    real = _frame.estimate_tag_poses
    bad = tags[1][0].tag_id

    def fail_on_bad(ids: list[int], *args: object, **kwargs: object) -> object:
        if bad in ids:
            raise ValueError("bad tag")
        return real(ids, *args, **kwargs)  # type: ignore[arg-type]

    def batch_fails(*args: object, **kwargs: object) -> None:
        raise ValueError("batched tag stage")

    monkeypatch.setattr(_frame, "finish_branches", batch_fails)  # after the batched refinement
    monkeypatch.setattr(_frame, "estimate_tag_poses", fail_on_bad)
    estimates, guess = estimate_frame(tags, CAMERA, noise, 2.0, tag_poses, None)
    assert guess is None and estimates[1] is None
    assert estimates[0] is not None and estimates[2] is not None


@pytest.mark.parametrize("stage", ["refine_joint_problem", "joint_estimate"])
def test_estimate_frame_keeps_the_tags_when_the_joint_stage_fails(
    monkeypatch: pytest.MonkeyPatch, stage: str
) -> None:
    tags, tag_poses = _frame_detections(5, 3)
    noise = NoiseModel(sigma_px=0.3)
    dets = [det for det, _ in tags]
    expected = observe_tags(dets, CAMERA, 0.16, tag_poses=tag_poses, noise=noise)

    def fail(*args: object, **kwargs: object) -> None:
        raise np.linalg.LinAlgError("joint stage")

    monkeypatch.setattr(_frame, stage, fail)
    refine_calls = _spy(monkeypatch, _frame, "refine_tag_problems")
    batch_calls = _spy(monkeypatch, _frame, "estimate_tag_poses")
    estimates, guess = estimate_frame(tags, CAMERA, noise, 2.0, tag_poses, None)
    assert guess is None
    assert len(refine_calls) == 1 and batch_calls == []  # the refined tags were kept
    ids = [det.tag_id for det in dets]
    corners = np.array([det.corners_px for det in dets])
    reference = estimate_tag_poses(ids, corners, [0.16] * 3, CAMERA, noise)
    for got, want in zip(estimates, reference, strict=True):
        _assert_same_estimate(got, want)
    # observe_tags then runs its own joint PnP (unpatched), to the same result
    joint_calls = _spy(monkeypatch, observation, "estimate_joint_pose")
    result = observe_tags(dets, CAMERA, 0.16, tag_poses=tag_poses, noise=noise)
    assert len(joint_calls) == 1
    assert expected.joint is not None
    _assert_same_joint(result.joint, expected.joint)
    for got_tag, want_tag in zip(result.accepted, expected.accepted, strict=True):
        _assert_same_estimate(got_tag, want_tag)
