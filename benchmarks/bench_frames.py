"""Per-call cost of ``tagloc.frames.TransformBuffer`` beside raw numpy / scipy references.

Run: ``.venv/bin/python benchmarks/bench_frames.py``. Each row is the median over repeats of the
mean time per call (per stamp for batched rows). The tree is the robot's: ``map -> odom``
(dynamic, 10 Hz) ``-> base_link`` (dynamic, 200 Hz) ``-> camera_mount -> camera_optical``
(static), 10 s window, full; lookups at random stamps inside it.
"""

from __future__ import annotations

import itertools
import statistics
import timeit
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3, SO3

S, MS = 1_000_000_000, 1_000_000
REPEATS = 7


def _poses(rng: np.random.Generator, n: int) -> SE3:
    return SE3.from_quat(Rotation.random(n, random_state=rng).as_quat(), rng.normal(size=(n, 3)))


def _per_call(fn: Callable[[], object], number: int, per: int = 1) -> float:
    """Median over ``REPEATS`` of the mean seconds per call (divided by ``per``)."""
    fn()  # warm the caches (the path cache, scipy's imports)
    times = timeit.repeat(fn, number=number, repeat=REPEATS)
    return statistics.median(times) / number / per


def main() -> None:
    rng = np.random.default_rng(0)
    s_map = np.arange(0, 10 * S + 1, 100 * MS, dtype=np.int64)
    s_odom = np.arange(0, 10 * S + 1, 5 * MS, dtype=np.int64)
    T_map_odom, T_odom_base = _poses(rng, len(s_map)), _poses(rng, len(s_odom))
    T_base_mount, T_mount_optical = _poses(rng, 1)[0], _poses(rng, 1)[0]
    buffer = TransformBuffer()
    buffer.set_transforms("map", "odom", s_map, T_map_odom)
    buffer.set_transforms("odom", "base_link", s_odom, T_odom_base)
    buffer.set_static("base_link", "camera_mount", T_base_mount)
    buffer.set_static("camera_mount", "camera_optical", T_mount_optical)

    query = rng.integers(1 * S, 9 * S, size=4096)
    many, many_f = np.sort(query), np.sort(query).astype(np.float64)
    stamps = itertools.cycle(query.tolist())

    # Inserts: a 1 kHz stream into a full 10 s window (one eviction per insert).
    stream = TransformBuffer()
    pool = itertools.cycle([T_odom_base[i] for i in range(64)])
    clock = itertools.count(0, MS)
    for _ in range(10_001):
        stream.set_transform("odom", "base_link", next(clock), next(pool))
    batch_poses = _poses(rng, 1000)

    def insert_batch() -> None:
        start = next(clock)
        for _ in range(999):
            next(clock)
        batch = np.arange(start, start + 1000 * MS, MS, dtype=np.int64)
        stream.set_transforms("odom", "base_link", batch, batch_poses)

    # References: the same arithmetic in raw numpy / scipy, no frame bookkeeping.
    M = [
        T_map_odom[3].as_matrix(),
        T_odom_base[7].as_matrix(),
        T_base_mount.as_matrix(),
        T_mount_optical.as_matrix(),
    ]
    slerp = Slerp(s_odom.astype(np.float64), Rotation.from_quat(T_odom_base.as_quat()))
    R, t = M[0][:3, :3].copy(), M[0][:3, 3].copy()

    # (name, call, calls per repeat, samples or stamps per call, unit)
    cases: list[tuple[str, Callable[[], object], int, int, str]] = [
        ("set_transform (1 kHz stream, full window)",
         lambda: stream.set_transform("odom", "base_link", next(clock), next(pool)),
         20_000, 1, "per call"),
        ("set_transforms (batches of 1000)", insert_batch, 50, 1000, "per sample"),
        ("lookup, 1 dynamic edge",
         lambda: buffer.lookup("odom", "base_link", next(stamps)), 20_000, 1, "per call"),
        ("lookup, 4-edge chain (2 dyn + 2 static)",
         lambda: buffer.lookup("map", "camera_optical", next(stamps)), 20_000, 1, "per call"),
        ("lookup, same chain inverted (optical <- map)",
         lambda: buffer.lookup("camera_optical", "map", next(stamps)), 20_000, 1, "per call"),
        ("can_transform, 4-edge chain",
         lambda: buffer.can_transform("map", "camera_optical", next(stamps)), 20_000, 1,
         "per call"),
        ("lookup_many, 4-edge chain, N=4096",
         lambda: buffer.lookup_many("map", "camera_optical", many), 20, len(many), "per stamp"),
        ("ref: numpy, compose four 4x4", lambda: M[0] @ M[1] @ M[2] @ M[3], 50_000, 1,
         "per call"),
        ("ref: scipy Slerp, 1 edge, 1 stamp (rotation)",
         lambda: slerp(float(next(stamps))).as_matrix(), 5_000, 1, "per call"),
        ("ref: scipy Slerp, 1 edge, N=4096 (rotation)",
         lambda: slerp(many_f).as_matrix(), 20, len(many), "per stamp"),
        ("ref: SE3(rotation=SO3.from_matrix(R), t)",
         lambda: SE3(rotation=SO3.from_matrix(R), translation=t), 20_000, 1, "per call"),
    ]  # fmt: skip
    rows = [(name, _per_call(fn, number, per), unit) for name, fn, number, per, unit in cases]

    print(f"{'operation':<46} {'time':>10}  unit")
    print("-" * 70)
    for name, seconds, unit in rows:
        print(f"{name:<46} {seconds * 1e6:>7.2f} us  {unit}")


if __name__ == "__main__":
    main()
