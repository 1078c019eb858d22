"""The node in real time on one core: odometry -> transform latency, image -> correction, drops.

Stream: the first ``--seconds`` of the simulator's default drive (office world, legged odometry,
seeded) with the odometry at ``--odom-hz`` (default 200 Hz) and the robot camera's 30 Hz
1280x720 images rendered by the simulator (:func:`tagloc.sim.render_frames`, default effects),
all rendered before the run and held in memory; ground truth passes through.

The driver's wall clock (:func:`tagloc.localize.driver.run`, ``clock="wall"``) feeds it to a
:class:`LocalizerNode` at speed 1.0, with AprilTag detection (default backend, ``nthreads=1``) on a
worker thread behind a drop-oldest queue of ``--queue`` frames, the worker at a lower priority
(``worker_nice=10``, the default), each odometry sample published before the frames it
completes (``publish_first``, as ``--realtime`` runs): the worker on the full frame
(``tags.roi.enabled: false``), then in the predicted regions (the default), ``--repeats``
times over, alternating, so both see the same load. Reported (definitions in
:class:`tagloc.localize.realtime_stats.RealtimeStats`):

- ``odometry -> transform``: from feeding an odometry sample to its ``Estimate`` (the published
  ``map -> odom``) at a sink; the target is p99 <= 2 ms. Below it the samples whose feed also
  decided a camera frame (PnP, gates, filter update happen there, before the estimate).
  ``odometry due -> transform`` counts from when the sample was due, so it adds the main
  thread's own backlog (and the core taken by detection);
- ``image -> correction``: from when a frame was due to the first estimate after its fixes;
- frames dropped (%), frames detected in regions / in full, and detector errors.

Reference, in the same run on the same images: the bare detector's time per frame
(``detector.detect(image)`` of every frame once, nothing else running), and the fixes accepted
and fused ATE of the replay clock's run (every frame detected inline, in regions by default,
nothing dropped) beside the real-time ones.
One core: the process is pinned to one CPU, ``cv2.setNumThreads(1)``.

Run: ``.venv/bin/python benchmarks/bench_realtime.py [--seconds 20] [--queue 2] [--repeats 2]``
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Iterator
from functools import partial
from typing import cast

import cv2
import numpy as np

from bench_detect import pin_one_core  # the same pinning as the detector benchmark
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.driver import record_run, run
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.messages import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    TransformMsg,
)
from tagloc.sim import load_default_world, render_frames
from tagloc.sim.scenario import Scenario
from tagloc.sim.scenario_source import BASE_FRAME, CAMERA_FRAME, MAP_FRAME, ODOM_FRAME, TF_STATIC
from tagloc.sim.scenarios import build_scenario
from tagloc.tags import make_detector

SEED = 1
ODOM_COV = np.eye(6) * 1e-4


def build(seconds: float, odom_hz: float) -> tuple[Scenario, list[ImageMsg]]:
    """The default scenario's first ``seconds`` with odometry at ``odom_hz``, and its images."""
    world = load_default_world()
    robot = world.robot.model_copy(update={"odom_rate_hz": odom_hz})
    world = world.model_copy(update={"robot": robot})
    scenario = build_scenario("default", SEED, seconds, world=world)
    frames = render_frames(scenario.drive, seed=SEED, stamps_ns=scenario.camera_stamps_ns)
    images = [ImageMsg(f.stamp_ns, CAMERA_FRAME, f.image, "mono8") for f in frames]
    return scenario, images


def stream(scenario: Scenario, images: list[ImageMsg]) -> Iterator[tuple[str, Message]]:
    """Camera info and extrinsics, then images, odometry and truth in stamp order (an image
    before the odometry of the same stamp)."""
    drive, camera = scenario.drive, scenario.world.robot.camera
    t0 = int(drive.stamps_ns[0])
    info = camera.camera_model().to_camera_info()
    yield "/camera/camera_info", CameraInfoMsg(t0, CAMERA_FRAME, info)
    T_base_cam = camera.T_base_cam.T_base_cam()
    yield TF_STATIC, TransformMsg(t0, BASE_FRAME, CAMERA_FRAME, T_base_cam, static=True)
    k = 0
    for i, stamp in enumerate(drive.stamps_ns.tolist()):
        while k < len(images) and images[k].stamp_ns <= stamp:
            yield "/camera/image", images[k]
            k += 1
        yield "/odom", OdometryMsg(stamp, ODOM_FRAME, BASE_FRAME, drive.T_odom_base[i], ODOM_COV)
        yield "/ground_truth", GroundTruthMsg(stamp, MAP_FRAME, drive.T_map_base[i])


