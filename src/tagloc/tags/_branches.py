"""Best and alternative branch of PnP problems, the valley between them, their covariances.

:func:`refine_branches` (refine every candidate with :func:`~tagloc.tags._refine.refine_poses`,
keep the best minimum and the best *other* minimum, else the worst raw candidate) then
:func:`finish_branches` (the valley between the two and both covariances). The second takes
several groups of problems at once (a frame's tags and its joint estimate, of different corner
counts) and gives each the numbers it would get alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.geometry.small_batch import row_norms, se3_minus, se3_plus
from tagloc.tags._refine import Refinement, StopRule, _residuals, refine_poses
from tagloc.tags.covariance import (
    Linearization,
    NoiseModel,
    laplace_covariance,
    linearized_pose_covariance,
)
from tagloc.tags.estimates import _range_and_view_angle

BoolArray = npt.NDArray[np.bool_]

#: A refined alternative within this rotation angle of the best one is the same minimum.
_SAME_MINIMUM_RAD = 1e-3
#: A branch this much worse than its rival (SSE / sigma_px^2, chi-square units: 4x the default
#: ambiguity threshold) after 3 iterations stops refining: its exact minimum decides nothing.
_SETTLE_CHI2 = 75.0


@dataclass(frozen=True, slots=True)
class Branches:
    """Best and alternative minimum of ``K`` PnP problems (:func:`finish_branches`).

    Attributes
    ----------
    R, t : (K, 2, 3, 3), (K, 2, 3) float
        ``T_cam_obj`` of the best (index 0) and the alternative (1) branch.
    sse_px2 : (K, 2) float
        Their SSE (``inf``: none / invalid).
    cov, cov_rot_laplace : (K, 2, 6, 6), (K, 2, 3, 3) float
        Full and Laplace covariances (see :class:`TagPoseEstimate`).
    view_angle : (K, 2) float
    T_best, T_alt : SE3, batches of K
    """

    R: FloatArray
    t: FloatArray
    sse_px2: FloatArray
    cov: FloatArray
    cov_rot_laplace: FloatArray
    view_angle: FloatArray
    T_best: SE3
    T_alt: SE3


def _plus(T: SE3, tau: FloatArray) -> SE3:
    """``T.plus(tau)`` (which raises on NaN / inf) through the small-batch fast path."""
    return se3_plus(T, tau) if np.isfinite(tau).all() else T.plus(tau)


def _as_se3(R: FloatArray, t: FloatArray) -> SE3:
    """The solver's rotations are orthonormal by construction (Cayley steps from IPPE's)."""
    return SE3.from_trusted(R, t)


def _pick_branches(
    ref: Refinement, valid: BoolArray, k: int, c: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Best refined minimum and best *distinct* one; without one, the worst other start."""
    R, t = ref.R_cam_obj.reshape(k, c, 3, 3), ref.t_cam_obj.reshape(k, c, 3)
    sse_initial = ref.sse_initial_px2.reshape(k, c)
    sse = np.where(valid & ~ref.stopped.reshape(k, c), ref.sse_px2.reshape(k, c), np.inf)
    J = ref.jacobian.reshape(k, c, *ref.jacobian.shape[1:])
    rows = np.arange(k)
    first = np.argmin(sse, axis=1)
    cos_rel = (np.einsum("kij,kcij->kc", R[rows, first], R) - 1.0) / 2.0
    far = row_norms(t - t[rows, first][:, None])
    distinct = (cos_rel < np.cos(_SAME_MINIMUM_RAD)) | (far > 1e-3 * row_norms(t))
    # within the best minimum, the start that was already best represents it
    raw_sse = np.where(valid, sse_initial, np.inf)
    best = np.argmin(np.where(~distinct & np.isfinite(sse), raw_sse, np.inf), axis=1)
    alt = np.argmin(np.where(distinct, sse, np.inf), axis=1)
    has_alt = np.isfinite(sse[rows, alt]) & distinct[rows, alt]
    pick = np.empty((k, 2), dtype=np.intp)
    pick[:, 0], pick[:, 1] = best, alt
    R_out, t_out = R[rows[:, None], pick], t[rows[:, None], pick]
    sse_out, J_out = sse[rows[:, None], pick], J[rows[:, None], pick]
    if has_alt.all():
        return R_out, t_out, sse_out, J_out
    other_raw = np.where(valid, sse_initial, -np.inf)
    other_raw[rows, best] = -np.inf
    raw = np.argmax(other_raw, axis=1)
    fb = ~has_alt & np.isfinite(other_raw[rows, raw]) & np.isfinite(sse[rows, best])
    if fb.any():
        R0, t0 = ref.R_initial.reshape(k, c, 3, 3), ref.t_initial.reshape(k, c, 3)
        R_out[fb, 1], t_out[fb, 1] = R0[fb, raw[fb]], t0[fb, raw[fb]]
        J_out[fb, 1] = ref.jacobian_initial.reshape(J.shape)[fb, raw[fb]]
        sse_out[fb, 1] = other_raw[fb, raw[fb]]
    sse_out[~has_alt & ~fb, 1] = np.inf
    return R_out, t_out, sse_out, J_out


