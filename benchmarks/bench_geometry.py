"""Benchmark tagloc.geometry.SE3 against raw numpy and GTSAM, in the same run.

Run: ``.venv/bin/python benchmarks/bench_geometry.py [--batch 10000] [--repeats 15]``

Prints, for compose / inverse / log / exp / act: the time per call on a single pose (tagloc,
GTSAM ``Pose3``, and a raw numpy 4x4 ``@`` as the floor), and the time per pose on a batch
(tagloc batched types against ``np.matmul`` on ``(N, 4, 4)`` stacks of the same poses). Each
figure is the median over ``repeats`` timings of a loop (``time.perf_counter_ns``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import gtsam
import numpy as np

from _timing import per_call_ns
from tagloc.geometry import SE3

SEED = 7


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=10_000, help="poses per batch")
    parser.add_argument("--repeats", type=int, default=15, help="timings per figure (median)")
    args = parser.parse_args()
    n, repeats = args.batch, args.repeats

    rng = np.random.default_rng(SEED)
    T1, T2 = SE3.random(rng), SE3.random(rng)
    xi = T1.log()
    point = rng.normal(size=3)
    M1, M2 = T1.as_matrix(), T2.as_matrix()
    p_h = np.append(point, 1.0)
    g1 = gtsam.Pose3(gtsam.Rot3(T1.rotation.as_matrix()), T1.translation.copy())
    g2 = gtsam.Pose3(gtsam.Rot3(T2.rotation.as_matrix()), T2.translation.copy())
    xi_g = np.concatenate([xi[3:], xi[:3]])

    B1, B2 = SE3.random(rng, n), SE3.random(rng, n)
    xis = B1.log()
    points = rng.normal(size=(n, 3))
    BM1, BM2 = B1.as_matrix(), B2.as_matrix()
    points_h = np.concatenate([points, np.ones((n, 1))], axis=1)[:, :, None]

    single: dict[str, tuple[Callable[[], object], Callable[[], object] | None]] = {
        "compose": (lambda: T1 @ T2, lambda: g1.compose(g2)),
        "inverse": (lambda: T1.inverse(), lambda: g1.inverse()),
        "log": (lambda: T1.log(), lambda: gtsam.Pose3.Logmap(g1)),
        "exp": (lambda: SE3.exp(xi), lambda: gtsam.Pose3.Expmap(xi_g)),
        "act (1 point)": (lambda: T1.act(point), lambda: g1.transformFrom(point)),
    }
    numpy_single: dict[str, Callable[[], object]] = {
        "compose": lambda: M1 @ M2,
        "inverse": lambda: M1 @ M2,
        "log": lambda: M1 @ M2,
        "exp": lambda: M1 @ M2,
        "act (1 point)": lambda: M1 @ p_h,
    }
    batched: dict[str, Callable[[], object]] = {
        "compose": lambda: B1 @ B2,
        "inverse": lambda: B1.inverse(),
        "log": lambda: B1.log(),
        "exp": lambda: SE3.exp(xis),
        "act (1 point)": lambda: B1.act(points),
    }
    numpy_batched: dict[str, Callable[[], object]] = {
        "compose": lambda: np.matmul(BM1, BM2),
        "inverse": lambda: np.matmul(BM1, BM2),
        "log": lambda: np.matmul(BM1, BM2),
        "exp": lambda: np.matmul(BM1, BM2),
        "act (1 point)": lambda: np.matmul(BM1, points_h),
    }

    header = (
        f"{'SE3 op':<14} | {'tagloc 1':>10} | {'gtsam 1':>10} | {'numpy 4x4 1':>11} | "
        f"{'tagloc batch':>13} | {'numpy batch':>12} | {'batch/numpy':>11}"
    )
    print(f"single: us per call; batch: ns per pose, N = {n}; median of {repeats} timings")
    print("numpy reference: 4x4 @ 4x4 (4x4 @ 4-vector for act), np.matmul on (N, 4, 4) stacks")
    print(header)
    print("-" * len(header))
    for name, (mine, theirs) in single.items():
        t_mine = per_call_ns(mine, repeats) / 1e3
        t_gtsam = per_call_ns(theirs, repeats) / 1e3 if theirs is not None else float("nan")
        t_np = per_call_ns(numpy_single[name], repeats) / 1e3
        b_mine = per_call_ns(batched[name], repeats) / n
        b_np = per_call_ns(numpy_batched[name], repeats) / n
        print(
            f"{name:<14} | {t_mine:>8.2f}us | {t_gtsam:>8.2f}us | {t_np:>9.2f}us | "
            f"{b_mine:>11.1f}ns | {b_np:>10.1f}ns | {b_mine / b_np:>10.2f}x"
        )


if __name__ == "__main__":
    main()
