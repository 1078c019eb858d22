"""The renderer's tunables: :class:`RenderConfig` (pydantic, ``extra="forbid"``, frozen).

Radiometry is linear: every surface has an *albedo* in ``[0, 1]``; the sensor turns it into
digital numbers ``DN = 255 * gain * albedo * shading`` (``shading`` is the vignetting map), adds
noise and rounds to ``uint8``. The defaults describe a mildly realistic indoor robot camera: 4 ms
exposure, a little read and shot noise, 20 % corner fall-off, in focus.
:meth:`RenderConfig.ideal` switches every effect off (the geometry-only image the corner-accuracy
tests use).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from tagloc.config import StrictModel


class RenderConfig(StrictModel):
    """How :mod:`tagloc.sim.render` turns a scene into an 8-bit gray image.

    Sampling
        ``supersample`` (2): samples per pixel side for tags (box filter over ``k x k`` ray
        samples; 2 means 2x2). ``background_scale`` (0.5): walls, floor and ceiling are ray-cast
        at this fraction of the resolution and upsampled bilinearly (they carry only a
        low-contrast texture; tags are always cast at full resolution times ``supersample``).
    Tags
        ``quiet_zone_cells`` (1): white margin around the black border, in cells (>= 1, as the
        AprilTag reference images). ``tag_black`` (0.05), ``tag_white`` (0.85): albedo of toner
        and paper. ``max_tag_range_m`` (30): tags farther away are not drawn.
    Surroundings
        ``wall_albedo`` (0.55) with a procedural texture of relative amplitude
        ``wall_texture_contrast`` (0.08: smooth noise plus faint vertical stripes, fixed in 3-D
        on the wall planes, seeded by ``texture_seed``); ``floor_albedo`` (0.3) and
        ``ceiling_albedo`` (0.75) are flat; ``ceiling_height_m`` (None: the tallest wall).
        Glass transmits ``glass_transmittance`` (0.85) of what is behind it and adds
        ``(1 - transmittance) * glass_albedo`` (0.6) per pane (a slight tint). Mirrors are drawn
        as an opaque flat shade ``mirror_albedo`` (0.7): no reflections.
    Exposure and lens
        ``gain`` (1.0); ``vignetting`` (0.2): shading ``1 - vignetting * rho^2`` with ``rho`` the
        distance from the principal point over the distance to the farthest image corner;
        ``defocus_sigma_px`` (0.0): Gaussian blur of the irradiance.
    Motion blur
        ``exposure_s`` (0.004; 0 switches it off): the frame's stamp is mid-exposure and the
        camera moves with its constant body twist across it. ``motion_blur`` selects the
        method: ``"directional"`` (default; each tag layer is convolved with a line kernel
        along its own image-space motion, the background with the median motion of the walls)
        or ``"subframes"`` (``subframes`` renders at poses spread over the exposure, averaged;
        exact for everything, ``subframes`` times the cost, ghosting when the motion exceeds
        about one pixel per subframe).
    Noise
        ``read_noise_dn`` (1.5): Gaussian read noise, DN. ``electrons_per_dn`` (10; None: no
        shot noise): conversion gain for Poisson shot noise, variance ``signal / electrons_per_dn``
        DN^2. ``seed`` (0): noise seed when the caller gives none.
    """

    supersample: int = Field(default=2, ge=1, le=8)
    background_scale: float = Field(default=0.5, gt=0.0, le=1.0)
    quiet_zone_cells: int = Field(default=1, ge=1, le=10)
    tag_black: float = Field(default=0.05, ge=0.0, le=1.0)
    tag_white: float = Field(default=0.85, ge=0.0, le=1.0)
    max_tag_range_m: float = Field(default=30.0, gt=0.0)
    wall_albedo: float = Field(default=0.55, ge=0.0, le=1.0)
    wall_texture_contrast: float = Field(default=0.08, ge=0.0, le=1.0)
    floor_albedo: float = Field(default=0.3, ge=0.0, le=1.0)
    ceiling_albedo: float = Field(default=0.75, ge=0.0, le=1.0)
    ceiling_height_m: float | None = Field(default=None, gt=0.0)
    glass_transmittance: float = Field(default=0.85, ge=0.0, le=1.0)
    glass_albedo: float = Field(default=0.6, ge=0.0, le=1.0)
    mirror_albedo: float = Field(default=0.7, ge=0.0, le=1.0)
    texture_seed: int = Field(default=0, ge=0)
    gain: float = Field(default=1.0, ge=0.0)
    vignetting: float = Field(default=0.2, ge=0.0, le=1.0)
    defocus_sigma_px: float = Field(default=0.0, ge=0.0, le=50.0)
    exposure_s: float = Field(default=0.004, ge=0.0, le=1.0)
    motion_blur: Literal["directional", "subframes"] = "directional"
    subframes: int = Field(default=8, ge=2, le=256)
    read_noise_dn: float = Field(default=1.5, ge=0.0)
    electrons_per_dn: float | None = Field(default=10.0, gt=0.0)
    seed: int = Field(default=0, ge=0)

    @classmethod
    def ideal(cls, **overrides: Any) -> RenderConfig:
        """A config with every effect off: no motion blur, noise, vignetting or defocus.

        Parameters
        ----------
        **overrides
            Fields to set on top (validated as usual).
        """
        values: dict[str, Any] = {
            "exposure_s": 0.0,
            "read_noise_dn": 0.0,
            "electrons_per_dn": None,
            "vignetting": 0.0,
            "defocus_sigma_px": 0.0,
        }
        values.update(overrides)
        return cls(**values)
