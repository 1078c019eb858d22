"""The sinks ``tagloc localize`` adds beside its files: the status line, the report, the view.

:func:`attach_live` puts them on a wired node (and the view's tap on its stream);
:meth:`LiveSinks.close` writes ``report.html`` after the run's files and finishes the view's
``.rrd``; :meth:`LiveSinks.abort`, after a failure, leaves neither.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence, ValuesView
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:

    from tagloc.adapters.rerun import RerunSink
    from tagloc.cli.status import StatusLine
    from tagloc.cli.wired import WiredNode
    from tagloc.eval.run_report import RunReportSink
    from tagloc.localize.node import LocalizerNode
    from tagloc.localize.outputs import OutputSink

__all__ = ["LiveSinks", "attach_live"]


@dataclass(slots=True)
class LiveSinks:
    status: StatusLine
    report: RunReportSink
    view: RerunSink | None

    @property
    def sinks(self) -> list[OutputSink]:
        """The sinks to run beside the files."""
        return [self.status, self.report, *([self.view] if self.view is not None else [])]

    def close(self, out: Path, summary_lines: list[str]) -> list[Path]:
        """After a run that ended well: end the status line, write ``out/report.html``, finish
        the view's file; return the paths written."""
        from tagloc.fileutil import atomic_write_text

        self.status.close()
        path = out / "report.html"
        atomic_write_text(path, self.report.html(summary_lines))
        saved = None if self.view is None else self.view.close()
        return [path] + ([saved] if saved is not None else [])

    def abort(self) -> None:
        """After a failed run: end the status line, drop the view's unfinished file."""
        self.status.close()
        if self.view is not None:
            self.view.abort()


def attach_live(
    wired: WiredNode, *, view: bool = False, view_save: Path | None = None
) -> tuple[WiredNode, LiveSinks]:
    """The status line, the report and (``view``: a spawned viewer; ``view_save``: an ``.rrd``
    file) the rerun view for ``wired``'s run: the sinks to pass to the driver beside the files,
    and ``wired`` with the view's tap on its stream and the status line reading the node's skip
    counts once the driver builds it."""
    from dataclasses import replace

    from tagloc.cli.status import StatusLine
    from tagloc.eval.run_report import RunReportSink

    status = StatusLine()
    live = LiveSinks(status, RunReportSink(wired.name), None)
    if view or view_save is not None:
        from tagloc.adapters.rerun import RerunSink

        frames = wired.config.frames
        live.view = RerunSink(
            wired.tag_map, map_frame=frames.map_frame, base_frame=frames.base_frame, spawn=view,
            save=view_save, premap=wired.premap, name=wired.name,
        )
        wired = replace(wired, stream=live.view.tap(wired.stream))
    build = wired.node

    def node(sinks: Sequence[OutputSink]) -> LocalizerNode:
        built = build(sinks)
        status.skipped = _Skipped(built)
        return built

    return replace(wired, node=node), live


class _Skipped(Mapping[str, int]):
    """A node's skip counts, read live (``LocalizerNode.skipped`` is computed on each read)."""

    def __init__(self, node: LocalizerNode) -> None:
        self._node = node

    def __getitem__(self, key: str) -> int:
        return self._node.skipped[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._node.skipped)

    def __len__(self) -> int:
        return len(self._node.skipped)

    def values(self) -> ValuesView[int]:
        return self._node.skipped.values()
