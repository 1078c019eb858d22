"""Read throughput of ``tagloc.io.BagSource`` beside rosbags' bare ``AnyReader`` loop.

Run: ``.venv/bin/python benchmarks/bench_io.py``. Two inputs:

- the dupont drive (``../shared/data/dupont/tag_detections.bag.bz2``, ROS 1, 13,500 messages of
  tag-corner arrays and odometry; decompressed once beforehand, not timed);
- a 100,000-message MCAP of ``nav_msgs/Odometry`` written by ``BagSink`` (write time reported).

Each read row is the median over repeats of a full pass. The reference deserializes every message
with ``AnyReader.deserialize`` and does nothing else; tagloc also builds and validates the records
(SE3 from the quaternion, covariance to the body frame, tag detections with their checks) and
checks per-topic stamp order.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from tagloc.geometry import SE3
from tagloc.io import BagSink, BagSource, OdometryMsg, open_bag

REPEATS = 3
DUPONT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "dupont"


def _median_seconds(fn: Callable[[], int]) -> tuple[float, int]:
    """Median wall time over ``REPEATS`` calls, and what the call returned (a count)."""
    count = fn()
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), count


def _raw_anyreader(path: Path) -> Callable[[], int]:
    from rosbags.highlevel import AnyReader

    def run() -> int:
        count = 0
        with AnyReader([path]) as reader:
            for conn, _, raw in reader.messages():
                reader.deserialize(raw, conn.msgtype)
                count += 1
        return count

    return run


def _tagloc(source: BagSource) -> Callable[[], int]:
    def run() -> int:
        return sum(1 for _ in source)

    return run


def _write_odometry(path: Path, n: int) -> float:
    rng = np.random.default_rng(0)
    poses = SE3.random(rng, 1000, translation_scale=20.0)
    cov = np.diag([1e-4, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5])
    twist = np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.1])
    records = [OdometryMsg(0, "odom", "base_link", poses[i], cov, twist) for i in range(1000)]
    start = time.perf_counter()
    with BagSink(path, "mcap") as sink:
        for i in range(n):
            r = records[i % 1000]
            msg = OdometryMsg(i * 10_000_000, "odom", "base_link", r.T_parent_child, r.cov, r.twist)
            sink.write("/odom", msg)
    return time.perf_counter() - start


def main() -> None:
    rows: list[tuple[str, int, float, float]] = []
    if (DUPONT / "tag_detections.bag.bz2").is_file():
        bag = DUPONT / "tag_detections.bag.bz2"
        source = BagSource(bag, corner_order="bl_br_tr_tl", default_family="tag36h11")
        t_tagloc, n = _median_seconds(_tagloc(source))
        t_raw, _ = _median_seconds(_raw_anyreader(open_bag(bag)))
        rows.append(("dupont ROS 1 bag (tags + odometry)", n, n / t_tagloc, n / t_raw))
    else:
        print(f"(dupont bag not found under {DUPONT.resolve()}; row skipped)")

    with tempfile.TemporaryDirectory() as tmp:
        mcap = Path(tmp) / "odom.mcap"
        n = 100_000
        t_write = _write_odometry(mcap, n)
        t_tagloc, count = _median_seconds(_tagloc(BagSource(mcap)))
        t_raw, _ = _median_seconds(_raw_anyreader(mcap))
        rows.append(("MCAP, 100k nav_msgs/Odometry", count, count / t_tagloc, count / t_raw))

    print(
        f"{'input':<38} {'messages':>9} {'tagloc msg/s':>13} {'AnyReader msg/s':>16} {'ratio':>6}"
    )
    print("-" * 86)
    for name, count, tagloc_rate, raw_rate in rows:
        print(
            f"{name:<38} {count:>9,} {tagloc_rate:>13,.0f} {raw_rate:>16,.0f} "
            f"{tagloc_rate / raw_rate:>6.2f}"
        )
    print(f"\nwrite (BagSink, MCAP, 100k odometry): {n / t_write:,.0f} msg/s")


if __name__ == "__main__":
    main()
