"""Orientation priors for the IPPE ambiguity policy: :class:`OrientationPrior` and its evidence.

A prior is a predicted ``R_cam_obj`` (a prior ``T_map_cam`` and the tag's map pose) and/or
gravity (the camera's up direction and the object's up axis). :func:`prior_evidence` evaluates it
on the two branches of an estimate as chi-squares (:class:`PriorEvidence`), which
:func:`tagloc.tags.gates.resolve_ambiguity` turns into log-odds and a consistency gate.
:func:`tag_prior_evidences` does all tags of a frame in one numpy pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import hat
from tagloc.tags.estimates import TagPoseEstimate

_EYE2, _EYE3 = np.eye(2), np.eye(3)


@dataclass(frozen=True, slots=True)
class OrientationPrior:
    """What is known of ``R_cam_obj`` (``obj`` = a tag, or the map) before looking at pixels.

    Attributes
    ----------
    R_cam_obj : (3, 3) float or None
        Predicted rotation (e.g. ``R_map_cam^T R_map_tag`` from a prior ``T_map_cam``).
    sigma_rad : float
        Per-axis 1-sigma of that prediction.
    up_cam : (3,) float or None
        The world's up direction in the camera frame (``R_base_cam^T e_z`` for an upright robot).
    up_obj : (3,) float
        The object's axis that points up: tag ``+y`` for an upright tag on a wall (default), or
        the tag's map pose ``R_map_tag^T e_z``; ``e_z`` for the map.
    up_sigma_rad : float
        1-sigma of the angle between the two up directions (robot tilt, tag mounting).
    """

    R_cam_obj: FloatArray | None = None
    sigma_rad: float = 0.1
    up_cam: FloatArray | None = None
    up_obj: tuple[float, float, float] | FloatArray = (0.0, 1.0, 0.0)
    up_sigma_rad: float = 0.05

    def chi2(self, R_cam_obj: npt.ArrayLike, cov_rot: npt.ArrayLike | None = None) -> float:
        """Prior chi-square of one candidate rotation (sum over the parts given).

        Innovation tests with the candidate's own uncertainty added to the prior's:
        ``e^T (sigma^2 I + C) e`` with ``e = Log(R_prior^T R)``; for gravity the tangent vector
        ``g = up_cam x (R up_obj)`` (``|g|`` is the sine of the angle between the two up
        directions) in a basis ``B`` of the plane normal to ``up_cam``, with covariance
        ``up_sigma^2 I + (B^T J) C (B^T J)^T``, ``J = [u]x R [a]x = d(g)/d(phi)`` (2 dof).

        Parameters
        ----------
        R_cam_obj : (3, 3) float
        cov_rot : (3, 3) float, optional
            Rotation block of the candidate's right-tangent covariance (zero if None).

        Returns
        -------
        float
        """
        R = np.asarray(R_cam_obj, dtype=np.float64)[None]
        C = None if cov_rot is None else np.asarray(cov_rot, dtype=np.float64)[None, None]
        return float(_prior_chi2(self, R, C)[0, 0])


def _prior_chi2(
    prior: OrientationPrior,
    R: FloatArray,
    C: FloatArray | None,
    R_prior: FloatArray | None = None,
    up_obj: FloatArray | None = None,
) -> FloatArray:
    """:meth:`OrientationPrior.chi2` of ``n`` rotations ``R`` (n, 3, 3) with ``m`` covariances
    each, ``C`` (m, n, 3, 3) (zero if None), as (m, n); one pass of numpy for all of them.

    ``R_prior`` (n, 3, 3) and ``up_obj`` (n, 3) replace the prior's own (one object per
    rotation, e.g. the tags of a frame); its sigmas and ``up_cam`` are shared.
    """
    C = np.zeros((1, 1, 3, 3)) if C is None else C
    total = np.zeros(np.broadcast_shapes(C.shape[:-2], R.shape[:-2]))
    if prior.R_cam_obj is not None:
        R_rel = np.swapaxes(np.asarray(prior.R_cam_obj if R_prior is None else R_prior), -1, -2) @ R
        e = np.array([cv2.Rodrigues(r)[0][:, 0] for r in R_rel])
        e = np.broadcast_to(e, (*total.shape, 3))[..., None]
        S = prior.sigma_rad**2 * _EYE3 + C
        total += (np.swapaxes(e, -1, -2) @ np.linalg.solve(S, e))[..., 0, 0]
    if prior.up_cam is not None:
        a = np.asarray(prior.up_obj if up_obj is None else up_obj, dtype=np.float64)
        u = np.asarray(prior.up_cam, dtype=np.float64)
        a = a / np.linalg.norm(a, axis=-1, keepdims=True)
        u = u / np.linalg.norm(u)
        hat_u = hat(u)
        e1 = hat_u @ _EYE3[int(np.argmin(np.abs(u)))]
        e1 /= np.linalg.norm(e1)
        B = np.stack([e1, hat_u @ e1])  # (2, 3): orthonormal basis of the plane
        BJ = B @ hat_u @ R @ hat(a)  # (n, 2, 3)
        g = (B @ (hat_u @ (R @ a[..., None])))[..., 0]
        S = prior.up_sigma_rad**2 * _EYE2 + BJ @ C @ np.swapaxes(BJ, -1, -2)
        g = np.broadcast_to(g, (*total.shape, 2))[..., None]
        total += (np.swapaxes(g, -1, -2) @ np.linalg.solve(S, g))[..., 0, 0]
    return total


@dataclass(frozen=True, slots=True)
class PriorEvidence:
    """An :class:`OrientationPrior` evaluated on the two branches (:func:`prior_evidence`).

    Attributes
    ----------
    chi2, chi2_alt : float
        Prior chi-square of each branch with the branch's Laplace rotation covariance added
        (the evidence ``N(R_prior; R_branch, S_prior + S_branch)`` up to a constant): their
        difference is the prior's log-odds for the best branch.
    innovation_chi2, innovation_chi2_alt : float
        The same with each branch's full (inflated) rotation covariance: the consistency test
        of the chosen branch against the prior.
    """

    chi2: float
    chi2_alt: float
    innovation_chi2: float
    innovation_chi2_alt: float


def prior_evidence(
    prior: OrientationPrior,
    R_best: npt.ArrayLike,
    R_alt: npt.ArrayLike,
    laplace_best: npt.ArrayLike,
    laplace_alt: npt.ArrayLike,
    cov_rot_best: npt.ArrayLike,
    cov_rot_alt: npt.ArrayLike,
) -> PriorEvidence:
    """Evaluate ``prior`` on the two branches of an estimate of ``R_cam_obj``.

    Parameters
    ----------
    prior : OrientationPrior
    R_best, R_alt : (3, 3) float
        The two branches' ``R_cam_obj``.
    laplace_best, laplace_alt : (3, 3) float
        Their Laplace rotation covariances (``TagPoseEstimate.cov_rot_laplace``).
    cov_rot_best, cov_rot_alt : (3, 3) float
        Rotation blocks of their full covariances.

    Returns
    -------
    PriorEvidence
    """
    R = np.array([R_best, R_alt], dtype=np.float64)
    C = np.array([[laplace_best, laplace_alt], [cov_rot_best, cov_rot_alt]], dtype=np.float64)
    (chi2, chi2_alt), (innovation, innovation_alt) = _prior_chi2(prior, R, C).tolist()
    return PriorEvidence(chi2, chi2_alt, innovation, innovation_alt)


def tag_prior_evidence(prior: OrientationPrior, estimate: TagPoseEstimate) -> PriorEvidence:
    """:func:`prior_evidence` of a single-tag estimate (``obj`` = the tag)."""
    return prior_evidence(
        prior,
        estimate.T_cam_tag.rotation.matrix,
        estimate.T_cam_tag_alt.rotation.matrix,
        estimate.cov_rot_laplace,
        estimate.cov_rot_laplace_alt,
        estimate.cov_cam_tag[3:, 3:],
        estimate.cov_cam_tag_alt[3:, 3:],
    )


def tag_prior_evidences(
    priors: Sequence[OrientationPrior], estimates: Sequence[TagPoseEstimate]
) -> list[PriorEvidence]:
    """:func:`tag_prior_evidence` of each ``(prior, estimate)`` pair (:func:`prior_evidences`).

    Parameters
    ----------
    priors : sequence of K OrientationPrior
    estimates : sequence of K TagPoseEstimate

    Returns
    -------
    list of K PriorEvidence
        Equal to ``[tag_prior_evidence(p, e) for p, e in zip(priors, estimates)]``.
    """
    if len(estimates) != len(priors):
        raise ValueError(f"{len(priors)} priors for {len(estimates)} estimates")
    return prior_evidences(
        priors,
        [e.T_cam_tag.rotation.matrix for e in estimates],
        [e.T_cam_tag_alt.rotation.matrix for e in estimates],
        [e.cov_rot_laplace for e in estimates],
        [e.cov_rot_laplace_alt for e in estimates],
        [e.cov_cam_tag[3:, 3:] for e in estimates],
        [e.cov_cam_tag_alt[3:, 3:] for e in estimates],
    )


def prior_evidences(
    priors: Sequence[OrientationPrior],
    R_best: Sequence[npt.ArrayLike],
    R_alt: Sequence[npt.ArrayLike],
    laplace_best: Sequence[npt.ArrayLike],
    laplace_alt: Sequence[npt.ArrayLike],
    cov_rot_best: Sequence[npt.ArrayLike],
    cov_rot_alt: Sequence[npt.ArrayLike],
) -> list[PriorEvidence]:
    """:func:`prior_evidence` of ``K`` estimates (one item of each sequence per estimate), in
    one numpy pass when the priors differ only in ``R_cam_obj`` and ``up_obj`` (the tags of a
    frame and its joint estimate); equal to the ``K`` calls.

    Raises
    ------
    ValueError
        If the sequences differ in length.
    """
    k = len(priors)
    columns = (R_best, R_alt, laplace_best, laplace_alt, cov_rot_best, cov_rot_alt)
    if any(len(column) != k for column in columns):
        raise ValueError(f"{k} priors for {[len(c) for c in columns]} estimates")
    if k <= 1 or not all(_shared_with(p, priors[0]) for p in priors):
        return [prior_evidence(p, *row) for p, *row in zip(priors, *columns, strict=True)]
    first = priors[0]
    # rows: the best branch of every estimate, then the alternative of every one
    R = np.array(list(R_best) + list(R_alt), dtype=np.float64)
    C = np.array(
        [list(laplace_best) + list(laplace_alt), list(cov_rot_best) + list(cov_rot_alt)],
        dtype=np.float64,
    )
    R_prior = None
    if first.R_cam_obj is not None:
        R_prior = np.array([p.R_cam_obj for p in priors] * 2, dtype=np.float64)
    up_obj = np.array([p.up_obj for p in priors] * 2, dtype=np.float64)
    (chi2, innovation) = _prior_chi2(first, R, C, R_prior, up_obj).tolist()
    return [PriorEvidence(chi2[i], chi2[k + i], innovation[i], innovation[k + i]) for i in range(k)]


def _shared_with(prior: OrientationPrior, first: OrientationPrior) -> bool:
    """Whether ``prior`` can share one :func:`_prior_chi2` pass with ``first``."""
    if (prior.R_cam_obj is None) != (first.R_cam_obj is None):
        return False
    if prior.sigma_rad != first.sigma_rad or prior.up_sigma_rad != first.up_sigma_rad:
        return False
    if prior.up_cam is None or first.up_cam is None:
        return prior.up_cam is first.up_cam
    return prior.up_cam is first.up_cam or bool(np.array_equal(prior.up_cam, first.up_cam))