def _pair_rule(R_start: FloatArray, settle_px2: float) -> StopRule:
    """``stop_early`` for pairs of starts ``(K, 2, 3, 3)`` (the two IPPE branches of a tag, or
    the two joint starts). Freeze a candidate that came within 35 % of the starting angle to
    the other start (it crossed into that basin); after three iterations, settle one whose SSE
    is more than ``settle_px2`` above its rival's (no policy would call that pair ambiguous)."""
    other = R_start[:, ::-1].reshape(-1, 3, 3)
    start_cos = np.einsum("kij,kij->k", R_start.reshape(-1, 3, 3), other)
    start_angle = np.arccos(np.clip((start_cos - 1.0) / 2.0, -1.0, 1.0))
    limit, apart = 0.35 * start_angle, start_angle > 0.05
    watch = bool(apart.any())  # pairs that start together never freeze
    never = np.zeros(len(start_angle), dtype=bool)
    calls = [0]

    def rule(R: FloatArray, t: FloatArray, sse: FloatArray) -> tuple[BoolArray, BoolArray]:
        calls[0] += 1
        freeze = never
        if watch:
            cos = np.clip((np.einsum("kij,kij->k", R, other) - 1.0) / 2.0, -1.0, 1.0)
            freeze = (np.arccos(cos) < limit) & apart
        if calls[0] < 3:
            return freeze, never
        rival = sse.reshape(-1, 2)[:, ::-1].reshape(-1)
        return freeze, np.asarray(sse > rival + settle_px2, dtype=bool)

    return rule


@dataclass(frozen=True, slots=True)
class Refined:
    """The refined branches of ``K`` PnP problems of ``N`` points, before valley and covariances.

    Attributes
    ----------
    R, t : (K, 2, 3, 3), (K, 2, 3) float
        Best (0) and alternative (1) ``T_cam_obj`` (the best again where there is none).
    sse_px2 : (K, 2) float
    jacobian : (K, 2, 2N, 6) float
        Reprojection Jacobians at the two.
    points_obj : (K, N, 3) float
    pixels : (K, N, 2) float
    extent_px : (K,) float
    view_angle : (K, 2) float
    """

    R: FloatArray
    t: FloatArray
    sse_px2: FloatArray
    jacobian: FloatArray
    points_obj: FloatArray
    pixels: FloatArray
    extent_px: FloatArray
    view_angle: FloatArray


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def refine_branches(
    R0: FloatArray,
    t0: FloatArray,
    valid0: BoolArray,
    points_obj: FloatArray,
    pixels: FloatArray,
    camera: CameraModel,
    noise: NoiseModel,
    extent_px: FloatArray,
    view_angle: FloatArray | None = None,
) -> Refined:
    """Refine ``C`` candidates of each of ``K`` PnP problems; pick the best and the alternative.

    Parameters
    ----------
    R0, t0 : (K, C, 3, 3), (K, C, 3) float
        Initial ``T_cam_obj`` candidates.
    valid0 : (K, C) bool
    points_obj : (K, N, 3) float
    pixels : (K, N, 2) float
    camera : CameraModel
    noise : NoiseModel
    extent_px : (K,) float
        Apparent target size for the systematic-error term.
    view_angle : (K,) float, optional
        Tag viewing angle for the noise model; default from each branch's pose (single tags).

    Returns
    -------
    Refined
        To be finished by :func:`finish_branches`.
    """
    k, c = valid0.shape
    n = points_obj.shape[1]
    R0 = np.where(valid0[..., None, None], R0, np.eye(3))
    t0 = np.where(valid0[..., None], t0, np.array([0.0, 0.0, 1.0]))
    stop = _pair_rule(R0, _SETTLE_CHI2 * noise.sigma_px**2) if c == 2 else None
    ref = refine_poses(
        R0.reshape(-1, 3, 3),
        t0.reshape(-1, 3),
        np.repeat(points_obj, c, axis=0),
        np.repeat(pixels, c, axis=0),
        camera,
        stop_early=stop,
    )
    R, t, sse, J = _pick_branches(ref, valid0, k, c)
    alt_ok = np.isfinite(sse[:, 1])
    R[~alt_ok, 1], t[~alt_ok, 1] = R[~alt_ok, 0], t[~alt_ok, 0]
    if view_angle is None:
        angle = _range_and_view_angle(R, t)[1]
    else:
        angle = np.repeat(np.asarray(view_angle, dtype=np.float64)[:, None], 2, axis=1)
    J = J.reshape(k, 2, 2 * n, 6)
    return Refined(R, t, sse, J, points_obj, pixels, np.asarray(extent_px, np.float64), angle)


