"""Memory of the streaming node over drives of different lengths: it must not grow with duration.

The simulated default drive (30 Hz tag detections, 100 Hz odometry) is built first (the source
holds the whole drive; that is the simulator's memory, not the node's), then fed through the
node with a sink that only counts. Reported per drive length: the node's traced allocations
(tracemalloc: peak and at the end, above the level before the first message) and the process's
resident set growth (VmRSS, sampled every 10 s of stream time). Reference: the 100 s drive.

    python benchmarks/bench_node_memory.py [--lengths 100 700]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import NodeOutput
from tagloc.sim.scenarios import ScenarioSource, build_scenario, calibrated_config, scenario_config

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
    return float("nan")


def measure(duration_s: float) -> dict[str, float]:
    scenario = build_scenario("default", seed=0, duration_s=duration_s)
    source = ScenarioSource(scenario)
    config = calibrated_config(scenario, scenario_config())
    sink = CountingSink()
    node = LocalizerNode(scenario.tag_map, config, [sink], frame_truth=source.frame_truth)
    rss0 = rss_mb()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    rss_peak, next_sample, t0 = rss0, 0, time.perf_counter()
    for topic, msg in source:
        node.feed(topic, msg)
        if msg.stamp_ns >= next_sample:
            rss_peak, next_sample = max(rss_peak, rss_mb()), msg.stamp_ns + 10 * S
    node.finish()
    now, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "duration_s": float(scenario.drive.stamps_ns[-1] - scenario.drive.stamps_ns[0]) / S,
        "traced_peak_mb": (peak - base) / 2**20, "traced_end_mb": (now - base) / 2**20,
        "rss_growth_mb": max(rss_peak, rss_mb()) - rss0, "outputs": sink.n,
        "wall_s": time.perf_counter() - t0,
    }  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lengths", type=float, nargs="+", default=[100.0, 700.0])
    args = parser.parse_args()
    rows = [measure(d) for d in args.lengths]
    ref = rows[0]["traced_peak_mb"]
    print(f"{'drive (s)':>10} | {'traced peak MB':>14} | {'traced end MB':>13} | "
          f"{'RSS growth MB':>13} | {'outputs':>8} | {'wall s':>7} | peak / first")  # fmt: skip
    for r in rows:
        print(
            f"{r['duration_s']:10.1f} | {r['traced_peak_mb']:14.2f} | {r['traced_end_mb']:13.2f} | "
            f"{r['rss_growth_mb']:13.1f} | {r['outputs']:8d} | {r['wall_s']:7.1f} | "
            f"{r['traced_peak_mb'] / ref:.2f}x"
        )


if __name__ == "__main__":
    main()
