"""The driver's replay clock: one code path for simulator and bag, bad input, late frames.

Oracle: the simulator's ground truth (and, for the bag path, the simulator path itself).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from tagloc.cli.localize_cmd import write_stream_bag
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.io import BagSource
from tagloc.localize import LocalizerConfig, LocalizerNode, StreamInputError, record_run
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.messages import Message, NodeTopics, OdometryMsg, TagDetectionsMsg
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags import TagDetection, TagMap

MS = 1_000_000


@pytest.fixture(scope="module")
def short() -> ScenarioSource:
    return ScenarioSource(build_scenario("default", seed=3, duration_s=20.0))


def _localize(
    stream: Iterable[tuple[str, Message]], tag_map: TagMap, config: LocalizerConfig,
    **options: object,
) -> LocalizationRun:  # fmt: skip
    node = partial(LocalizerNode, tag_map, config, **options)  # type: ignore[arg-type]
    return record_run(node, stream)


def _run(
    stream: Iterable[tuple[str, Message]], source: ScenarioSource, **kw: object
) -> LocalizationRun:
    config = calibrated_config(source.scenario, scenario_config())
    return _localize(stream, source.scenario.tag_map, config, frame_truth=source.frame_truth, **kw)


def _ate(run: LocalizationRun) -> float:
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation) - run.T_map_base_truth.translation
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def test_sim_stream_localizes_against_ground_truth(short: ScenarioSource) -> None:
    run = _run(short, short)
    assert run.initialized[-1] and run.initialized.mean() > 0.5
    assert _ate(run) < 0.1  # measured 0.04 m on this 20 s stretch; odometry ~0.3 m
    assert len(run.frames) == len(short.frames)
    assert sum(a.accepted for a in run.fixes) > 100
    # rows before initialization: identity correction and NaN covariance
    first = int(np.argmax(run.initialized))
    assert np.isnan(run.cov_map_base[0]).all() and np.isfinite(run.cov_map_base[first]).all()


def test_a_bag_of_the_simulated_drive_localizes_identically(
    short: ScenarioSource, tmp_path: Path
) -> None:
    path = tmp_path / "drive.mcap"
    n = write_stream_bag(short, path)
    assert n > 2000
    from_sim = _run(short, short)
    from_bag = _run(BagSource(path), short)
    np.testing.assert_array_equal(from_bag.stamps_ns, from_sim.stamps_ns)
    np.testing.assert_array_equal(from_bag.initialized, from_sim.initialized)
    np.testing.assert_allclose(
        from_bag.T_map_odom.as_matrix(), from_sim.T_map_odom.as_matrix(), atol=1e-6
    )
    assert [a.decision for a in from_bag.fixes] == [a.decision for a in from_sim.fixes]
    assert from_bag.T_map_base_truth is not None


def _delayed(source: ScenarioSource, delay_ns: int) -> Iterator[tuple[str, Message]]:
    """The stream with each camera frame arriving ``delay_ns`` after its exposure."""
    held: list[tuple[int, str, Message]] = []
    for topic, msg in source:
        if isinstance(msg, TagDetectionsMsg):
            held.append((msg.stamp_ns + delay_ns, topic, msg))
            continue
        if isinstance(msg, OdometryMsg):
            while held and held[0][0] <= msg.stamp_ns:
                yield held[0][1], held.pop(0)[2]
        yield topic, msg


def test_frames_300_ms_late_apply_at_their_own_stamps(short: ScenarioSource) -> None:
    on_time = _run(short, short)
    late = _run(_delayed(short, 300 * MS), short)
    assert late.metadata["event_counts"].get("no_odometry", 0) == 0
    n_late, n_on_time = (sum(a.accepted for a in r.fixes) for r in (late, on_time))
    assert abs(n_late - n_on_time) <= 0.05 * n_on_time  # measured 283 vs 291
    assert abs(_ate(late) - _ate(on_time)) < 0.01


def _odom(stamp: int, x: float = 0.0) -> OdometryMsg:
    T = SE3.from_rotvec(np.zeros(3), [x, 0.0, 0.0])
    return OdometryMsg(stamp, "odom", "base_link", T, np.eye(6) * 1e-4)


def test_bad_odometry_stamps_are_counted_skips(short: ScenarioSource) -> None:
    recorder = RunRecorder()
    node = LocalizerNode(short.scenario.tag_map, LocalizerConfig(), [recorder])
    for stamp, x in ((10 * MS, 0.0), (20 * MS, 0.01), (20 * MS, 0.02), (15 * MS, 0.03)):
        node.feed("/odom", _odom(stamp, x))
    node.feed("/odom", _odom(30 * MS, 0.03))
    node.finish()
    run = recorder.run(node.metadata())
    np.testing.assert_array_equal(run.stamps_ns, [10 * MS, 20 * MS, 30 * MS])
    assert node.skipped == {"odom_duplicate_stamp": 1, "odom_stamp_backwards": 1}


def test_nan_odometry_cannot_enter_the_stream() -> None:
    """NaN is stopped before the node: a record cannot hold it, and a bag's NaN odometry is
    a counted ``non_finite`` skip of :class:`BagSource` (tests/io/test_bag_errors.py)."""
    from tagloc.errors import GeometryError

    with pytest.raises(GeometryError, match="NaN"):
        SE3.from_rotvec(np.zeros(3), [np.nan, 0.0, 0.0])


def test_missing_odometry_topic_is_one_clear_error(short: ScenarioSource) -> None:
    topics = NodeTopics(odom="/robot/odom")
    with pytest.raises(StreamInputError, match=r"'/robot/odom' is not in the input"):
        _run(short, short, topics=topics)
    only_frames = [(t, m) for t, m in short if isinstance(m, TagDetectionsMsg)][:5]
    with pytest.raises(StreamInputError, match="no usable odometry on '/odom'"):
        _run(only_frames, short)


def test_unknown_tag_ids_are_counted_rejections(short: ScenarioSource) -> None:
    frame = next(f for f in short.frames if f.detections)
    alien = TagDetection(
        tag_id=300, family="tag36h11", corners_px=frame.detections[0].corners_px + 50.0,
        hamming=0, decision_margin=80.0,
    )  # fmt: skip

    def stream() -> Iterator[tuple[str, Message]]:
        for topic, msg in short:
            if isinstance(msg, TagDetectionsMsg) and msg.stamp_ns == frame.stamp_ns:
                msg = TagDetectionsMsg(msg.stamp_ns, msg.frame_id, (*msg.detections, alien))
            yield topic, msg

    run = _localize(stream(), short.scenario.tag_map, scenario_config())
    unknown = [a for a in run.fixes if a.decision == "rejected:unknown_tag"]
    assert [a.tag_ids for a in unknown] == [(300,)]


def test_truncated_bag_is_one_line_error(short: ScenarioSource, tmp_path: Path) -> None:
    from tagloc.io import BagFormatError

    path = tmp_path / "drive.mcap"
    write_stream_bag(short, path)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagFormatError) as info:
        _run(BagSource(cut), short)
    assert "cut.mcap" in str(info.value) and "\n" not in str(info.value)
