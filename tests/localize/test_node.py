"""The streaming node: outputs as they happen, odometry from /tf, one configuration."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from list_sink import ListSink

from tagloc.errors import ConfigError
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.localize import LocalizerConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import Estimate
from tagloc.messages import OdometryMsg, TransformMsg
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.supervise import LadderTransition, StatusReport

S = 1_000_000_000


@pytest.fixture(scope="module")
def source() -> ScenarioSource:
    return ScenarioSource(build_scenario("default", seed=1, duration_s=20.0))


def _node(source: ScenarioSource, sink: ListSink, **config: object) -> LocalizerNode:
    base = calibrated_config(source.scenario, scenario_config())
    cfg = LocalizerConfig.model_validate({**base.model_dump(), **config}) if config else base
    return LocalizerNode(source.scenario.tag_map, cfg, [sink], frame_truth=source.frame_truth)


def test_outputs_stream_as_the_messages_arrive(source: ScenarioSource) -> None:
    sink = ListSink()
    node = _node(source, sink)
    n_odom = 0
    for topic, msg in source:
        node.feed(topic, msg)
        if isinstance(msg, OdometryMsg):
            n_odom += 1
            # every odometry sample has its estimate before the next message is fed
            last = sink.of(Estimate)[-1]
            assert last.stamp_ns == msg.stamp_ns and len(sink.of(Estimate)) == n_odom
        if n_odom == 1000:  # 10 s in: the ladder moved and status flowed, nothing finished
            break
    status = sink.of(StatusReport)
    assert [s.stamp_ns for s in status] == [k * S for k in range(len(status))]  # 1 Hz
    assert len(status) == 10
    moves = sink.of(LadderTransition)
    assert moves and moves[0].to_level == 3 and "markers_alone available" in moves[0].reason
    published = [e for e in sink.of(Estimate) if e.publish]
    gaps = {b.stamp_ns - a.stamp_ns for a, b in itertools.pairwise(published)}
    assert gaps == {S // 10}  # output.publish_rate_hz: 10


def test_odometry_from_tf_localizes_exactly_as_odometry_messages(source: ScenarioSource) -> None:
    as_odom, as_tf = ListSink(), ListSink()
    node_a, node_b = _node(source, as_odom), _node(source, as_tf)
    for topic, msg in source:
        node_a.feed(topic, msg)
        if isinstance(msg, OdometryMsg):
            tf = TransformMsg(msg.stamp_ns, msg.frame_id, msg.child_frame_id, msg.T_parent_child)
            node_b.feed("/tf", tf)
        else:
            node_b.feed(topic, msg)
    node_a.finish()
    node_b.finish()
    a, b = as_odom.of(Estimate), as_tf.of(Estimate)
    assert len(a) == len(b) > 1900
    assert [x.stamp_ns for x in a] == [y.stamp_ns for y in b]
    np.testing.assert_array_equal(
        SE3.stack([x.T_map_odom for x in a]).as_matrix(),
        SE3.stack([y.T_map_odom for y in b]).as_matrix(),
    )
    assert sum(x.initialized for x in a) > 1000


def test_dimos_convention_names_and_publishes_the_inverse_edge() -> None:
    cfg = LocalizerConfig.from_yaml_text("frames: {convention: dimos}\n", "localizer.yaml")
    f = cfg.frames
    assert (f.map_frame, f.odom_frame, f.base_frame) == ("map", "world", "base_link")
    assert f.published_edge == ("world", "map")
    ros = LocalizerConfig().frames
    assert ros.published_edge == ("map", "odom")
    own = LocalizerConfig.from_yaml_text("frames: {odom_frame: odom_legs}\n", "x.yaml").frames
    assert own.published_edge == ("map", "odom_legs")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "supervisor: {status_rate_hz: 0}\n",
            "localizer.yaml: supervisor.status_rate_hz: input should be greater than 0",
        ),
        (
            "supervisor: {ladder: {dwell: 3}}\n",
            "localizer.yaml: supervisor.ladder.dwell: extra inputs are not permitted",
        ),
        (
            "supervisor: {ladder: {exit_nis: 9}}\n",
            "localizer.yaml: supervisor.ladder: exit_nis must be <= enter_nis (hysteresis)",
        ),
        (
            "tags: {mode: bundle}\n",
            "localizer.yaml: tags.mode: input should be 'single' or 'joint'",
        ),
        (
            "tags: {noise: {sigma_px: -1}}\n",
            "localizer.yaml: tags.noise.sigma_px: input should be greater than 0",
        ),
        (
            "cap: {max_speed_m_s: .nan}\n",
            "localizer.yaml: cap.max_speed_m_s: input should be a finite number",
        ),
        (
            "frames: {convention: tf2}\n",
            "localizer.yaml: frames.convention: input should be 'ros' or 'dimos'",
        ),
        (
            "output: {publish_rate_hz: -2}\n",
            "localizer.yaml: output.publish_rate_hz: input should be greater than or equal to 0",
        ),
    ],
)
def test_bad_configuration_is_one_line_naming_the_field(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        LocalizerConfig.from_yaml_text(text, "localizer.yaml")
    assert str(err.value) == message


def test_the_resolved_configuration_round_trips() -> None:
    cfg = LocalizerConfig.from_yaml_text("frames: {convention: dimos}\ngates: {gap_s: 7}\n", "a")
    again = LocalizerConfig.from_yaml_text(cfg.to_yaml_text(), "b")
    assert again == cfg and again.frames.publish == "odom_to_map" and again.gates.gap_s == 7


def test_images_of_the_wrong_size_are_counted_skips(source: ScenarioSource) -> None:
    from tagloc.messages import ImageMsg

    class NeverCalled:
        def detect(self, image: object) -> list[object]:
            raise AssertionError("a mis-sized image must not reach the detector")

    sink = ListSink()
    camera = source.camera
    node = LocalizerNode(
        source.scenario.tag_map, scenario_config(), [sink], camera=camera,
        detector=NeverCalled(),  # type: ignore[arg-type]
    )  # fmt: skip
    image = np.zeros((camera.height // 2, camera.width // 2), np.uint8)
    for k in range(3):
        node.feed("/camera/image", ImageMsg(k * S, "camera_optical", image, "mono8"))
    assert node.skipped == {"image_size_mismatch": 3}


@pytest.mark.parametrize("planar", [False, True])
def test_odometry_covariance_growth_adds_to_the_correction_covariance(planar: bool) -> None:
    """With ``odometry_covariance: growth``, standing still with no fix, the correction's
    covariance grows by exactly the odometry covariance's growth (the planar block in planar
    mode); ``ignore`` leaves only the configured walk."""
    from tagloc.tags import TagMap

    step = np.diag([1e-4, 2e-4, 3e-5, 1e-6, 2e-6, 4e-6])
    P = {}
    for mode in ("ignore", "growth"):
        cfg = LocalizerConfig.model_validate(
            {"process_noise": {"odometry_covariance": mode}, "filter": {"planar": planar}}
        )
        node = LocalizerNode(TagMap.from_yaml_text("version: 1\ntags: []\n", "t"), cfg)
        T = SE3.identity()
        node.feed("/odom", OdometryMsg(0, "odom", "base_link", T, np.eye(6) * 1e-3))
        node.filter.initialize(0, SE3.identity(), np.eye(6) * 1e-2)
        for k in range(1, 101):
            cov = np.eye(6) * 1e-3 + k * step
            node.feed("/odom", OdometryMsg(k * S // 100, "odom", "base_link", T, cov))
        P[mode] = node.filter.covariance
    axes = [0, 1, 5] if planar else list(range(6))
    expected = np.zeros((6, 6))
    expected[np.ix_(axes, axes)] = (100 * step)[np.ix_(axes, axes)]
    np.testing.assert_allclose(P["growth"] - P["ignore"], expected, rtol=1e-9, atol=1e-15)