def ate_m(run: LocalizationRun) -> float:
    """RMS of the fused position error against the simulator's truth, m."""
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation) - run.T_map_base_truth.translation
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def detector_ms(images: list[ImageMsg]) -> tuple[float, float]:
    """Median and p99 of the bare detector's time per frame, ms (each frame once)."""
    detector = make_detector("apriltag", "tag36h11")
    detector.detect(images[0].image)
    times = []
    for msg in images:
        start = time.perf_counter_ns()
        detector.detect(msg.image)
        times.append((time.perf_counter_ns() - start) / 1e6)
    p50, p99 = np.percentile(times, [50.0, 99.0])
    return float(p50), float(p99)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="stretch of the drive, s")
    parser.add_argument("--odom-hz", type=float, default=200.0, help="odometry rate, Hz")
    parser.add_argument("--queue", type=int, default=2, help="frames waiting at most")
    parser.add_argument("--speed", type=float, default=1.0, help="stream s per wall s")
    parser.add_argument("--repeats", type=int, default=2, help="pairs of real-time runs")
    args = parser.parse_args()
    load_before = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    pinned = pin_one_core()
    cv2.setNumThreads(1)
    start = time.perf_counter()
    scenario, images = build(args.seconds, args.odom_hz)
    render_s = time.perf_counter() - start
    config = calibrated_config(scenario, scenario_config())
    # reference: the bare detector, then the replay clock (every frame detected inline)
    det_p50, det_p99 = detector_ms(images)
    offline = record_run(partial(LocalizerNode, scenario.tag_map, config), stream(scenario, images))
    counts = cast("dict[str, int]", offline.metadata.get("regions") or {})
    offline_regions = f"{counts.get('frames_regions', 0)} / {counts.get('frames_full', 0)}"
    # the real-time runs, the worker at a lower priority, in the live order (each odometry
    # sample published before the frames it completes, as --realtime runs): the worker on the
    # full frame, then in the predicted regions, twice over (the same load for both)
    output = config.output.model_copy(update={"publish_first": True})
    runs = []
    for _ in range(args.repeats):
        for regions in (False, True):
            roi = config.tags.roi.model_copy(update={"enabled": regions})
            tags = config.tags.model_copy(update={"roi": roi})
            live = config.model_copy(update={"output": output, "tags": tags})
            recorder = RunRecorder()
            detector = make_detector(config.tags.backend, config.tags.family)
            result = run(
                partial(LocalizerNode, scenario.tag_map, live), stream(scenario, images),
                [recorder], clock="wall", speed=args.speed, queue_size=args.queue,
                detector=detector, worker_nice=10,
            )  # fmt: skip
            assert result.realtime is not None
            runs.append((result.realtime, recorder.run(result.node.metadata())))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    n_odom = len(scenario.drive.stamps_ns)
    print(f"default drive, first {args.seconds:g} s: {len(images)} images 1280x720 at 30 Hz "
          f"(rendered in {render_s:.0f} s), {n_odom} odometry samples at {args.odom_hz:g} Hz; "
          f"AprilTag tag36h11 nthreads=1, cv2.setNumThreads(1), {pinned}; "
          f"load average before {load_before}, after {load}")  # fmt: skip
    walls = " | ".join(f"{s.wall_s:.1f}" for s, _ in runs)
    print(f"run(clock='wall', speed={args.speed:g}, queue_size={args.queue}, worker_nice=10, "
          f"publish_first=True), full frame | regions (x{args.repeats}): {walls} s wall for "
          f"{runs[0][0].stream_s:.1f} s of stream")  # fmt: skip
    labels = [("full", "regions")[i % 2] + f" #{i // 2 + 1}" for i in range(len(runs))]
    header = f"{'measure':42s} " + " ".join(f"{x:>16s}" for x in labels) + "   reference"
    print(header)
    print("-" * (len(header) + 30))

    def row(label: str, cells: list[str], reference: str = "") -> None:
        print(f"{label:42s} " + " ".join(f"{c:>16s}" for c in cells) + f"   {reference}")

    rows = [
        ("odometry -> transform p50 / p99 (ms)", "odom_to_estimate", "target p99 <= 2"),
        ("  of those, with a frame decided", "odom_frame_to_estimate", ""),
        ("  of those, without", "odom_only_to_estimate", ""),
        ("odometry due -> transform p50 / p99 (ms)", "odom_due_to_estimate", ""),
        ("image due -> correction p50 / p99 (ms)", "image_to_correction",
         f"bare detector {det_p50:.1f} / {det_p99:.1f} ms per frame"),
        ("worker: detection p50 / p99 (ms)", "worker_detect", "lock released in the C library"),
        ("worker: fix computation p50 / p99 (ms)", "worker_fixes", "holds the lock"),
    ]  # fmt: skip
    for label, field, reference in rows:
        summaries = [getattr(stats, field) for stats, _ in runs]
        row(label, [f"{x.p50_ms:.2f} / {x.p99_ms:.2f}" for x in summaries], reference)
    row("frames dropped",
        [f"{100 * s.drop_fraction:.1f} % ({s.frames_dropped}/{s.frames_in})" for s, _ in runs],
        "offline: 0 %")  # fmt: skip
    row("frames in regions / full", [f"{s.frames_regions} / "
        f"{sum(s.full_frame_reasons.values())}" for s, _ in runs],
        f"offline: {offline_regions}")  # fmt: skip
    row("detector errors", [str(s.detector_errors) for s, _ in runs], "offline: 0")
    offline_accepted = sum(a.accepted for a in offline.fixes)
    row("fixes accepted", [str(sum(a.accepted for a in r.fixes)) for _, r in runs],
        f"offline (regions): {offline_accepted}")  # fmt: skip
    row("fused ATE (m)", [f"{ate_m(r):.3f}" for _, r in runs],
        f"offline: {ate_m(offline):.3f}")  # fmt: skip
    for i, (stats, _) in enumerate(runs):
        if stats.full_frame_reasons:
            print(f"full frames of {labels[i]}: {dict(sorted(stats.full_frame_reasons.items()))}")


if __name__ == "__main__":
    main()