@np.errstate(all="ignore")  # NaN/inf mark invalid candidates on purpose
def finish_branches(
    camera: CameraModel, noise: NoiseModel, groups: Sequence[Refined]
) -> list[Branches]:
    """Valley and covariances of the refined branches of several groups of problems at once.

    Per group only what depends on its point count (projections, ``J^T J``); everything else
    in one pass over all rows. Each group's :class:`Branches` equals ``finish_branches(camera,
    noise, [group])[0]``.
    """
    bounds = np.cumsum([0] + [len(g.R) for g in groups]).tolist()
    R = np.concatenate([g.R for g in groups])
    t = np.concatenate([g.t for g in groups])
    sse = np.concatenate([g.sse_px2 for g in groups])
    ok, alt_ok = np.isfinite(sse[:, 0]), np.isfinite(sse[:, 1])
    T_best, T_alt = _as_se3(R[:, 0], t[:, 0]), _as_se3(R[:, 1], t[:, 1])
    delta, barrier = _valleys(
        camera, T_best, T_alt, sse, [g.points_obj for g in groups], [g.pixels for g in groups]
    )
    barrier[~alt_ok] = np.inf
    angle = np.concatenate([g.view_angle for g in groups])
    cov, laplace = _covariances(camera, noise, R, t, delta, barrier, angle, groups)
    cov[~ok] = np.nan
    out = []
    for a, b in pairwise(bounds):
        rows = slice(a, b)
        branches = Branches(
            R[rows], t[rows], sse[rows], cov[rows], laplace[rows], angle[rows],
            T_best[rows], T_alt[rows],
        )  # fmt: skip
        out.append(branches)
    return out


def _valleys(
    camera: CameraModel,
    T_best: SE3,
    T_alt: SE3,
    sse: FloatArray,
    points_obj: Sequence[FloatArray],
    pixels: Sequence[FloatArray],
) -> tuple[FloatArray, FloatArray]:
    """Tangents between the two branches of problems stacked in ``T_best``, ``T_alt``, ``sse``
    (group ``g`` has ``points_obj[g]`` (K_g, N_g, 3), ``pixels[g]``) and the cost barrier
    between them; the midpoints of all groups are projected at once.

    Returns
    -------
    delta : (K, 2, 6) float
        ``T_other (-) T`` from each branch to the other.
    barrier : (K, 2) float
        SSE at the geodesic midpoint minus each branch's SSE (pixels^2).
    """
    delta = se3_minus(T_alt, T_best)
    mid = _plus(T_best, 0.5 * delta)
    points_cam, start = [], 0
    for points in points_obj:
        points_cam.append(mid[start : start + len(points)].act(points).reshape(-1, 3))
        start += len(points)
    projected = camera.project(np.concatenate(points_cam) if len(points_cam) > 1 else points_cam[0])
    sse_mid = np.empty(len(sse))
    row = point = 0
    for observed, p in zip(pixels, points_cam, strict=True):
        r = projected[point : point + len(p)].reshape(observed.shape) - observed
        sse_mid[row : row + len(observed)] = np.einsum("kni,kni->k", r, r)
        row, point = row + len(observed), point + len(p)
    sse_mid[~np.isfinite(sse_mid)] = np.inf
    return np.stack([delta, -delta], axis=1), sse_mid[:, None] - sse


