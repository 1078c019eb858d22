"""Does the wall clock's detection worker hold the interpreter lock against the odometry?

The main thread sleeps 5 ms at a time (the 200 Hz odometry's wait) and measures how late it
wakes (p50 / p99 / max, ms) while a worker thread loops over one piece of the worker's job on a
rendered frame of the default drive (18.5 s in, a tag in view):

- ``nothing``: no worker (the machine's own wake-up noise);
- ``detect``: ``detector.detect(image)``, the AprilTag C library on the full frame;
- ``fixes``: the frame's fix computation (``FiducialFixSource.frame_fixes``: PnP, covariance,
  gates; Python and small numpy calls).

Each with the worker on the main thread's CPU at ``nice +10`` (as ``run_wall`` runs it on one
core) and on the other CPU (two cores: what is left of the lateness is the lock alone).

Run: ``.venv/bin/python benchmarks/bench_worker_lock.py [--seconds 3]``
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Callable

import cv2
import numpy as np

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.fiducial import FiducialFixSource
from tagloc.localize.realtime_worker import lower_thread_priority
from tagloc.sim import render_frames
from tagloc.sim.scenarios import build_scenario
from tagloc.tags import make_detector

SLEEP_S = 0.005


def lateness_ms(seconds: float) -> tuple[float, float, float]:
    late = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        start = time.perf_counter()
        time.sleep(SLEEP_S)
        late.append(time.perf_counter() - start - SLEEP_S)
    ms = np.asarray(late) * 1e3
    p50, p99 = np.percentile(ms, [50.0, 99.0])
    return float(p50), float(p99), float(ms.max())


def with_worker(work: Callable[[], object] | None, cpu: int | None, seconds: float) -> str:
    stop = threading.Event()

    def loop() -> None:
        if cpu is None:
            lower_thread_priority(10)
        else:
            os.sched_setaffinity(threading.get_native_id(), {cpu})
        while not stop.is_set():
            assert work is not None
            work()

    thread = threading.Thread(target=loop, daemon=True)
    if work is not None:
        thread.start()
    p50, p99, worst = lateness_ms(seconds)
    stop.set()
    if work is not None:
        thread.join()
    return f"{p50:6.2f} / {p99:6.2f} / {worst:6.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="per measurement, s")
    args = parser.parse_args()
    cpus = sorted(os.sched_getaffinity(0))
    main_cpu, other = cpus[-1], (cpus[0] if len(cpus) > 1 else None)
    os.sched_setaffinity(0, {main_cpu})
    cv2.setNumThreads(1)
    scenario = build_scenario("default", 1, 20.0)
    drive = scenario.drive
    at = drive.stamps_ns[0] + 18_500_000_000
    stamp = drive.camera_stamps_ns[np.searchsorted(drive.camera_stamps_ns, at)]
    image = next(iter(render_frames(drive, seed=1, stamps_ns=[stamp]))).image
    detector = make_detector("apriltag", "tag36h11")
    detections = tuple(detector.detect(image))
    config = calibrated_config(scenario, scenario_config())
    camera = scenario.world.robot.camera
    source = FiducialFixSource(
        camera.camera_model(), camera.T_base_cam.T_base_cam(), scenario.tag_map,
        family=config.tags.family, gates=config.gates.observation_gates(),
        noise=config.tags.noise, config=config.tags, map_frame=config.frames.map_frame,
    )  # fmt: skip
    start = time.perf_counter()
    n = 0
    while time.perf_counter() - start < 0.5:
        source.frame_fixes(int(stamp), detections, None)
        n += 1
    fix_ms = (time.perf_counter() - start) / n * 1e3
    works: dict[str, Callable[[], object] | None] = {
        "nothing": None,
        "detect (C, full frame)": lambda: detector.detect(image),
        "fixes (Python, numpy)": lambda: source.frame_fixes(int(stamp), detections, None),
    }
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"main thread on CPU {main_cpu}, sleeping {SLEEP_S * 1e3:g} ms at a time; "
          f"{len(detections)} tag(s) in the frame; one fix computation {fix_ms:.2f} ms; "
          f"switch interval {1e3 * sys.getswitchinterval():g} ms; "
          f"load average {load}")  # fmt: skip
    header = f"{'worker loops on':26s} {'one core, nice +10':>24s} {'other core':>24s}"
    print(header + "\n" + "-" * len(header))
    print(f"{'':26s} {'late p50 / p99 / max ms':>24s} {'late p50 / p99 / max ms':>24s}")
    for name, work in works.items():
        same = with_worker(work, None, args.seconds)
        apart = with_worker(work, other, args.seconds) if other is not None else "n/a"
        print(f"{name:26s} {same:>24s} {apart:>24s}")


if __name__ == "__main__":
    main()
