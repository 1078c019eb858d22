"""Initial values for the factor graph: keyframe poses by re-seated odometry, tags by their
least ambiguous observation, and each observation's IPPE branch.

1. **Keyframes** (one pass in time): dead-reckon with odometry from the latest fix; at a keyframe
   that sees an already placed tag with a clear IPPE solution (ambiguity ratio below the
   threshold), re-seat the keyframe on the nearest such tag (``T_map_base = T_map_tag @
   T_base_tag^-1``) unless that disagrees with dead reckoning by more than the drift could
   explain (a glint). After the first fix only the keyframe's *position* comes from the tag
   (a far, face-on tag's tilt can be 20 degrees wrong, which would move the keyframe by metres)
   and its yaw from the track between fixes at least :data:`YAW_BASE_M` apart. New tags are
   placed from re-seated keyframes once three sightings agree within :data:`AGREE_RADIUS_M`
   (a false detection under a new id cannot place it). Without
   anchors, the first tag seen is the origin. Keyframes before the first fix are back-filled.
2. **Tags** (robust): each observation implies a ``T_map_tag``; among those within
   :data:`INLIER_RADIUS_M` of the median position, the least ambiguous one (lowest ratio, then
   nearest) initializes the tag's position; its rotation is the one most observations agree
   with, counting either IPPE branch (:func:`consensus_rotation`). Anchors keep their
   surveyed pose.
3. **Branches**: each observation uses the IPPE branch whose rotation is closer to the
   prediction from the current keyframe and tag estimates.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import inverse_h as inverse_h  # re-exported for modules not yet moved
from tagloc.mapping.observations import Observations
from tagloc.mapping.survey import MappingError

IntArray = npt.NDArray[np.int64]

INLIER_RADIUS_M = 0.5
#: During the keyframe pass, a new tag is placed once 3 sightings agree within this radius.
AGREE_RADIUS_M = 0.3
CONSENSUS_ANGLE_RAD = np.radians(8.0)
#: Yaw is corrected from the track between position fixes at least this far apart (m).
YAW_BASE_M = 2.0
#: Re-seating a keyframe may move it this much plus a fraction of the distance since the last fix.
RESEAT_TOLERANCE_M, RESEAT_TOLERANCE_PER_M = 1.0, 0.1


def rotation_angle(R_a: FloatArray, R_b: FloatArray) -> FloatArray:
    """Angle of ``R_a^T R_b`` (rad), batched over leading axes."""
    cos = (np.einsum("...ji,...ji->...", R_a, R_b) - 1.0) / 2.0
    return np.asarray(np.arccos(np.clip(cos, -1.0, 1.0)))


def initialize_keyframes(
    obs: Observations, M_map_anchor: Mapping[int, FloatArray], max_ambiguity: float
) -> FloatArray:
    """``(K, 4, 4)`` initial ``T_map_base`` of the keyframes (step 1 of the module docstring).

    ``M_map_anchor`` maps tag indices (into ``obs.tag_keys``) to their ``T_map_tag``.
    """
    M_odom_base = obs.T_odom_base.as_matrix().reshape(-1, 4, 4)
    n_kf = len(M_odom_base)
    order = np.argsort(obs.keyframe, kind="stable")
    bounds = np.searchsorted(obs.keyframe[order], np.arange(n_kf + 1))
    M_map_tag: dict[int, FloatArray] = {j: np.asarray(M) for j, M in M_map_anchor.items()}
    M_map_base = np.full((n_kf, 4, 4), np.nan)
    M_map_odom: FloatArray | None = None
    sightings: dict[int, list[FloatArray]] = {}
    last_fix: FloatArray | None = None
    travelled = 0.0
    for k in range(n_kf):
        idx = order[bounds[k] : bounds[k + 1]]
        clear = idx[obs.ambiguity[idx] <= max_ambiguity]
        if k > 0:
            travelled += float(np.linalg.norm(M_odom_base[k, :3, 3] - M_odom_base[k - 1, :3, 3]))
        pred = None if M_map_odom is None else M_map_odom @ M_odom_base[k]
        known = [i for i in clear if int(obs.tag[i]) in M_map_tag]
        if known:
            i = min(known, key=lambda i: obs.range_m[i])
            M_tag = M_map_tag[int(obs.tag[i])]
            if pred is None:  # the first fix: the rotation the sightings agree with
                meas = _first_fix(obs, M_odom_base, order, bounds, M_map_tag, k, i)
            else:  # position from the tag; yaw from the track between fixes (tilts may be wrong)
                meas = pred.copy()
                meas[:3, 3] = M_tag[:3, 3] - pred[:3, :3] @ obs.T_base_tag[i, 0, :3, 3]
                if last_fix is not None:
                    meas[:3, :3] = _yaw_fix(last_fix, pred[:3, 3], meas[:3, 3]) @ pred[:3, :3]
            limit = RESEAT_TOLERANCE_M + RESEAT_TOLERANCE_PER_M * travelled
            if pred is None or np.linalg.norm(meas[:3, 3] - pred[:3, 3]) <= limit:
                pred, travelled = meas, 0.0
                if last_fix is None or np.linalg.norm(meas[:2, 3] - last_fix[:2]) >= YAW_BASE_M:
                    last_fix = meas[:3, 3].copy()
        elif pred is None and not M_map_anchor and len(idx):
            i = min(idx, key=lambda i: (obs.ambiguity[i], obs.range_m[i]))
            M_map_tag[int(obs.tag[i])] = np.eye(4)  # the first tag seen is the origin
            pred = inverse_h(obs.T_base_tag[i, 0])
        if pred is None:
            continue
        M_map_base[k] = pred
        M_map_odom = pred @ inverse_h(M_odom_base[k])
        for i in clear:  # place a new tag once 3 sightings agree (a glint does not)
            j = int(obs.tag[i])
            if j not in M_map_tag:
                seen = sightings.setdefault(j, [])
                seen.append(pred @ obs.T_base_tag[i, 0])
                placed_at = _agreeing(seen)
                if placed_at is not None:
                    M_map_tag[j] = placed_at
    placed = np.flatnonzero(np.isfinite(M_map_base[:, 0, 0]))
    if len(placed) == 0:
        raise MappingError("no keyframe sees an anchor tag: the map cannot be placed")
    k0 = int(placed[0])
    M_map_base[:k0] = (M_map_base[k0] @ inverse_h(M_odom_base[k0])) @ M_odom_base[:k0]
    return M_map_base


#: The first fix's rotation is the consensus of the sightings of placed tags over this much
#: odometry travel from it (m): enough for the viewpoint to change (the wrong IPPE branch turns
#: with it, the right one stays), short enough that the odometry's drift (0.3 deg/m of yaw bias:
#: 3 deg) stays well inside :data:`CONSENSUS_ANGLE_RAD`.
FIRST_FIX_TRAVEL_M = 10.0


def _first_fix(
    obs: Observations,
    M_odom_base: FloatArray,
    order: IntArray,
    bounds: IntArray,
    M_map_tag: Mapping[int, FloatArray],
    k0: int,
    i0: int,
) -> FloatArray:
    """``T_map_base`` at keyframe ``k0`` from sighting ``i0``: the rotation most sightings of
    placed tags over :data:`FIRST_FIX_TRAVEL_M` of travel agree with, the position from ``i0``.

    The whole start of the map hangs on the first fix. Each sighting implies an ``R_map_odom``
    on each of its two IPPE branches; a face-on tag's wrong branch often reprojects better (one
    turned every keyframe by 143 deg, and later fixes, disagreeing with it, were refused as
    glints), and over the first second of driving the wrong branches of all sightings agree
    too (the viewpoint hardly changes: the better branches of the first 12 sightings of the
    simulated sparse building's anchor put the map 9 to 31 deg off on three seeds of three). Over
    10 m the wrong branch turns with the viewpoint while the right one stays:
    :func:`consensus_rotation` over both branches of every sighting picks it (the same three
    seeds: 7 to 11 mrad), and the mean of the sightings that agree with it is the rotation.
    """
    R_both: list[FloatArray] = []
    k, travelled = k0, 0.0
    while k < len(M_odom_base) and travelled <= FIRST_FIX_TRAVEL_M:
        if k > k0:
            travelled += float(np.linalg.norm(M_odom_base[k, :3, 3] - M_odom_base[k - 1, :3, 3]))
        for i in order[bounds[k] : bounds[k + 1]]:
            j = int(obs.tag[i])
            if j in M_map_tag:
                R_base_tag = np.swapaxes(obs.T_base_tag[i, :, :3, :3], 1, 2)
                R_both.append(M_map_tag[j][:3, :3] @ R_base_tag @ M_odom_base[k, :3, :3].T)
        k += 1
    both = np.asarray(R_both)  # (n, 2, 3, 3); sighting i0 among them
    angle = rotation_angle(consensus_rotation(both)[None, None], both)  # (n, 2)
    branch = np.argmin(angle, axis=1)
    agree = angle[np.arange(len(both)), branch] < CONSENSUS_ANGLE_RAD
    U, _, Vt = np.linalg.svd(both[np.arange(len(both)), branch][agree].sum(axis=0))
    R_map_odom = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt  # the chordal mean
    M = np.eye(4)
    M[:3, :3] = R_map_odom @ M_odom_base[k0, :3, :3]
    M[:3, 3] = M_map_tag[int(obs.tag[i0])][:3, 3] - M[:3, :3] @ obs.T_base_tag[i0, 0, :3, 3]
    return M


def _yaw_fix(origin: FloatArray, predicted: FloatArray, fixed: FloatArray) -> FloatArray:
    """Rotation about z turning the track ``origin -> predicted`` onto ``origin -> fixed``."""
    a, b = predicted[:2] - origin[:2], fixed[:2] - origin[:2]
    if min(np.linalg.norm(a), np.linalg.norm(b)) < YAW_BASE_M:
        return np.eye(3)
    angle = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _agreeing(seen: list[FloatArray], needed: int = 3) -> FloatArray | None:
    """The latest of ``seen`` once ``needed`` of them lie within :data:`AGREE_RADIUS_M` of it."""
    if len(seen) < needed:
        return None
    positions = np.array([M[:3, 3] for M in seen])
    near = np.linalg.norm(positions - positions[-1], axis=1) <= AGREE_RADIUS_M
    return seen[-1] if int(near.sum()) >= needed else None


def initialize_tags(
    obs: Observations, M_map_base: FloatArray, M_map_anchor: Mapping[int, FloatArray]
) -> dict[int, FloatArray]:
    """Initial ``T_map_tag`` of every observed tag (step 2 of the module docstring)."""
    implied_both = M_map_base[obs.keyframe, None] @ obs.T_base_tag  # (M, 2, 4, 4)
    implied = implied_both[:, 0]
    result: dict[int, FloatArray] = {}
    for j in np.unique(obs.tag):
        j = int(j)
        if j in M_map_anchor:
            result[j] = np.asarray(M_map_anchor[j])
            continue
        idx = np.flatnonzero(obs.tag == j)
        median = np.median(implied[idx, :3, 3], axis=0)
        near = idx[np.linalg.norm(implied[idx, :3, 3] - median, axis=1) <= INLIER_RADIUS_M]
        pool = near if len(near) else idx
        best = min(pool, key=lambda i: (obs.ambiguity[i], obs.range_m[i]))
        result[j] = implied[best].copy()
        result[j][:3, :3] = consensus_rotation(implied_both[pool, :, :3, :3])
    return result


def consensus_rotation(R_both: FloatArray, max_candidates: int = 64) -> FloatArray:
    """The rotation most observations agree with, taking either IPPE branch of each.

    ``R_both`` is ``(n, 2, 3, 3)``: both branches of each observation's implied ``R_map_tag``.
    The wrong branch of near face-on views scatters with the viewpoint while the right one
    repeats, so the candidate (from up to ``max_candidates`` observations, both branches) with
    the most observations within :data:`CONSENSUS_ANGLE_RAD` wins (ties: the mean angle).
    """
    n = len(R_both)
    step = max(1, n // max_candidates)
    candidates = R_both[::step].reshape(-1, 3, 3)
    cos = (np.einsum("cij,nbij->cnb", candidates, R_both) - 1.0) / 2.0
    angle = np.arccos(np.clip(cos, -1.0, 1.0)).min(axis=2)  # (C, n), best branch of each
    support = (angle < CONSENSUS_ANGLE_RAD).sum(axis=1)
    score = support - np.mean(np.minimum(angle, CONSENSUS_ANGLE_RAD), axis=1)
    return np.asarray(candidates[int(np.argmax(score))])


def choose_branches(
    obs: Observations, M_map_base: FloatArray, M_map_tag: Mapping[int, FloatArray]
) -> IntArray:
    """Per observation, 0 or 1: the IPPE branch nearer the prediction (step 3)."""
    tags = np.array([M_map_tag[int(j)] for j in obs.tag])
    M_pred = inverse_h(M_map_base[obs.keyframe]) @ tags
    R_pred = M_pred[:, None, :3, :3]
    angle = rotation_angle(R_pred, obs.T_base_tag[:, :, :3, :3])  # (M, 2)
    return np.asarray((angle[:, 1] < angle[:, 0]).astype(np.int64))
