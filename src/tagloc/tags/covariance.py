"""Honest 6x6 covariance of a PnP pose: reprojection Jacobian plus what linearization misses.

Every covariance here is over the right tangent of ``T_cam_obj`` (``obj`` = a tag, or the map for
joint PnP), ordered ``[x, y, z, rx, ry, rz]``: ``T_true = T_cam_obj @ Exp(d)``, ``d ~ N(0, C)``;
the translation block is therefore in the *object* frame. :func:`pose_covariance` builds it in
five steps (:class:`NoiseModel` holds the parameters):

1. **Pixel noise**: ``C0 = s^2 (J^T J)^-1`` (Gauss-Newton / Cramer-Rao) with ``J`` the stacked
   reprojection Jacobian ``d(residual)/d(d)``, ``s = sigma_px (1 + gain (1/cos(a) - 1))``:
   corners of a foreshortened tag are noisier (shorter edges to fit), which corner simulators
   with constant noise do not show.
2. **Valley** (ambiguity, :func:`valley_term`): towards the other IPPE branch the cost can be
   flatter than its quadratic model; the measured barrier between the branches sets the
   variance along ``delta = T_other (-) T`` (added as ``var_s delta delta^T``).
3. **Second order** (range): the estimate is Gaussian in the coordinates the solver moves in
   (camera-frame translation, rotation), while ``Log`` mixes them: ``rho_Log = rho - phi x rho / 2
   + O(3)``. At range both the depth error (~ d^2) and the tilt error are large, and the product
   dominates the tiny lateral variance: without it the NEES at 6 m is ~4x too high. The second
   moment ``E[(phi x rho)(phi x rho)^T] / 4`` under ``N(0, C)`` (Isserlis' theorem) is added to
   the translation block (T. Barfoot, P. Furgale, "Associating uncertainty with
   three-dimensional poses for use in estimation problems", IEEE T-RO 30(3), 2014).
4. **Systematic depth error** (distance): a corner bias ``b`` (px, from blur and thresholding)
   shrinks the apparent extent ``D`` (px) by ``2b`` and a relative calibration / print error
   ``e`` scales everything: depth variance ``(2 b d / D)^2 + (e d)^2`` along the line of sight.
   ``d / D ~ d^2 / (f s)``, so this grows like distance squared; pixel noise averages down over
   corners and frames, a bias does not.
5. **Floor**: ``diag(floor_translation_m^2 x 3, floor_rotation_rad^2 x 3)`` is added.

The viewing angle enters through step 1 and, near face-on, through where the Jacobian is
evaluated (:mod:`tagloc.tags.pnp` keeps the wider of the covariances at the estimate and two
sigmas towards the other branch: the tilt information grows like ``sin^2`` of the tilt).
Once the policy knows the posterior odds of the branches, :func:`ambiguity_mixture` folds in the
other branch: the second moment about the chosen pose of the two-branch mixture.

The covariance of the derived ``T_map_cam`` / ``T_map_base`` and :func:`nees` are in
:mod:`tagloc.tags.pose_chain` (re-exported here).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import Field, field_validator

from tagloc._types import FloatArray
from tagloc.config import StrictModel
from tagloc.geometry import SE3, se3_right_jacobian_inv
from tagloc.geometry.small_batch import row_norms
from tagloc.tags.pose_chain import map_base_from_cam, map_cam_from_tag, nees

__all__ = [
    "MIN_SIGMA_PX", "Linearization", "NoiseModel", "ambiguity_mixture", "ambiguity_weight",
    "laplace_covariance", "linearized_pose_covariance", "map_base_from_cam", "map_cam_from_tag",
    "nees", "pose_covariance", "reprojection_covariance", "second_order_term", "valley_term",
]  # fmt: skip

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0
_EPS9 = _EPS.reshape(3, 9)  # (i, jk)


#: Smallest corner noise accepted, px.
MIN_SIGMA_PX = 1e-3


class NoiseModel(StrictModel):
    """Pixel-noise model and covariance inflation parameters (``localizer.yaml``: ``noise``).

    Attributes
    ----------
    sigma_px : float
        1-sigma corner noise per pixel coordinate, face-on (default 0.5 px: AprilTag 3 corners on
        real images; calibrate on your detector). Also the scale of the ambiguity chi-square.
    view_angle_gain : float
        Noise growth with the viewing angle ``a``: ``sigma_px (1 + gain (1/cos(a) - 1))``
        (default 0.05: +5 % at 60 deg, +14 % at 75 deg).
    corner_bias_px : float
        Systematic corner bias that does not average out (default 0.1 px).
    scale_rel : float
        Relative scale error: tag print size, focal length (default 0.002).
    floor_translation_m, floor_rotation_rad : float
        Added to every translation / rotation variance (default 0.3 mm, 0.0005 rad = 0.03 deg).
    second_order : bool
        Add the ``phi x rho`` term (step 3 of the module docstring); default True.
    """

    sigma_px: float = Field(0.5, gt=0.0, le=100.0)
    view_angle_gain: float = Field(0.05, ge=0.0, le=100.0)
    corner_bias_px: float = Field(0.1, ge=0.0, le=100.0)
    scale_rel: float = Field(0.002, ge=0.0, le=1.0)
    floor_translation_m: float = Field(0.0003, ge=0.0, le=100.0)
    floor_rotation_rad: float = Field(0.0005, ge=0.0, le=3.2)
    second_order: bool = True

    @classmethod
    def pixels_only(cls, sigma_px: float) -> NoiseModel:
        """Constant pixel noise and nothing else (step 1 alone, no inflation): the plain
        Gauss-Newton covariance ``sigma_px^2 (J^T J)^-1``."""
        return cls(sigma_px=sigma_px, view_angle_gain=0.0, corner_bias_px=0.0, scale_rel=0.0,
                   floor_translation_m=0.0, floor_rotation_rad=0.0, second_order=False)  # fmt: skip

    @field_validator("sigma_px")
    @classmethod
    def _sigma_floor(cls, sigma_px: float) -> float:
        if sigma_px < MIN_SIGMA_PX:  # its inverse square would overflow the information
            raise ValueError(f"must be at least {MIN_SIGMA_PX:g} px, got {sigma_px:g}")
        return sigma_px


def _sym(cov: FloatArray) -> FloatArray:
    return np.asarray(0.5 * (cov + np.swapaxes(cov, -1, -2)))


def reprojection_covariance(jacobian: npt.ArrayLike, sigma_px: npt.ArrayLike) -> FloatArray:
    """``sigma^2 (J^T J)^-1`` for a stack of reprojection Jacobians (pseudo-inverse if singular).

    Parameters
    ----------
    jacobian : (K, M, 6) float
        ``d(residual_px)/d(xi)`` of ``M`` residual components, right perturbation.
    sigma_px : float or (K,) float

    Returns
    -------
    (K, 6, 6) float
    """
    return _scaled(Linearization.of(jacobian).info_inv, sigma_px)


@dataclass(frozen=True, slots=True)
class Linearization:
    """What the covariances take from reprojection Jacobians ``J`` (K, M, 6).

    Problems of different ``M`` (a tag's 8 residuals, a joint estimate's 8 per tag) are
    linearized separately and :meth:`stack` -ed, then share one pass of
    :func:`linearized_pose_covariance` (every step after this one is per row).

    Attributes
    ----------
    info_inv : (K, 6, 6) float
        ``(J^T J)^-1`` (the pseudo-inverse for all K if one is singular).
    curvature : (K,) float or None
        ``|J delta|^2`` towards the other branch (the valley's linearized curvature).
    """

    info_inv: FloatArray
    curvature: FloatArray | None = None

    @classmethod
    def of(cls, jacobian: npt.ArrayLike, delta_other: npt.ArrayLike | None = None) -> Linearization:
        """Linearize ``J`` (K, M, 6), and along ``delta_other`` (K, 6) if given."""
        J = np.asarray(jacobian, dtype=np.float64)
        info = np.swapaxes(J, 1, 2) @ J
        with np.errstate(all="ignore"):
            try:
                info_inv = np.asarray(np.linalg.inv(info))
            except np.linalg.LinAlgError:
                info_inv = np.asarray(np.linalg.pinv(info, hermitian=True))
        return cls(info_inv, None if delta_other is None else _curvature(J, delta_other))

    @classmethod
    def stack(cls, items: Sequence[Linearization]) -> Linearization:
        """One linearization of the rows of all ``items``, in order."""
        info_inv = np.concatenate([item.info_inv for item in items])
        curvatures = [item.curvature for item in items]
        if any(c is None for c in curvatures):
            return cls(info_inv)
        return cls(info_inv, np.concatenate([c for c in curvatures if c is not None]))


def _scaled(info_inv: FloatArray, sigma_px: npt.ArrayLike) -> FloatArray:
    """``sigma^2 (J^T J)^-1``, symmetrized."""
    sigma = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), info_inv.shape[:1])
    return _sym(sigma[:, None, None] ** 2 * info_inv)


def second_order_term(cov: npt.ArrayLike) -> FloatArray:
    """``E[(phi x rho)(phi x rho)^T] / 4`` for ``(rho, phi) ~ N(0, cov)`` (Isserlis' theorem).

    Parameters
    ----------
    cov : (K, 6, 6) float, order ``[rho, phi]``

    Returns
    -------
    (K, 3, 3) float
        To be added to the translation block.
    """
    P = np.asarray(cov, dtype=np.float64)
    k = len(P)
    B, A, C = P[:, :3, :3], P[:, 3:, 3:], P[:, 3:, :3]  # rho rho, phi phi, E[phi rho^T]
    v = np.einsum("ijk,xjk->xi", _EPS, C)  # E[phi x rho]
    M = np.einsum("xjm,xkn->xjkmn", A, B) + np.einsum("xjn,xmk->xjkmn", C, C)
    second = _EPS9 @ M.reshape(k, 9, 9) @ _EPS9.T + v[:, :, None] * v[:, None, :]
    return np.asarray(0.25 * second)


def pose_covariance(
    jacobian: npt.ArrayLike,
    R_cam_obj: npt.ArrayLike,
    t_cam_obj: npt.ArrayLike,
    extent_px: npt.ArrayLike,
    noise: NoiseModel,
    view_angle_rad: npt.ArrayLike | None = None,
    delta_other: npt.ArrayLike | None = None,
    barrier_px2: npt.ArrayLike | None = None,
) -> FloatArray:
    """Covariance of ``K`` PnP poses given their branch (steps 1-5 of the module docstring).

    Parameters
    ----------
    jacobian : (K, M, 6) float
        Reprojection Jacobians at the solutions (pixels per unit right perturbation).
    R_cam_obj : (K, 3, 3) float
    t_cam_obj : (K, 3) float
        The solutions; ``|t|`` is the range, ``R^T t / |t|`` the line of sight in the object frame.
    extent_px : (K,) float
        Apparent size of the target in the image (pixels): a tag's mean diagonal, or the
        largest corner-to-corner distance of a multi-tag set.
    noise : NoiseModel
    view_angle_rad : (K,) float, optional
        Angle between the tag normal and the ray to the camera (0 = face-on, the default).
    delta_other : (K, 6) float, optional
        ``T_other (-) T`` to the other IPPE branch (no valley term if None).
    barrier_px2 : (K,) float, optional
        SSE at the midpoint between the branches minus this branch's SSE (``inf``: none).

    Returns
    -------
    (K, 6, 6) float
        Right-tangent covariances, ``[x, y, z, rx, ry, rz]``; NaN where ``J`` holds NaN.
    """
    J = np.asarray(jacobian, dtype=np.float64)
    has_valley = delta_other is not None and barrier_px2 is not None
    lin = Linearization.of(J, delta_other if has_valley else None)
    return linearized_pose_covariance(
        lin, R_cam_obj, t_cam_obj, extent_px, noise, view_angle_rad, delta_other, barrier_px2
    )


def linearized_pose_covariance(
    lin: Linearization, R_cam_obj: npt.ArrayLike, t_cam_obj: npt.ArrayLike,
    extent_px: npt.ArrayLike, noise: NoiseModel, view_angle_rad: npt.ArrayLike | None = None,
    delta_other: npt.ArrayLike | None = None, barrier_px2: npt.ArrayLike | None = None,
) -> FloatArray:  # fmt: skip
    """:func:`pose_covariance` from the Jacobians' :class:`Linearization` (the same numbers).

    Parameters are those of :func:`pose_covariance`; the valley term needs ``lin.curvature``.
    """
    R = np.asarray(R_cam_obj, dtype=np.float64)
    t = np.asarray(t_cam_obj, dtype=np.float64)
    k = len(R)
    angle = np.zeros(k) if view_angle_rad is None else np.asarray(view_angle_rad, np.float64)
    gain = 1.0 / np.maximum(np.cos(angle), 0.1) - 1.0
    # 1. pixel noise through the Jacobian
    sigma = noise.sigma_px * (1.0 + noise.view_angle_gain * gain)
    cov = _scaled(lin.info_inv, sigma)
    # 2. the valley towards the other branch
    if delta_other is not None and barrier_px2 is not None:
        assert lin.curvature is not None, "the valley term needs Linearization.of(J, delta)"
        cov += _valley(lin.curvature, sigma, delta_other, barrier_px2)
    # 3. second-order mixing of rotation and translation errors
    if noise.second_order:
        cov[:, :3, :3] += second_order_term(cov)
    # 4. systematic depth error along the line of sight (object frame)
    range_m = row_norms(t)
    with np.errstate(all="ignore"):
        ray_obj = np.einsum("kji,kj->ki", R, t) / range_m[:, None]
        rel = np.hypot(2.0 * noise.corner_bias_px / np.asarray(extent_px), noise.scale_rel)
    cov[:, :3, :3] += (rel * range_m)[:, None, None] ** 2 * (ray_obj[:, :, None] * ray_obj[:, None])
    # 5. floor
    return _sym(cov + _floor(noise.floor_translation_m, noise.floor_rotation_rad))


@functools.lru_cache(maxsize=16)
def _floor(floor_translation_m: float, floor_rotation_rad: float) -> FloatArray:
    """``diag(floor_translation_m^2 x 3, floor_rotation_rad^2 x 3)`` (read-only)."""
    floor = np.diag([floor_translation_m**2] * 3 + [floor_rotation_rad**2] * 3)
    floor.flags.writeable = False
    return floor


def laplace_covariance(
    lin: Linearization, sigma_px: float, delta_other: npt.ArrayLike, barrier_px2: npt.ArrayLike
) -> FloatArray:
    """The likelihood lobe ``sigma^2 (J^T J)^-1`` plus :func:`valley_term` (no inflation).

    Equal to ``reprojection_covariance(J, sigma_px) + valley_term(J, sigma_px, delta_other,
    barrier_px2)`` for ``lin = Linearization.of(J, delta_other)``; (K, 6, 6).
    """
    assert lin.curvature is not None, "the valley term needs Linearization.of(J, delta)"
    return _scaled(lin.info_inv, sigma_px) + _valley(
        lin.curvature, sigma_px, delta_other, barrier_px2
    )


def valley_term(
    jacobian: npt.ArrayLike,
    sigma_px: npt.ArrayLike,
    delta_other: npt.ArrayLike,
    barrier_px2: npt.ArrayLike,
) -> FloatArray:
    """Extra variance along the direction to the other IPPE branch where the cost is flatter
    than its linearization (step 2 of the module docstring).

    Along ``s -> T (+) s delta`` the linearization predicts ``SSE(s) - SSE(0) = s^2 delta^T H
    delta`` (``H = J^T J``); the measured midpoint barrier ``b`` gives the secant curvature
    ``4 b``. Where it is lower the variance of ``s`` is ``sigma^2 / (4 b)`` instead of
    ``sigma^2 / (delta^T H delta)``; the difference (capped at ``1/4``: half the separation as
    one sigma) times ``delta delta^T`` is returned.

    Parameters
    ----------
    jacobian : (K, M, 6) float
    sigma_px : float or (K,) float
    delta_other : (K, 6) float
    barrier_px2 : (K,) float

    Returns
    -------
    (K, 6, 6) float
    """
    J = np.asarray(jacobian, dtype=np.float64)
    return _valley(_curvature(J, delta_other), sigma_px, delta_other, barrier_px2)


def _curvature(J: FloatArray, delta_other: npt.ArrayLike) -> FloatArray:
    """``|J delta|^2`` (K,): the linearized curvature of the cost along ``delta``."""
    J_delta = np.einsum("kmi,ki->km", J, np.asarray(delta_other, dtype=np.float64))
    return np.asarray(np.einsum("km,km->k", J_delta, J_delta))


def _valley(
    curvature_lin: FloatArray,
    sigma_px: npt.ArrayLike,
    delta_other: npt.ArrayLike,
    barrier_px2: npt.ArrayLike,
) -> FloatArray:
    """:func:`valley_term` from the linearized curvature ``|J delta|^2`` (K,)."""
    delta = np.asarray(delta_other, dtype=np.float64)
    sigma2 = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), delta.shape[:1]) ** 2
    barrier = np.maximum(np.asarray(barrier_px2, dtype=np.float64), 1e-12)
    with np.errstate(all="ignore"):
        var_s = sigma2 / (4.0 * barrier) - sigma2 / curvature_lin
    var_s = np.where(np.isfinite(var_s), np.clip(var_s, 0.0, 0.25), 0.0)
    return np.asarray(var_s[:, None, None] * delta[:, :, None] * delta[:, None, :])


def ambiguity_weight(log_odds: npt.ArrayLike) -> FloatArray:
    """Posterior probability of the other branch, ``1 / (1 + exp(log_odds / 2))``.

    ``log_odds`` is in chi-square units: ``2 ln(p_chosen / p_other)``, e.g. the difference of
    the two branches' ``SSE / sigma^2`` plus the prior's term (:mod:`tagloc.tags.gates`).
    """
    return np.asarray(0.5 * (1.0 - np.tanh(0.25 * np.asarray(log_odds, dtype=np.float64))))


def ambiguity_mixture(
    T_chosen: SE3,
    cov_chosen: npt.ArrayLike,
    T_other: SE3,
    cov_other: npt.ArrayLike,
    log_odds: float,
) -> FloatArray:
    """Second moment about ``T_chosen`` of the two-branch mixture (module docstring).

    ``(1 - w) C + w (Jr^-1(delta) C_other Jr^-T(delta) + delta delta^T)`` with
    ``delta = T_other (-) T_chosen`` and ``w = ambiguity_weight(log_odds)``: the covariance that
    keeps the NEES honest if the other branch is the true one with probability ``w``.

    Parameters
    ----------
    T_chosen, T_other : SE3 (single)
    cov_chosen, cov_other : (6, 6) float, right tangents of each
    log_odds : float
        ``2 ln(p_chosen / p_other)``; ``inf`` for no alternative.

    Returns
    -------
    (6, 6) float
    """
    C = np.asarray(cov_chosen, dtype=np.float64)
    w = float(ambiguity_weight(log_odds))
    if w < 1e-12 or not np.isfinite(np.asarray(cov_other)).all():
        return C.copy()
    delta = T_other.minus(T_chosen)
    J = se3_right_jacobian_inv(delta)
    other = J @ np.asarray(cov_other, dtype=np.float64) @ J.T + np.outer(delta, delta)
    return _sym((1.0 - w) * C + w * other)
