"""A one-line live status in the terminal while a long command runs, as an output sink.

``t 123.4 s | ladder 2 markers_carry | fixes 812/1303 accepted | dropped 3 | 4.1x``: the
stream time since the first output, the ladder level, the fixes accepted of those attempted, the
input the node dropped (its ``skipped`` counts, read live) and the speed against the wall clock.
In a building of several floors or with elevators the status's floor and cab state follow the
level: ``| floor 2`` in the map, ``| floor ? in_cab elevator_cab`` riding.
Redrawn at most :data:`REFRESH_S` apart, on stderr, and only on a terminal (a pipe or a log file
gets nothing); :meth:`StatusLine.close` removes it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt
from tagloc.supervise import LadderTransition, StatusReport

__all__ = ["REFRESH_S", "StatusLine"]

REFRESH_S = 0.25


class StatusLine:
    """The live status line (module docstring).

    Parameters
    ----------
    skipped : Mapping[str, int], optional
        The node's live skip counts (``LocalizerNode.skipped``).
    console : rich.console.Console, optional
        Default: stderr. Nothing is drawn unless it is a terminal.
    """

    def __init__(self, skipped: Mapping[str, int] | None = None, console: Any = None) -> None:
        from rich.console import Console
        from rich.live import Live

        self.console = console if console is not None else Console(stderr=True)
        self.skipped = skipped if skipped is not None else {}
        self.t0_ns: int | None = None
        self.stamp_ns = 0
        self.level: tuple[int, str] | None = None
        self.attempts = self.accepted = 0
        self.place = ""  # floor and cab, from the status
        self._wall0 = time.perf_counter()
        self._next = 0.0
        self._live = None
        if self.console.is_terminal:
            self._live = Live("", console=self.console, auto_refresh=False, transient=True)
            self._live.start()

    def write(self, output: NodeOutput) -> None:
        stamp = getattr(output, "stamp_ns", None)
        if isinstance(stamp, int):
            self.t0_ns = stamp if self.t0_ns is None else self.t0_ns
            self.stamp_ns = max(self.stamp_ns, stamp)
        if isinstance(output, StatusReport):
            self.level = (int(output.level), output.level.label)
            self.place = _place(output)
        elif isinstance(output, LadderTransition):
            self.level = (int(output.to_level), output.to_level.label)
        elif isinstance(output, FixAttempt):
            self.attempts += 1
            self.accepted += output.accepted
        if isinstance(output, Estimate) and self._live is not None:
            now = time.perf_counter()
            if now >= self._next:
                self._next = now + REFRESH_S
                self._live.update(self.line(), refresh=True)

    def line(self) -> str:
        """The status as text."""
        t = 0.0 if self.t0_ns is None else (self.stamp_ns - self.t0_ns) * 1e-9
        level = "n/a" if self.level is None else f"{self.level[0]} {self.level[1]}"
        wall = time.perf_counter() - self._wall0
        speed = f" | {t / wall:.1f}x" if wall > 0 else ""
        dropped = sum(self.skipped.values())
        return (f"t {t:.1f} s | ladder {level}{self.place} | fixes {self.accepted}/"
                f"{self.attempts} accepted | dropped {dropped}{speed}")  # fmt: skip

    def close(self) -> None:
        """Remove the line (it is transient)."""
        if self._live is not None:
            self._live.stop()
            self._live = None


def _place(status: StatusReport) -> str:
    """`` | floor 2``, `` | floor ? in_cab elevator_cab`` (empty: no floors, no cab)."""
    cab = "" if not status.cab.in_cab else f" {status.cab} {status.cab_frame}"
    if status.floor is None and not cab:
        return ""
    return f" | floor {status.floor if status.floor is not None else '?'}{cab}"
