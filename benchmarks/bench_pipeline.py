"""Per camera frame, the node's whole tag pipeline with full-frame detection and with predicted
regions, on one stream of rendered images; and the filter's CPU share.

Stream: the first ``--seconds`` of a simulated scenario (default: the office route, legged
odometry, seed 1) with the robot camera's 30 Hz 1280x720 frames rendered by the simulator
(:func:`tagloc.sim.render_frames`, default effects) in place of its pre-detected corners; the
lidar is off. Two :class:`~tagloc.localize.node.LocalizerNode` s, one with ``tags.roi.enabled``
false (the reference) and one with it true, are fed each message in turn, so both see every image
under the same machine load; each image is rendered once and dropped after both saw it.

Timed per camera frame, per node, with ``time.perf_counter_ns``: the tag source's ``arrive``
(detection: the full frame, or the prediction, the regions and the detection in them) plus its
``fixes`` (PnP with both IPPE branches, covariance, gates) for that frame; the filter's update is
not included. The table gives the median and p90 over every frame and over the frames once the
reference's filter is initialized (before it, both detect the full frame), the tags detected,
fixes accepted and the fused position RMS against the simulator's truth, and the region
detector's counts (frames in regions, the full-frame reasons).

``filter_cpu_share``: the fraction of one core that ``MapOdomFilter`` costs in the eager mode
(``predict`` at each of 200 odometry samples/s plus ``update`` of 30 fixes/s), by thread CPU time
(:func:`bench_filter.stream_cpu_ns`: the 20 s drive streamed with the filter, less the same
stream with the odometry inserts alone, best of 3), so time other processes hold the core does
not count as the filter's.

One core: the process is pinned to one CPU, ``cv2.setNumThreads(1)``, AprilTag ``nthreads=1``.

Run: ``.venv/bin/python benchmarks/bench_pipeline.py [--seconds 60] [--scenario kidnap] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from bench_detect import pin_one_core  # the same pinning as the detector benchmark
from bench_filter import stream_cpu_ns
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.localize.source_tags import TagSource
from tagloc.messages import ImageMsg, Message, TagDetectionsMsg
from tagloc.sim import render_frames
from tagloc.sim.scenario import Scenario
from tagloc.sim.scenario_source import CAMERA_FRAME, ScenarioSource
from tagloc.sim.scenarios import build_scenario

SEED = 1
IMAGE_TOPIC = "/camera/image"


@dataclass
class FrameTimer:
    """Per frame stamp: ns spent in the tag source's ``arrive`` (images: detection) and in its
    ``fixes`` (PnP, covariance, gates)."""

    detect_ns: dict[int, int] = field(default_factory=dict)
    rest_ns: dict[int, int] = field(default_factory=dict)

    @property
    def ns(self) -> dict[int, int]:
        """Both, per frame."""
        return {s: v + self.rest_ns.get(s, 0) for s, v in self.detect_ns.items()}

    def wrap(self, source: TagSource) -> None:
        arrive, fixes = source.arrive, source.fixes

        def timed_arrive(topic: str, msg: Message) -> Any:
            start = time.perf_counter_ns()
            out = arrive(topic, msg)
            if isinstance(msg, ImageMsg):
                self.detect_ns[msg.stamp_ns] = time.perf_counter_ns() - start
            return out

        def timed_fixes(payload: object, context: Any) -> Any:
            start = time.perf_counter_ns()
            out = fixes(payload, context)
            stamp = int(payload.stamp_ns)  # type: ignore[attr-defined]
            self.rest_ns[stamp] = time.perf_counter_ns() - start
            return out

        source.arrive = timed_arrive  # type: ignore[method-assign]
        source.fixes = timed_fixes  # type: ignore[method-assign]


def image_stream(scenario: Scenario) -> Iterator[tuple[str, Message]]:
    """The scenario's stream (lidar off) with each camera frame's corners replaced by its image."""
    source = ScenarioSource(scenario, lidar=False)
    frames = render_frames(scenario.drive, seed=SEED, stamps_ns=scenario.camera_stamps_ns)
    for topic, msg in source:
        if not isinstance(msg, TagDetectionsMsg):
            yield topic, msg
            continue
        frame = next(frames)
        while frame.stamp_ns < msg.stamp_ns:  # a frame the stream's faults dropped
            frame = next(frames)
        yield IMAGE_TOPIC, ImageMsg(msg.stamp_ns, CAMERA_FRAME, frame.image, "mono8")


def configs(
    scenario: Scenario, alarm_frames: int | None = None
) -> tuple[LocalizerConfig, LocalizerConfig]:
    """The scenario's calibrated configuration, lidar off: full frame, and predicted regions
    (``alarm_frames``: their ``full_frames_after_alarm``, default the configuration's)."""
    config = calibrated_config(scenario, scenario_config())
    config = config.model_copy(update={"lidar": config.lidar.model_copy(update={"enabled": False})})
    tags = config.tags
    off = tags.model_copy(update={"roi": tags.roi.model_copy(update={"enabled": False})})
    update: dict[str, Any] = {"enabled": True}
    if alarm_frames is not None:
        update["full_frames_after_alarm"] = alarm_frames
    on = tags.model_copy(update={"roi": tags.roi.model_copy(update=update)})
    return config.model_copy(update={"tags": off}), config.model_copy(update={"tags": on})


def position_rms_m(run: LocalizationRun) -> float:
    """RMS of the fused position error against the simulator's truth, m."""
    assert run.T_map_base_truth is not None
    d = np.asarray(run.T_map_base.translation) - run.T_map_base_truth.translation
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def filter_cpu_share(seconds: float = 20.0, repeats: int = 3) -> float:
    """Fraction of one core: eager ``predict`` at 200 Hz + ``update`` at 30 Hz, by thread CPU
    time (module docstring)."""
    both = min(stream_cpu_ns(seconds, False, True) for _ in range(repeats))
    inserts = min(stream_cpu_ns(seconds, False, False) for _ in range(repeats))
    return (both - inserts) / seconds / 1e9


@dataclass
class Result:
    run: LocalizationRun
    timer: FrameTimer

    def ms(self, stamps: list[int] | None = None, part: str = "") -> np.ndarray:
        """Per frame ms: the pipeline, or ``part`` ``"detect"`` / ``"rest"``."""
        ns = getattr(self.timer, f"{part}_ns") if part else self.timer.ns
        keys = sorted(ns) if stamps is None else [s for s in stamps if s in ns]
        return np.array([ns[s] / 1e6 for s in keys])


def measure(scenario: Scenario, alarm_frames: int | None = None) -> tuple[Result, Result]:
    """Both nodes fed the one stream in turn (module docstring)."""
    nodes, results = [], []
    for config in configs(scenario, alarm_frames):
        recorder, timer = RunRecorder(), FrameTimer()
        node = LocalizerNode(scenario.tag_map, config, [recorder])
        (tags,) = [s for s in node.fix_sources if isinstance(s, TagSource)]
        timer.wrap(tags)
        nodes.append((node, recorder))
        results.append(timer)
    for topic, msg in image_stream(scenario):
        for node, _ in nodes:
            node.feed(topic, msg)
    out = []
    for (node, recorder), timer in zip(nodes, results, strict=True):
        node.finish()
        out.append(Result(recorder.run(node.metadata()), timer))
    return out[0], out[1]


def summary(full: Result, roi: Result) -> dict[str, Any]:
    """The JSON object (module docstring) and the table's numbers."""
    ref = full.run
    t_init = ref.stamps_ns[np.argmax(ref.initialized)] if ref.initialized.any() else None
    tracked = [s for s in sorted(full.timer.ns) if t_init is not None and s >= t_init]
    detected = [sum(f.n_detections for f in r.run.frames) for r in (full, roi)]
    accepted = [sum(a.accepted for a in r.run.fixes) for r in (full, roi)]
    out: dict[str, Any] = {
        "full_frame_ms": float(np.median(full.ms())), "roi_ms": float(np.median(roi.ms())),
        "detected_full": detected[0], "detected_roi": detected[1],
        "accepted_full": accepted[0], "accepted_roi": accepted[1],
        "ate_full_m": position_rms_m(full.run), "ate_roi_m": position_rms_m(roi.run),
        "frames": len(full.timer.ns), "frames_tracking": len(tracked),
    }  # fmt: skip
    if tracked:
        out["full_frame_tracking_ms"] = float(np.median(full.ms(tracked)))
        out["roi_tracking_ms"] = float(np.median(roi.ms(tracked)))
    out["regions"] = roi.run.metadata.get("regions", {})
    per_tag = [Counter(i for a in r.run.fixes for i in a.tag_ids) for r in (full, roi)]
    out["tag_observations_lost"] = {
        str(i): per_tag[0][i] - per_tag[1][i] for i in sorted(per_tag[0] | per_tag[1])
        if per_tag[0][i] != per_tag[1][i]
    }  # fmt: skip
    return out


def print_table(s: dict[str, Any], full: Result, roi: Result, header: str) -> None:
    print(header)
    head = f"{'measure':44s} {'full frame (ref)':>18s} {'regions':>12s} {'ratio':>7s}"
    print(head)
    print("-" * len(head))

    def row(label: str, a: float, b: float, fmt: str = ".2f") -> None:
        ratio = f"{b / a:.2f}x" if a else "-"
        print(f"{label:44s} {a:>18{fmt}} {b:>12{fmt}} {ratio:>7s}")

    row("pipeline ms per frame, median (all frames)", s["full_frame_ms"], s["roi_ms"])
    row("  p90", *(float(np.percentile(r.ms(), 90)) for r in (full, roi)))
    for part, label in (("detect", "detection"), ("rest", "PnP + covariance + gates")):
        row(f"  of which {label}, median", *(float(np.median(r.ms(part=part)))
                                              for r in (full, roi)))  # fmt: skip
    if "roi_tracking_ms" in s:
        row(f"  median once tracking ({s['frames_tracking']} frames)",
            s["full_frame_tracking_ms"], s["roi_tracking_ms"])  # fmt: skip
    row("tags detected over the drive", s["detected_full"], s["detected_roi"], "d")
    row("fixes accepted", s["accepted_full"], s["accepted_roi"], "d")
    row("fused position RMS vs truth (m)", s["ate_full_m"], s["ate_roi_m"], ".4f")
    regions = s["regions"]
    if regions:
        print(f"regions: {regions['frames_regions']} frames in regions "
              f"(mean area {100 * (regions['mean_region_area_fraction'] or 0):.1f} % of the "
              f"frame), {regions['frames_full']} full frames {regions['full_frame_reasons']}, "
              f"tags missed {regions['tags_missed']}")  # fmt: skip
    print(f"tag observations (fixes and refusals) full frame minus regions, by tag: "
          f"{s['tag_observations_lost'] or 'none'}")  # fmt: skip
    print(f"filter CPU share (eager predict 200 Hz + update 30 Hz): "
          f"{100 * s['filter_cpu_share']:.3f} % of one core")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="stretch of the drive, s")
    parser.add_argument("--scenario", default="default", help="a simulator scenario's name")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--alarm-frames", type=int, default=None,
                        help="tags.roi.full_frames_after_alarm of the regions' node")  # fmt: skip
    args = parser.parse_args()
    pinned = pin_one_core()
    cv2.setNumThreads(1)
    scenario = build_scenario(args.scenario, SEED, args.seconds)
    start = time.perf_counter()
    full, roi = measure(scenario, args.alarm_frames)
    wall_s = time.perf_counter() - start
    s = summary(full, roi)
    s["filter_cpu_share"] = filter_cpu_share()
    if args.json:
        print(json.dumps(s))
        return
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    alarm = "" if args.alarm_frames is None else f", full_frames_after_alarm {args.alarm_frames}"
    print_table(s, full, roi,
                f"scenario {args.scenario}{alarm}, first {args.seconds:g} s, seed {SEED}: "
                f"{s['frames']} images 1280x720 at 30 Hz, both nodes on each ({wall_s:.0f} s "
                f"wall with rendering); AprilTag nthreads=1, {pinned}; load {load}")  # fmt: skip


if __name__ == "__main__":
    main()
