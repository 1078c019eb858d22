"""Anchors: tags whose pose in ``map`` was measured (a total station, a tape and a level).

An anchor is a prior on its tag's ``T_map_tag`` with the measurement's standard deviations, not a
rigid constraint: several far-apart anchors with honest sigmas let the survey correct a badly
measured one, and their sigmas enter every tag's marginal covariance. An anchor given as a bare
:class:`~tagloc.geometry.SE3` gets the builder's default sigmas
(:attr:`~tagloc.mapping.config.MapBuildConfig.anchor_sigma_m`, ``anchor_sigma_rad``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.mapping.config import MapBuildConfig


@dataclass(frozen=True, slots=True)
class Anchor:
    """A measured tag pose and its standard deviations.

    Attributes
    ----------
    T_map_tag : SE3
    sigma_position_m : float or None
        Per axis (x, y, z of the tag frame's right perturbation), metres; None: the default.
    sigma_rotation_deg : float or None
        Per axis, degrees; None: the default.
    """

    T_map_tag: SE3
    sigma_position_m: float | None = None
    sigma_rotation_deg: float | None = None

    def __post_init__(self) -> None:
        for name in ("sigma_position_m", "sigma_rotation_deg"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"anchor {name}: must be > 0, got {value}")

    def sigmas(self, config: MapBuildConfig) -> FloatArray:
        """``(6,)`` standard deviations ``[x, y, z, rx, ry, rz]`` (m, rad) of the prior."""
        default = anchor_default_sigmas(config)
        pos = default[0] if self.sigma_position_m is None else self.sigma_position_m
        rot = default[3] if self.sigma_rotation_deg is None else np.radians(self.sigma_rotation_deg)
        return np.array([pos] * 3 + [rot] * 3, dtype=np.float64)


def anchor_default_sigmas(config: MapBuildConfig) -> FloatArray:
    """``(6,)`` sigmas of an anchor without its own (and of the origin tag without anchors)."""
    return np.array([config.anchor_sigma_m] * 3 + [config.anchor_sigma_rad] * 3)


def as_anchor(value: SE3 | Anchor) -> Anchor:
    """``value`` as an :class:`Anchor` (a bare pose: default sigmas)."""
    return value if isinstance(value, Anchor) else Anchor(value)
