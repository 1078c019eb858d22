"""What ``tagloc detect`` prints and saves of a :class:`~tagloc.eval.tag_check.FrameCheck`:
a few lines per tag for the terminal, and a JSON-ready dict (``detections.json``).

Poses are ``T_cam_tag`` (the tag in the camera's optical frame: x right, y down, z forward),
translation in metres and rotation as ``quat_xyzw``; ``sigma`` is the 1-sigma of the accepted
covariance (right tangent, ``[x, y, z]`` m in the tag frame, ``[rx, ry, rz]`` rad).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tagloc.eval.tag_check import FrameCheck, GateResult, TagCheck
from tagloc.geometry import SE3

__all__ = ["frame_check_dict", "frame_check_lines"]


def _pose(T: SE3) -> dict[str, list[float]]:
    return {
        "translation_m": [float(v) for v in T.translation],
        "quat_xyzw": [float(v) for v in T.rotation.as_quat()],
    }


def _num(value: float) -> float | None:
    return None if not math.isfinite(value) else float(value)


def _gate(g: GateResult) -> dict[str, Any]:
    return {
        "name": g.name,
        "value": _num(g.value),
        "limit": _num(g.limit),
        "passed": g.passed,
        "detail": g.detail,
    }


def _tag_dict(tag: TagCheck) -> dict[str, Any]:
    det, est = tag.detection, tag.estimate
    out: dict[str, Any] = {
        "id": det.tag_id,
        "family": det.family,
        "size_m": tag.size_m,
        "in_map": tag.in_map,
        "accepted": tag.accepted is not None,
        "refusal": tag.refusal,
        "corners_px": np.asarray(det.corners_px).tolist(),
        "hamming": det.hamming,
        "decision_margin": _num(det.decision_margin),
    }
    chosen = tag.accepted or est
    if chosen is not None:
        sigma = tag.sigma
        out["T_cam_tag"] = _pose(chosen.T_cam_tag)
        out["sigma"] = None if sigma is None else [float(v) for v in sigma]
        out["reproj_err_px"] = float(chosen.reproj_err_px)
        out["range_m"] = float(chosen.range_m)
        out["view_angle_deg"] = math.degrees(chosen.view_angle_rad)
    if est is not None:
        out["branches"] = [
            {**_pose(est.T_cam_tag), "reproj_err_px": float(est.reproj_err_px)},
            {**_pose(est.T_cam_tag_alt), "reproj_err_px": _num(est.reproj_err_alt_px)},
        ]
    if tag.decision is not None:
        d = tag.decision
        out["ambiguity"] = {
            "choose_alt": d.choose_alt,
            "log_odds": _num(d.log_odds),
            "data_log_odds": _num(d.data_log_odds),
            "reason": None if d.reason is None else str(d.reason),
            "detail": d.detail,
        }
    out["gates"] = [_gate(g) for g in tag.gates]
    out["notes"] = list(tag.notes)
    return out


def frame_check_dict(check: FrameCheck) -> dict[str, Any]:
    """``check`` as plain JSON types (non-finite numbers as null)."""
    joint = None
    if check.joint is not None:
        joint = {
            "tag_ids": list(check.joint.tag_ids),
            "T_map_cam": _pose(check.joint.T_map_cam),
            "reproj_err_px": float(check.joint.reproj_err_px),
        }
    return {
        "image": check.name,
        "image_size": list(check.image_size),
        "tags": [_tag_dict(t) for t in check.tags],
        "mirrored": [
            {"id": d.tag_id, "family": d.family, "corners_px": np.asarray(d.corners_px).tolist()}
            for d in check.mirrored
        ],
        "joint": joint,
        "notes": list(check.notes),
    }


def _gate_text(g: GateResult) -> str:
    if g.passed is None:
        return f"{g.name} n/a"
    mark = "ok" if g.passed else "FAIL"
    if g.name == "fix_quality":
        return f"{g.name} {mark}" + (f" ({g.detail})" if g.detail else "")
    return f"{g.name} {g.value:.3g}/{g.limit:.3g} {mark}"


def frame_check_lines(check: FrameCheck) -> list[str]:
    """A few lines per tag: verdict, pose and sigma, both branches, the decision, the gates."""
    width, height = check.image_size
    lines = [f"{check.name} ({width}x{height}): {len(check.tags)} tag(s)"]
    for tag in check.tags:
        det, est = tag.detection, tag.estimate
        verdict = "accepted" if tag.accepted is not None else f"refused ({tag.refusal})"
        size = "size unknown" if tag.size_m is None else f"size {tag.size_m:g} m"
        where = "in the map" if tag.in_map else "not in the map"
        lines.append(f"  tag {det.family}:{det.tag_id} {verdict}; {size}, {where}")
        chosen = tag.accepted or est
        if chosen is not None and tag.sigma is not None:
            t = chosen.T_cam_tag.translation
            rv = np.degrees(chosen.T_cam_tag.rotation.as_rotvec())
            s = tag.sigma
            lines.append(
                f"    T_cam_tag t [{t[0]:+.3f} {t[1]:+.3f} {t[2]:+.3f}] m, rotvec "
                f"[{rv[0]:+.1f} {rv[1]:+.1f} {rv[2]:+.1f}] deg; sigma "
                f"[{1e3 * s[0]:.1f} {1e3 * s[1]:.1f} {1e3 * s[2]:.1f}] mm "
                f"[{np.degrees(s[3]):.2f} {np.degrees(s[4]):.2f} {np.degrees(s[5]):.2f}] deg"
            )
        if est is not None:
            R_best, R_alt = est.T_cam_tag.rotation, est.T_cam_tag_alt.rotation
            apart = np.degrees(np.linalg.norm((R_best.inverse() @ R_alt).as_rotvec()))
            lines.append(
                f"    IPPE branches: best {est.reproj_err_px:.3f} px, other "
                f"{est.reproj_err_alt_px:.3f} px, {apart:.1f} deg apart"
            )
        if tag.decision is not None:
            d = tag.decision
            lines.append(f"    ambiguity: {'refused' if d.reason else 'decided'}, {d.detail}")
        lines.append("    gates: " + ", ".join(_gate_text(g) for g in tag.gates))
    if check.joint is not None:
        j = check.joint
        lines.append(
            f"  joint over tags {', '.join(map(str, j.tag_ids))}: camera in the map at "
            f"{np.round(j.T_map_cam.translation, 3).tolist()} m, "
            f"{j.reproj_err_px:.3f} px"
        )
    lines += [f"  NOTE: {note}" for note in check.notes]
    return lines
