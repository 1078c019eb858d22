"""Pieces of the localization layer: config file, value types, event log, Jacobians, gates."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from test_localize_sim import FIX_COV, S, make_filter

from tagloc.errors import ConfigError, TaglocError
from tagloc.frames import TransformBuffer
from tagloc.geometry import (
    SE2,
    SE3,
    se2_right_jacobian,
    se2_right_jacobian_inv,
    se3_right_jacobian,
    se3_right_jacobian_inv,
)
from tagloc.localize import (
    CorrectionCap,
    EventKind,
    EventLog,
    FilterEvent,
    FixQuality,
    LocalizeError,
    LocalizerConfig,
    MapOdomFilter,
    ProcessNoise,
    QualityLimits,
    TagFix,
    chi2_threshold,
    load_localizer_config,
    planar_projection_jacobian,
    save_localizer_config,
)
from tagloc.localize._series import jr as series_jr
from tagloc.localize._series import jr_inv as series_jr_inv
from tagloc.localize.candidate import Candidate

# ----- localizer.yaml ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "gates:\n  chi2_quantile: 1.5\n",
            "localizer.yaml: gates.chi2_quantile: input should be less than 1",
        ),
        (
            "gates:\n  chi2_quantil: 0.99\n",
            "localizer.yaml: gates.chi2_quantil: extra inputs are not permitted",
        ),
        (
            "process_noise:\n  sigma_per_sqrt_m: [0.1, 0.1, -0.1, 0.01, 0.01, 0.01]\n",
            "localizer.yaml: process_noise.sigma_per_sqrt_m[2]: input should be greater than or "
            "equal to 0",
        ),
        (
            "cap:\n  max_translation_m: .nan\n",
            "localizer.yaml: cap.max_translation_m: input should be a finite number",
        ),
        (
            "kidnap:\n  n_fixes: 1\n",
            "localizer.yaml: kidnap.n_fixes: input should be greater than or equal to 2",
        ),
        ("version: 2\n", "localizer.yaml: version: input should be 1"),
    ],
)
def test_config_errors_are_one_line_naming_the_field(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        LocalizerConfig.from_yaml_text(text, "localizer.yaml")
    assert str(info.value) == message and "\n" not in str(info.value)


def test_config_round_trips_and_loads_from_files(tmp_path) -> None:
    text = "filter:\n  planar: true\ncap:\n  max_rotation_deg: 2\n"
    config = LocalizerConfig.from_yaml_text(text)
    path = tmp_path / "localizer.yaml"
    save_localizer_config(config, path)
    assert load_localizer_config(path) == config
    assert LocalizerConfig.from_yaml_text(LocalizerConfig().to_yaml_text()) == LocalizerConfig()
    with pytest.raises(ConfigError, match=r"missing\.yaml: cannot read localizer config"):
        load_localizer_config(tmp_path / "missing.yaml")


def test_from_config_unpacks_units() -> None:
    config = LocalizerConfig.model_validate(
        {"filter": {"planar": True}, "gates": {"chi2_quantile": 0.99}}
    )
    flt = MapOdomFilter.from_config(config, TransformBuffer())
    assert flt.dof == 3 and flt.threshold == pytest.approx(11.3449, abs=1e-4)
    assert flt.policy.cap.max_rotation_rad == pytest.approx(math.radians(5.0))
    noise = flt.estimator.path.noise
    assert noise.step_ns == S // 10
    np.testing.assert_allclose(noise.var_per_m, np.square([0.05, 0.05, 0.02]))


def test_chi2_thresholds() -> None:
    assert chi2_threshold(0.999, 6) == pytest.approx(22.4577, abs=1e-4)
    assert chi2_threshold(0.999, 3) == pytest.approx(16.2662, abs=1e-4)


# ----- value types --------------------------------------------------------------------------
def _fix(**kw: object) -> TagFix:
    args: dict[str, object] = dict(
        stamp_ns=S, T_map_base=SE3.identity(), cov=FIX_COV, source="tag:1", quality=FixQuality(0.3)
    )
    args.update(kw)
    return TagFix(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"stamp_ns": 1.5}, "stamp_ns must be an integer"),
        ({"stamp_ns": True}, "stamp_ns must be an integer"),
        ({"source": ""}, "source must be a non-empty string"),
        ({"cov": np.eye(3)}, r"cov must be \(6, 6\)"),
        ({"cov": -np.eye(6)}, "not positive definite"),
        ({"cov": np.triu(np.ones((6, 6)))}, "not symmetric"),
        ({"cov": np.full((6, 6), np.nan)}, "NaN"),
        ({"T_map_base": SE3.identity(2)}, "must be one SE3"),
    ],
)
def test_tag_fix_validates(kw: dict[str, object], match: str) -> None:
    with pytest.raises(LocalizeError, match=match) as info:
        _fix(**kw)
    assert isinstance(info.value, TaglocError)


def test_tag_fix_is_frozen_with_a_read_only_covariance() -> None:
    fix = _fix(stamp_ns=np.int64(5))
    assert type(fix.stamp_ns) is int
    with pytest.raises(AttributeError):
        fix.source = "tag:2"  # type: ignore[misc]
    with pytest.raises(ValueError):
        fix.cov[0, 0] = 1.0


def test_planar_projection_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(0)
    for _ in range(5):
        T = SE3.random(rng, translation_scale=3.0)
        J = planar_projection_jacobian(T)
        eps, numeric = 1e-6, np.zeros((3, 6))
        for i in range(6):
            d = np.zeros(6)
            d[i] = eps
            numeric[:, i] = (
                SE2.from_se3(T.plus(d)).minus(SE2.from_se3(T))
                - SE2.from_se3(T.plus(-d)).minus(SE2.from_se3(T))
            ) / (2 * eps)
        np.testing.assert_allclose(J, numeric, atol=1e-8)


# ----- Jacobians of the filter --------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-3, 0.04, 0.5])
def test_jacobian_series_match_the_closed_forms(scale: float) -> None:
    rng = np.random.default_rng(1)
    for tau, jr, jr_inv in (
        (scale * rng.standard_normal(6), se3_right_jacobian, se3_right_jacobian_inv),
        (scale * rng.standard_normal(3), se2_right_jacobian, se2_right_jacobian_inv),
    ):
        np.testing.assert_allclose(series_jr(tau), jr(tau), atol=1e-7)
        np.testing.assert_allclose(series_jr_inv(tau), jr_inv(tau), atol=1e-7)


@pytest.mark.parametrize("planar", [False, True])
def test_measurement_jacobian_matches_finite_differences(planar: bool) -> None:
    rng = np.random.default_rng(2)
    buffer = TransformBuffer()
    odom = SE3.random(rng, translation_scale=4.0)
    buffer.set_static("odom", "base_link", odom)
    flt = make_filter(buffer, filter={"planar": planar})
    X = SE3.random(rng, translation_scale=2.0)
    flt.initialize(0, X, np.eye(6) * 0.1)
    z = X @ odom @ SE3.exp(0.3 * rng.standard_normal(6))
    cand = Candidate.of_fix(_fix(T_map_base=z, stamp_ns=0), odom, planar)
    innov = flt.estimator.innovation(cand)
    X0, eps = flt.estimator.pose, 1e-6
    numeric = np.zeros((flt.dof, flt.dof))
    for i in range(flt.dof):
        d = np.zeros(flt.dof)
        d[i] = eps
        nus = [cand.z.minus(X0.plus(s * d) @ cand.A) for s in (1, -1)]
        numeric[:, i] = -(nus[0] - nus[1]) / (2 * eps)
    np.testing.assert_allclose(innov.H, numeric, atol=1e-6)
    assert isinstance(X0, SE2 if planar else SE3)


# ----- gates and the event log --------------------------------------------------------------
def test_quality_limits() -> None:
    limits = QualityLimits(2.0, 0.8, 5.0)
    assert limits.check(FixQuality(1.0, ambiguity_ratio=0.5, range_m=3.0)) is None
    assert limits.check(FixQuality(2.5))[0] is EventKind.GATED_REPROJ
    assert limits.check(FixQuality(math.nan))[0] is EventKind.GATED_REPROJ
    assert limits.check(FixQuality(1.0, ambiguity_ratio=0.9))[0] is EventKind.GATED_QUALITY
    assert limits.check(FixQuality(1.0, range_m=6.0))[0] is EventKind.GATED_QUALITY


def test_a_fix_with_high_reprojection_error_never_reaches_the_state() -> None:
    buffer = TransformBuffer()
    buffer.set_static("odom", "base_link", SE3.identity())
    flt = make_filter(buffer)
    for k in range(5):
        event = flt.update(_fix(stamp_ns=k * S, quality=FixQuality(3.0)))
        assert event.kind is EventKind.GATED_REPROJ and event.threshold == 2.0
    assert not flt.initialized and flt.corrections == ()


def test_a_fix_without_odometry_is_reported() -> None:
    buffer = TransformBuffer()
    buffer.set_transforms("odom", "base_link", np.array([0, S]), SE3.identity(2))
    event = make_filter(buffer).update(_fix(stamp_ns=3 * S))
    assert event.kind is EventKind.NO_ODOMETRY and "base_link" in event.detail


@pytest.mark.parametrize("kind", [SE3, SE2])
def test_cap_clips_translation_and_rotation_separately(kind: type) -> None:
    cap = CorrectionCap(0.25, math.radians(5), True)
    jump = (
        SE3.from_rotvec([0, 0, math.radians(20)], [1.0, 0.5, 0.0])
        if kind is SE3
        else SE2(1.0, 0.5, math.radians(20))
    )
    step, clipped = cap.clip(jump)
    assert clipped
    assert np.linalg.norm(step.translation) == pytest.approx(0.25)
    assert np.linalg.norm(step.log()[2 if kind is SE2 else 3 :]) == pytest.approx(math.radians(5))
    small = kind.identity()
    assert cap.clip(small) == (small, False)
    # exceeds() is clip()'s verdict without building the clipped pose
    assert cap.exceeds(jump) and not cap.exceeds(small)
    just_over = SE3.from_rotvec([0, 0, 0], [0.26, 0, 0]) if kind is SE3 else SE2(0.26, 0, 0)
    assert cap.exceeds(just_over) == cap.clip(just_over)[1] is True


def test_event_log_counts_by_kind_and_source() -> None:
    log = EventLog(max_events=2)
    for kind, source in [
        (EventKind.ACCEPTED, "tag:1"),
        (EventKind.GATED_CHI2, "tag:1"),
        (EventKind.ACCEPTED, "tag:2"),
    ]:
        log.append(FilterEvent(0, kind, source, 1.0, 2.0))
    assert len(log) == 2 and log.last is not None and log.last.source == "tag:2"
    assert log.counts_by_kind() == {EventKind.ACCEPTED: 2, EventKind.GATED_CHI2: 1}
    assert log.count(EventKind.ACCEPTED, "tag:1") == 1
    assert log.counts_by_source()["tag:1"][EventKind.GATED_CHI2] == 1
    assert str(EventKind.REINITIALIZED_KIDNAP) == "reinitialized_kidnap"


@pytest.mark.parametrize("planar", [False, True])
def test_process_noise_one_increment_equals_the_path_integral(planar: bool) -> None:
    rng = np.random.default_rng(3)
    A0, A1 = SE3.random(rng, translation_scale=3.0), SE3.random(rng, translation_scale=3.0)
    axes = [0, 1, 5] if planar else list(range(6))
    noise = ProcessNoise(
        rng.uniform(0.1, 1, 6)[axes],
        rng.uniform(0.1, 1, 6)[axes],
        rng.uniform(0.1, 1, 6)[axes],
        S // 10,
    )
    R = np.stack([A0.rotation.matrix, A1.rotation.matrix])
    t = np.stack([A0.translation, A1.translation])
    path = noise.path(np.array([0, S // 20]), R, t, planar)
    Q_path, d_path = path.Q, path.distance_m
    one = noise.increment(S // 20, R[0], t[0], R[1], t[1], planar)
    Q_one, d_one = one.Q, one.distance_m
    np.testing.assert_allclose(one.M, path.M, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(Q_one, Q_path, rtol=1e-12, atol=1e-15)
    assert d_one == pytest.approx(d_path) == pytest.approx(np.linalg.norm(t[1] - t[0]))
    Ad = (SE2.from_se3(A1) if planar else A1).adjoint()
    angle = np.linalg.norm((A0.rotation.inverse() @ A1.rotation).log())
    var = d_one * noise.var_per_m + angle * noise.var_per_rad + 0.05 * noise.var_per_s
    np.testing.assert_allclose(Q_one, Ad @ np.diag(var) @ Ad.T, rtol=1e-10)
    # without the drift: the same walk and distance, no M
    for full, bare in (
        (path, noise.path(np.array([0, S // 20]), R, t, planar, drift=False)),
        (one, noise.increment(S // 20, R[0], t[0], R[1], t[1], planar, drift=False)),
    ):
        assert np.array_equal(bare.Q, full.Q) and bare.distance_m == full.distance_m
        assert bare.M.shape == (len(axes), 0)


class _CountingBuffer(TransformBuffer):
    """A buffer that records the odometry paths asked of it (``lookup_many``: one call per
    integrated path) and the single lookups."""

    def __init__(self) -> None:
        super().__init__()
        self.paths: list[tuple[int, int]] = []
        self.lookups: list[int] = []

    def lookup_many(self, target: str, source: str, stamps_ns: npt.ArrayLike) -> SE3:
        stamps = np.asarray(stamps_ns)
        self.paths.append((int(stamps[0]), int(stamps[-1])))
        return super().lookup_many(target, source, stamps_ns)

    def lookup(self, target: str, source: str, stamp_ns: int | np.integer) -> SE3:
        self.lookups.append(int(stamp_ns))
        return super().lookup(target, source, stamp_ns)


def _inner(lo: int, hi: int, step: int = S // 10) -> tuple[int, int]:
    """First and last inner sample of the path ``lo..hi`` integrated in ``step`` steps."""
    n = math.ceil((hi - lo) / step)
    return lo + round(1 * ((hi - lo) / n)), lo + round((n - 1) * ((hi - lo) / n))


def test_a_frames_prior_and_its_fix_share_one_path_and_the_state_revision_counts() -> None:
    buffer = _CountingBuffer()
    stamps = np.arange(0, 3 * S, S // 100)
    poses = SE3.from_rotvec(np.zeros((len(stamps), 3)), np.outer(stamps / S, [1.0, 0, 0]))
    buffer.set_transforms("odom", "base_link", stamps, poses)
    flt = make_filter(buffer, calibration={"enabled": True})
    flt.initialize(0, SE3.identity(), np.eye(6) * 1e-2)
    revision = flt.revision
    buffer.paths.clear()
    T = flt.T_map_base_at(S // 2)  # a frame's prior, then its fix: one integration
    assert flt.revision == revision  # a prior does not change the state
    event = flt.update(TagFix(S // 2, T, FIX_COV, "tag:1", FixQuality(reproj_err_px=0.4)))
    assert event.kind is EventKind.ACCEPTED and buffer.paths == [_inner(0, S // 2)]
    assert flt.revision == revision + 2  # the prediction, then the update
    flt.predict(S // 2 + S // 1000)  # less than a motion step: the state stays
    assert flt.revision == revision + 2
    flt.predict(S)
    assert flt.revision == revision + 3 and flt.stamp_ns == S
    flt.pose_at(2 * S)
    flt.pose_at(2 * S)
    # a changed buffer integrates again
    buffer.set_transform("odom", "base_link", 3 * S, SE3.from_rotvec([0, 0, 0], [3.0, 0, 0]))
    flt.pose_at(2 * S)
    assert buffer.paths[1:] == [_inner(S // 2, S), _inner(S, 2 * S), _inner(S, 2 * S)]


def test_odometry_lookups_are_reused_only_while_the_buffer_is_unchanged() -> None:
    buffer = _CountingBuffer()
    buffer.set_transforms("odom", "base_link", np.array([0, 2 * S]), SE3.identity(2))
    path = make_filter(buffer).estimator.path
    revision = buffer.revision
    first = path.lookup(S)
    assert path.lookup(S) is first and buffer.revision == revision
    assert buffer.lookups == [S]  # asked of the buffer once
    # a late sample between the two changes the interpolation at 1 s: looked up again
    buffer.set_transform("odom", "base_link", S, SE3.from_rotvec([0, 0, 0], [1.0, 0, 0]))
    assert buffer.revision == revision + 1
    np.testing.assert_allclose(path.lookup(S).translation, [1.0, 0.0, 0.0])
    assert buffer.lookups == [S, S]