def _covariances(
    camera: CameraModel,
    noise: NoiseModel,
    R: FloatArray,
    t: FloatArray,
    delta: FloatArray,
    barrier: FloatArray,
    view_angle: FloatArray,
    groups: Sequence[Refined],
) -> tuple[FloatArray, FloatArray]:
    """Covariances ``(K, 2, 6, 6)`` of both branches: :func:`pose_covariance` at the branch, and
    again with the Jacobian taken two sigmas towards the other branch; the one wider along
    ``delta`` is kept. Near face-on the tilt information grows like ``sin^2`` of the tilt, so
    the Jacobian at an estimate whose tilt came out large overstates what the pixels know (NEES
    at 3-6 m and 10-15 deg: ~10 -> ~5; elsewhere the two agree). Also the lobes' rotation
    covariances ``(K, 2, 3, 3)``: ``sigma^2 (J^T J)^-1`` plus the valley term.

    Rows are ``2 i + b`` (branch ``b`` of problem ``i``) across all ``groups``.
    """
    k = len(R)
    d = delta.reshape(-1, 6)
    # row bounds of the groups (two rows per problem)
    bounds = (2 * np.cumsum([0] + [len(g.R) for g in groups])).tolist()
    lin = Linearization.stack(
        [
            Linearization.of(g.jacobian.reshape(-1, *g.jacobian.shape[2:]), d[a:b])
            for g, a, b in zip(groups, bounds[:-1], bounds[1:], strict=True)
        ]
    )
    R2, t2 = R.reshape(-1, 3, 3), t.reshape(-1, 3)
    extent2 = np.repeat(np.concatenate([g.extent_px for g in groups]), 2)
    angle2, barrier2 = view_angle.reshape(-1), barrier.reshape(-1)
    cov = linearized_pose_covariance(lin, R2, t2, extent2, noise, angle2, d, barrier2)
    laplace = laplace_covariance(lin, noise.sigma_px, d, barrier2)[:, 3:, 3:]
    spread = np.einsum("ki,kij,kj->k", d, cov, d)
    with np.errstate(all="ignore"):
        s = 2.0 * np.sqrt(np.maximum(spread, 0.0)) / np.einsum("ki,ki->k", d, d)
    s = np.where(np.isnan(s), 0.0, np.minimum(s, 0.5))  # nan_to_num, then at most 0.5
    # only where the shift turns the pose by more than ~2 deg does the information change
    rows = np.flatnonzero((s * row_norms(d[:, 3:]) > 0.03) & np.isfinite(spread))
    if len(rows):
        T = SE3.from_trusted(R2[rows], t2[rows])
        shifted = _plus(T, s[rows, None] * d[rows])
        R_shift, t_shift = shifted.rotation.matrix, shifted.translation
        parts = []
        for g, a, b in zip(groups, bounds[:-1], bounds[1:], strict=True):
            mine = (rows >= a) & (rows < b)
            if not mine.any():
                continue
            local = rows[mine] - a
            _, J_shift, _ = _residuals(
                camera,
                R_shift[mine],
                t_shift[mine],
                np.repeat(g.points_obj, 2, axis=0)[local],
                np.repeat(g.pixels, 2, axis=0)[local],
            )
            parts.append(Linearization.of(J_shift, d[rows[mine]]))
        cov_shift = linearized_pose_covariance(
            Linearization.stack(parts),
            R2[rows],
            t2[rows],
            extent2[rows],
            noise,
            angle2[rows],
            d[rows],
            barrier2[rows],
        )
        wider = np.einsum("ki,kij,kj->k", d[rows], cov_shift, d[rows]) > spread[rows]
        cov[rows[wider]] = cov_shift[wider]
    return cov.reshape(k, 2, 6, 6), laplace.reshape(k, 2, 3, 3)
