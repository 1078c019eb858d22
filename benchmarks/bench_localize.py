"""End-to-end cost of the localization node on the demo drive, beside the filter's own share.

Run: ``.venv/bin/python benchmarks/bench_localize.py [--seconds 120] [--images 90]``

1. Detection excluded: the default scenario's first ``--seconds`` s (pre-detected corners from
   ``simulate_observations``) through the node on the driver's replay clock
   (:func:`tagloc.localize.driver.run`); every call of the filter's ``predict`` and ``update`` is
   timed on its own. Replay speed = simulated seconds per wall second of the run (the corner
   simulation is timed separately).
2. Detection included: ``--images`` frames rendered with ``render_frames`` (a 3 s stretch with
   tags in view), fed as ``ImageMsg`` through the same node (AprilTag 3 detector); the
   replay speed at 30 Hz is estimated from the per-frame cost plus the odometry rows' cost.
3. CPU share of the filter: everything it does per simulated second of this drive (``predict``
   per 100 Hz odometry row, ``update`` per fix, ``T_map_base_at`` per frame for the fix source's
   prior), and at 200 Hz odometry with one fix per 30 Hz frame (each added ``predict`` at the
   median cost: the 100 ms integration steps do not double; ``update`` and prior at their mean).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from typing import Any

import numpy as np

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.driver import run
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import OutputSink, RunRecorder
from tagloc.messages import ImageMsg, Message, OdometryMsg
from tagloc.sim import render_frames
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags import make_detector

S = 1_000_000_000


def _wrap(obj: Any, name: str, out: list[int]) -> None:
    """Time every call of ``obj.name`` into ``out`` (ns)."""
    inner: Callable[..., Any] = getattr(obj, name)

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter_ns()
        try:
            return inner(*args, **kwargs)
        finally:
            out.append(time.perf_counter_ns() - t0)

    setattr(obj, name, timed)


def _node(
    source: ScenarioSource, timings: dict[str, list[int]], sinks: Sequence[OutputSink]
) -> LocalizerNode:
    """The scenario's node with its sinks, each method named in ``timings`` of its filter (or,
    for ``detect``, of its detector) timed into the list."""
    scenario = source.scenario
    config = calibrated_config(scenario, scenario_config())
    detector = make_detector(config.tags.backend, config.tags.family)
    node = LocalizerNode(scenario.tag_map, config, sinks, frame_truth=source.frame_truth,
                         detector=detector)  # fmt: skip
    for name, out in timings.items():
        _wrap(detector if name == "detect" else node.filter, name, out)
    return node


def _us(samples: list[int]) -> tuple[float, float, float]:
    if not samples:
        return (float("nan"),) * 3
    p90 = float(np.percentile(samples, 90))
    return statistics.median(samples) / 1e3, p90 / 1e3, statistics.fmean(samples) / 1e3


def corners_replay(seconds: float) -> dict[str, Any]:
    """Part 1: pre-detected corners."""
    t0 = time.perf_counter()
    scenario = build_scenario("default", seed=0, duration_s=seconds)
    source = ScenarioSource(scenario)  # simulates the corners of every frame
    t_sim = time.perf_counter() - t0
    predict: list[int] = []
    update: list[int] = []
    prior: list[int] = []
    timings = {"predict": predict, "update": update, "T_map_base_at": prior}
    recorder = RunRecorder()
    t0 = time.perf_counter()
    run(partial(_node, source, timings), source, [recorder])
    t_run = time.perf_counter() - t0
    run_ = recorder.run({})
    sim_s = (run_.stamps_ns[-1] - run_.stamps_ns[0]) / S
    return {
        "sim_s": sim_s, "t_sim": t_sim, "t_run": t_run, "predict": predict, "update": update,
        "prior": prior, "rows": len(run_.stamps_ns), "frames": len(run_.frames),
    }  # fmt: skip


def _image_stream(source: ScenarioSource, frames: list[Any]) -> Iterator[tuple[str, Message]]:
    """Odometry of the stretch and the rendered images, in stamp order."""
    drive, t = source.scenario.drive, source.t
    lo, hi = frames[0].stamp_ns - S // 2, frames[-1].stamp_ns + S // 10
    pending = iter(frames)
    frame = next(pending, None)
    for topic, msg in source:
        if not isinstance(msg, OdometryMsg) and topic not in (t.camera_info, "/tf_static"):
            continue
        if isinstance(msg, OdometryMsg) and not lo <= msg.stamp_ns <= hi:
            continue
        while frame is not None and isinstance(msg, OdometryMsg) and frame.stamp_ns <= msg.stamp_ns:
            yield t.image, ImageMsg(frame.stamp_ns, "camera_optical", frame.image, "mono8")
            frame = next(pending, None)
        yield topic, msg
    del drive


def images_replay(n_images: int) -> dict[str, Any]:
    """Part 2: rendered images through the detector, the same node."""
    scenario = build_scenario("default", seed=0, duration_s=60.0)
    source = ScenarioSource(scenario)
    cams = scenario.camera_stamps_ns
    start = int(np.searchsorted(cams, cams[0] + 38 * S))  # tags 4 and 5 in view
    stamps = cams[start : start + n_images]
    t0 = time.perf_counter()
    frames = list(render_frames(scenario.drive, stamps_ns=stamps))
    t_render = time.perf_counter() - t0
    detect: list[int] = []
    stream = list(_image_stream(source, frames))
    make_detector("apriltag", "tag36h11").detect(frames[0].image)  # warm up
    recorder = RunRecorder()
    t0 = time.perf_counter()
    run(partial(_node, source, {"detect": detect}), stream, [recorder])
    t_run = time.perf_counter() - t0
    n_odom = sum(isinstance(m, OdometryMsg) for _, m in stream)
    return {
        "t_render": t_render, "t_run": t_run, "detect": detect, "n_odom": n_odom,
        "n_images": len(frames), "accepted": sum(a.accepted for a in recorder.fixes),
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--images", type=int, default=90)
    args = parser.parse_args()
    c = corners_replay(args.seconds)
    im = images_replay(args.images)
    p_med, p_90, p_mean = _us(c["predict"])
    u_med, u_90, u_mean = _us(c["update"])
    d_med, d_90, d_mean = _us(im["detect"])
    # per simulated second at 30 Hz with detection: images' node time scaled to 30 frames
    # plus 100 Hz odometry rows (the corner replay's time per row, frames excluded)
    per_frame_s = im["t_run"] / max(im["n_images"], 1)
    row_s = (c["t_run"] - sum(c["update"]) / 1e9) / max(c["rows"], 1)
    speed_images = 1.0 / (30 * per_frame_s + 100 * row_s)
    # the filter's own work per simulated second on this drive (100 Hz odometry, 30 Hz camera,
    # all its fixes, the fix source's prior), and the same with 200 Hz odometry: twice the
    # predict calls, the added ones at the median (the 0.1 s integration steps do not double)
    work_ns = sum(c["predict"]) + sum(c["update"]) + sum(c["prior"])
    share = work_ns / 1e9 / c["sim_s"]
    predict_200 = (sum(c["predict"]) / 1e9 + c["rows"] * p_med / 1e6) / c["sim_s"]
    prior_mean = statistics.fmean(c["prior"]) / 1e9 if c["prior"] else 0.0
    share_200 = predict_200 + 30 * (u_mean / 1e6 + prior_mean)  # one fix per frame at 30 Hz
    fixes_per_s = len(c["update"]) / c["sim_s"]
    print(f"default scenario, first {c['sim_s']:.0f} s: {c['rows']} odometry rows, "
          f"{c['frames']} frames")  # fmt: skip
    print(f"{'quantity':<58} {'median':>10} {'p90':>10} {'mean':>10}")
    print("-" * 92)
    for name, (m, p, mu) in (
        ("filter predict (per odometry row)", (p_med, p_90, p_mean)),
        ("filter update (per fix)", (u_med, u_90, u_mean)),
        ("AprilTag 3 detection (1280x720, per image)", (d_med, d_90, d_mean)),
    ):
        print(f"{name:<58} {m:>7.1f} us {p:>7.1f} us {mu:>7.1f} us")
    print("-" * 92)
    rows = [
        ("corner simulation (simulate_observations), x real time", c["sim_s"] / c["t_sim"]),
        ("replay, detection excluded (node), x real time", c["sim_s"] / c["t_run"]),
        ("replay, detection included (30 Hz images), x real time", speed_images),
        (f"filter CPU share, this drive ({fixes_per_s:.0f} fixes/s), % of a core", 100 * share),
        ("filter CPU share, 200 Hz odometry + 30 fixes/s, % of a core", 100 * share_200),
    ]
    for name, value in rows:
        print(f"{name:<58} {value:>10.2f}")
    print(f"images: {im['n_images']} rendered in {im['t_render']:.1f} s, {im['accepted']} fixes "
          f"accepted from them")  # fmt: skip


if __name__ == "__main__":
    main()
