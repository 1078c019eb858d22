"""The on-site evaluation's outputs: ``summary.json``, ``summary.txt`` and ``report.html``
(figures embedded as PNG, as ``tagloc eval run``'s report), written together atomically.

:func:`onsite_summary` gathers the parts (held-out tags, checkpoints, acceptance by conditions,
the camera checks) into one JSON-ready dict; :func:`summary_lines` is its text table;
:func:`write_onsite_report` writes the three files.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from tagloc.eval.onsite import HeldOutResult
from tagloc.eval.onsite_checkpoints import CheckpointSpread, Stop
from tagloc.eval.report_plots import pyplot
from tagloc.fileutil import atomic_write_texts

__all__ = ["ONSITE_FILES", "clean_json", "onsite_summary", "summary_lines", "write_onsite_report"]

#: The files :func:`write_onsite_report` writes into its directory.
ONSITE_FILES = ("summary.json", "summary.txt", "report.html")


def onsite_summary(
    name: str, held_out: HeldOutResult | None, stops: list[Stop],
    spreads: list[CheckpointSpread], acceptance: dict[str, Any], *,
    checkpoints_from: str, extrinsic_check: dict[str, Any] | None,
    camera_check: dict[str, Any] | None, run_facts: dict[str, Any],
) -> dict[str, Any]:  # fmt: skip
    """One JSON-ready dict of the on-site evaluation."""
    return {
        "name": name, "run": run_facts,
        "held_out_tags": None if held_out is None else held_out.to_dict(),
        "checkpoints": {"from": checkpoints_from, "stops": len(stops),
                        "repeatability": [s.to_dict() for s in spreads]},
        "acceptance": acceptance, "extrinsic_check": extrinsic_check,
        "camera_check": camera_check,
    }  # fmt: skip


def _f(value: float | None, scale: float = 1.0, digits: int = 1) -> str:
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value * scale:.{digits}f}"


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The summary as a text table (held-out tags per tag, checkpoints, acceptance)."""
    lines = [f"{summary['name']}: on-site evaluation"]
    ho = summary["held_out_tags"]
    if ho is not None:
        lines.append("held-out tags: tag pose predicted from the fused pose vs surveyed")
        lines.append(f"{'tag':>8} {'views':>6} {'pos med cm':>11} {'pos p95 cm':>11} "
                     f"{'yaw med deg':>12} {'yaw p95 deg':>12}")  # fmt: skip
        rows = [*ho["per_tag"].items(), ("overall", ho["overall"])]
        for tag, s in rows:
            p, y = s["position_m"], s["yaw_deg"]
            lines.append(
                f"{tag:>8} {p['n']:>6} {_f(p['median'], 100):>11} {_f(p['p95'], 100):>11} "
                f"{_f(y['median'], 1, 2):>12} {_f(y['p95'], 1, 2):>12}"
            )
        if ho["unseen_tags"]:
            lines.append(f"held out but never seen near: {ho['unseen_tags']}")
    cp = summary["checkpoints"]
    lines.append(f"checkpoints ({cp['from']}): {cp['stops']} stops")
    for c in cp["repeatability"]:
        lines.append(
            f"  {c['name']}: {c['visits']} visits, spread RMS {_f(c['rms_m'], 100)} cm, max "
            f"{_f(c['max_m'], 100)} cm, yaw std {_f(c['yaw_std_deg'], 1, 2)} deg"
        )
    acc = summary["acceptance"]
    lines.append(
        f"fix acceptance: {acc['accepted']} of {acc['attempts']} ({acc['note']}; "
        f"{acc['view_angle_unknown']} refused before PnP have no viewing angle)"
    )
    for key, unit in (("distance_m", "m"), ("view_angle_deg", "deg"),
                      ("laplacian_var", "lap.var"), ("brightness", "grey")):  # fmt: skip
        bins = [b for b in acc.get(key, []) if b["attempts"]]
        if bins:
            lines.append(f"  by {key}: " + ", ".join(
                f"[{b['lo']:g}, {b['hi']:g}) {unit} {b['accepted']}/{b['attempts']}"
                for b in bins))  # fmt: skip
    ext = summary["extrinsic_check"]
    if ext is not None:
        lines.append(
            f"extrinsic check: {ext['rotation_deg']:.2f} deg / {ext['translation_m'] * 100:.1f} "
            f"cm from {ext['n_pairs']} fix pairs (unobservable: "
            f"{', '.join(ext['unobservable']) or 'none'})"
        )
        if ext["warning"]:
            lines.append(f"WARNING: {ext['warning']}")
    return lines


def _png(fig: Any) -> str:
    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png")
    pyplot().close(fig)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _figures(summary: dict[str, Any], held_out: HeldOutResult | None,
             stops: list[Stop]) -> list[tuple[str, str]]:  # fmt: skip
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
    fig, axes = plt.subplots(1, len(keys), figsize=(4 * len(keys), 3.5), dpi=100, squeeze=False)
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
    if stops:
        fig, ax = plt.subplots(figsize=(6, 5), dpi=100)
        ax.plot([s.x for s in stops], [s.y for s in stops], "o", markersize=4)
        for c in summary["checkpoints"]["repeatability"]:
            ax.annotate(c["name"], c["mean_xy_m"], fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title("stops (fused pose)")
        out.append(("Checkpoints", _png(fig)))
    return out


def write_onsite_report(
    summary: dict[str, Any], held_out: HeldOutResult | None, stops: list[Stop], out_dir: Path
) -> list[Path]:
    """Write ``summary.json``, ``summary.txt`` and ``report.html`` into ``out_dir`` (all or
    none); return their paths."""
    lines = summary_lines(summary)
    figures = "".join(
        f"<h2>{html.escape(title)}</h2><img src='data:image/png;base64,{png}'>"
        for title, png in _figures(summary, held_out, stops)
    )
    page = (
        f"<!doctype html><html><head><meta charset='utf-8'><title>"
        f"{html.escape(summary['name'])}</title></head><body><h1>On-site evaluation: "
        f"{html.escape(summary['name'])}</h1><pre>{html.escape(chr(10).join(lines))}</pre>"
        f"{figures}</body></html>\n"
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        out_dir / "summary.json": json.dumps(clean_json(summary), indent=2, allow_nan=False) + "\n",
        out_dir / "summary.txt": "\n".join(lines) + "\n",
        out_dir / "report.html": page,
    }
    atomic_write_texts(files)
    return list(files)


def clean_json(value: Any) -> Any:
    """NaN and infinities as null (strict JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: clean_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [clean_json(v) for v in value]
    return value
