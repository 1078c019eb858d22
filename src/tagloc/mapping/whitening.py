"""Whitening with per-axis sigmas along rotated axes (the odometry steps, level with gravity;
the anchors, whose tilt gravity decides).

An error ``e = [e_t, e_r]`` (translation, rotation; a right tangent) is whitened as
``[R e_t, R e_r] / sigmas``: its covariance is ``blockdiag(R, R)^T diag(sigmas^2) blockdiag(R, R)``.
``R = None`` is the plain diagonal model, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from tagloc._types import FloatArray
from tagloc.mapping.gtsam_bridge import PERM, diagonal_sigmas


@dataclass(frozen=True, slots=True, eq=False)
class AxisWhitening:
    """Whitening of ``n`` errors ``e = [e_t, e_r]`` with per-axis sigmas along rotated axes:
    ``[R e_t, R e_r] / sigmas`` (module docstring).

    Attributes
    ----------
    sigmas : (n, 6) float
        Standard deviations ``[x, y, z, rx, ry, rz]`` along the rotated axes.
    R_level_base : (n, 3, 3) float or None
        Rotation of each error into the sigmas' axes; None: the error's own axes.
    """

    sigmas: FloatArray
    R_level_base: FloatArray | None = None

    def __len__(self) -> int:
        return len(self.sigmas)

    def whiten(self, e: FloatArray) -> FloatArray:
        """``(n, 6)`` whitened errors of ``e (n, 6)``."""
        if self.R_level_base is None:
            return np.asarray(e / self.sigmas)
        R = self.R_level_base
        level = np.concatenate(
            [np.einsum("kij,kj->ki", R, e[:, :3]), np.einsum("kij,kj->ki", R, e[:, 3:])], axis=1
        )
        return np.asarray(level / self.sigmas)

    def whiten_jacobian(self, A: FloatArray) -> FloatArray:
        """``(n, 6, m)`` whitened Jacobians of the errors, ``A (n, 6, m)``."""
        if self.R_level_base is None:
            return np.asarray(A / self.sigmas[:, :, None])
        R = self.R_level_base
        level = np.concatenate(
            [np.einsum("kij,kjn->kin", R, A[:, :3]), np.einsum("kij,kjn->kin", R, A[:, 3:])],
            axis=1,
        )
        return np.asarray(level / self.sigmas[:, :, None])

    def gtsam_model(self, k: int) -> gtsam.noiseModel.Base:
        """Error ``k``'s noise model for a GTSAM pose factor (rotation first)."""
        if self.R_level_base is None:
            return diagonal_sigmas(self.sigmas[k])
        S = np.zeros((6, 6))
        S[:3, :3] = self.R_level_base[k]
        S[3:, 3:] = self.R_level_base[k]
        S = S / self.sigmas[k][:, None]  # sqrt information, tagloc order
        return gtsam.noiseModel.Gaussian.SqrtInformation(np.ascontiguousarray(S[PERM][:, PERM]))
