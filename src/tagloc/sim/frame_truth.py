"""What only the simulator knows of each camera frame, in bounded memory: :class:`FrameTruthMap`.

A scenario's stream (:class:`~tagloc.sim.scenarios.ScenarioSource`) simulates its camera frames
lazily; the node looks a frame's truth up (:class:`~tagloc.messages.FrameTruth`: which
detections are injected glints, the nearest tag truly in view, overall and per tag frame:
``map`` or an elevator cab's) once the frame has reached it.
The map keeps the truth of the last ``cache`` frames the stream produced; any other frame of
the drive is simulated again on lookup (each frame's noise is seeded by its stamp alone, so the
result is the same as the stream's). Its keys are the drive's camera stamps.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Mapping

import numpy as np
import numpy.typing as npt

from tagloc.messages import FrameTruth
from tagloc.sim.observations import ObservedFrame

__all__ = ["FrameTruthMap", "frame_truth_of"]


def frame_truth_of(
    frame: ObservedFrame, tag_frames: Mapping[int, str] | None = None
) -> FrameTruth:
    """The run record's truth of one simulated frame; ``tag_frames`` (tag id -> the frame it
    is posed in; default: every tag in ``map``) gives the nearest tag per frame."""
    nearest: dict[str, float] = {}
    for s in frame.truth:
        f = "map" if tag_frames is None else tag_frames.get(s.tag_id, "map")
        nearest[f] = min(nearest.get(f, math.inf), s.range_m)
    return FrameTruth(
        frame.false_detection, min(nearest.values(), default=math.inf),
        tuple(sorted(nearest.items())),
    )  # fmt: skip


class FrameTruthMap(Mapping[int, FrameTruth]):
    """Stamp -> :class:`~tagloc.messages.FrameTruth` of a drive's camera frames (module
    docstring). ``simulate(stamps)``: the frames at those stamps, in order; ``tag_frames``: as
    :func:`frame_truth_of`'s."""

    def __init__(
        self,
        stamps_ns: npt.NDArray[np.int64],
        simulate: Callable[[npt.NDArray[np.int64]], Iterable[ObservedFrame]],
        cache: int = 4096,
        tag_frames: Mapping[int, str] | None = None,
    ) -> None:
        self._stamps = np.asarray(stamps_ns, dtype=np.int64)
        self._simulate, self._cache_size = simulate, cache
        self._tag_frames = None if tag_frames is None else dict(tag_frames)
        self._cache: OrderedDict[int, FrameTruth] = OrderedDict()

    def record(self, frame: ObservedFrame) -> None:
        """Keep the truth of a frame the stream just produced (the oldest kept is dropped)."""
        self._keep(frame.stamp_ns, frame_truth_of(frame, self._tag_frames))

    def _keep(self, stamp: int, truth: FrameTruth) -> None:
        self._cache[stamp] = truth
        self._cache.move_to_end(stamp)
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)

    @property
    def held(self) -> int:
        """Frames whose truth is held."""
        return len(self._cache)

    def __getitem__(self, stamp: int) -> FrameTruth:
        truth = self._cache.get(stamp)
        if truth is not None:
            return truth
        k = int(np.searchsorted(self._stamps, stamp))
        if k == len(self._stamps) or int(self._stamps[k]) != stamp:
            raise KeyError(stamp)
        frame = next(iter(self._simulate(self._stamps[k : k + 1])))
        truth = frame_truth_of(frame, self._tag_frames)
        self._keep(stamp, truth)
        return truth

    def __iter__(self) -> Iterator[int]:
        return iter(self._stamps.tolist())

    def __len__(self) -> int:
        return len(self._stamps)

    def __contains__(self, stamp: object) -> bool:
        if not isinstance(stamp, (int, np.integer)):
            return False
        k = int(np.searchsorted(self._stamps, stamp))
        return k < len(self._stamps) and int(self._stamps[k]) == stamp
