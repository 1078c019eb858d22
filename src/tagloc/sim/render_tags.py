"""Tags by ray casting: each supersample's ray meets the tag plane, the hit is looked up in the
tag's bitmap (bilinear), and walls nearer along the same ray hide it.

Exactness. The bitmap is chosen (per tag and view, in powers of two) with a texel no larger than
one supersample at the tag's nearest point, so bilinear interpolation between texel centers puts
every black/white transition exactly on the cell boundary (its 50 % crossing), and the ``k x k``
box filter of the supersamples is the pixel's area average. Tag plane coordinates map to bitmap
pixels with :func:`tagloc.tags.bitmap_corners_px`' convention (texel ``i`` spans
``[i - 0.5, i + 0.5]``), and samples sit at OpenCV pixel centers
(:mod:`tagloc.sim.render_geometry`), so the true corners are ``camera.project`` of the tag's
object points with no half-pixel offset.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3, SO3
from tagloc.sim.render_config import RenderConfig
from tagloc.sim.render_geometry import (
    Float32Array,
    RayGrid,
    boxes_overlap,
    polygon_bboxes,
)
from tagloc.sim.render_scene import GLASS, Scene, SceneTag, ViewWalls
from tagloc.tags import bitmap_corners_px, family_spec, tag_bitmap, tag_object_points

#: A wall hides a tag sample when it is nearer by more than this (m, plus 1e-5 of the range):
#: tags lie on their walls, so equal depths must not count.
OCCLUSION_EPS_M = 1e-3
#: Largest bitmap cell, pixels (a closer tag gets a texel larger than a supersample).
MAX_CELL_PX = 128


@dataclass(frozen=True, slots=True, eq=False)
class TagTruth:
    """Ground truth of one tag in one rendered image.

    Attributes
    ----------
    tag_id : int
    family : str
    size : float
        Black-border edge, m.
    corners_px : (4, 2) float
        Where the black-border corners project (top-left, top-right, bottom-right, bottom-left
        of the upright tag; OpenCV pixel centers): the detector's convention. A corner outside
        the camera model's domain is NaN; a corner may lie outside the image.
    T_cam_tag : SE3
        True pose of the tag in the camera's optical frame (mid-exposure).
    range_m : float
        Distance from the camera center to the tag center, m.
    view_angle_rad : float
        Angle between the tag's face normal and the line of sight from the tag to the camera
        (0 = seen head-on).
    fraction_visible : float
        Fraction of the black-border square's area that is in the image and not hidden by a wall
        (0 for a tag in the field of view but fully occluded): the tag-plane area of the visible
        ray samples. Within about 1 % for tags at least 10 px across seen at up to 75 degrees;
        noisy for tags only a few pixels across (grazing views).

    Notes
    -----
    Equality is identity (arrays inside); ``corners_px`` is read-only.
    """

    tag_id: int
    family: str
    size: float
    corners_px: FloatArray
    T_cam_tag: SE3
    range_m: float
    view_angle_rad: float
    fraction_visible: float

    @property
    def visible(self) -> bool:
        """Whether any part of the black-border square is visible."""
        return self.fraction_visible > 0.0


@dataclass(frozen=True, slots=True)
class TagLayer:
    """A tag rendered into a pixel window, ready to composite.

    Attributes
    ----------
    bbox : (x0, y0, x1, y1)
        Image window, end-exclusive.
    premultiplied : (y1 - y0, x1 - x0) float32
        Area average of ``albedo * coverage``.
    coverage : (y1 - y0, x1 - x0) float32
        Area fraction covered by the (visible part of the) tag sheet.
    center_cam : (3,) float
        Tag center in the optical frame (for sorting and motion blur).
    """

    bbox: tuple[int, int, int, int]
    premultiplied: Float32Array
    coverage: Float32Array
    center_cam: FloatArray


@functools.lru_cache(maxsize=32)
def _tag_texture(
    family: str, tag_id: int, cells_px: int, quiet_zone_cells: int
) -> tuple[Float32Array, float, float]:
    """The bitmap in ``[0, 1]`` (float32), its black-border corner ``a`` and edge ``B``, pixels."""
    bitmap = tag_bitmap(family, tag_id, cells_px, quiet_zone_cells).astype(np.float32) / 255.0
    corners = bitmap_corners_px(family, cells_px, quiet_zone_cells)
    return bitmap, float(corners[0, 0]), float(corners[1, 0] - corners[0, 0])


@dataclass(frozen=True, slots=True)
class TagView:
    """A tag facing the camera whose sheet projects into the image.

    Attributes
    ----------
    tag : SceneTag
    T_cam_tag : SE3
    half_sheet : float
        Half the edge of the sheet (black border plus quiet zone), m.
    sheet_z_min : float
        Smallest depth of the sheet's corners, m.
    bbox : (x0, y0, x1, y1)
        Image pixels the sheet can cover.
    """

    tag: SceneTag
    T_cam_tag: SE3
    half_sheet: float
    sheet_z_min: float
    bbox: tuple[int, int, int, int]


def tags_in_view(
    scene: Scene, T_cam_map: SE3, camera: CameraModel, config: RenderConfig
) -> list[TagView]:
    """The scene's tags that face the camera, lie within ``max_tag_range_m`` and project into it.

    Culling is vectorized over all tags; one ``camera.project`` call bounds every sheet.
    """
    if not scene.tags:
        return []
    R_cam_map = T_cam_map.rotation.as_matrix()
    R = R_cam_map @ scene.tag_rotation  # (N, 3, 3) R_cam_tag
    p = scene.tag_translation @ R_cam_map.T + np.asarray(T_cam_map.translation)
    facing = np.einsum("ij,ij->i", R[:, :, 2], p) < 0.0  # the camera is on the printed side
    near = np.linalg.norm(p, axis=1) <= config.max_tag_range_m
    candidates = np.flatnonzero(facing & near).tolist()
    q = config.quiet_zone_cells
    halves, sheets = [], []
    unit = np.array([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]])
    for i in candidates:
        tag = scene.tags[i]
        border_cells = family_spec(tag.family).border_cells
        halves.append(0.5 * tag.size * (border_cells + 2 * q) / border_cells)
        sheets.append((halves[-1] * unit) @ R[i].T + p[i])
    views = []
    for i, half, sheet, bbox in zip(
        candidates, halves, sheets, polygon_bboxes(camera, sheets), strict=True
    ):
        if bbox is not None:
            T_cam_tag = SE3(rotation=SO3.from_matrix(R[i]), translation=p[i])
            views.append(TagView(scene.tags[i], T_cam_tag, half, float(sheet[:, 2].min()), bbox))
    return views


def rasterize_tag(
    view: TagView,
    camera: CameraModel,
    grid: RayGrid,
    walls: ViewWalls | None,
    config: RenderConfig,
) -> tuple[TagLayer | None, TagTruth]:
    """Render one tag (sheet and quiet zone) into its image window, with its ground truth.

    Parameters
    ----------
    view : TagView
        The tag and where it is (from :func:`tags_in_view`).
    camera : CameraModel
    grid : RayGrid
        The supersampled ray grid (``config.supersample`` times the image in each direction).
    walls : ViewWalls or None
        Occluders (None: none).
    config : RenderConfig

    Returns
    -------
    layer : TagLayer or None
        None if nothing of the sheet is visible.
    truth : TagTruth
    """
    tag, T_cam_tag, half_sheet, bbox = view.tag, view.T_cam_tag, view.half_sheet, view.bbox
    R = T_cam_tag.rotation.as_matrix()
    p0 = np.asarray(T_cam_tag.translation, dtype=np.float64)
    ex, ey, n = R[:, 0], R[:, 1], R[:, 2]
    range_m = float(np.linalg.norm(p0))
    border_cells = family_spec(tag.family).border_cells
    q = config.quiet_zone_cells
    corners_px = camera.project(T_cam_tag.act(tag_object_points(tag.size)))
    corners_px.flags.writeable = False
    view_angle = math.acos(min(1.0, float(-(n @ p0)) / range_m))
    k = config.supersample
    rows, cols = grid.window(bbox)
    r = grid.rays[:, rows, cols]
    # 1. ray / tag-plane intersection and tag-plane coordinates of every supersample
    f32 = np.float32
    with np.errstate(divide="ignore", invalid="ignore"):
        rn = f32(n[0]) * r[0] + f32(n[1]) * r[1] + f32(n[2]) * r[2]
        t = f32(n @ p0) / rn
        x = t * (f32(ex[0]) * r[0] + f32(ex[1]) * r[1] + f32(ex[2]) * r[2]) - f32(ex @ p0)
        y = t * (f32(ey[0]) * r[0] + f32(ey[1]) * r[1] + f32(ey[2]) * r[2]) - f32(ey @ p0)
        valid = rn < 0
        on_sheet = valid & (np.abs(x) <= half_sheet) & (np.abs(y) <= half_sheet)
    # 2. occlusion and tint by walls along the same rays
    visible, transmitted = _occlusion(on_sheet, t, r, bbox, walls, config)
    # 3. bitmap lookup (bilinear) at a texel no larger than a supersample
    z_near = max(view.sheet_z_min, 1e-3)
    cell_px = max(camera.K[0, 0], camera.K[1, 1]) * tag.size / border_cells / z_near * k
    cells_px = int(min(MAX_CELL_PX, 2 ** math.ceil(math.log2(max(cell_px, 1.0)))))
    bitmap, a, edge = _tag_texture(tag.family, tag.tag_id, cells_px, q)
    scale = f32(edge / tag.size)
    map_u = np.nan_to_num(f32(a + 0.5 * edge) + x * scale, nan=-1.0)
    map_v = np.nan_to_num(f32(a + 0.5 * edge) - y * scale, nan=-1.0)
    value = cv2.remap(bitmap, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    albedo = f32(config.tag_black) + f32(config.tag_white - config.tag_black) * value
    albedo = albedo * transmitted + f32(config.glass_albedo) * (1.0 - transmitted)
    # 4. ground truth: visible fraction of the black-border square, by tag-plane area
    fraction = _square_area(x, y, visible, 0.5 * tag.size) / tag.size**2
    truth = TagTruth(
        tag.tag_id, tag.family, tag.size, corners_px, T_cam_tag, range_m, view_angle,
        min(1.0, fraction),
    )  # fmt: skip
    if not visible.any():
        return None, truth
    # 5. box filter of the k x k supersamples of each pixel
    size = (bbox[2] - bbox[0], bbox[3] - bbox[1])
    cover = visible.astype(np.float32)
    premultiplied = cv2.resize(albedo * cover, size, interpolation=cv2.INTER_AREA)
    coverage = cv2.resize(cover, size, interpolation=cv2.INTER_AREA)
    return (
        TagLayer(
            bbox,
            np.asarray(premultiplied, dtype=np.float32),
            np.asarray(coverage, dtype=np.float32),
            p0,
        ),
        truth,
    )


def _occlusion(
    on_sheet: np.ndarray,
    t: Float32Array,
    r: Float32Array,
    bbox: tuple[int, int, int, int],
    walls: ViewWalls | None,
    config: RenderConfig,
) -> tuple[np.ndarray, Float32Array]:
    """Samples of the sheet no opaque wall hides, and the glass transmittance in front of them."""
    transmitted = np.ones(t.shape, dtype=np.float32)
    if walls is None or not on_sheet.any():
        return on_sheet, transmitted
    t_far = float(np.max(t, where=on_sheet, initial=0.0))
    visible = on_sheet.copy()
    limit = t * np.float32(1.0 - 1e-5) - np.float32(OCCLUSION_EPS_M)
    rz_up = walls.up[0] * r[0] + walls.up[1] * r[1] + walls.up[2] * r[2]
    for k in range(len(walls.index)):
        if walls.min_dist[k] >= t_far or not boxes_overlap(walls.bbox[k], bbox):
            continue
        nearer = walls.hits(k, r, rz_up) < limit
        if walls.material[k] == GLASS:
            transmitted[nearer] *= np.float32(config.glass_transmittance)
        else:
            visible &= ~nearer
    return visible, transmitted


def _square_area(x: Float32Array, y: Float32Array, mask: np.ndarray, half: float) -> float:
    """Area (m^2) of the square ``|x|, |y| <= half`` covered by the samples in ``mask``.

    Each sample stands for the tag-plane parallelogram ``|det J|``, ``J = d(x, y)/d(row, col)``;
    near the square's edges it counts with the fraction of its extent inside (a linear ramp over
    the sample's extent ``|x_r| + |x_c|`` across the edge), which removes the sample-counting
    error of about one sample per side.
    """
    if min(x.shape) < 2 or not mask.any():
        return 0.0
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    x_r, x_c = np.gradient(x64)
    y_r, y_c = np.gradient(y64)
    with np.errstate(invalid="ignore", divide="ignore"):
        inside_x = np.clip(0.5 + (half - np.abs(x64)) / (np.abs(x_r) + np.abs(x_c)), 0.0, 1.0)
        inside_y = np.clip(0.5 + (half - np.abs(y64)) / (np.abs(y_r) + np.abs(y_c)), 0.0, 1.0)
        d_area = np.abs(x_c * y_r - x_r * y_c) * inside_x * inside_y
    return float(np.nansum(d_area, where=mask))
