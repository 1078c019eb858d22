"""``tagloc eval bag``'s ``report.html``, in the style of the other reports
(:mod:`tagloc.eval.report_style`): the verdict, the summary table, the trajectory (the estimate
over the odometry, the stops marked), the ladder over time, the fix decisions by reason, the
held-out tags' errors, acceptance by conditions.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from tagloc.eval.onsite import HeldOutResult
from tagloc.eval.onsite_checkpoints import Stop
from tagloc.eval.report_plots import pyplot
from tagloc.eval.report_style import figure, page, table, verdict
from tagloc.eval.run_figures import decisions_png, ladder_png, trajectory_png
from tagloc.eval.supervision import ladder_steps
from tagloc.localize.run import LocalizationRun

__all__ = ["render_html"]


def render_html(
    summary: dict[str, Any], lines: list[str], held_out: HeldOutResult | None,
    stops: list[Stop], run: LocalizationRun | None,
) -> str:  # fmt: skip
    """The page (``lines``: the summary as text)."""
    v = summary.get("verdict") or {"passed": None, "reason": "not judged"}
    parts = [verdict(v["passed"], v["reason"]), "<pre>"
             + "\n".join(_esc(line) for line in lines) + "</pre>"]  # fmt: skip
    if run is not None and len(run.stamps_ns) >= 2:
        paths = {"odometry": np.asarray(run.T_odom_base.translation)[:, :2]}
        init = np.asarray(run.initialized, dtype=bool)
        paths["fused"] = np.asarray(run.T_map_base.translation)[init, :2]
        if run.T_map_base_truth is not None:
            paths["truth"] = np.asarray(run.T_map_base_truth.translation)[:, :2]
        marks = {"stops": np.array([(s.x, s.y) for s in stops]).reshape(-1, 2)}
        parts += ["<h2>Trajectory (top-down)</h2>", figure(trajectory_png(paths, marks), "path")]
        if run.ladder:
            t_s, level = ladder_steps(run)
            parts += ["<h2>Degradation ladder</h2>", figure(ladder_png(t_s, level), "ladder")]
        decisions = Counter(f.decision for f in run.fixes)
        if decisions:
            rows = sorted(decisions.items(), key=lambda kv: -kv[1])
            parts += ["<h2>Fix decisions (refusals by reason)</h2>",
                      table(["decision", "attempts"], rows),
                      figure(decisions_png(decisions), "decisions")]  # fmt: skip
    for title, png in _figures(summary, held_out):
        parts += [f"<h2>{_esc(title)}</h2>", figure(png, title)]
    return page(f"tagloc on-site evaluation: {summary['name']}", parts)


def _esc(text: str) -> str:
    import html

    return html.escape(text)


def _png(fig: Any) -> bytes:
    import io

    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png")
    pyplot().close(fig)
    return buffer.getvalue()


def _figures(summary: dict[str, Any], held_out: HeldOutResult | None) -> list[tuple[str, bytes]]:
    plt = pyplot()
    out = []
    if held_out is not None and held_out.observations:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4), dpi=100)
        ids = held_out.tag_ids()
        data = [[o.position_err_m * 100 for o in held_out.observations if o.tag_id == i]
                for i in ids]  # fmt: skip
        ax1.boxplot(data, whis=(5, 95), showfliers=False)
        ax1.set_xticks(range(1, len(ids) + 1), [str(i) for i in ids], rotation=90)
        ax1.set_xlabel("held-out tag")
        ax1.set_ylabel("tag position error (cm)")
        r = np.array([o.range_m for o in held_out.observations])
        e = np.array([o.position_err_m * 100 for o in held_out.observations])
        ax2.plot(r, e, ".", markersize=2, alpha=0.5)
        ax2.set_xlabel("range (m)")
        ax2.set_ylabel("tag position error (cm)")
        out.append(("Held-out tags", _png(fig)))
    acc = summary["acceptance"]
    keys = [k for k in ("distance_m", "view_angle_deg", "laplacian_var", "brightness") if k in acc]
    if keys:
        fig, axes = plt.subplots(1, len(keys), figsize=(4 * len(keys), 3.5), dpi=100,
                                 squeeze=False)  # fmt: skip
        for ax, key in zip(axes[0], keys, strict=True):
            bins = acc[key]
            labels = [f"{b['lo']:g}-{b['hi']:g}" for b in bins]
            rates = [b["rate"] if b["attempts"] else 0.0 for b in bins]
            ax.bar(range(len(bins)), rates, color="tab:blue")
            ax.set_xticks(range(len(bins)), labels, rotation=45, fontsize=7)
            ax.set_ylim(0, 1)
            ax.set_title(key, fontsize=9)
            ax.set_ylabel("accepted fraction")
        out.append(("Fix acceptance by conditions", _png(fig)))
    return out
