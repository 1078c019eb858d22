"""Writing the tag map as ``tags.yaml`` text: the header comment and each entry's lines, in a
fixed layout with fixed precision, so that the same map always gives the same bytes."""

from __future__ import annotations

import json

import numpy as np
import numpy.typing as npt
import yaml

from tagloc.tags.tag_entry import TagEntry
from tagloc.tags.tagmap_checks import Row6, _canonical_sign, _covariance_problem

_INFLATIONS = (0.0, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)

_HEADER = (
    "# tagloc tag map. Check: `tagloc map check FILE`; compare two: `tagloc map diff A B`.",
    "# A tag's pose is T_frame_tag: the tag frame (origin at the tag centre, z out of the printed",
    "#   face towards a viewer, x to the viewer's right, y up) expressed in `frame`: `map`",
    "#   (static) or a moving frame listed in `frames` (e.g. elevator_cab).",
    "# size: black-border edge, metres. position: [x, y, z], metres (6 decimals = micrometres).",
    "# quat_xyzw: [x, y, z, w] (ROS/scipy order), unit norm within 1e-6, written with w >= 0.",
    "# covariance (optional): 6x6 rows of the right perturbation T_frame_tag (+) [x, y, z, rx,",
    "#   ry, rz] (metres, radians; translation first, as ROS PoseWithCovariance).",
    "# anchor: true = surveyed pose, a prior of the map builder; anchor_sigma: its standard",
    "#   deviation per axis {position_m, rotation_deg}. observations: builder count.",
    "# Tags are sorted by (family, id). Saving rewrites the file: comments are lost; use note.",
)


def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _height(value: float) -> str:
    text = _fixed(value, 6).rstrip("0")
    return text + "0" if text.endswith(".") else text


def _sci(value: float) -> str:
    text = f"{value:.2e}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _plain(text: str) -> str:
    """``text`` as a YAML scalar: plain if it reads back as the same string, else quoted."""
    return text if yaml.safe_load(text) == text else json.dumps(text)


def _quat_for_file(quat_xyzw: tuple[float, float, float, float]) -> list[str]:
    """9 decimals of the quaternion, normalized if off by > 1e-8, sign chosen after rounding.

    Rounding can push a barely-unit quaternion past the tolerance; it is then normalized and
    rounded again (which stays within 1e-9), so the written values are a fixed point: loading
    and saving them again gives the same bytes.
    """

    def rounded(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.array([float(_fixed(float(c), 9)) for c in q])

    q = np.array(quat_xyzw, dtype=float)
    if abs(np.linalg.norm(q) - 1.0) > 1e-8:
        q = q / np.linalg.norm(q)
    q = rounded(q)
    if abs(np.linalg.norm(q) - 1.0) > 1e-8:
        q = rounded(q / np.linalg.norm(q))
    x, y, z, w = (float(c) for c in q)
    return [_fixed(c, 9) for c in _canonical_sign((x, y, z, w))]


def _covariance_for_file(covariance: tuple[Row6, ...]) -> list[str]:
    """Rows of 3-significant-digit numbers that read back as a symmetric PSD matrix."""
    cov = np.array(covariance)
    cov = (cov + cov.T) / 2
    for inflation in _INFLATIONS:
        rows = [[_sci(float(v)) for v in row] for row in cov + inflation * np.diag(np.diag(cov))]
        if _covariance_problem(np.array(rows, dtype=float)) is None:
            return [f"      - [{', '.join(row)}]" for row in rows]
    raise AssertionError("unreachable: a PSD covariance stays PSD after inflating by 10 %")


def _entry_lines(tag: TagEntry) -> list[str]:
    size = _fixed(tag.size, 6).rstrip("0")
    lines = [
        f"  - id: {tag.id}",
        f"    family: {tag.family}",
        f"    size: {size}0" if size.endswith(".") else f"    size: {size}",
        f"    frame: {_plain(tag.frame)}",
        *([f"    floor: {json.dumps(tag.floor)}"] if tag.floor is not None else []),
        f"    position: [{', '.join(_fixed(v, 6) for v in tag.position)}]",
        f"    quat_xyzw: [{', '.join(_quat_for_file(tag.quat_xyzw))}]",
    ]
    if tag.anchor:
        lines.append("    anchor: true")
    if tag.anchor_sigma is not None:
        sigma = tag.anchor_sigma
        lines.append(
            f"    anchor_sigma: {{position_m: {sigma.position_m:.6g}, "
            f"rotation_deg: {sigma.rotation_deg:.6g}}}"
        )
    if tag.observations is not None:
        lines.append(f"    observations: {tag.observations}")
    if tag.note:
        lines.append(f"    note: {json.dumps(tag.note, ensure_ascii=False)}")
    if tag.covariance is not None:
        lines += ["    covariance:", *_covariance_for_file(tag.covariance)]
    return lines
