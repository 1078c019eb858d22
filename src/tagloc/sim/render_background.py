"""Walls, floor and ceiling by ray casting a (coarse) ray grid; the procedural wall texture.

Every sample starts on the floor (ray pointing down) or the ceiling (pointing up); opaque walls
(``wall``, ``mirror``) are then cast nearest first, each only over its projected bounding box and
skipped when everything in that box is already nearer than the wall can be (a cheap z-buffer
cull); glass panes nearer than the opaque surface finally tint it.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from tagloc.sim.render_config import RenderConfig
from tagloc.sim.render_geometry import Float32Array, RayGrid
from tagloc.sim.render_scene import GLASS, MIRROR, Scene, ViewWalls

#: Wall texture: texel edge (m) and tile size (texels); stripes every STRIPE_TEXELS.
TEXEL_M = 0.01
TILE_TEXELS = 240
STRIPE_TEXELS = 60


@functools.lru_cache(maxsize=4)
def wall_texture(seed: int) -> Float32Array:
    """A tileable ``TILE_TEXELS``-square texture with values in about ``[-1, 1]``.

    Band-limited Gaussian noise (two octaves, correlation lengths 3 and 12 texels, made tileable
    by filtering in the Fourier domain) plus faint vertical stripes.
    """
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(TILE_TEXELS)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    spectrum = np.fft.fft2(rng.standard_normal((TILE_TEXELS, TILE_TEXELS)))
    noise = np.zeros((TILE_TEXELS, TILE_TEXELS))
    for sigma, weight in ((3.0, 0.5), (12.0, 1.0)):
        octave = np.real(np.fft.ifft2(spectrum * np.exp(-2.0 * (np.pi * sigma) ** 2 * f2)))
        noise += weight * octave / octave.std()
    noise /= 3.0 * noise.std()
    stripes = 0.3 * np.sin(2.0 * np.pi * np.arange(TILE_TEXELS) / STRIPE_TEXELS)
    return np.clip(noise + stripes[None, :], -1.0, 1.0).astype(np.float32)


def render_background(
    scene: Scene, walls: ViewWalls, grid: RayGrid, config: RenderConfig
) -> tuple[Float32Array, Float32Array]:
    """Albedo and depth of the surroundings at every sample of ``grid``.

    Parameters
    ----------
    scene : Scene
        Must have a floor and ceiling (``scene.ceiling_z`` not None).
    walls : ViewWalls
        The scene's walls in this view.
    grid : RayGrid
        Rays of the samples (any resolution).
    config : RenderConfig

    Returns
    -------
    albedo : (h, w) float32
        Albedo seen along each ray (glass tint applied).
    depth : (h, w) float32
        Distance to the first opaque surface, m (``inf`` where the ray hits nothing).
    """
    assert scene.ceiling_z is not None
    r = grid.rays
    up = walls.up
    rz_up = up[0] * r[0] + up[1] * r[1] + up[2] * r[2]
    # 1. floor and ceiling
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(
            rz_up < 0, -walls.cam_z / rz_up, (scene.ceiling_z - walls.cam_z) / rz_up
        ).astype(np.float32)
    depth[~np.isfinite(depth) | (depth < 0)] = np.inf
    albedo = np.where(rz_up < 0, config.floor_albedo, config.ceiling_albedo).astype(np.float32)
    tex_u = np.zeros_like(depth)
    tex_v = np.zeros_like(depth)
    textured = np.zeros(depth.shape, dtype=bool)
    variation = np.random.default_rng(config.texture_seed).uniform(-1.0, 1.0, (scene.num_walls, 2))
    # 2. opaque walls, nearest first
    for k in range(len(walls.index)):
        if walls.material[k] == GLASS:
            continue
        win = grid.window(walls.bbox[k])
        d_win = depth[win]
        if d_win.size == 0 or float(d_win.max()) <= walls.min_dist[k]:
            continue
        r_win = r[:, win[0], win[1]]
        t = walls.hits(k, r_win, rz_up[win])
        nearer = t < d_win
        np.copyto(d_win, t, where=nearer)
        if walls.material[k] == MIRROR:
            np.copyto(albedo[win], np.float32(config.mirror_albedo), where=nearer)
            np.copyto(textured[win], False, where=nearer)
            continue
        j = int(walls.index[k])
        shade = config.wall_albedo * (1.0 + 0.1 * variation[j, 0])
        np.copyto(albedo[win], np.float32(shade), where=nearer)
        np.copyto(textured[win], True, where=nearer)
        offset = np.float32(TILE_TEXELS * TEXEL_M * (1.0 + variation[j, 1]))
        with np.errstate(invalid="ignore"):
            np.copyto(tex_u[win], walls.along_wall(k, t, r_win) + offset, where=nearer)
            np.copyto(tex_v[win], walls.cam_z + t * rz_up[win], where=nearer)
    # 3. texture on plain walls
    if config.wall_texture_contrast > 0 and textured.any():
        period = np.float32(TILE_TEXELS * TEXEL_M)
        map_u = np.mod(tex_u, period) / np.float32(TEXEL_M)
        map_v = np.mod(tex_v, period) / np.float32(TEXEL_M)
        texture = cv2.remap(
            wall_texture(config.texture_seed),
            map_u,
            map_v,
            interpolation=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_WRAP,
        )
        factor = 1.0 + np.float32(config.wall_texture_contrast) * texture
        albedo = np.where(textured, albedo * factor, albedo)
    # 4. glass in front of the opaque surface
    transmitted = np.ones_like(depth)
    for g in np.flatnonzero(walls.material == GLASS).tolist():
        win = grid.window(walls.bbox[g])
        if transmitted[win].size == 0:
            continue
        t = walls.hits(g, r[:, win[0], win[1]], rz_up[win])
        transmitted[win] *= np.where(t < depth[win], config.glass_transmittance, 1.0).astype(
            np.float32
        )
    albedo = albedo * transmitted + np.float32(config.glass_albedo) * (1.0 - transmitted)
    albedo[np.isnan(rz_up)] = 0.0  # no ray: outside a fisheye's image circle
    return albedo.astype(np.float32), depth
