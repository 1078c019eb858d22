"""The overlay image of ``tagloc detect``: what :func:`~tagloc.eval.tag_check.check_frame` found,
drawn on the camera image (a pure function; the file is written by :mod:`tagloc.io.images`).

Each tag: its corners (green if accepted, red if refused, orange if mirrored), the tag frame's
axes through the camera model (x red, y green, z blue, half the tag's size long, from the
accepted pose or else PnP's best branch), its id and the verdict (``ok`` or the reason).
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from tagloc.camera import CameraModel
from tagloc.eval.tag_check import FrameCheck, TagCheck

__all__ = ["draw_frame_check"]

_GREEN, _RED, _ORANGE = (60, 200, 60), (40, 40, 230), (0, 160, 255)
_AXES = ((0, 0, 255), (0, 200, 0), (255, 80, 0))  # BGR of x, y, z


def draw_frame_check(
    image: npt.NDArray[np.uint8], check: FrameCheck, camera: CameraModel
) -> npt.NDArray[np.uint8]:
    """A BGR copy of ``image`` with every tag of ``check`` drawn (module docstring)."""
    canvas: npt.NDArray[np.uint8] = np.asarray(
        cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy(), np.uint8
    )
    scale = max(1, round(max(canvas.shape[:2]) / 900))
    for tag in check.tags:
        _draw_tag(canvas, tag, camera, scale)
    for det in check.mirrored:
        _polygon(canvas, det.corners_px, _ORANGE, scale)
        _label(canvas, det.corners_px, f"id {det.tag_id} MIRRORED", _ORANGE, scale)
    y = 20 * scale
    for note in check.notes:
        cv2.rectangle(canvas, (0, y - 15 * scale), (canvas.shape[1], y + 5 * scale), (0, 0, 0), -1)
        cv2.putText(
            canvas,
            note[:150],
            (8, y),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45 * scale,
            (255, 255, 255),
            scale,
            cv2.LINE_AA,
        )
        y += 20 * scale
    return canvas


def _draw_tag(
    canvas: npt.NDArray[np.uint8], tag: TagCheck, camera: CameraModel, scale: int
) -> None:
    ok = tag.accepted is not None
    color = _GREEN if ok else _RED
    corners = tag.detection.corners_px
    _polygon(canvas, corners, color, scale)
    est = tag.accepted or tag.estimate
    if est is not None:
        half = 0.5 * est.size
        points_tag = np.array([[0, 0, 0], [half, 0, 0], [0, half, 0], [0, 0, half]], float)
        px = camera.project(est.T_cam_tag.act(points_tag))
        if np.isfinite(px).all():
            origin = tuple(round(float(v)) for v in px[0])
            for k in range(3):
                end = tuple(round(float(v)) for v in px[k + 1])
                cv2.line(canvas, origin, end, _AXES[k], 2 * scale, cv2.LINE_AA)
    verdict = "ok" if ok else (tag.refusal.split(":")[0] or "refused")
    _label(canvas, corners, f"id {tag.detection.tag_id} {verdict}", color, scale)


def _polygon(
    canvas: npt.NDArray[np.uint8], corners: npt.ArrayLike, color: tuple[int, int, int], scale: int
) -> None:
    pts = np.round(np.asarray(corners)).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(canvas, [pts], True, color, 2 * scale, cv2.LINE_AA)
    cv2.circle(canvas, tuple(int(v) for v in pts[0, 0]), 4 * scale, color, -1)  # top-left


def _label(
    canvas: npt.NDArray[np.uint8],
    corners: npt.ArrayLike,
    text: str,
    color: tuple[int, int, int],
    scale: int,
) -> None:
    c = np.asarray(corners)
    x, y = int(c[:, 0].min()), int(c[:, 1].min()) - 6 * scale
    cv2.putText(
        canvas,
        text,
        (x, max(y, 12 * scale)),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.5 * scale,
        color,
        max(1, scale),
        cv2.LINE_AA,
    )
