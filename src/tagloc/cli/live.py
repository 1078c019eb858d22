"""The sinks ``tagloc localize`` adds beside its files: the status line, the report, the view.

:func:`attach_live` puts them on a wired node (and the view's tap on its stream);
:meth:`LiveSinks.close` writes ``report.html`` after the run's files and finishes the view's
``.rrd``; :meth:`LiveSinks.abort`, after a failure, leaves neither.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from tagloc.adapters.rerun import RerunSink
    from tagloc.cli.localize_cmd import WiredNode
    from tagloc.cli.status import StatusLine
    from tagloc.eval.run_report import RunReportSink
    from tagloc.tags import TagMap

__all__ = ["LiveSinks", "attach_live"]


@dataclass(slots=True)
class LiveSinks:
    status: StatusLine
    report: RunReportSink
    view: RerunSink | None

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
    wired: WiredNode, tag_map: TagMap | None, *, view: bool = False, view_save: Path | None = None,
    premap: np.ndarray | None = None,
) -> LiveSinks:  # fmt: skip
    """Add the status line, the report and (``view``: a spawned viewer; ``view_save``: an
    ``.rrd`` file) the rerun view to ``wired``'s node and stream."""
    from tagloc.cli.status import StatusLine
    from tagloc.eval.run_report import RunReportSink

    node = wired.node
    live = LiveSinks(StatusLine(node.skipped), RunReportSink(wired.name), None)
    if view or view_save is not None:
        from tagloc.adapters.rerun import RerunSink

        frames = node.config.frames
        live.view = RerunSink(
            tag_map, map_frame=frames.map_frame, base_frame=frames.base_frame, spawn=view,
            save=view_save, premap=premap, name=wired.name,
        )
        wired.stream = live.view.tap(wired.stream)
    node.sinks += [live.status, live.report, *([live.view] if live.view else [])]
    return live
