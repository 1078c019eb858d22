"""Fixes from every camera of a rig: each camera on its own topic, judged by independent oracles.

The simulator's default drive gives the front camera; a second camera looks backwards from the
same base (turned 180 deg about the base's z, its frames at the same instants). Its corners are
projected here with OpenCV (``cv2.projectPoints`` of the map's tag corners from the simulator's
true pose, 0.3 px noise), not with tagloc's camera model. Oracles: OpenCV's ``solvePnP``
(IPPE-square, refined) on each back frame's single tag composed with the extrinsics, and the
simulator's truth. The rig's stream is built in ``tests/rig_stream.py``.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from list_sink import ListSink

from rig_stream import BACK, UNIT, Rig, make_rig, matrix
from tagloc.eval.refusals import fix_decisions
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.localize import LocalizeError
from tagloc.localize.node import LocalizerNode, NodeCamera
from tagloc.localize.outputs import Estimate
from tagloc.localize.run import FixAttempt
from tagloc.messages import Message
from tagloc.sim.scenarios import ScenarioSource


@pytest.fixture(scope="module")
def rig() -> Rig:
    return make_rig()


def _run(
    source: ScenarioSource, stream: list[tuple[str, Message]], cameras: list[NodeCamera]
) -> ListSink:
    sink = ListSink()
    cfg = calibrated_config(source.scenario, scenario_config())
    node = LocalizerNode(source.scenario.tag_map, cfg, [sink], cameras=cameras)
    for topic, msg in stream:
        node.feed(topic, msg)
    node.finish()
    return sink


def _cameras(source: ScenarioSource, T_base_back: SE3) -> list[NodeCamera]:
    topic = source.t.detections
    return [NodeCamera("front", topic, source.camera, source.T_base_cam),
            NodeCamera("back", BACK, source.camera, T_base_back)]  # fmt: skip


def test_every_camera_gives_fixes_that_match_truth(rig: Rig) -> None:
    source, T_base_back, _, stream = rig
    sink = _run(source, stream, _cameras(source, T_base_back))
    attempts = sink.of(FixAttempt)
    decisions = fix_decisions(attempts)
    by_camera = {c.camera: c for c in decisions.by_camera}
    assert set(by_camera) == {"front", "back"}
    assert by_camera["back"].n_attempts >= 50 and by_camera["back"].acceptance >= 0.8
    # the back camera's fixes sit on the simulator's truth as closely as the front camera's
    # (single-tag fixes: the error grows with range; the filter fuses them)
    for r_max in (3.0, 4.0):
        err = {name: _errors(source, attempts, name, r_max) for name in ("front", "back")}
        assert len(err["back"]) >= 50
        assert float(np.median(err["back"])) < 0.10
        assert float(np.median(err["back"])) <= 1.5 * float(np.median(err["front"])) + 0.01


def _errors(
    source: ScenarioSource, attempts: list[FixAttempt], camera: str, r_max: float
) -> np.ndarray:
    """Position errors (m) against truth of a camera's accepted fixes within ``r_max``."""
    accepted = [a for a in attempts if a.camera == camera and a.accepted and a.range_m <= r_max]
    stamps = np.array([a.stamp_ns for a in accepted], dtype=np.int64)
    truth = source.scenario.drive.ground_truth_at(stamps).T_map_base
    xyz = np.array([np.asarray(a.T_map_base.translation) for a in accepted]).reshape(-1, 3)
    return np.linalg.norm(xyz - np.asarray(truth.translation).reshape(-1, 3), axis=1)


def test_back_fixes_agree_with_opencv_solvepnp(rig: Rig) -> None:
    source, T_base_back, back, stream = rig
    sink = _run(source, stream, _cameras(source, T_base_back))
    cam = source.camera
    K, D = np.asarray(cam.K), np.asarray(cam.dist_coeffs, dtype=np.float64)
    tag_map = {t.id: t for t in source.scenario.tag_map.in_frame("map")}
    X_inv = np.linalg.inv(matrix(T_base_back))
    checked = 0
    for a in sink.of(FixAttempt):
        if a.camera != "back" or not a.accepted or len(back[a.stamp_ns]) != 1:
            continue
        det = back[a.stamp_ns][0]
        tag = tag_map[det.tag_id]
        obj = tag.size * UNIT
        px = np.asarray(det.corners_px, dtype=np.float64)
        ok, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, px, K, D, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        assert ok
        best = None
        for rvec, tvec in zip(rvecs, tvecs, strict=True):
            rvec, tvec = cv2.solvePnPRefineLM(obj, px, K, D, rvec, tvec)
            T_cam_tag = np.eye(4)
            T_cam_tag[:3, :3], T_cam_tag[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
            T_map_base = matrix(tag.T_frame_tag()) @ np.linalg.inv(T_cam_tag) @ X_inv
            gap = np.linalg.norm(T_map_base[:3, 3] - np.asarray(a.T_map_base.translation))
            best = gap if best is None else min(best, gap)
        assert best is not None and best < 0.005  # one of OpenCV's branches, to 5 mm
        checked += 1
    assert checked >= 20


def test_two_cameras_localize_at_least_as_well_as_one(rig: Rig) -> None:
    source, T_base_back, _, stream = rig
    both = _run(source, stream, _cameras(source, T_base_back))
    one = _run(source, stream, _cameras(source, T_base_back)[:1])
    assert all(a.camera == "front" for a in one.of(FixAttempt))  # the back topic is not read

    def ate(sink: ListSink) -> float:
        est = [e for e in sink.of(Estimate) if e.initialized]
        stamps = np.array([e.stamp_ns for e in est], dtype=np.int64)
        truth = source.scenario.drive.ground_truth_at(stamps).T_map_base
        d = np.array([np.asarray(e.T_map_base.translation) for e in est]) - np.asarray(
            truth.translation
        )
        return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))

    n_both = sum(a.accepted for a in both.of(FixAttempt))
    n_one = sum(a.accepted for a in one.of(FixAttempt))
    assert n_both > n_one
    assert ate(both) <= ate(one) + 0.01


def test_one_named_camera_is_the_single_camera_node(rig: Rig) -> None:
    source, _, _, stream = rig
    named = _run(source, stream, [NodeCamera("", source.t.detections, source.camera,
                                             source.T_base_cam)])  # fmt: skip
    sink = ListSink()
    cfg = calibrated_config(source.scenario, scenario_config())
    node = LocalizerNode(source.scenario.tag_map, cfg, [sink], camera=source.camera,
                         T_base_cam=source.T_base_cam)  # fmt: skip
    for topic, msg in stream:
        node.feed(topic, msg)
    node.finish()
    a = [e.T_map_base.translation for e in named.of(Estimate)]
    b = [e.T_map_base.translation for e in sink.of(Estimate)]
    assert len(a) == len(b) and np.allclose(a, b, atol=1e-12, rtol=0)


def test_cameras_sharing_a_topic_are_refused(rig: Rig) -> None:
    source = rig[0]
    cams = [NodeCamera("a", "/t", source.camera, source.T_base_cam),
            NodeCamera("b", "/t", source.camera, source.T_base_cam)]  # fmt: skip
    with pytest.raises(LocalizeError, match="topic is used twice"):
        LocalizerNode(source.scenario.tag_map, cameras=cams)
    with pytest.raises(LocalizeError, match="per camera"):
        LocalizerNode(source.scenario.tag_map, camera=source.camera, cameras=cams[:1])
