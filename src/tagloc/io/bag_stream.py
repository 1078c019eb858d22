"""A bag as a replayable stream that another process can open: its path and reading options.

Evaluations replay a log once per pass, possibly in worker processes or on a cluster
(:mod:`tagloc.eval.engine`); a :class:`BagStream` is the picklable recipe of the stream (an open
:class:`~tagloc.io.BagSource` holds a file), called to open it afresh.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from tagloc.io.bag_reader import BagSource

__all__ = ["BagStream"]


@dataclass(frozen=True, slots=True)
class BagStream:
    """``BagStream(path, topics, corner_order, default_family)()`` is a new
    :class:`~tagloc.io.BagSource` of those topics (all when ``topics`` is empty)."""

    path: Path
    topics: tuple[str, ...] = ()
    corner_order: str = "tl_tr_br_bl"
    default_family: str | None = None

    def __call__(self) -> BagSource:
        return BagSource(
            self.path, list(self.topics) or None, corner_order=self.corner_order,
            default_family=self.default_family,
        )  # fmt: skip
