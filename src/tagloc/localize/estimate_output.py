"""The node's :class:`~tagloc.localize.outputs.Estimate` at each odometry sample.

The published correction in force at the sample, the filter's own estimate, and the covariance
of ``T_map_base``, recomputed when the filter's state may have changed
(:attr:`~tagloc.localize.fusion.Fusion.changes`) or a motion step passed, else repeated (it
grows by the odometry random walk of less than one step meanwhile); ``publish`` on the
configured rate.
"""

from __future__ import annotations

import numpy as np

from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fusion import Fusion
from tagloc.localize.outputs import Estimate
from tagloc.units import S_NS

__all__ = ["EstimateOutput"]



class EstimateOutput:
    """Estimates of one node (module docstring)."""

    def __init__(self, config: LocalizerConfig) -> None:
        self._step_ns = round(config.process_noise.motion_step_s * S_NS)
        rate = config.output.publish_rate_hz
        self._publish_ns = 0 if rate == 0 else round(S_NS / rate)
        self._edge = config.frames.published_edge
        self._cov_stamp = 0
        self.reset()

    @property
    def cov_map_base(self) -> np.ndarray | None:
        """The latest covariance of ``T_map_base`` (None before the filter is initialized)."""
        return self._cov

    def reset(self) -> None:
        """Start over (the filter was reset)."""
        self._cov: np.ndarray | None = None
        self._changes: tuple[int, int] | None = None
        self._next_publish = 0

    def estimate(self, fusion: Fusion, stamp: int, T_odom_base: SE3) -> Estimate:
        """The estimate at odometry sample ``stamp``."""
        flt = fusion.filter
        cov = estimate = None
        if flt.initialized:
            T_map_odom = flt.correction_at(stamp)
            estimate = flt.T_map_odom
            changes = fusion.changes
            if changes != self._changes or stamp - self._cov_stamp >= self._step_ns:
                self._cov = flt.pose_at(stamp).cov
                self._changes, self._cov_stamp = changes, stamp
            cov = self._cov
        else:
            T_map_odom = SE3.identity()
        publish = stamp >= self._next_publish
        if publish:
            self._next_publish = stamp + self._publish_ns
        parent, child = self._edge
        return Estimate(stamp, T_odom_base, T_map_odom, cov, flt.initialized, publish, parent,
                        child, estimate)  # fmt: skip
