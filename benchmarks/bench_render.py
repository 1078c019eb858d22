"""Benchmark tagloc.sim.render: per-frame time of rendering the default office drive.

Run: ``.venv/bin/python benchmarks/bench_render.py [--frames 40] [--supersample 2]``

For a pinhole (90 deg horizontal field of view) and a fisheye (the dupont ``cam0`` equidistant
coefficients, focal length scaled to the width) at 640x480 and 1280x720, renders ``frames``
camera frames spread over the whole drive and prints the median and 90th-percentile wall time per
frame: without effects (``RenderConfig.ideal()``), with the default effects (directional motion
blur, noise, vignetting) and with defocus plus 8-subframe motion blur. The one-off cost of the
ray grids (first frame of a camera) is printed separately and excluded from the table.
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time

import numpy as np

from tagloc.camera import CameraModel, PinholeEquidistant, PinholeRadtan
from tagloc.sim import load_default_world, simulate_drive
from tagloc.sim.drive import Drive
from tagloc.sim.render import RenderConfig, render_frames

#: dupont cam0 (``/work/shared/data/dupont/cameras.yaml``): fx / width and k1..k4.
DUPONT_F_OVER_W = 603.924 / 1280
DUPONT_K = (-0.0122741, -0.0100319, 0.00752173, -0.00247881)


def cameras(width: int, height: int) -> dict[str, CameraModel]:
    """A pinhole and a fisheye model of this size, principal point at the image center."""
    cx, cy = (width - 1) / 2, (height - 1) / 2
    f_pin, f_fish = width / 2, DUPONT_F_OVER_W * width
    k1, k2, k3, k4 = DUPONT_K
    return {
        "pinhole": PinholeRadtan(width=width, height=height, fx=f_pin, fy=f_pin, cx=cx, cy=cy),
        "fisheye": PinholeEquidistant(
            width=width,
            height=height,
            fx=f_fish,
            fy=f_fish,
            cx=cx,
            cy=cy,
            k1=k1,
            k2=k2,
            k3=k3,
            k4=k4,
        ),
    }


def frame_times_ms(
    drive: Drive, camera: CameraModel, config: RenderConfig, stamps: np.ndarray
) -> list[float]:
    """Wall time (ms) of each frame of ``render_frames`` over ``stamps``."""
    times: list[float] = []
    frames = render_frames(drive, camera, config, seed=0, stamps_ns=stamps)
    while True:
        start = time.perf_counter()
        frame = next(frames, None)
        if frame is None:
            return times
        times.append(1e3 * (time.perf_counter() - start))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--supersample", type=int, default=2)
    args = parser.parse_args()

    drive = simulate_drive(load_default_world(), seed=1)
    stamps = drive.camera_stamps_ns[:: max(1, len(drive.camera_stamps_ns) // args.frames)]
    stamps = stamps[: args.frames]
    k = args.supersample
    configs = {
        "none": RenderConfig.ideal(supersample=k),
        "none, walls full res": RenderConfig.ideal(supersample=k, background_scale=1.0),
        "default effects": RenderConfig(supersample=k),
        "defocus+subframes(8)": RenderConfig(
            supersample=k, defocus_sigma_px=1.0, motion_blur="subframes", subframes=8
        ),
    }
    print(f"{len(stamps)} frames over the office drive, supersample {k}x{k}")
    print(f"| {'camera':<8} | {'size':<9} | {'effects':<20} | median ms | p90 ms |")
    print(f"|{'-' * 10}|{'-' * 11}|{'-' * 22}|{'-' * 11}|{'-' * 8}|")
    setup = []
    for (width, height), name in itertools.product(
        ((640, 480), (1280, 720)), ("pinhole", "fisheye")
    ):
        camera = cameras(width, height)[name]
        start = time.perf_counter()
        frame_times_ms(drive, camera, configs["none"], stamps[:1])  # builds the ray grids
        setup.append(f"{name} {width}x{height}: {time.perf_counter() - start:.2f} s")
        for label, config in configs.items():
            times = frame_times_ms(drive, camera, config, stamps)
            print(
                f"| {name:<8} | {f'{width}x{height}':<9} | {label:<20} | "
                f"{statistics.median(times):9.1f} | {np.percentile(times, 90):6.1f} |"
            )
    print("first frame (ray grids, once per camera): " + "; ".join(setup))


if __name__ == "__main__":
    main()
