"""Tags stuck on the wrong tilt: the planar ambiguity, resolved with all of a tag's corners.

A tag seen only near face-on and far away has two tilts that each fit every single view (the
IPPE ambiguity, the normal mirrored about the line of sight); when most views start on the wrong
one, the joint optimum stays there (measured on the simulated office with perfect odometry:
tags 14, 16 and 24 at 18-22 degrees, although the true tilt fits their corners better by a
log-likelihood of 14-20, at 0.5 px assumed noise). A tag initialized from drifted keyframes
can be off by more than that: tag 0 of the one-loop survey, seen only on the way back after
190 m, started 135 degrees off, and the robust kernels rejected its views (32 outliers) until
this test. So after the corner refinement, each tag is tested:

1. candidate rotations: the current one; the consensus of its observations' implied rotations
   at the optimized keyframes, either IPPE branch
   (:func:`~tagloc.mapping.initialize.consensus_rotation`); the consensus of their *other*
   branches; the current normal mirrored about the mean line of sight;
2. each candidate is fitted to the tag's corners with the keyframes held
   (:func:`~tagloc.mapping.tag_fit.fit_tag_pose`), giving local optima and their robust
   negative log-likelihoods;
3. the best optimum replaces the tag if it is a different tilt (more than :data:`SAME_DEG`) and
   better by :data:`MIN_GAIN_NLL`; the builder then refines the whole graph again. A tag whose
   second-best distinct optimum is within :data:`AMBIGUOUS_NLL` is reported as tilt ambiguous.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.mapping.initialize import consensus_rotation, rotation_angle
from tagloc.mapping.observations import Observations
from tagloc.mapping.tag_fit import HeldViews, fit_tag_pose

#: Optima closer than this (degrees) are the same tilt.
SAME_DEG = 3.0
#: A different tilt must fit better by this log-likelihood to replace the current one.
MIN_GAIN_NLL = 2.0
#: A distinct second optimum within this log-likelihood of the best: the tilt is ambiguous.
AMBIGUOUS_NLL = 5.0


def _mirrored(R_map_tag: FloatArray, view_dir: FloatArray) -> FloatArray:
    """``R_map_tag`` turned so that its normal (z) is mirrored about the unit ``view_dir``."""
    n = R_map_tag[:, 2]
    n_alt = 2.0 * float(n @ view_dir) * view_dir - n
    axis = np.cross(n, n_alt)
    s, c = float(np.linalg.norm(axis)), float(n @ n_alt)
    if s < 1e-9:
        return R_map_tag
    R_turn = SE3.from_rotvec(axis / s * np.arctan2(s, c), np.zeros(3)).rotation.as_matrix()
    return np.asarray(R_turn @ R_map_tag)


def _candidates(
    M_map_tag: FloatArray, implied: FloatArray, view_dir: FloatArray
) -> list[FloatArray]:
    """Start rotations (step 1), near-duplicates (within :data:`SAME_DEG`) removed."""
    R = implied[:, :, :3, :3]  # (n, 2, 3, 3)
    angle = rotation_angle(np.broadcast_to(M_map_tag[:3, :3], R.shape), R)
    other = R[np.arange(len(R)), np.argmax(angle, axis=1)]
    rotations = [
        M_map_tag[:3, :3],
        consensus_rotation(R),
        consensus_rotation(other[:, None]),
        _mirrored(M_map_tag[:3, :3], view_dir),
    ]
    kept: list[FloatArray] = []
    for R_c in rotations:
        if all(np.degrees(rotation_angle(R_c, R_k)) >= SAME_DEG for R_k in kept):
            kept.append(R_c)
    return kept


def flip_stuck_tags(
    obs: Observations,
    M_map_base: FloatArray,
    M_map_tag: Mapping[int, FloatArray],
    fixed: set[int],
    cameras: Mapping[str, CameraModel],
    T_base_cam: Mapping[str, SE3],
    sigma_px: float,
) -> tuple[dict[int, FloatArray], list[int], list[int]]:
    """``M_map_tag`` with stuck tags flipped to their better tilt; flipped and ambiguous indices.

    Parameters
    ----------
    obs : Observations
    M_map_base : (K, 4, 4) float
        Optimized keyframes (held).
    M_map_tag : mapping of int to (4, 4) float
        Optimized tags, by index into ``obs.tag_keys``.
    fixed : set of int
        Tags not to test (anchors).
    cameras, T_base_cam : mapping of str
    sigma_px : float
        Corner noise, pixels per axis.

    Returns
    -------
    (M_map_tag, flipped, ambiguous)
        Tags after the test (flipped ones at their fitted pose), and the indices flipped and
        reported ambiguous (steps 1-3 of the module docstring).
    """
    result = {j: np.array(M) for j, M in M_map_tag.items()}
    flipped, ambiguous = [], []
    implied_all = M_map_base[obs.keyframe, None] @ obs.T_base_tag  # (M, 2, 4, 4)
    cam_origin = {name: T.as_matrix()[:3, 3] for name, T in T_base_cam.items()}
    for j, M in M_map_tag.items():
        if j in fixed:
            continue
        idx = np.flatnonzero(obs.tag == j)
        offsets = np.array([cam_origin[obs.camera[i]] for i in idx])
        p_cam = np.einsum("mij,mj->mi", M_map_base[obs.keyframe[idx], :3, :3], offsets)
        p_cam += M_map_base[obs.keyframe[idx], :3, 3]
        view = np.mean((p_cam - M[:3, 3]) / np.linalg.norm(p_cam - M[:3, 3], axis=1)[:, None], 0)
        view /= max(float(np.linalg.norm(view)), 1e-12)
        fits = []
        views = HeldViews(obs, idx, M_map_base, cameras, T_base_cam, sigma_px)
        for R_start in _candidates(np.asarray(M), implied_all[idx], view):
            M_start = np.array(M)
            M_start[:3, :3] = R_start
            fits.append(fit_tag_pose(views, M_start))
        nll = np.array([f[1] for f in fits])
        best = int(np.argmin(nll))
        distinct = [
            i
            for i, (M_fit, _) in enumerate(fits)
            if np.degrees(rotation_angle(M_fit[:3, :3], fits[best][0][:3, :3])) >= SAME_DEG
        ]
        moved_deg = np.degrees(rotation_angle(fits[0][0][:3, :3], fits[best][0][:3, :3]))
        if moved_deg >= SAME_DEG and nll[best] < nll[0] - MIN_GAIN_NLL:
            result[j] = fits[best][0]
            flipped.append(j)
        if distinct and float(nll[distinct].min()) - float(nll[best]) < AMBIGUOUS_NLL:
            ambiguous.append(j)
    return result, flipped, ambiguous
