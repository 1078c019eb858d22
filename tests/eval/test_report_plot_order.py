"""The report's trajectory plot draws the estimate over the truth: where the fused path lies on
the truth, its pixels are the fused colour, not the truth's."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
from matplotlib.colors import to_rgb
from test_report import synthetic_run

from tagloc.eval.report import evaluate
from tagloc.eval.report_plots import COLORS, trajectories_png


def _pixels_near(image_rgb: np.ndarray, color: str) -> int:
    target = np.array(to_rgb(COLORS[color])) * 255
    return int((np.abs(image_rgb.astype(float) - target).max(axis=2) < 12).sum())


def test_fused_is_drawn_over_the_truth() -> None:
    run = synthetic_run()
    # the fused path exactly on the truth: only the one drawn last can show
    T_map_odom = run.T_map_base_truth @ run.T_odom_base.inverse()
    run = dataclasses.replace(run, T_map_odom=T_map_odom)
    png = trajectories_png(evaluate(run, None))
    image = cv2.cvtColor(
        cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB
    )
    fused, truth = _pixels_near(image, "fused"), _pixels_near(image, "truth")
    assert fused > 200 and truth < fused / 10, (fused, truth)  # the truth only in the legend
