"""Memory of the mounting check against the drive's length: the recorder and the fit.

A synthetic planar drive (100 Hz odometry, turning; fixes at 30 Hz, one camera, 20 tags) of
100 s to 700 s is streamed through :class:`~tagloc.localize.extrinsic_rig.ExtrinsicRecorder`
as the node streams its outputs; then the check runs. For each length the table prints the
fixes the recorder holds, the numbers it has allocated, and the tracemalloc peak of the check
(the fit), once with the default bound (``MAX_FIXES`` fixes a camera: whole blocks thinned
past it) and once, as the reference in the same run, with no bound (every fix kept and fitted,
as the check was before the bound).

    python benchmarks/bench_extrinsic_memory.py [--seconds 100 300 700]
"""

from __future__ import annotations

import argparse
import math
import time
import tracemalloc

import numpy as np

from tagloc.geometry import SE3
from tagloc.localize.extrinsic_check import MAX_FIXES
from tagloc.localize.extrinsic_rig import ExtrinsicRecorder
from tagloc.localize.outputs import Estimate
from tagloc.localize.run import FixAttempt

S = 1_000_000_000
T_BASE_CAM = SE3.from_rotvec([-math.pi / 2, 0.0, 0.0], [0.25, 0.0, 0.5]) @ SE3.from_rotvec(
    [0.0, -math.pi / 2, 0.0], [0.0, 0.0, 0.0]
)


def drive(seconds: float, rng: np.random.Generator) -> tuple[np.ndarray, SE3]:
    n = int(seconds * 100)
    t = np.arange(n) / 100.0
    yaw = np.cumsum(0.6 * np.sin(0.21 * t) + 0.4 * np.sin(0.05 * t + 1.0)) / 100.0
    speed = 0.5 + 0.3 * np.sin(0.13 * t)
    xy = np.cumsum(np.stack([speed * np.cos(yaw), speed * np.sin(yaw)], 1), 0) / 100.0
    rotvec = np.column_stack([np.zeros((n, 2)), yaw])
    return (t * S).astype(np.int64), SE3.from_rotvec(rotvec, np.column_stack([xy, np.zeros(n)]))


def one(seconds: float, max_fixes: int) -> tuple[int, int, float, float]:
    rng = np.random.default_rng(1)
    stamps, T_map_base = drive(seconds, rng)
    sig = np.array([0.01, 0.01, 0.01, 0.005, 0.005, 0.005])
    cov = np.diag(sig**2)
    recorder = ExtrinsicRecorder(max_fixes=max_fixes)
    for k, stamp in enumerate(stamps.tolist()):
        recorder.write(Estimate(stamp, T_map_base[k], SE3.identity(), None, True, True,
                                "map", "odom"))  # fmt: skip
        if k % 3 == 0:  # 33 Hz fixes, released at once
            T_map_cam = T_map_base[k] @ T_BASE_CAM @ SE3.exp(rng.normal(0.0, sig))
            tag = 1 + (k // 500) % 20
            recorder.write(FixAttempt(stamp, f"tag:{tag}", (tag,),
                                      T_map_cam @ T_BASE_CAM.inverse(), cov, "accepted", 2.0,
                                      0.3))  # fmt: skip
    held = recorder.held
    tracemalloc.start()
    start = time.perf_counter()
    check = recorder.check(T_BASE_CAM)
    wall = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    assert check is not None and check.warning is None
    return held["fixes"], held["numbers"], peak, wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, nargs="+", default=[100.0, 300.0, 700.0])
    args = parser.parse_args()
    header = (f"{'drive s':>7} | {'bound':>9} | {'fixes held':>10} | {'numbers held':>12} | "
              f"{'fit peak MB':>11} | {'fit s':>6}")  # fmt: skip
    print(header)
    print("-" * len(header))
    for seconds in args.seconds:
        for label, bound in ((f"{MAX_FIXES}", MAX_FIXES), ("none", 10**9)):
            fixes, numbers, peak, wall = one(seconds, bound)
            print(f"{seconds:7.0f} | {label:>9} | {fixes:10d} | {numbers:12d} | {peak:11.1f} | "
                  f"{wall:6.2f}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
