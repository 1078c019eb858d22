"""A simulated two-camera rig's stream for tests: the default drive's front camera and a second
camera looking backwards from the same base (turned 180 deg about the base's z, its frames at the
same instants). The back camera's corners are projected with OpenCV (``cv2.projectPoints`` of the
map's tag corners from the simulator's true pose, 0.3 px noise), not with tagloc's camera model.
"""

from __future__ import annotations

import cv2
import numpy as np

from tagloc.geometry import SE3
from tagloc.messages import Message, TagDetectionsMsg
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags import TagDetection

BACK = "/back/tags"
#: Tag corners in the tag frame (x right, y up): top-left, top-right, bottom-right, bottom-left.
UNIT = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


Rig = tuple[ScenarioSource, SE3, dict[int, list[TagDetection]], list[tuple[str, Message]]]


def matrix(T: SE3) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = T.rotation.as_matrix(), np.asarray(T.translation)
    return M


def make_rig(duration_s: float = 40.0) -> Rig:
    """The scenario, the back camera's mount, its detections by stamp, and the merged stream."""
    source = ScenarioSource(build_scenario("default", seed=1, duration_s=duration_s))
    cam = source.camera
    turn = SE3.from_trusted(np.diag([-1.0, -1.0, 1.0]), np.zeros(3))
    T_base_back = turn @ source.T_base_cam
    K, D = np.asarray(cam.K), np.asarray(cam.dist_coeffs, dtype=np.float64)
    stamps = np.array([f.stamp_ns for f in source.frames], dtype=np.int64)
    truth = source.scenario.drive.ground_truth_at(stamps).T_map_base
    rng = np.random.default_rng(7)
    tags = source.scenario.tag_map.in_frame("map")
    back: dict[int, list[TagDetection]] = {}
    for k, stamp in enumerate(stamps.tolist()):
        T_cam_map = np.linalg.inv(matrix(truth[k]) @ matrix(T_base_back))
        dets = []
        for tag in tags:
            pts = (matrix(tag.T_frame_tag()) @ np.c_[tag.size * UNIT, np.ones(4)].T).T[:, :3]
            cam_pts = (T_cam_map[:3, :3] @ pts.T).T + T_cam_map[:3, 3]
            normal = T_cam_map[:3, :3] @ tag.T_frame_tag().rotation.as_matrix()[:, 2]
            centre = cam_pts.mean(axis=0)
            angle = np.degrees(np.arccos(-normal @ centre / np.linalg.norm(centre)))
            if centre[2] < 0.3 or np.linalg.norm(centre) > 6.0 or angle > 65.0:
                continue
            px, _ = cv2.projectPoints(pts, cv2.Rodrigues(T_cam_map[:3, :3])[0], T_cam_map[:3, 3],
                                      K, D)  # fmt: skip
            px = px.reshape(4, 2) + rng.normal(0.0, 0.3, (4, 2))
            if (
                (px < 5).any()
                or (px[:, 0] > cam.width - 5).any()
                or (px[:, 1] > cam.height - 5).any()
            ):
                continue
            dets.append(TagDetection.from_corners(tag.id, tag.family, px))
        if dets:
            back[stamp] = dets
    stream: list[tuple[str, Message]] = []
    for topic, msg in source:
        stream.append((topic, msg))
        if isinstance(msg, TagDetectionsMsg) and msg.stamp_ns in back:
            stream.append(
                (BACK, TagDetectionsMsg(msg.stamp_ns, "back_optical", tuple(back[msg.stamp_ns])))
            )
    return source, T_base_back, back, stream
