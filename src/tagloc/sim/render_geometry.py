"""Geometry for the renderer: cached ray grids and image bounding boxes of planar polygons.

Ray grids follow ``cv2.resize`` geometry: a grid of ``w x h`` samples over a ``W x H`` image has
its sample ``(i, j)`` at image pixel ``((i + 0.5) W / w - 0.5, (j + 0.5) H / h - 0.5)`` (OpenCV
pixel centers), so a grid ``k`` times finer than the image is the ``k x k`` supersampling pattern
of every pixel, and ``cv2.resize(..., INTER_AREA)`` of it is the exact box filter.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel

Float32Array = npt.NDArray[np.float32]

#: Points closer to the camera plane than this (m) are clipped before projection.
Z_NEAR_M = 1e-3
#: Samples per polygon edge for bounding boxes (distortion bends the projected edges).
EDGE_SAMPLES = 24
#: Padding of projected bounding boxes, pixels (covers the bulge between edge samples).
BBOX_PAD_PX = 2.0
#: Ray grids kept (about 16 bytes per sample: 44 MB for 1280 x 720 at 2 x 2).
RAY_CACHE_SIZE = 6
#: Rows of the grid passed to ``camera.rays`` at once (bounds the temporary memory).
_CHUNK = 400_000


@dataclass(frozen=True, slots=True)
class RayGrid:
    """Unit rays of a regular grid of sample positions over a camera's image.

    Attributes
    ----------
    rays : (3, h, w) float32
        Ray components ``x, y, z`` in the optical frame as three planes; NaN where the camera
        model has no ray (outside its domain).
    scale_x, scale_y : float
        Samples per image pixel along ``u`` and ``v`` (``w / W``, ``h / H``).
    """

    rays: Float32Array
    scale_x: float
    scale_y: float

    @property
    def shape(self) -> tuple[int, int]:
        """``(h, w)``."""
        return (int(self.rays.shape[1]), int(self.rays.shape[2]))

    def window(self, bbox: tuple[int, int, int, int]) -> tuple[slice, slice]:
        """Grid rows and columns covering image pixels ``bbox = (x0, y0, x1, y1)`` (end-exclusive).

        For a supersampled grid (integer scale) the window is exactly those pixels' samples.
        """
        x0, y0, x1, y1 = bbox
        h, w = self.shape
        c0 = max(0, int(np.floor(x0 * self.scale_x)))
        c1 = min(w, int(np.ceil(x1 * self.scale_x)))
        r0 = max(0, int(np.floor(y0 * self.scale_y)))
        r1 = min(h, int(np.ceil(y1 * self.scale_y)))
        return slice(r0, r1), slice(c0, c1)


_V = TypeVar("_V")


class LruCache:
    """A small thread-safe least-recently-used cache (camera models are hashable values)."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._items: OrderedDict[tuple[object, ...], object] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple[object, ...], make: Callable[[], _V]) -> _V:
        """The value stored under ``key``, made with ``make()`` on a miss."""
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]  # type: ignore[return-value]
        value = make()
        with self._lock:
            self._items[key] = value
            while len(self._items) > self._size:
                self._items.popitem(last=False)
        return value


_RAY_GRIDS = LruCache(RAY_CACHE_SIZE)


def ray_grid(camera: CameraModel, width: int, height: int) -> RayGrid:
    """The (cached) rays of a ``width x height`` sample grid over ``camera``'s image.

    Parameters
    ----------
    camera : CameraModel
        A hashable (frozen) camera model.
    width, height : int
        Grid size; ``k * camera.width`` for ``k x k`` supersampling.

    Returns
    -------
    RayGrid
    """
    return _RAY_GRIDS.get((camera, width, height), lambda: _make_ray_grid(camera, width, height))


