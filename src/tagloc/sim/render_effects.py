"""Camera effects on the irradiance image: motion blur kernels, vignetting, noise, quantization.

Motion: over the exposure the camera moves with its constant body twist ``xi = [v, w]``
(optical frame, ``[x, y, z, rx, ry, rz]``), so at time ``tau`` from mid-exposure its pose is
``T_map_cam @ Exp(tau xi)`` and a static point ``p`` (optical frame at mid-exposure) is at
``Exp(tau xi)^-1 p``. Its image-space motion over the exposure is the *flow*
``project(p(+e/2)) - project(p(-e/2))``, and a linear blur spreads it evenly along that segment.

Noise (in DN, after ``DN = 255 gain albedo shading``): shot noise with variance
``DN / electrons_per_dn`` and Gaussian read noise ``read_noise_dn``. Shot noise is drawn as a
Poisson count of electrons where the mean is below ``POISSON_BELOW_E`` electrons and as a Gaussian
of the same variance above it (skewness ``1 / sqrt(mean) < 0.1`` there; numpy's Poisson sampler
costs about 30 ms per megapixel, the Gaussian a quarter of that).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.sim.render_config import RenderConfig
from tagloc.sim.render_geometry import Float32Array, LruCache, RayGrid

#: Shot noise is sampled exactly (Poisson) below this mean electron count.
POISSON_BELOW_E = 100.0
#: Flows shorter than this (px) are not blurred.
MIN_BLUR_PX = 0.05
#: Background flow is estimated on at most this many grid samples per side.
FLOW_PROBES = 16


def point_flow(
    camera: CameraModel, points_cam: FloatArray, twist_cam: FloatArray, exposure_s: float
) -> FloatArray:
    """Image motion (px) of static points over the exposure; NaN where it cannot be projected.

    Parameters
    ----------
    camera : CameraModel
    points_cam : (N, 3) float
        Points in the optical frame at mid-exposure.
    twist_cam : (6,) float
        Camera body twist ``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s), optical frame.
    exposure_s : float

    Returns
    -------
    (N, 2) float
    """
    ends = []
    for tau in (-0.5 * exposure_s, 0.5 * exposure_s):
        T_cam0_cam = SE3.exp(tau * np.asarray(twist_cam, dtype=np.float64))
        ends.append(camera.project(T_cam0_cam.inverse().act(points_cam)))
    flow: FloatArray = ends[1] - ends[0]
    return flow


def background_flow(
    camera: CameraModel,
    grid: RayGrid,
    depth: Float32Array,
    twist_cam: FloatArray,
    exposure_s: float,
) -> FloatArray:
    """Median flow (2,) px of the background, from its depth on a sparse set of samples."""
    h, w = depth.shape
    rows = np.linspace(0, h - 1, min(h, FLOW_PROBES)).astype(int)
    cols = np.linspace(0, w - 1, min(w, FLOW_PROBES)).astype(int)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    d = depth[rr, cc].ravel().astype(np.float64)
    rays = grid.rays[:, rr, cc].reshape(3, -1).T.astype(np.float64)
    keep = np.isfinite(d) & np.isfinite(rays).all(axis=1)
    if not keep.any():
        return np.zeros(2)
    flow = point_flow(camera, rays[keep] * d[keep, None], twist_cam, exposure_s)
    flow = flow[np.isfinite(flow).all(axis=1)]
    return np.asarray(np.median(flow, axis=0) if len(flow) else np.zeros(2), dtype=np.float64)


def line_kernel(flow_px: FloatArray) -> Float32Array | None:
    """A normalized kernel spreading a point evenly along the segment ``[-flow/2, +flow/2]``.

    The segment is sampled every 0.25 px and splatted bilinearly, so the kernel is point-symmetric
    (correlation equals convolution) and sub-pixel lengths are represented. None when the flow is
    shorter than ``MIN_BLUR_PX`` or not finite.
    """
    length = float(np.hypot(*flow_px))
    if not math.isfinite(length) or length < MIN_BLUR_PX:
        return None
    radius = math.ceil(0.5 * max(abs(flow_px[0]), abs(flow_px[1]))) + 1
    kernel = np.zeros((2 * radius + 1, 2 * radius + 1), dtype=np.float64)
    s = np.linspace(-0.5, 0.5, max(2, math.ceil(4.0 * length) + 1))
    x, y = radius + s * flow_px[0], radius + s * flow_px[1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    for dx, dy, weight in (
        (0, 0, (1 - fx) * (1 - fy)),
        (1, 0, fx * (1 - fy)),
        (0, 1, (1 - fx) * fy),
        (1, 1, fx * fy),
    ):
        np.add.at(kernel, (y0 + dy, x0 + dx), weight)
    kernel = 0.5 * (kernel + kernel[::-1, ::-1])  # exact point symmetry
    return np.asarray(kernel / kernel.sum(), dtype=np.float32)


def blur(image: Float32Array, kernel: Float32Array | None) -> Float32Array:
    """``image`` filtered with ``kernel`` (edges replicated); unchanged for None."""
    if kernel is None:
        return image
    return np.asarray(
        cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE), dtype=np.float32
    )


_SHADING = LruCache(4)


def shading_map(camera: CameraModel, vignetting: float) -> Float32Array:
    """``1 - vignetting * rho^2``, ``rho`` = distance to the principal point / to the far corner."""
    return _SHADING.get((camera, vignetting), lambda: _make_shading(camera, vignetting))


def _make_shading(camera: CameraModel, vignetting: float) -> Float32Array:
    K = camera.K
    u = np.arange(camera.width, dtype=np.float64) - K[0, 2]
    v = np.arange(camera.height, dtype=np.float64) - K[1, 2]
    corner2 = max(
        (cu - K[0, 2]) ** 2 + (cv - K[1, 2]) ** 2
        for cu in (-0.5, camera.width - 0.5)
        for cv in (-0.5, camera.height - 0.5)
    )
    rho2 = (u[None, :] ** 2 + v[:, None] ** 2) / corner2
    shading = np.asarray(1.0 - vignetting * rho2, dtype=np.float32)
    shading.flags.writeable = False
    return shading


def expose(
    irradiance: Float32Array, camera: CameraModel, config: RenderConfig, rng: np.random.Generator
) -> npt.NDArray[np.uint8]:
    """The 8-bit image of an albedo-irradiance image: defocus, gain, vignetting, noise, rounding.

    Parameters
    ----------
    irradiance : (H, W) float32
        Albedo-weighted irradiance (1.0 = white paper under full light).
    camera : CameraModel
    config : RenderConfig
    rng : numpy.random.Generator
        Noise source (the only randomness).

    Returns
    -------
    (H, W) uint8
    """
    image = irradiance
    if config.defocus_sigma_px > 0:
        image = np.asarray(
            cv2.GaussianBlur(
                image, (0, 0), config.defocus_sigma_px, borderType=cv2.BORDER_REPLICATE
            ),
            dtype=np.float32,
        )
    signal = image * np.float32(255.0 * config.gain)
    if config.vignetting > 0:
        signal = signal * shading_map(camera, config.vignetting)
    signal = np.maximum(signal, np.float32(0.0))
    e_per_dn = config.electrons_per_dn
    read = np.float32(config.read_noise_dn)
    if e_per_dn is not None or read > 0:
        normal = rng.standard_normal(signal.shape, dtype=np.float32)
        if e_per_dn is None:
            signal = signal + read * normal
        else:
            electrons = signal * np.float32(e_per_dn)
            std = np.sqrt(signal / np.float32(e_per_dn) + read * read)
            noisy = signal + std * normal
            few = electrons < POISSON_BELOW_E
            if few.any():
                counts = rng.poisson(electrons[few].astype(np.float64)).astype(np.float32)
                noisy[few] = counts / np.float32(e_per_dn) + read * normal[few]
            signal = noisy
    return np.asarray(np.clip(np.rint(signal), 0, 255), dtype=np.uint8)
