"""The node's transform buffer and ``map -> odom`` filter, built and reset together.

:class:`Fusion` holds the odometry's :class:`~tagloc.frames.TransformBuffer` (a bounded window,
the stream's static transforms) and the :class:`~tagloc.localize.filter.MapOdomFilter` that
reads it. :meth:`Fusion.reset` starts both over (a clock jump back: like ROS tf, the estimate is
dropped), keeping the static transforms; :class:`Fusion` also notes when the filter's state may
have changed, so that what is computed from it can be kept until then.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tagloc.frames import TransformBuffer
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.events import APPLIED, FilterEvent
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.floors import FloorFilter, FloorFrame

__all__ = ["BUFFER_WINDOW_NS", "Fusion"]

#: The odometry kept in the buffer (30 s).
BUFFER_WINDOW_NS = 30 * 1_000_000_000


class Fusion:
    """The buffer and the filter (module docstring).

    Parameters
    ----------
    config : LocalizerConfig
    on_event : callable
        Receives every event of the filter (of each filter :meth:`reset` builds).
    floors : FloorFrame, optional
        A building of several floors: the filter works in the current floor's frame
        (:class:`~tagloc.localize.floors.FloorFilter`).
    """

    def __init__(
        self, config: LocalizerConfig, on_event: Callable[[FilterEvent], None],
        floors: FloorFrame | None = None,
    ) -> None:  # fmt: skip
        self._config, self._on_event, self._floors = config, on_event, floors
        self._statics: dict[tuple[str, str], SE3] = {}
        self._changes = 0
        self._odom_cov: np.ndarray | None = None
        self._buffer, self._filter = self._build()

    @property
    def buffer(self) -> TransformBuffer:
        return self._buffer

    @property
    def filter(self) -> MapOdomFilter:
        return self._filter

    @property
    def changes(self) -> tuple[int, int]:
        """Differs from an earlier value when the filter's state may have changed since: a fix
        applied, a (re)initialization, process noise added, or a prediction to a new stamp."""
        return self._changes, self._filter.stamp_ns

    def set_static(self, parent: str, child: str, T_parent_child: SE3) -> None:
        """A static transform (kept across :meth:`reset`)."""
        self._buffer.set_static(parent, child, T_parent_child)
        self._statics[parent, child] = T_parent_child

    def odometry_covariance(self, cov: np.ndarray) -> None:
        """``process_noise.odometry_covariance: growth``: the positive part of the odometry
        covariance's change since the previous message enters the filter's covariance
        (:meth:`MapOdomFilter.add_process_noise`)."""
        last, self._odom_cov = self._odom_cov, cov
        if last is None or not np.isfinite(cov).all() or not self._filter.initialized:
            return
        w, V = np.linalg.eigh(0.5 * ((cov - last) + (cov - last).T))
        if w.max() > 0:
            self._filter.add_process_noise((V * np.clip(w, 0.0, None)) @ V.T)
            self._changes += 1

    def reset(self) -> None:
        """A new buffer (with the static transforms) and a new filter."""
        self._buffer, self._filter = self._build()
        self._odom_cov = None
        self._changes += 1

    def _build(self) -> tuple[TransformBuffer, MapOdomFilter]:
        buffer = TransformBuffer(window_ns=BUFFER_WINDOW_NS)
        for (parent, child), T in self._statics.items():
            buffer.set_static(parent, child, T)
        flt = (
            MapOdomFilter.from_config(self._config, buffer)
            if self._floors is None
            else FloorFilter.build(self._config, buffer, self._floors)
        )
        flt.events.listeners.append(self._event)
        return buffer, flt

    def _event(self, event: FilterEvent) -> None:
        if event.kind.value in APPLIED:
            self._changes += 1
        self._on_event(event)
