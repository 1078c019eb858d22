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
from tagloc.mapping.whitening import AxisWhitening


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


#: Standard deviation (rad) of a held tag's tilt when gravity priors level the map: its
#: measured roll and pitch give way to thousands of keyframes' gravity; its heading does not.
LEVEL_ANCHOR_TILT_RAD = 0.1


def anchor_whitening(
    sigmas: FloatArray, M_map_tag: FloatArray | None = None
) -> AxisWhitening:
    """The prior of a held tag: ``sigmas (6,)`` along the tag's axes, or with ``M_map_tag``
    given (gravity priors on), along ``map``'s axes with the tilt free.

    An anchor's orientation measured with a level that disagrees with gravity by a degree (or a
    peer's frame that is not level) otherwise fights the gravity priors, and the compromise
    turns the whole map about the vertical: a real one-anchor drive came out 1.0 deg turned
    with its anchor held exactly, 0.1 deg with the anchor's tilt left to gravity. The
    rotation error ``Log(T_prior^-1 T)`` lives in the tag's tangent; ``R_map_tag`` takes it
    into ``map``, where rotations about x and y get :data:`LEVEL_ANCHOR_TILT_RAD` and the
    rotation about z (heading) keeps the anchor's own sigma.
    """
    s = np.asarray(sigmas, dtype=np.float64)
    if M_map_tag is None:
        return AxisWhitening(s[None])
    level = s.copy()
    level[3:5] = max(LEVEL_ANCHOR_TILT_RAD, float(s[3:5].max()))
    return AxisWhitening(level[None], np.asarray(M_map_tag, dtype=np.float64)[None, :3, :3])

