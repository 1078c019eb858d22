"""Soak: an hour of simulated 30 Hz tag detections and 200 Hz odometry through the live node.

The built-in office route is driven lap after lap (legged odometry drifting throughout) and fed
to the streaming node with a sink that only counts, as a robot would run it for an hour. Every
5 minutes of stream time the table prints the node's memory (tracemalloc: traced now and peak
since the last row, above the level before the first message; the process's VmRSS) and the
latency of ``node.feed`` (p50 / p99 / max, ms) for odometry samples and for camera frames, so
growth and slow-down show as a trend. The last line compares memory at the end with the row
at 10 minutes (flat: within 10 %). A shorter check of the same: ``--minutes 12 --every 1.667``
(rows at 100 s ... 700 s of the drive).

With ``--cli-sinks`` the node runs with the sinks ``tagloc localize`` attaches (the run's
files in a temporary directory, the mounting check's recorder, the report), and a first pass of
the same stream through the node alone (a counting sink) gives the reference rows, so the
sinks' share shows against the node's in the same process; the last column is what the
mounting check's recorder holds.

    python benchmarks/bench_soak.py [--minutes 12] [--every 1.667] [--cli-sinks]
    python benchmarks/bench_soak.py --minutes 60 --every 5 --cli-sinks   # the hour
"""

from __future__ import annotations

import argparse
import math
import time
import tracemalloc
from pathlib import Path

import numpy as np

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import NodeOutput, OutputSink
from tagloc.messages import OdometryMsg, TagDetectionsMsg
from tagloc.sim import load_default_world
from tagloc.sim.drive import simulate_drive
from tagloc.sim.observations import ObservationConfig
from tagloc.sim.scenarios import Scenario, ScenarioSource, tag_map_from_world, truncate_drive

S = 1_000_000_000


class CountingSink:
    def __init__(self) -> None:
        self.n = 0

    def write(self, output: NodeOutput) -> None:
        self.n += 1


def rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return math.nan


def soak_scenario(minutes: float) -> Scenario:
    world = load_default_world()
    lap_s = 700.0
    laps = max(1, math.ceil(minutes * 60 / lap_s))
    robot = world.robot.model_copy(update={"odom_rate_hz": 200.0})
    world = world.model_copy(
        update={"route": world.route.model_copy(update={"repeat": laps}), "robot": robot}
    )
    drive = simulate_drive(world, seed=0)
    drive = truncate_drive(drive, float(minutes * 60))
    return Scenario(
        name="default", drive=drive, observation=ObservationConfig(), world=world,
        tag_map=tag_map_from_world(world), camera_stamps_ns=drive.camera_stamps_ns,
        kidnaps_ns=[],
    )  # fmt: skip


def ms(samples: list[float]) -> str:
    if not samples:
        return "-"
    p50, p99 = np.percentile(samples, [50, 99])
    return f"{p50:.2f} / {p99:.2f} / {max(samples):.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=12.0, help="60: the hour")
    parser.add_argument("--every", type=float, default=5.0 / 3.0, help="minutes per row")
    parser.add_argument("--cli-sinks", action="store_true",
                        help="also run with tagloc localize's sinks (after the node alone)")
    parser.add_argument(
        "--rss-only", action="store_true",
        help="no tracemalloc (3-4x faster): the traced columns read 0, RSS is the measure",
    )  # fmt: skip
    args = parser.parse_args()
    t_build = time.perf_counter()
    scenario = soak_scenario(args.minutes)
    source = ScenarioSource(scenario)
    build_s = time.perf_counter() - t_build
    config = calibrated_config(scenario, scenario_config())
    n_odom, n_frames = len(scenario.drive.stamps_ns), source.n_frames
    span_min = (scenario.drive.stamps_ns[-1] - scenario.drive.stamps_ns[0]) / S / 60
    print(f"{span_min:.1f} min of stream (asked: {args.minutes:g}; a simulated drive holds at "
          f"most 500 000 odometry samples): {n_odom} odometry samples at 200 Hz, {n_frames} "
          f"camera frames at 30 Hz (built in {build_s:.0f} s)")  # fmt: skip
    passes = [("node alone", None)] + ([("with tagloc localize's sinks", True)]
                                        if args.cli_sinks else [])  # fmt: skip
    for title, cli in passes:
        print(f"\n{title}")
        soak(scenario, source, config, args, cli is not None)


def soak(scenario: Scenario, source: ScenarioSource, config: LocalizerConfig,
         args: argparse.Namespace, cli: bool) -> None:  # fmt: skip
    """One pass of the stream through a node (module docstring), printing the rows."""
    import tempfile

    from tagloc.eval.run_report import RunReportSink
    from tagloc.io.node_sinks import RunFilesSink
    from tagloc.localize.extrinsic_rig import ExtrinsicRecorder

    tmp = tempfile.TemporaryDirectory()
    recorder = ExtrinsicRecorder()
    sinks: list[OutputSink] = [CountingSink()]
    if cli:
        sinks += [RunFilesSink(Path(tmp.name), "map", bag=False), recorder,
                  RunReportSink("soak")]  # fmt: skip
    node = LocalizerNode(scenario.tag_map, config, sinks, frame_truth=source.frame_truth)
    header = (f"{'minute':>6} | {'traced MB':>9} | {'peak MB':>8} | {'RSS MB':>7} | "
              f"{'odometry feed ms p50/p99/max':>28} | {'frame feed ms p50/p99/max':>26} | "
              "wall s | recorder fixes / odometry")  # fmt: skip
    print(header)
    print("-" * len(header))
    t0 = int(scenario.drive.stamps_ns[0])
    every_ns = round(args.every * 60 * S)
    if not args.rss_only:
        tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    rss_rows: list[tuple[float, float]] = []
    next_row = t0 + every_ns
    odo: list[float] = []
    frm: list[float] = []
    rows: list[tuple[float, float]] = []
    wall0 = time.perf_counter()
    for topic, msg in source:
        start = time.perf_counter()
        node.feed(topic, msg)
        dt = (time.perf_counter() - start) * 1e3
        if isinstance(msg, OdometryMsg):
            odo.append(dt)
        elif isinstance(msg, TagDetectionsMsg):
            frm.append(dt)
        if msg.stamp_ns >= next_row:
            now, peak = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            minute = (msg.stamp_ns - t0) / S / 60
            traced = (now - base) / 2**20
            rows.append((minute, traced))
            rss_rows.append((minute, rss_mb()))
            print(f"{minute:6.1f} | {traced:9.2f} | {(peak - base) / 2**20:8.2f} | "
                  f"{rss_mb():7.1f} | {ms(odo):>28} | {ms(frm):>26} | "
                  f"{time.perf_counter() - wall0:.0f} | {recorder.held['fixes']} / "
                  f"{recorder.held['odometry']}", flush=True)  # fmt: skip
            odo, frm = [], []
            next_row += every_ns
    node.finish()
    tracemalloc.stop()
    rss10 = [r for m, r in rss_rows if m >= 10.0]
    if rss10:
        print(f"RSS at the end / at 10 min: {rss_rows[-1][1]:.1f} / {rss10[0]:.1f} MB "
              f"= {rss_rows[-1][1] / rss10[0]:.3f}")  # fmt: skip
    at10 = [t for m, t in rows if m >= 10.0]
    if at10 and rows and not args.rss_only:
        print(f"traced memory at the end / at 10 min: {rows[-1][1]:.2f} / {at10[0]:.2f} MB "
              f"= {rows[-1][1] / at10[0]:.3f} (flat: within 10 %)")  # fmt: skip

    tmp.cleanup()


if __name__ == "__main__":
    main()
