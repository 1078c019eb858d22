"""How the simulated detector of :mod:`tagloc.sim.observations` sees tags (its configuration)."""

from __future__ import annotations

from pydantic import Field

from tagloc.config import StrictModel

__all__ = ["ObservationConfig"]


class ObservationConfig(StrictModel):
    """How the simulated detector sees tags (see the module docstring)."""

    pixel_sigma_px: float = Field(default=0.3, ge=0.0, description="corner noise, px per axis")
    max_range_m: float = Field(default=8.0, gt=0.0)
    max_view_angle_deg: float = Field(default=75.0, gt=0.0, le=90.0)
    min_side_px: float = Field(default=10.0, ge=0.0)
    margin_px: float = Field(default=2.0, ge=0.0)
    detection_probability: float = Field(default=1.0, ge=0.0, le=1.0)
    glint_rate: float = Field(default=0.0, ge=0.0, description="false detections per frame")
    glint_wrong_id_fraction: float = Field(default=0.5, ge=0.0, le=1.0)
    seed: int = 0
