"""The renderer's pipeline for one image: tag layers, surroundings, motion blur, the sensor.

:func:`render_image` is what :func:`tagloc.sim.render.render_view`, ``render_tags_scene`` and
``render_frames`` call; the steps are described in :mod:`tagloc.sim.render`.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.sim.render_background import render_background
from tagloc.sim.render_config import RenderConfig
from tagloc.sim.render_effects import background_flow, blur, expose, line_kernel, point_flow
from tagloc.sim.render_geometry import Float32Array, ray_grid
from tagloc.sim.render_scene import Scene, view_walls
from tagloc.sim.render_tags import TagLayer, TagTruth, rasterize_tag, tags_in_view


def render_image(
    scene: Scene,
    camera: CameraModel,
    T_map_cam: SE3,
    config: RenderConfig,
    rng: np.random.Generator | None,
    twist_cam: npt.ArrayLike | None,
    backdrop: Float32Array | None,
) -> tuple[npt.NDArray[np.uint8], tuple[TagTruth, ...]]:
    """The 8-bit image of ``scene`` from ``T_map_cam``, and the truths of the tags in view.

    Parameters
    ----------
    scene : Scene
    camera : CameraModel
    T_map_cam : SE3
        Camera pose at mid-exposure.
    config : RenderConfig
    rng : numpy.random.Generator or None
        Noise source (None: ``default_rng(config.seed)``).
    twist_cam : (6,) array_like or None
        Camera body twist (optical frame) for motion blur.
    backdrop : (H, W) float32 or None
        Flat backdrop albedo instead of the scene's walls, floor and ceiling.

    Returns
    -------
    image : (H, W) uint8
    truths : tuple of TagTruth
    """
    rng = rng if rng is not None else np.random.default_rng(config.seed)
    twist = None if twist_cam is None else np.asarray(twist_cam, dtype=np.float64).reshape(6)
    moving = twist is not None and config.exposure_s > 0 and bool(np.any(twist != 0))
    if moving and config.motion_blur == "subframes":
        assert twist is not None
        n = config.subframes
        taus = ((np.arange(n) + 0.5) / n - 0.5) * config.exposure_s
        irradiance = np.zeros((camera.height, camera.width), dtype=np.float32)
        for tau in taus:
            sub, _ = _irradiance(scene, camera, T_map_cam.plus(tau * twist), config, backdrop)
            irradiance += sub / np.float32(n)
        truths = _irradiance(scene, camera, T_map_cam, config, backdrop, tags_only=True)[1]
    else:
        irradiance, truths = _irradiance(
            scene, camera, T_map_cam, config, backdrop, twist if moving else None
        )
    return expose(irradiance, camera, config, rng), truths


def _irradiance(
    scene: Scene,
    camera: CameraModel,
    T_map_cam: SE3,
    config: RenderConfig,
    backdrop: Float32Array | None,
    twist: FloatArray | None = None,
    *,
    tags_only: bool = False,
) -> tuple[Float32Array, tuple[TagTruth, ...]]:
    """Albedo-irradiance image and tag truths; ``twist`` set: directional motion blur."""
    W, H = camera.width, camera.height
    T_cam_map = T_map_cam.inverse()
    k = config.supersample
    walls = view_walls(scene, camera, T_map_cam) if backdrop is None else None
    # 1. tag layers (and ground truth), far to near
    layers: list[TagLayer] = []
    truths: list[TagTruth] = []
    grid_tags = ray_grid(camera, W * k, H * k)
    for view in tags_in_view(scene, T_cam_map, camera, config):
        layer, truth = rasterize_tag(view, camera, grid_tags, walls, config)
        truths.append(truth)
        if layer is not None:
            layers.append(layer)
    if tags_only:
        return np.zeros((0, 0), np.float32), tuple(truths)
    layers.sort(key=lambda layer: -float(np.linalg.norm(layer.center_cam)))
    # 2. background: backdrop, or surroundings cast at background_scale and upsampled
    if backdrop is not None:
        image = backdrop.copy()
    else:
        w_bg = max(1, round(W * config.background_scale))
        h_bg = max(1, round(H * config.background_scale))
        grid_bg = ray_grid(camera, w_bg, h_bg)
        assert walls is not None
        albedo, depth = render_background(scene, walls, grid_bg, config)
        image = np.asarray(cv2.resize(albedo, (W, H), interpolation=cv2.INTER_LINEAR))
        if twist is not None:
            flow = background_flow(camera, grid_bg, depth, twist, config.exposure_s)
            image = blur(image, line_kernel(flow))
    # 3. composite the tag layers over it, each blurred along its own flow
    for layer in layers:
        premultiplied, coverage, bbox = layer.premultiplied, layer.coverage, layer.bbox
        if twist is not None:
            flow = point_flow(camera, layer.center_cam[None, :], twist, config.exposure_s)[0]
            premultiplied, coverage, bbox = _blurred_layer(layer, line_kernel(flow), (W, H))
        x0, y0, x1, y1 = bbox
        window = image[y0:y1, x0:x1]
        window *= 1.0 - coverage
        window += premultiplied
    return image, tuple(truths)


def _blurred_layer(
    layer: TagLayer, kernel: Float32Array | None, image_size: tuple[int, int]
) -> tuple[Float32Array, Float32Array, tuple[int, int, int, int]]:
    """A tag layer convolved with ``kernel``, in its window grown by the kernel's radius."""
    if kernel is None:
        return layer.premultiplied, layer.coverage, layer.bbox
    radius = kernel.shape[0] // 2
    x0, y0, x1, y1 = layer.bbox
    X0, Y0 = max(0, x0 - radius), max(0, y0 - radius)
    X1, Y1 = min(image_size[0], x1 + radius), min(image_size[1], y1 + radius)
    out: list[Float32Array] = []
    for plane in (layer.premultiplied, layer.coverage):
        padded = np.zeros((Y1 - Y0, X1 - X0), dtype=np.float32)
        padded[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0] = plane
        filtered = cv2.filter2D(padded, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        out.append(np.asarray(filtered, dtype=np.float32))
    coverage = np.asarray(np.clip(out[1], 0.0, 1.0), dtype=np.float32)
    return out[0], coverage, (X0, Y0, X1, Y1)
