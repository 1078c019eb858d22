"""The fleet evaluation's outputs: ``summary.json``, ``summary.txt`` and ``report.html``, written
together atomically (all or none) once every pass has finished.

Per log and pooled: reliability (with ground truth), fix decisions by reason, time at each
ladder level, suspect tags, skipped input, held-out-tag errors; a verdict (pooled reliability
against the protocol's target where the logs have truth, else the held-out tags' p95 position
error against :data:`HELD_OUT_P95_M`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from tagloc.eval.fleet import LogResult, pooled
from tagloc.eval.onsite_report import HELD_OUT_P95_M, clean_json
from tagloc.eval.protocol import EvalConfig
from tagloc.eval.report_plots import pyplot
from tagloc.eval.report_style import figure, page, table, verdict
from tagloc.fileutil import atomic_write_texts

__all__ = ["FLEET_FILES", "HELD_OUT_P95_M", "fleet_summary", "fleet_verdict", "summary_lines",
           "write_fleet_report"]  # fmt: skip

FLEET_FILES = ("summary.json", "summary.txt", "report.html")
LEVELS = ("lidar_nominal", "markers_carry", "markers_alone", "odometry_only")


def fleet_summary(
    results: list[LogResult], config: EvalConfig, engine: dict[str, Any]
) -> dict[str, Any]:
    """One JSON-ready dict: every log, the pool, the verdict and how it ran."""
    pool = pooled(results)
    passed, why = fleet_verdict(pool, config)
    return {"logs": [r.to_dict() for r in results], "pooled": pool,
            "verdict": {"passed": passed, "reason": why}, "engine": engine}  # fmt: skip


def fleet_verdict(pool: dict[str, Any], config: EvalConfig) -> tuple[bool | None, str]:
    """Pass/fail (None: cannot tell) and why (module docstring)."""
    rel = pool["reliability"]
    if rel["opportunities"]:
        ok = rel["fraction"] >= config.target_reliability
        return ok, (f"pooled reliability {rel['fraction']:.4f} over {rel['opportunities']} "
                    f"opportunities (target >= {config.target_reliability:g})")  # fmt: skip
    held = pool["held_out_tags"]
    if held is not None and held["position_m"]["n"]:
        p95 = held["position_m"]["p95"]
        return p95 <= HELD_OUT_P95_M, (f"held-out tags' position error p95 {p95 * 100:.1f} cm "
                                       f"(target <= {HELD_OUT_P95_M * 100:g} cm)")  # fmt: skip
    return None, "no ground truth and no held-out tag seen"


def _f(value: float | None, scale: float = 1.0, digits: int = 1) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value * scale:.{digits}f}"


def _row(name: str, d: dict[str, Any]) -> list[str]:
    """One log's (or the pool's) headline numbers as table cells."""
    rel = d["reliability"]
    frac = rel["fraction"]
    ho = d["held_out_tags"]
    ho = ho.get("overall", ho) if ho is not None else None
    pos = ho["position_m"] if ho is not None else None
    ladder = d["ladder_s"]
    total = sum(ladder.values()) or math.nan
    return [
        name, _f(d["duration_s"]), f"{d['fixes_accepted']}/{d['fix_attempts']}",
        "n/a" if frac is None else f"{frac:.4f}",
        f"{rel['successes']}/{rel['opportunities']}" if rel["opportunities"] else "n/a",
        _f(ladder.get("odometry_only", 0.0) / total, 100),
        str(len(d["suspect_sources"])),
        "n/a" if pos is None or not pos["n"] else f"{_f(pos['median'], 100)}/{_f(pos['p95'], 100)}",
    ]  # fmt: skip


HEADER = ["log", "s", "fixes acc/att", "reliability", "succ/opp", "% odom only", "suspects",
          "held-out cm med/p95"]  # fmt: skip


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The summary as a text table: a row per log, the pool, refusals by reason, the verdict."""
    rows = [_row(d["name"], d) for d in summary["logs"]]
    rows.append(_row("pooled", summary["pooled"]))
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(HEADER)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(HEADER, widths, strict=True))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    pool = summary["pooled"]
    decisions = ", ".join(f"{k} {v}" for k, v in pool["decisions"].items()) or "none"
    lines.append(f"fix decisions (all logs): {decisions}")
    if pool["suspect_sources"]:
        lines.append(f"suspect tags: {', '.join(pool['suspect_sources'])}")
    if pool["skipped"]:
        lines.append("skipped input: " + ", ".join(f"{k} {v}" for k, v in pool["skipped"].items()))
    v = summary["verdict"]
    word = {True: "PASS", False: "FAIL", None: "NO VERDICT"}[v["passed"]]
    lines.append(f"verdict: {word}: {v['reason']}")
    return lines


def _figures(summary: dict[str, Any]) -> list[str]:
    plt = pyplot()
    logs = summary["logs"]
    names = [d["name"] for d in logs]
    x = np.arange(len(logs))
    out = []
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4), dpi=100)
    bottom = np.zeros(len(logs))
    for level in LEVELS:
        secs = np.array([d["ladder_s"].get(level, 0.0) for d in logs])
        ax1.bar(x, secs, bottom=bottom, label=level)
        bottom += secs
    ax1.set_xticks(x, names, rotation=60, fontsize=7)
    ax1.set_ylabel("time at ladder level (s)")
    ax1.legend(fontsize=7)
    reasons = sorted({k for d in logs for k in d["decisions"]})
    bottom = np.zeros(len(logs))
    for reason in reasons:
        n = np.array([d["decisions"].get(reason, 0) for d in logs], dtype=float)
        ax2.bar(x, n, bottom=bottom, label=reason)
        bottom += n
    ax2.set_xticks(x, names, rotation=60, fontsize=7)
    ax2.set_ylabel("fix attempts by decision")
    ax2.legend(fontsize=6)
    fig.tight_layout()
    out.append(figure(_png(fig), "ladder and decisions per log"))
    return out


def _png(fig: Any) -> bytes:
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    pyplot().close(fig)
    return buffer.getvalue()


def render_html(summary: dict[str, Any]) -> str:
    """The fleet report page."""
    v = summary["verdict"]
    rows = [_row(d["name"], d) for d in summary["logs"]]
    rows.append(_row("pooled", summary["pooled"]))
    pool = summary["pooled"]
    reasons = [[k, n] for k, n in pool["decisions"].items()]
    engine = summary["engine"]
    parts = [
        verdict(v["passed"], v["reason"]),
        f"<p>{len(summary['logs'])} logs on {engine['kind']} with {engine['jobs']} job(s), "
        f"{engine['passes']} localizer passes.</p>",
        "<h2>Per log and pooled</h2>", table(HEADER, rows),
        "<h2>Fix decisions, all logs</h2>", table(["decision", "attempts"], reasons),
        "<h2>Suspect tags</h2>",
        table(["log:source"], [[s] for s in pool["suspect_sources"]]) if pool["suspect_sources"]
        else "<p>none</p>",
        *_figures(summary),
    ]  # fmt: skip
    return page(f"tagloc fleet evaluation: {len(summary['logs'])} logs", parts)


def write_fleet_report(summary: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the three files into ``out_dir`` (all or none); return their paths."""
    lines = summary_lines(summary)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        out_dir / "summary.json": json.dumps(clean_json(summary), indent=2, allow_nan=False)
        + "\n",
        out_dir / "summary.txt": "\n".join(lines) + "\n",
        out_dir / "report.html": render_html(summary),
    }
    atomic_write_texts(files)
    return list(files)