def _make_ray_grid(camera: CameraModel, width: int, height: int) -> RayGrid:
    sx, sy = width / camera.width, height / camera.height
    u = (np.arange(width) + 0.5) / sx - 0.5
    v = (np.arange(height) + 0.5) / sy - 0.5
    planes = np.empty((3, height, width), dtype=np.float32)
    rows = max(1, _CHUNK // width)
    for r0 in range(0, height, rows):
        vv, uu = np.meshgrid(v[r0 : r0 + rows], u, indexing="ij")
        rays = camera.rays(np.stack([uu.ravel(), vv.ravel()], axis=-1))
        planes[:, r0 : r0 + rows, :] = rays.T.reshape(3, vv.shape[0], width)
    planes.flags.writeable = False
    return RayGrid(planes, sx, sy)


def clip_polygon(points_cam: FloatArray, z_near: float = Z_NEAR_M) -> FloatArray:
    """Clip a convex planar polygon to the half-space ``z >= z_near`` (Sutherland-Hodgman).

    Parameters
    ----------
    points_cam : (n, 3) float
        Vertices in order, optical frame.
    z_near : float
        Clipping plane, metres.

    Returns
    -------
    (m, 3) float
        The clipped polygon (``m = 0`` when it lies entirely behind the plane).
    """
    out: list[FloatArray] = []
    n = len(points_cam)
    for i in range(n):
        p, q = points_cam[i], points_cam[(i + 1) % n]
        p_in, q_in = p[2] >= z_near, q[2] >= z_near
        if p_in:
            out.append(p)
        if p_in != q_in:
            s = (z_near - p[2]) / (q[2] - p[2])
            out.append(p + s * (q - p))
    return np.array(out, dtype=np.float64).reshape(-1, 3)


def polygon_bboxes(
    camera: CameraModel, polygons: list[FloatArray]
) -> list[tuple[int, int, int, int] | None]:
    """Image pixels each convex planar polygon can cover, as ``(x0, y0, x1, y1)`` (end-exclusive).

    Each polygon is clipped to ``z >= Z_NEAR_M``, its edges are sampled and projected (one
    ``camera.project`` call for all), and the box of the projections (padded by ``BBOX_PAD_PX``)
    is clipped to the image. This bounds the projected region because the models map directions
    in their domain one-to-one onto the image plane. When an edge sample falls outside the
    model's domain (beyond a distortion fold) the whole image is returned (conservative).

    Parameters
    ----------
    camera : CameraModel
    polygons : list of (n, 3) float
        Polygon vertices in the optical frame.

    Returns
    -------
    list of (tuple of 4 int, or None)
        None for a polygon behind the camera or projecting outside the image.
    """
    s = np.linspace(0.0, 1.0, EDGE_SAMPLES, endpoint=False)[None, :, None]
    clipped = [clip_polygon(points) for points in polygons]
    samples = [
        (c[:, None, :] * (1.0 - s) + np.roll(c, -1, axis=0)[:, None, :] * s).reshape(-1, 3)
        for c in clipped
        if len(c) >= 3
    ]
    if not samples:
        return [None] * len(polygons)
    with np.errstate(invalid="ignore", over="ignore"):
        pixels = camera.project(np.vstack(samples))
    boxes: list[tuple[int, int, int, int] | None] = []
    start = 0
    for c in clipped:
        if len(c) < 3:
            boxes.append(None)
            continue
        px = pixels[start : start + len(c) * EDGE_SAMPLES]
        start += len(c) * EDGE_SAMPLES
        boxes.append(_clipped_box(camera, px))
    return boxes


def _clipped_box(camera: CameraModel, pixels: FloatArray) -> tuple[int, int, int, int] | None:
    if not np.isfinite(pixels).all():
        return (0, 0, camera.width, camera.height)
    lo = pixels.min(axis=0) - BBOX_PAD_PX
    hi = pixels.max(axis=0) + BBOX_PAD_PX
    # Pixel j covers [j - 0.5, j + 0.5].
    x0 = max(0, int(np.floor(lo[0] + 0.5)))
    y0 = max(0, int(np.floor(lo[1] + 0.5)))
    x1 = min(camera.width, int(np.floor(hi[0] + 0.5)) + 1)
    y1 = min(camera.height, int(np.floor(hi[1] + 0.5)) + 1)
    if x1 <= x0 or y1 <= y0:
        return None
    return (x0, y0, x1, y1)


def boxes_overlap(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    """Whether two end-exclusive pixel boxes ``(x0, y0, x1, y1)`` intersect."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
