"""Per-frame time of tag detection alone vs detection + PnP + covariance + gates, same frames.

Frames: four tag36h11 tags (0.16 m, one per image quadrant, 1-2.5 m away, 15-60 deg off
face-on, upright) rendered by the simulator (:func:`tagloc.sim.render_tags_scene`, default
sensor effects: shot and read noise, vignetting) through a 90-degree pinhole at 640x480 and
1280x720, seeded. Each backend configuration runs ``REPEATS`` times over ``FRAMES`` frames after
one warm-up and accuracy pass; in every pass each frame is timed twice back to back, so both
numbers see the same machine load:

- ``detect``: ``detector.detect(image)``;
- ``rest``: :func:`tagloc.tags.observe_tags` on those detections with the tag map and the
  localizer's orientation prior (PnP with both IPPE branches and LM refinement, covariance,
  gates, ambiguity policy, joint PnP over the 4 tags): everything after detection;
- ``full``: their sum per frame; ``Hz`` is ``1000 / median(full)``.

The table gives medians (p90 for ``full``), ``rest / detect`` (the issue's target: <= 30 %),
tags found and accepted out of those present, and the largest corner error against the
renderer's truth. One core: the process is pinned to one CPU, ``cv2.setNumThreads(1)``,
AprilTag ``nthreads=1``.

Run: ``.venv/bin/python benchmarks/bench_detect.py [--repeats 20]``
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

from tagloc.camera import PinholeRadtan
from tagloc.geometry import SE3, SO3
from tagloc.sim import RenderConfig, render_tags_scene
from tagloc.tags import NoiseModel, PosePrior, TagDetector, make_detector, observe_tags

RESOLUTIONS = ((640, 480), (1280, 720))
SIZE = 0.16
FRAMES = 5
CONFIGS: tuple[tuple[str, str, dict[str, object], float], ...] = (
    # backend, label, options, sigma_px of the noise model (tagloc.eval.tag_sweep_config)
    ("apriltag", "quad_decimate=2 (default)", {}, 0.1),
    ("apriltag", "quad_decimate=1", {"quad_decimate": 1.0}, 0.1),
    ("apriltag", "quad_sigma=0.8", {"quad_sigma": 0.8}, 0.1),
    ("aruco", "subpix (default)", {}, 0.2),
)
#: A level camera's optical axes in a z-up map (x right, y down = -z, z forward = +y).
R_MAP_CAM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


class Frame:
    """One rendered frame: image, true corners, tag map and the camera's prior."""

    def __init__(self, camera: PinholeRadtan, rng: np.random.Generator) -> None:
        T_map_cam = SE3(rotation=SO3.from_matrix(R_MAP_CAM), translation=np.array([0, 0, 1.2]))
        tags = []
        for i, tag_id in enumerate(rng.choice(587, 4, replace=False)):
            u = camera.width * (0.25 + 0.5 * (i % 2)) + rng.uniform(-0.05, 0.05) * camera.width
            v = camera.height * (0.25 + 0.5 * (i // 2)) + rng.uniform(-0.05, 0.05) * camera.height
            ray = np.array([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0])
            ray /= np.linalg.norm(ray)
            # face normal (towards the camera) turned about the camera's vertical by 15-60 deg
            a = np.deg2rad(rng.uniform(15.0, 60.0)) * rng.choice([-1, 1])
            turn = SO3.from_rotvec([0.0, a, 0.0]).matrix
            z = turn @ -ray
            up = np.array([0.0, -1.0, 0.0])  # the camera's up; the tag's y axis is up too
            y = up - (up @ z) * z
            y /= np.linalg.norm(y)
            R_cam_tag = np.stack([np.cross(y, z), y, z], axis=1)
            distance = rng.uniform(1.0, 2.5)
            T_cam_tag = SE3(rotation=SO3.from_matrix(R_cam_tag), translation=distance * ray)
            tags.append((int(tag_id), SIZE, T_cam_tag))
        self.image, truths = render_tags_scene(camera, tags, RenderConfig(), rng)
        self.truth = {t.tag_id: t.corners_px for t in truths}
        self.tag_poses = {tag_id: T_map_cam @ T for tag_id, _, T in tags}
        up_cam = T_map_cam.rotation.inverse().act(np.array([0.0, 0.0, 1.0]))
        predicted = T_map_cam.plus(np.r_[0.0, 0.0, 0.0, np.deg2rad(2.0) * rng.normal(size=3)])
        self.prior = PosePrior(predicted, np.deg2rad(3.0), up_cam, np.deg2rad(3.0))


def time_pipeline(
    detector: TagDetector, camera: PinholeRadtan, frames: list[Frame], noise: NoiseModel,
    repeats: int,
) -> dict[str, float]:  # fmt: skip
    """Median detect / rest / full times (ms), p90 of full, found, accepted, worst corner error."""
    found = accepted = 0
    worst = 0.0
    for f in frames:  # warm-up and accuracy pass
        detections = detector.detect(f.image)
        result = observe_tags(detections, camera, SIZE, tag_poses=f.tag_poses, prior=f.prior,
                              noise=noise)  # fmt: skip
        accepted += len(result.accepted)
        for det in detections:
            if det.tag_id in f.truth:
                found += 1
                error = np.linalg.norm(det.corners_px - f.truth[det.tag_id], axis=1).max()
                worst = max(worst, float(error))
    detect, rest = [], []
    for _ in range(repeats):
        for f in frames:
            start = time.perf_counter_ns()
            detections = detector.detect(f.image)
            middle = time.perf_counter_ns()
            observe_tags(detections, camera, SIZE, tag_poses=f.tag_poses, prior=f.prior,
                         noise=noise)  # fmt: skip
            end = time.perf_counter_ns()
            detect.append((middle - start) / 1e6)
            rest.append((end - middle) / 1e6)
    full = np.add(detect, rest)
    return {
        "detect": float(np.median(detect)),
        "rest": float(np.median(rest)),
        "full": float(np.median(full)),
        "full_p90": float(np.percentile(full, 90)),
        "found": found,
        "accepted": accepted,
        "worst": worst,
    }


def pin_one_core() -> str:
    """Pin this process to one CPU (Linux); returns a description."""
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}"
    return "not pinned (no sched_setaffinity)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="passes over the frames")
    args = parser.parse_args()
    pinned = pin_one_core()
    cv2.setNumThreads(1)
    rng = np.random.default_rng(2024)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"4 tag36h11 tags per frame (rendered, 1-2.5 m, 15-60 deg), {FRAMES} frames x "
          f"{args.repeats} repeats; OpenCV {cv2.__version__}, cv2.setNumThreads(1), AprilTag "
          f"nthreads=1, {pinned}; load average {load}")  # fmt: skip
    header = (f"{'backend':9s} {'options':26s} {'frame':>9s} {'found':>6s} {'acc':>6s} "
              f"{'detect ms':>9s} {'rest ms':>8s} {'full ms':>8s} {'full p90':>8s} "
              f"{'rest/det':>8s} {'full Hz':>7s} {'max err px':>10s}")  # fmt: skip
    print(header)
    print("-" * len(header))
    for width, height in RESOLUTIONS:
        f_px = width / 2.0  # 90 deg horizontal field of view
        camera = PinholeRadtan(width=width, height=height, fx=f_px, fy=f_px,
                               cx=(width - 1) / 2, cy=(height - 1) / 2)  # fmt: skip
        frames = [Frame(camera, rng) for _ in range(FRAMES)]
        present = 4 * FRAMES
        for backend, label, options, sigma_px in CONFIGS:
            detector = make_detector(backend, "tag36h11", **options)
            t = time_pipeline(detector, camera, frames, NoiseModel(sigma_px=sigma_px),
                              args.repeats)  # fmt: skip
            found, accepted = f"{t['found']}/{present}", f"{t['accepted']}/{present}"
            print(f"{backend:9s} {label:26s} {f'{width}x{height}':>9s} {found:>6s} {accepted:>6s} "
                  f"{t['detect']:9.2f} {t['rest']:8.2f} {t['full']:8.2f} {t['full_p90']:8.2f} "
                  f"{100 * t['rest'] / t['detect']:7.0f}% {1e3 / t['full']:7.1f} "
                  f"{t['worst']:10.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
