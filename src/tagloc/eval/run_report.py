"""``tagloc localize``'s ``report.html``, built by a sink as the run streams.

:class:`RunReportSink` keeps what the page shows and nothing more: the fused, odometry and
truth paths thinned to at most :data:`MAX_POINTS` samples each (every k-th sample, k doubling
when full: memory does not grow with the drive), the fix decisions by reason, the ladder's moves
and the unaligned error against truth where known. :meth:`RunReportSink.html` renders the page
(the run's summary lines, a verdict, the trajectory with the estimate over the truth, the ladder
over time, refusals by reason) in the style of the other reports.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from tagloc.eval.refusals import DecisionBook
from tagloc.eval.report_style import figure, page, table, verdict
from tagloc.eval.run_figures import decisions_png, ladder_png, trajectory_png
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.localize.run import FixAttempt
from tagloc.messages import GroundTruthMsg
from tagloc.supervise import LadderTransition

__all__ = ["MAX_POINTS", "RunReportSink"]

MAX_POINTS = 4000
#: The verdict with ground truth: the fused estimate's unaligned position RMSE at most this, m.
TARGET_ATE_M = 0.05


class _Thinned:
    """Every k-th of a stream of ``(t, x, y)`` rows, k doubling to keep <= MAX_POINTS rows."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float]] = []
        self.k, self.n = 1, 0

    def add(self, t: float, x: float, y: float) -> None:
        if self.n % self.k == 0:
            self.rows.append((t, x, y))
            if len(self.rows) >= MAX_POINTS:
                self.rows, self.k = self.rows[::2], self.k * 2
        self.n += 1

    def xy(self) -> np.ndarray:
        return np.array([(x, y) for _, x, y in self.rows]).reshape(-1, 2)


class RunReportSink:
    """Collects a run's report as it streams (module docstring)."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.paths = {k: _Thinned() for k in ("fused", "odometry", "truth")}
        self.decisions: Counter[str] = Counter()
        self.book = DecisionBook()  # the same by camera, and the hint
        self.ladder: list[tuple[int, int]] = []  # (stamp_ns, level), first 10000 moves
        self.t0_ns: int | None = None
        self.t_end_ns = 0
        self._last: Estimate | None = None
        self._sq, self._n = 0.0, 0

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self.t0_ns = output.stamp_ns if self.t0_ns is None else self.t0_ns
            self.t_end_ns = output.stamp_ns
            t = (output.stamp_ns - self.t0_ns) * 1e-9
            self._last = output
            if output.initialized:
                x, y = np.asarray(output.T_map_base.translation)[:2]
                self.paths["fused"].add(t, float(x), float(y))
            x, y = np.asarray(output.T_odom_base.translation)[:2]
            self.paths["odometry"].add(t, float(x), float(y))
        elif isinstance(output, GroundTruthMsg):
            p = np.asarray(output.T_frame_child.translation)
            self.paths["truth"].add(0.0, float(p[0]), float(p[1]))
            e = self._last
            if e is not None and e.stamp_ns == output.stamp_ns:
                self._sq += float(np.sum((np.asarray(e.T_map_base.translation) - p) ** 2))
                self._n += 1
        elif isinstance(output, FixAttempt):
            self.decisions[output.decision] += 1
            self.book.add(output)
        elif isinstance(output, LadderTransition) and len(self.ladder) < 10_000:
            if not self.ladder:
                self.ladder.append((output.stamp_ns, int(output.from_level)))
            self.ladder.append((output.stamp_ns, int(output.to_level)))

    @property
    def ate_m(self) -> float | None:
        """RMSE of the published position (``T_map_base``, before initialization the odometry)
        against truth, m (None without truth): the summary's unaligned ATE."""
        return math.sqrt(self._sq / self._n) if self._n else None

    def verdict(self) -> tuple[bool | None, str]:
        """Against truth: the fused error; without: whether any fix was accepted."""
        accepted = self.decisions["accepted"] + self.decisions["initialized"]
        ate = self.ate_m
        if ate is not None:
            return ate <= TARGET_ATE_M, (f"fused position RMSE {ate * 100:.1f} cm against truth "
                                         f"(target <= {TARGET_ATE_M * 100:g} cm)")  # fmt: skip
        if not accepted:
            return False, "no fix was accepted: the map was never used"
        return None, f"{accepted} fixes accepted; no ground truth to score against"

    def html(self, summary_lines: list[str]) -> str:
        """The page (``summary_lines``: the run's text summary)."""
        passed, why = self.verdict()
        parts = [verdict(passed, why), "<pre>" + "\n".join(_esc(s) for s in summary_lines)
                 + "</pre>", "<h2>Trajectory (top-down)</h2>"]  # fmt: skip
        paths = {k: v.xy() for k, v in self.paths.items() if v.rows}
        parts.append(figure(trajectory_png(paths), "trajectory"))
        if self.ladder and self.t0_ns is not None:
            t = [(s - self.t0_ns) * 1e-9 for s, _ in self.ladder]
            t[0] = 0.0  # the first move's "from" level held since the start
            t.append((self.t_end_ns - self.t0_ns) * 1e-9)
            levels = [lv for _, lv in self.ladder] + [self.ladder[-1][1]]
            parts += ["<h2>Degradation ladder</h2>",
                      figure(ladder_png(np.array(t), np.array(levels)), "ladder")]  # fmt: skip
        if self.decisions:
            rows = sorted(self.decisions.items(), key=lambda kv: -kv[1])
            parts += ["<h2>Fix decisions</h2>", *_refusal_parts(self.book),
                      table(["decision", "attempts"], rows),
                      figure(decisions_png(self.decisions), "decisions")]  # fmt: skip
        return page(f"tagloc localize: {self.name}", parts)


def _refusal_parts(book: DecisionBook) -> list[str]:
    """The hint of a dominant refusal and the acceptance per camera (several cameras)."""
    found = book.result()
    parts = [] if found.hint is None else [f"<p><b>{_esc(found.hint)}</b></p>"]
    if len(found.by_camera) > 1:
        rows = [[c.camera, c.n_attempts, c.n_accepted, c.acceptance] for c in found.by_camera]
        parts.append(table(["camera", "attempts", "accepted", "acceptance"], rows))
    return parts


def _esc(text: str) -> str:
    import html

    return html.escape(text)
