"""Which pose directions a registration constrains: eigen-analysis of its Hessian.

A corridor (two parallel walls and a floor) pins the lateral and vertical position, roll, pitch
and yaw, but not the position along the corridor: the Hessian of the registration cost has a
(near) null direction there. A fix must not report such a direction, or the filter would pull
the robot to wherever the optimiser happened to stop (Zhang, Kaess, Singh, "On degeneracy of
optimization-based state estimation problems", ICRA 2016; Tuna et al., "X-ICP", T-RO 2023).

Translation and rotation are judged separately because their units differ (m vs rad): a joint
eigen-analysis would need a characteristic length to compare them, and its verdict would change
with that length (a room of 4 m vs a hall of 40 m). Each block is taken as a Schur complement,
the information left about translation once rotation is free (``H_tt - H_tr H_rr^-1 H_rt``) and
the reverse, so a null direction that mixes both (a cylinder's screw motion) still shows in each
block. Within a block a direction is constrained when its eigenvalue is at least
``min_eigenvalue_ratio`` times the block's largest: a ratio, because the Hessian's scale grows
with the number of points. The lidar fix feeds the point-to-plane Hessian (no in-plane terms);
what a flat wall still seems to say along itself comes from the error of the estimated normals
(a few hundredths of a radian): in a 2.5 m corridor seen by a 16-beam lidar (+-15 deg) the
along-axis ratio is at most ``1.3e-3`` (median ``5e-4``, 20 poses) while the weakest real
direction, the roll about the corridor axis, is at least ``7.5e-3``. The default ``3e-3`` sits
between (a factor 2.3 from each).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import Field

from tagloc.config import StrictModel
from tagloc.errors import GeometryError

__all__ = ["Degeneracy", "DegeneracyConfig", "analyse_hessian"]


class DegeneracyConfig(StrictModel):
    """Thresholds of :func:`analyse_hessian`."""

    min_eigenvalue_ratio: float = Field(0.003, gt=0.0, lt=1.0)
    """A direction is constrained when its eigenvalue is at least this fraction of the largest
    one of its block (translation or rotation)."""
    min_information: float = Field(1e-9, ge=0.0, le=1e12)
    """... and at least this (absolute, the Hessian's units): an all-zero Hessian constrains
    nothing."""


@dataclass(frozen=True, slots=True, eq=False)
class Degeneracy:
    """Eigen-analysis of a registration Hessian (tagloc order ``[x, y, z, rx, ry, rz]``).

    Attributes
    ----------
    eigenvalues : (6,) float
        Of the translation block's Schur complement (first 3, ascending), then the rotation's.
    eigenvectors : (6, 6) float
        Columns, block-diagonal: translation directions in rows 0-2, rotation in rows 3-5.
    constrained : (6,) bool
        Per eigenvector.
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    constrained: np.ndarray

    def basis(self) -> np.ndarray:
        """``(6, k)`` orthonormal columns spanning the constrained directions (k = 0..6)."""
        return np.array(self.eigenvectors[:, self.constrained])

    @property
    def num_constrained(self) -> int:
        return int(np.count_nonzero(self.constrained))


def analyse_hessian(hessian: npt.ArrayLike, config: DegeneracyConfig) -> Degeneracy:
    """Split a registration's Hessian into constrained and unconstrained directions.

    Parameters
    ----------
    hessian : (6, 6) float
        Symmetric PSD, tagloc order (``Registration.hessian``).
    config : DegeneracyConfig

    Raises
    ------
    GeometryError
        ``hessian`` is not a finite ``(6, 6)`` array.
    """
    H = np.asarray(hessian, dtype=np.float64)
    if H.shape != (6, 6) or not np.isfinite(H).all():
        raise GeometryError(f"hessian must be a finite (6, 6) array, got shape {H.shape}")
    H = 0.5 * (H + H.T)
    values = np.zeros(6)
    vectors = np.zeros((6, 6))
    constrained = np.zeros(6, dtype=bool)
    for block, other in ((slice(0, 3), slice(3, 6)), (slice(3, 6), slice(0, 3))):
        schur = H[block, block] - H[block, other] @ _pinv_psd(H[other, other]) @ H[other, block]
        w, v = np.linalg.eigh(0.5 * (schur + schur.T))
        w = np.clip(w, 0.0, None)
        values[block], vectors[block, block] = w, v
        largest = w[-1]
        constrained[block] = (w >= config.min_eigenvalue_ratio * largest) & (
            w > config.min_information
        )
    return Degeneracy(values, vectors, constrained)


def _pinv_psd(A: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of a small symmetric matrix: eigenvalues below ``1e-9`` of the largest
    in magnitude count as zero (``np.linalg.pinv(A, rcond=1e-9, hermitian=True)``, without its
    general-purpose checks)."""
    w, v = np.linalg.eigh(A)
    magnitude = np.abs(w)
    keep = magnitude > 1e-9 * magnitude.max()
    inverse = np.zeros_like(w)
    inverse[keep] = 1.0 / w[keep]
    out: np.ndarray = (v * inverse) @ v.T
    return out
