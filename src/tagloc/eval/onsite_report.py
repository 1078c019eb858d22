"""The on-site evaluation's outputs: ``summary.json``, ``summary.txt`` and ``report.html``
(figures embedded as PNG, as ``tagloc eval run``'s report), written together atomically.

:func:`onsite_summary` gathers the parts (held-out tags, checkpoints, acceptance by conditions,
the camera checks) into one JSON-ready dict; :func:`summary_lines` is its text table;
:func:`write_onsite_report` writes the three files.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from tagloc.eval.onsite import HeldOutResult
from tagloc.eval.onsite_checkpoints import CheckpointSpread, Stop
from tagloc.fileutil import atomic_write_texts
from tagloc.localize.run import LocalizationRun

__all__ = [
    "HELD_OUT_P95_M",
    "ONSITE_FILES",
    "clean_json",
    "onsite_summary",
    "onsite_verdict",
    "summary_lines",
    "write_onsite_report",
]

#: The files :func:`write_onsite_report` writes into its directory.
ONSITE_FILES = ("summary.json", "summary.txt", "report.html")


def onsite_summary(
    name: str, held_out: HeldOutResult | None, stops: list[Stop],
    spreads: list[CheckpointSpread], acceptance: dict[str, Any], *,
    checkpoints_from: str, extrinsic_check: dict[str, Any] | None,
    camera_check: dict[str, Any] | None, run_facts: dict[str, Any],
    extrinsic_by_camera: dict[str, dict[str, Any] | None] | None = None,
    extrinsic_rig: str | None = None,
) -> dict[str, Any]:  # fmt: skip
    """One JSON-ready dict of the on-site evaluation, with its verdict (:func:`onsite_verdict`).
    On a rig, ``extrinsic_by_camera`` holds each camera's mounting check (``extrinsic_check``
    the first camera's) and ``extrinsic_rig`` their relative mounting."""
    passed, why = onsite_verdict(held_out, extrinsic_check, extrinsic_by_camera)
    rig = {} if not extrinsic_by_camera else {
        "extrinsic_check_by_camera": extrinsic_by_camera, "extrinsic_check_rig": extrinsic_rig}
    return {**rig,
        "name": name, "run": run_facts,
        "held_out_tags": None if held_out is None else held_out.to_dict(),
        "checkpoints": {"from": checkpoints_from, "stops": len(stops),
                        "repeatability": [s.to_dict() for s in spreads]},
        "acceptance": acceptance, "extrinsic_check": extrinsic_check,
        "camera_check": camera_check, "verdict": {"passed": passed, "reason": why},
    }  # fmt: skip


#: The verdict's bound on the held-out tags' position error p95, m.
HELD_OUT_P95_M = 0.10


def onsite_verdict(
    held_out: HeldOutResult | None, extrinsic_check: dict[str, Any] | None,
    by_camera: dict[str, dict[str, Any] | None] | None = None,
) -> tuple[bool | None, str]:  # fmt: skip
    """Pass when the held-out tags' position error p95 is within :data:`HELD_OUT_P95_M` and the
    extrinsic check (of every camera of a rig, ``by_camera``) raised no warning; None (no
    verdict) when no held-out tag was seen."""
    warning: str | None
    if by_camera:
        warning = "; ".join(f"camera {n}: {c['warning']}" for n, c in by_camera.items()
                            if c and c.get("warning"))  # fmt: skip
    else:
        warning = (extrinsic_check or {}).get("warning")
    if held_out is None or not held_out.observations:
        if warning:
            return False, str(warning)
        return None, "no held-out tag seen: nothing to judge the map and the estimate by"
    p95 = held_out.stats()["position_m"].p95
    text = (f"held-out tags' position error p95 {p95 * 100:.1f} cm (target <= "
            f"{HELD_OUT_P95_M * 100:g} cm)")  # fmt: skip
    if warning:
        return False, f"{text}; {warning}"
    return bool(p95 <= HELD_OUT_P95_M), text


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
        for camera, s in ho.get("per_camera", {}).items():
            p = s["position_m"]
            lines.append(f"  camera {camera}: {p['n']} views, position median "
                         f"{_f(p['median'], 100)} cm, p95 {_f(p['p95'], 100)} cm")  # fmt: skip
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
        f"{acc['view_angle_unknown']} refused by a per-observation gate, before or after PnP, "
        "have no viewing angle)"
    )
    for key, unit in (("distance_m", "m"), ("view_angle_deg", "deg"),
                      ("laplacian_var", "lap.var"), ("brightness", "grey")):  # fmt: skip
        bins = [b for b in acc.get(key, []) if b["attempts"]]
        if bins:
            lines.append(f"  by {key}: " + ", ".join(
                f"[{b['lo']:g}, {b['hi']:g}) {unit} {b['accepted']}/{b['attempts']}"
                for b in bins))  # fmt: skip
    checks = summary.get("extrinsic_check_by_camera") or {"": summary["extrinsic_check"]}
    for camera, ext in checks.items():
        if ext is None:
            continue
        lines.append(
            f"extrinsic check{f' {camera}' if camera else ''}: {ext['rotation_deg']:.2f} deg / "
            f"{ext['translation_m'] * 100:.1f} cm from {ext['n_pairs']} fix pairs (unobservable: "
            f"{', '.join(ext['unobservable']) or 'none'})"
        )
        if ext["warning"]:
            lines.append(f"WARNING: {ext['warning']}")
    if summary.get("extrinsic_check_rig"):
        lines.append(f"rig: {summary['extrinsic_check_rig']}")
    v = summary.get("verdict")
    if v is not None:
        word = {True: "PASS", False: "FAIL", None: "NO VERDICT"}[v["passed"]]
        lines.append(f"verdict: {word}: {v['reason']}")
    return lines


def write_onsite_report(
    summary: dict[str, Any], held_out: HeldOutResult | None, stops: list[Stop], out_dir: Path,
    run: LocalizationRun | None = None,
) -> list[Path]:  # fmt: skip
    """Write ``summary.json``, ``summary.txt`` and ``report.html`` into ``out_dir`` (all or
    none); return their paths. ``run``: the whole-map pass, for the trajectory and the ladder."""
    from tagloc.eval.onsite_page import render_html

    lines = summary_lines(summary)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        out_dir / "summary.json": json.dumps(clean_json(summary), indent=2, allow_nan=False) + "\n",
        out_dir / "summary.txt": "\n".join(lines) + "\n",
        out_dir / "report.html": render_html(summary, lines, held_out, stops, run),
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
