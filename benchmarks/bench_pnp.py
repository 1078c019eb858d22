"""Benchmark tag pose estimation: OpenCV IPPE alone against the full tagloc per-tag pipeline.

Run: ``.venv/bin/python benchmarks/bench_pnp.py [--repeats 15]``

Rows (1280x720, fx = 640, 0.16 m tags at 1-4 m and 15-60 deg, 0.3 px corner noise):

- ``cv2 IPPE_SQUARE``: ``cv2.solvePnPGeneric`` alone on pixel corners (both solutions).
- ``estimate_tag_poses``: undistort + IPPE (both) + LM refinement of both branches + valley +
  covariances, for all tags of a frame in one call.
- ``observe_tags``: the above plus gates and the ambiguity policy (with a gravity and rotation
  prior), and joint PnP when the tags are in the map.
- ``estimate_joint_pose``: joint PnP alone, given the single-tag estimates.

Each figure is the median over ``repeats`` timings of a loop (``time.perf_counter_ns``), given
per frame and per tag. These costs do not depend on the image size; ``bench_detect.py`` sets
them against the detector's own time on rendered 640x480 and 1280x720 frames (the issue's
"everything after detection adds at most 30 %").
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import cv2
import numpy as np

from _timing import per_call_ns
from tagloc.camera import PinholeRadtan
from tagloc.geometry import SE3, SO3
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.detection import TagDetection, tag_object_points
from tagloc.tags.observation import PosePrior, observe_tags
from tagloc.tags.pnp import estimate_joint_pose, estimate_tag_poses

SEED = 7
SIZE = 0.16
CAMERA = PinholeRadtan(
    width=1280, height=720, fx=640.0, fy=640.0, cx=639.5, cy=359.5, k1=-0.05, k2=0.01
)


def frame(n_tags: int, rng: np.random.Generator) -> tuple[list[TagDetection], dict[int, SE3], SE3]:
    """``n_tags`` upright tags on a wall 1-4 m away seen at 15-60 deg, with noisy corners."""
    T_map_cam = SE3(
        rotation=SO3.from_matrix([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]),
        translation=np.array([0.0, 0.0, 1.0]),
    )  # level camera looking along map +y
    detections, tag_poses = [], {}
    for i in range(n_tags):
        distance, yaw = rng.uniform(1.0, 4.0), np.deg2rad(rng.uniform(15, 60) * rng.choice([-1, 1]))
        bearing = np.deg2rad(rng.uniform(-30, 30))
        center = np.array([distance * np.sin(bearing), distance * np.cos(bearing), 1.0])
        normal = -np.array([np.sin(bearing + yaw), np.cos(bearing + yaw), 0.0])
        up = np.array([0.0, 0.0, 1.0])
        R_map_tag = np.stack([np.cross(up, normal), up, normal], axis=1)
        tag_poses[i] = SE3(rotation=SO3.from_matrix(R_map_tag), translation=center)
        T_cam_tag = T_map_cam.inverse() @ tag_poses[i]
        corners = CAMERA.project(T_cam_tag.act(tag_object_points(SIZE)))
        detections.append(
            TagDetection(i, "tag36h11", corners + rng.normal(0, 0.3, (4, 2)), 0, 60.0)
        )
    return detections, tag_poses, T_map_cam


def stages(n: int, rng: np.random.Generator) -> dict[str, Callable[[], object]]:
    """The timed calls for one frame of ``n`` tags."""
    noise = NoiseModel(sigma_px=0.3)
    dets, tag_poses, T_map_cam = frame(n, rng)
    ids = [d.tag_id for d in dets]
    corners = np.array([d.corners_px for d in dets])
    sizes = [SIZE] * n
    up_cam = T_map_cam.rotation.inverse().act(np.array([0.0, 0.0, 1.0]))
    prior = PosePrior(T_map_cam, 0.05, up_cam, 0.05)
    points = tag_object_points(SIZE)

    def ippe() -> None:
        for c in corners:
            cv2.solvePnPGeneric(
                points, c, CAMERA.K, CAMERA.dist_coeffs, flags=cv2.SOLVEPNP_IPPE_SQUARE
            )

    out: dict[str, Callable[[], object]] = {
        "cv2 IPPE_SQUARE (both solutions)": ippe,
        "estimate_tag_poses (undistort+IPPE+refine+cov)": lambda: estimate_tag_poses(
            ids, corners, sizes, CAMERA, noise
        ),
        "observe_tags, no map (+gates+policy)": lambda: observe_tags(
            dets, CAMERA, SIZE, noise=noise, prior=prior
        ),
        "observe_tags, tag map (+joint PnP if n>=2)": lambda: observe_tags(
            dets, CAMERA, SIZE, tag_poses=tag_poses, noise=noise, prior=prior
        ),
    }
    if n >= 2:
        estimates = [e for e in estimate_tag_poses(ids, corners, sizes, CAMERA, noise) if e]
        maps = [tag_poses[i] for i in ids]
        out["estimate_joint_pose alone"] = lambda: estimate_joint_pose(
            estimates, corners, maps, CAMERA, noise
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15, help="timings per figure (median)")
    args = parser.parse_args()
    rng = np.random.default_rng(SEED)
    rows = [
        (name, n, per_call_ns(fn, args.repeats))
        for n in (1, 2, 4, 8)
        for name, fn in stages(n, rng).items()
    ]
    print(f"{'stage':50s} {'tags':>4s} {'per frame':>11s} {'per tag':>10s}")
    for name, n, ns in sorted(rows, key=lambda r: (r[0], r[1])):
        print(f"{name:50s} {n:4d} {ns / 1e3:8.0f} us {ns / 1e3 / n:7.0f} us")


if __name__ == "__main__":
    main()
