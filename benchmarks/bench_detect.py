"""Per-frame tag detection time of each backend at 640x480 and 1280x720.

Synthetic frames: four tag36h11 tags (one per frame quadrant, 18-28 % of the frame height,
random in-plane angle, mild perspective) rendered area-sampled onto a gray background with
Gaussian noise (sigma 2 gray levels), seeded. Each detector runs ``REPEATS`` times over
``FRAMES`` frames after one warm-up pass; the table gives the median and 90th percentile of the
per-frame wall time, the tags found out of those present, and the largest corner error against
the rendered truth.

Run: ``.venv/bin/python benchmarks/bench_detect.py`` (single-threaded detectors).
"""

from __future__ import annotations

import time

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.tags import TagDetector, make_detector
from tagloc.tags.bitmaps import render_tag

RESOLUTIONS = ((640, 480), (1280, 720))
TAGS_PER_FRAME = 4
FRAMES = 5
REPEATS = 20
CONFIGS: tuple[tuple[str, str, dict[str, object]], ...] = (
    ("apriltag", "quad_decimate=2 (default)", {}),
    ("apriltag", "quad_decimate=1", {"quad_decimate": 1.0}),
    ("aruco", "subpix (default)", {}),
)

Frame = tuple[npt.NDArray[np.uint8], dict[int, npt.NDArray[np.float64]]]


def make_frame(rng: np.random.Generator, width: int, height: int) -> Frame:
    """A noisy gray frame with ``TAGS_PER_FRAME`` tags in separate cells, and their corners."""
    image = np.full((height, width), 128, np.uint8)
    truth: dict[int, npt.NDArray[np.float64]] = {}
    cell_w, cell_h = width / 2, height / 2
    for i, tag_id in enumerate(rng.choice(587, TAGS_PER_FRAME, replace=False)):
        side = rng.uniform(0.18, 0.28) * height
        center = np.array([(i % 2 + 0.5) * cell_w, (i // 2 + 0.5) * cell_h])
        center += rng.uniform(-0.05, 0.05, 2) * [cell_w, cell_h]
        angle = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        square = 0.5 * side * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        corners = square @ R.T + center + rng.normal(0, 0.03 * side, (4, 2))
        image = render_tag(image, "tag36h11", int(tag_id), corners)
        truth[int(tag_id)] = corners
    noise = rng.normal(0.0, 2.0, image.shape)
    return np.clip(image + noise, 0, 255).astype(np.uint8), truth


def time_detector(detector: TagDetector, frames: list[Frame]) -> tuple[list[float], int, float]:
    """Per-frame times (ms), tags found in one pass, worst corner error (px)."""
    found, worst = 0, 0.0
    for image, truth in frames:  # warm-up and accuracy pass
        for det in detector.detect(image):
            if det.tag_id in truth:
                found += 1
                error = np.linalg.norm(det.corners_px - truth[det.tag_id], axis=1).max()
                worst = max(worst, float(error))
    times_ms = []
    for _ in range(REPEATS):
        for image, _truth in frames:
            start = time.perf_counter_ns()
            detector.detect(image)
            times_ms.append((time.perf_counter_ns() - start) / 1e6)
    return times_ms, found, worst


def main() -> None:
    cv2.setNumThreads(1)
    rng = np.random.default_rng(2024)
    header = f"{'backend':9s} {'options':26s} {'frame':>9s} {'found':>7s} {'median ms':>10s} "
    header += f"{'p90 ms':>8s} {'max err px':>11s}"
    print(f"{TAGS_PER_FRAME} tag36h11 tags per frame, {FRAMES} frames x {REPEATS} repeats")
    print(f"OpenCV {cv2.__version__}, cv2.setNumThreads(1), AprilTag nthreads=1")
    print(header)
    print("-" * len(header))
    for width, height in RESOLUTIONS:
        frames = [make_frame(rng, width, height) for _ in range(FRAMES)]
        present = FRAMES * TAGS_PER_FRAME
        for backend, label, options in CONFIGS:
            detector = make_detector(backend, "tag36h11", **options)
            times_ms, found, worst = time_detector(detector, frames)
            print(
                f"{backend:9s} {label:26s} {f'{width}x{height}':>9s} {f'{found}/{present}':>7s} "
                f"{np.median(times_ms):10.2f} {np.percentile(times_ms, 90):8.2f} {worst:11.3f}"
            )


if __name__ == "__main__":
    main()
