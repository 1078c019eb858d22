"""Least-squares alignment of two point sets: Umeyama (1991), with or without scale.

Given the estimate's positions ``x_i`` and the reference's ``y_i`` (``i = 1..n``, paired by
stamp), find the rotation ``R``, translation ``t`` and scale ``c`` minimizing

``e^2(R, t, c) = 1/n sum_i |y_i - (c R x_i + t)|^2``            (Umeyama eq. 1)

The closed form (S. Umeyama, "Least-squares estimation of transformation parameters between two
point patterns", IEEE PAMI 13(4), 1991; equation numbers are the paper's):

- means ``mu_x = 1/n sum x_i``, ``mu_y = 1/n sum y_i``                               (34, 35)
- variance ``sigma_x^2 = 1/n sum |x_i - mu_x|^2``                                    (36)
- covariance ``Sigma_xy = 1/n sum (y_i - mu_y)(x_i - mu_x)^T = U D V^T`` (SVD)      (38)
- ``S = diag(1, 1, -1)`` if ``det(U) det(V) < 0`` else ``I`` (a proper rotation)    (43)
- ``R = U S V^T``, ``c = tr(D S) / sigma_x^2`` (1 without scale), ``t = mu_y - c R mu_x``
                                                                                     (40-42)

It is the alignment of ``evo_ape -a`` (``c = 1``) and ``-as``: a pose ``T_map_base`` of the
estimate becomes ``[R R_map_base, c R t_map_base + t]``. The solution is unique when ``Sigma_xy``
has rank >= 2; a static or straight track (rank < 2) leaves a rotation about the line free and is
an error here. Rank counts singular values above ``1e-12`` of the largest (evo counts those
above machine epsilon, an absolute threshold that depends on the units).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.eval.errors import EvaluationError
from tagloc.geometry import SE3, SO3

#: Singular values of ``Sigma_xy`` below this fraction of the largest count as zero.
RANK_RTOL = 1e-12


@dataclass(frozen=True, slots=True)
class Alignment:
    """The similarity ``y = scale * R_ref_est @ x + t_ref_est`` (module docstring).

    Attributes
    ----------
    R_ref_est : (3, 3) float
    t_ref_est : (3,) float
    scale : float
        1.0 unless solved for.
    """

    R_ref_est: FloatArray
    t_ref_est: FloatArray
    scale: float

    def apply_to_positions(self, positions_est: npt.ArrayLike) -> FloatArray:
        """``(N, 3)`` positions aligned: ``c R x_i + t``."""
        x = np.asarray(positions_est, dtype=np.float64)
        aligned: FloatArray = (self.scale * x) @ self.R_ref_est.T + self.t_ref_est
        return aligned

    def apply(self, T_map_base_est: SE3) -> SE3:
        """The estimate's poses aligned: ``[R R_i, c R t_i + t]`` (scale acts on positions)."""
        R = SO3.from_matrix(self.R_ref_est, normalize=True)
        return SE3(
            rotation=R @ T_map_base_est.rotation,
            translation=self.apply_to_positions(T_map_base_est.translation),
        )


def umeyama_alignment(
    positions_est: npt.ArrayLike, positions_ref: npt.ArrayLike, *, with_scale: bool = False
) -> Alignment:
    """Umeyama's least-squares alignment of ``positions_est`` onto ``positions_ref``.

    Parameters
    ----------
    positions_est, positions_ref : (N, 3) float
        Paired positions (row ``i`` of one with row ``i`` of the other).
    with_scale : bool
        Also solve for the scale (``evo_ape -as``); otherwise ``scale = 1`` (``-a``).

    Raises
    ------
    EvaluationError
        Shapes differ, fewer than 2 points, or ``Sigma_xy`` has rank < 2 (static or straight).
    """
    x = np.asarray(positions_est, dtype=np.float64)
    y = np.asarray(positions_ref, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3 or len(x) < 2:
        raise EvaluationError(
            f"alignment needs two (N, 3) position arrays of the same shape, N >= 2; got "
            f"{x.shape} and {y.shape}"
        )
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)  # (34), (35)
    dx, dy = x - mu_x, y - mu_y
    sigma2_x = float(np.sum(dx * dx)) / len(x)  # (36)
    cov_xy = dy.T @ dx / len(x)  # (38)
    U, d, Vt = np.linalg.svd(cov_xy)
    if np.count_nonzero(d > RANK_RTOL * d[0]) < 2:
        raise EvaluationError(
            "cannot align the estimate onto the reference: the positions do not span enough "
            "space (a static or straight track); evaluate it without alignment"
        )
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0.0:  # (43)
        S[2, 2] = -1.0
    R = U @ S @ Vt  # (40)
    scale = float(np.trace(np.diag(d) @ S) / sigma2_x) if with_scale else 1.0  # (42)
    t = mu_y - scale * (R @ mu_x)  # (41)
    return Alignment(R_ref_est=R, t_ref_est=t, scale=scale)
