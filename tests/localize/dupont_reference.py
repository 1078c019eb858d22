"""An independent reference of the dupont drive: the rig's pose from TagSLAM's tag map.

For every camera frame that sees >= ``min_tags`` tags of TagSLAM's own map of this drive
(``tagslam_map.yaml``: a peer's answer, never an input of tagloc's map or localizer), OpenCV
solves the camera's pose from all their corners (fisheye undistortion, ``solvePnP`` on the
normalized points) and the rig's odometry child frame follows with the calibration files read
here with yaml and scipy: ``T_map_base = T_map_cam @ (T_body_odom^-1 @ T_body_cam)^-1``. Frames
whose solve leaves more than ``max_rms_px`` of corner residual or whose tags lie beyond
``max_range_m`` are left out. Nothing of tagloc's PnP, map or configuration enters.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from tagloc.io import BagSource

DUPONT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "dupont"
BAG = DUPONT / "tag_detections.bag.bz2"
TOPICS = {"/fla/ovc_node/left/tags": "cam0", "/fla/ovc_node/right/tags": "cam1"}
#: The tag's corners in its frame (x right, y up), top-left, top-right, bottom-right, bottom-left.
_UNIT = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


@dataclass(frozen=True)
class Reference:
    """Reference poses of the base: ``stamps_ns`` (K,), ``positions_map`` (K, 3), ``R_map_base``
    (K, 3, 3), and the camera of each."""

    stamps_ns: np.ndarray
    positions_map: np.ndarray
    R_map_base: np.ndarray
    cameras: list[str]


def _pose(d: dict) -> np.ndarray:
    p, r = d["position"], d["rotation"]
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([r["x"], r["y"], r["z"]]).as_matrix()
    T[:3, 3] = [p["x"], p["y"], p["z"]]
    return T


def base_from_cameras() -> dict[str, np.ndarray]:
    """``T_base_cam`` (4x4) of each camera, base = the odometry's child frame."""
    poses = yaml.safe_load((DUPONT / "camera_poses.yaml").read_text())
    rig = yaml.safe_load((DUPONT / "tagslam.yaml").read_text())
    body = next(b["rig"] for b in rig["bodies"] if "rig" in b)
    T_body_odom = _pose(body["T_body_odom"])
    return {c: np.linalg.inv(T_body_odom) @ _pose(poses[c]["pose"]) for c in ("cam0", "cam1")}


def tagslam_tags() -> dict[int, np.ndarray]:
    """``T_map_tag`` (4x4) of TagSLAM's map."""
    data = yaml.safe_load((DUPONT / "tagslam_map.yaml").read_text())
    out = {}
    for t in data["tags"]:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(t["quat_xyzw"]).as_matrix()
        T[:3, 3] = t["position"]
        out[int(t["id"])] = T
    return out


def reference(
    t_end_s: float | None = None, *, min_tags: int = 2, max_rms_px: float = 1.0,
    max_range_m: float = 4.0, size_m: float = 0.15,
) -> Reference:  # fmt: skip
    """The reference poses of the drive (module docstring), up to ``t_end_s`` after its start."""
    cams = yaml.safe_load((DUPONT / "cameras.yaml").read_text())
    K = {c: np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
         for c, v in ((c, cams[c]["intrinsics"]) for c in TOPICS.values())}  # fmt: skip
    D = {c: np.array(cams[c]["distortion_coeffs"], dtype=np.float64) for c in TOPICS.values()}
    X = base_from_cameras()
    tags = tagslam_tags()
    source = BagSource(BAG, list(TOPICS), corner_order="bl_br_tr_tl", default_family="tag36h11")
    stamps, positions, rotations, which = [], [], [], []
    t0 = None
    for topic, msg in source:
        t0 = msg.stamp_ns if t0 is None else t0
        if t_end_s is not None and msg.stamp_ns - t0 > t_end_s * 1e9:
            break
        cam = TOPICS[topic]
        dets = [d for d in msg.detections if d.tag_id in tags]
        if len(dets) < min_tags:
            continue
        obj = np.concatenate([(tags[d.tag_id] @ np.c_[size_m * _UNIT, np.ones(4)].T).T[:, :3]
                              for d in dets])  # fmt: skip
        px = np.concatenate([np.asarray(d.corners_px, dtype=np.float64) for d in dets])
        norm = cv2.fisheye.undistortPoints(px[:, None, :], K[cam], D[cam]).reshape(-1, 2)
        ok, rvec, tvec = cv2.solvePnP(obj, norm, np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, norm, np.eye(3), None, rvec, tvec)
        proj, _ = cv2.fisheye.projectPoints(obj[:, None, :], rvec, tvec, K[cam], D[cam])
        rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - px) ** 2, axis=1))))
        T_cam_map = np.eye(4)
        T_cam_map[:3, :3] = cv2.Rodrigues(rvec)[0]
        T_cam_map[:3, 3] = tvec.ravel()
        ranges = np.linalg.norm((T_cam_map[:3, :3] @ obj.T).T + T_cam_map[:3, 3], axis=1)
        if rms > max_rms_px or ranges.max() > max_range_m:
            continue
        T_map_base = np.linalg.inv(T_cam_map) @ np.linalg.inv(X[cam])
        stamps.append(msg.stamp_ns)
        positions.append(T_map_base[:3, 3])
        rotations.append(T_map_base[:3, :3])
        which.append(cam)
    return Reference(np.array(stamps, dtype=np.int64), np.array(positions).reshape(-1, 3),
                     np.array(rotations).reshape(-1, 3, 3), which)  # fmt: skip


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``stamps_ns``, positions (K, 3) and rotations (K, 3, 3) of a TUM file."""
    rows = [line.split() for line in path.read_text().splitlines() if line and line[0] != "#"]
    stamps = np.array([int(r[0].replace(".", "")) for r in rows], dtype=np.int64)
    values = np.array([[float(v) for v in r[1:8]] for r in rows])
    return stamps, values[:, :3], Rotation.from_quat(values[:, 3:7]).as_matrix()


def errors_against(ref: Reference, tum: Path) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and heading (deg, about the map's z) errors of a trajectory file at the
    reference stamps (nearest sample within 30 ms; the others are left out)."""
    stamps, pos, rot = read_tum(tum)
    i = np.clip(np.searchsorted(stamps, ref.stamps_ns), 1, len(stamps) - 1)
    i = np.where(np.abs(stamps[i - 1] - ref.stamps_ns) < np.abs(stamps[i] - ref.stamps_ns),
                 i - 1, i)  # fmt: skip
    near = np.abs(stamps[i] - ref.stamps_ns) < 30_000_000
    d_pos = np.linalg.norm(pos[i[near]] - ref.positions_map[near], axis=1)
    # heading: the base's forward axis (z of the camera-like frame) turned about the map's up
    fwd_ref = ref.R_map_base[near][:, :, 2]
    fwd_est = rot[i[near]][:, :, 2]
    yaw_est = np.arctan2(fwd_est[:, 1], fwd_est[:, 0])
    yaw = np.degrees(yaw_est - np.arctan2(fwd_ref[:, 1], fwd_ref[:, 0]))
    return d_pos, (yaw + 180.0) % 360.0 - 180.0
