"""The wall clock's detection worker in predicted regions, on rendered frames of a drive.

Oracle: the replay clock's run of the same stream (the node's thread detects each frame in the
regions as it arrives; nothing dropped) and the simulator's ground truth. The stream has a
camera outage (the ``gap`` rule) and one false tag detection whose fix the filter gates (the
``inconsistent_fix`` rule), beside the periodic full frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import numpy as np
import pytest

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.driver import record_run, run
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.roi_detector import ALARMS
from tagloc.localize.run import FixAttempt, LocalizationRun
from tagloc.messages import (
    CameraInfoMsg,
    ImageMsg,
    Message,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.sim import render_frames
from tagloc.sim.scenario import Scenario
from tagloc.sim.scenario_source import BASE_FRAME, CAMERA_FRAME, TF_STATIC
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags import TagDetection, make_detector

S = 1_000_000_000
#: The default drive: pre-detected frames until 9 s (the filter initializes on them), then
#: rendered images until 14 s, the worker detecting them.
IMAGES_S, LAST_S = 9.0, 14.0
#: No camera frames from 11.0 s to 11.8 s (longer than ``tags.roi.gap_s``, 0.5 s).
OUTAGE_S = (11.0, 11.8)
#: One false detection at 12.5 s: a real one's corners moved 60 px sideways (a tag where the
#: map has none), so the filter gates its fix.
FALSE_S, FALSE_SHIFT_PX = 12.5, 60.0
#: Fixes the wall clock accepts, against the replay clock's: the worker decides a frame a
#: little later (its orientation prior and the prediction come from a slightly older state).
ACCEPTED_TOL = 0.1


def _stream(scenario: Scenario) -> list[tuple[str, Message]]:
    drive, camera = scenario.drive, scenario.world.robot.camera
    t0 = int(drive.stamps_ns[0])
    t = (drive.camera_stamps_ns - t0) / S
    keep = (t >= IMAGES_S) & ~((t >= OUTAGE_S[0]) & (t < OUTAGE_S[1]))
    frames = render_frames(drive, seed=3, stamps_ns=drive.camera_stamps_ns[keep])
    images = {f.stamp_ns: ImageMsg(f.stamp_ns, CAMERA_FRAME, f.image, "mono8") for f in frames}
    # the false detection, between two frames
    at = next(m for m in images.values() if m.stamp_ns - t0 >= FALSE_S * S)
    real = make_detector("apriltag", "tag36h11").detect(at.image)[0]
    shifted = real.corners_px + np.array([FALSE_SHIFT_PX, 0.0])
    moved = TagDetection.from_corners(real.tag_id, real.family, shifted)
    pending = [TagDetectionsMsg(at.stamp_ns + S // 100, CAMERA_FRAME, (moved,))]
    info = camera.camera_model().to_camera_info()
    T_base_cam = camera.T_base_cam.T_base_cam()
    out: list[tuple[str, Message]] = [
        ("/camera/camera_info", CameraInfoMsg(t0, CAMERA_FRAME, info)),
        (TF_STATIC, TransformMsg(t0, BASE_FRAME, CAMERA_FRAME, T_base_cam, static=True)),
    ]
    for topic, msg in ScenarioSource(scenario):
        if isinstance(msg, TagDetectionsMsg) and msg.stamp_ns - t0 >= IMAGES_S * S:
            if msg.stamp_ns in images:
                out.append(("/camera/image", images[msg.stamp_ns]))
            continue
        if pending and msg.stamp_ns >= pending[0].stamp_ns:
            out.append(("/tag_detections", pending.pop()))
        out.append((topic, msg))
    return out


def _truth_ate(run: LocalizationRun, scenario: Scenario) -> float:
    truth = scenario.drive.ground_truth_at(np.asarray(run.stamps_ns)).T_map_base
    d = np.asarray(run.T_map_base.translation) - truth.translation
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


@pytest.fixture(scope="module")
def drive() -> tuple[Scenario, list[tuple[str, Message]]]:
    scenario = build_scenario("default", 1, LAST_S)
    return scenario, _stream(scenario)


def _accepted(fixes: Sequence[FixAttempt]) -> int:
    return sum(f.accepted for f in fixes)


def test_the_worker_detects_in_regions_and_accepts_the_replay_clocks_fixes(
    drive: tuple[Scenario, list[tuple[str, Message]]],
) -> None:
    scenario, stream = drive
    config = calibrated_config(scenario, scenario_config())
    node = partial(LocalizerNode, scenario.tag_map, config)
    offline = record_run(node, stream)
    recorder = RunRecorder()
    n_images = sum(isinstance(m, ImageMsg) for _, m in stream)
    assert n_images > 100
    # every frame kept (the queue holds them all), the worker at the main thread's priority:
    # the comparison is of the regions, not of a loaded machine's drops
    result = run(node, stream, [recorder], clock="wall", speed=1.0, queue_size=n_images,
                 worker_nice=0)  # fmt: skip
    stats = result.realtime
    assert stats is not None
    assert stats.frames_in == n_images and stats.frames_dropped == 0
    # the worker's frames: in regions, the full frame on the region detector's triggers
    reasons = stats.full_frame_reasons
    n_full = sum(reasons.values())
    assert stats.frames_regions + n_full == n_images
    assert stats.frames_regions > 0.5 * n_images, reasons
    assert reasons["gap"] >= 2  # the first image, and the first after the outage
    assert reasons["inconsistent_fix"] >= 1  # after the false detection's gated fix
    assert reasons["periodic"] >= 1
    every = config.tags.roi.full_frame_every  # at most every - 1 region frames in a row
    assert stats.frames_regions <= (every - 1) * (n_full + 1)
    # the replay clock's run: the same triggers, about as many frames in regions
    replay = offline.metadata["regions"]
    assert isinstance(replay, dict)
    assert set(reasons) == set(replay["full_frame_reasons"]), (reasons, replay)
    assert abs(stats.frames_regions - replay["frames_regions"]) <= 0.1 * n_images
    # as many fixes accepted as the replay clock, the fused pose on the truth
    want, got = _accepted(offline.fixes), _accepted(recorder.fixes)
    assert want > 50 and abs(got - want) <= ACCEPTED_TOL * want, (got, want)
    realtime = recorder.run(result.node.metadata())
    assert _truth_ate(realtime, scenario) <= 1.2 * _truth_ate(offline, scenario) + 0.01


def test_the_regions_come_from_the_node_state_at_hand_off(
    drive: tuple[Scenario, list[tuple[str, Message]]],
) -> None:
    """A frame's region detection taken before the false detection's fix is decided searches
    the regions; the same frame's taken after it (the filter alarmed) the full frame."""
    scenario, stream = drive
    config = calibrated_config(scenario, scenario_config())
    node = LocalizerNode(scenario.tag_map, config)
    first_image = next(i for i, (_, m) in enumerate(stream) if isinstance(m, ImageMsg))
    false = next(i for i in range(first_image, len(stream)) if stream[i][0] == "/tag_detections")
    after = next(i for i in range(false, len(stream)) if isinstance(stream[i][1], ImageMsg))
    image = stream[after][1]
    assert isinstance(image, ImageMsg)
    for topic, msg in stream[:false]:
        node.feed(topic, msg)

    def counts() -> tuple[int, int]:
        meta = node.metadata()
        alarms = sum(meta["event_counts"].get(str(k), 0) for k in ALARMS)
        regions = meta["regions"]
        return alarms, regions["full_frame_reasons"].get("inconsistent_fix", 0)

    before = node.region_detect(image.stamp_ns)
    alarms0, full0 = counts()
    for topic, msg in stream[false:after]:  # the false detection, decided by the odometry
        node.feed(topic, msg)
    late = node.region_detect(image.stamp_ns)
    assert before is not None and late is not None
    alarms1, _ = counts()
    assert alarms1 > alarms0  # the filter gated (or held) the false fix
    detector = make_detector("apriltag", "tag36h11")
    before(image.image, detector)  # the state at hand-off: no alarm yet
    assert counts()[1] == full0
    late(image.image, detector)  # the state after the alarm
    assert counts()[1] == full0 + 1
