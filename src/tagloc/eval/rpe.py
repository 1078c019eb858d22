"""Relative pose error (RPE) per distance travelled or per time elapsed.

RPE follows Sturm et al. (2012, "A benchmark for the evaluation of RGB-D SLAM systems", eq. 3)
as ``evo_rpe`` computes it. For a pair of stamps ``(i, j)`` with reference poses ``Q`` and
estimated poses ``P`` (both ``T_map_base``):

``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``

its translation error is ``|t(E_ij)|`` (metres) and its rotation error the angle of
``R(E_ij)``, ``|Log(R(E_ij))|`` (degrees).

Pairs are *consecutive* (``evo_rpe`` without ``--all_pairs``) and chosen on the reference:

- by distance (``evo_rpe --delta D --delta_unit m --pairs_from_reference``): start at pose 0,
  add the reference's step lengths ``|t(Q_k) - t(Q_(k-1))|``; the first pose at which the sum
  reaches ``D`` ends the pair and starts the next one (the sum restarts at 0);
- by time (evo has no time unit): start at pose 0; the first pose whose stamp is at least
  ``delta`` later ends the pair and starts the next one. On stamps evenly ``dt`` apart with
  ``delta = k dt`` these are ``evo_rpe --delta k --delta_unit f`` (frames) pairs.

So every estimate of the same run is scored on the same pairs.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.eval.errors import EvaluationError
from tagloc.geometry import SE3

IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class RelativeError:
    """RPE over consecutive pairs (module docstring): by distance or by time.

    The per-pair values are :func:`pair_errors` of :func:`pairs_by_path` or
    :func:`pairs_by_time`.

    Attributes
    ----------
    delta_m : float
        Reference path between the two poses of a pair, metres (NaN when pairs are by time).
    delta_s : float
        Time between the two poses of a pair, seconds (NaN when pairs are by distance).
    n_pairs : int
    translation_rmse_m, translation_max_m : float
        Of ``|t(E_ij)|`` over the pairs, metres (per ``delta``).
    rotation_rmse_deg, rotation_max_deg : float
        Of the angle of ``R(E_ij)`` over the pairs, degrees.
    """

    delta_m: float
    delta_s: float
    n_pairs: int
    translation_rmse_m: float
    translation_max_m: float
    rotation_rmse_deg: float
    rotation_max_deg: float


def pairs_by_path(positions_ref: npt.ArrayLike, delta_m: float) -> IntArray:
    """Consecutive pairs ``(i, j)`` of ``delta_m`` reference path (module docstring), (K, 2)."""
    xyz = np.asarray(positions_ref, dtype=np.float64)
    steps = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    ends = [0]
    path = 0.0
    for k, step in enumerate(steps.tolist(), start=1):  # a sequential sum, restarted per pair
        path += step
        if path >= delta_m:
            ends.append(k)
            path = 0.0
    return np.array(list(itertools.pairwise(ends)), dtype=np.int64).reshape(-1, 2)


def pairs_by_time(stamps_ns: npt.ArrayLike, delta_ns: int) -> IntArray:
    """Consecutive pairs ``(i, j)`` with ``j`` the first stamp ``>= stamps[i] + delta_ns``."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    ends = [0]
    while len(stamps):
        nxt = int(np.searchsorted(stamps, stamps[ends[-1]] + delta_ns, side="left"))
        if nxt >= len(stamps):
            break
        ends.append(max(nxt, ends[-1] + 1))
    return np.array(list(itertools.pairwise(ends)), dtype=np.int64).reshape(-1, 2)


def pair_errors(T_ref: SE3, T_est: SE3, pairs: IntArray) -> tuple[FloatArray, FloatArray]:
    """Translation (m) and rotation-angle (deg) of ``E_ij`` (module docstring) for each pair."""
    i, j = pairs[:, 0], pairs[:, 1]
    E = (T_ref[i].inverse() @ T_ref[j]).inverse() @ (T_est[i].inverse() @ T_est[j])
    translation = np.linalg.norm(np.asarray(E.translation), axis=-1)
    rotation = np.degrees(np.linalg.norm(np.asarray(E.rotation.as_rotvec()), axis=-1))
    return translation, rotation


def _check(stamps_ns: IntArray, T_ref: SE3, T_est: SE3, delta: float, unit: str) -> None:
    if not (math.isfinite(delta) and delta > 0):
        raise EvaluationError(f"RPE pair spacing {delta!r} {unit}: expected a finite number > 0")
    if len(T_ref) != len(stamps_ns) or len(T_est) != len(stamps_ns):
        raise EvaluationError("relative_pose_error: trajectory lengths differ from the stamps")


def _summarize(
    pairs: IntArray, T_ref: SE3, T_est: SE3, delta_m: float, delta_s: float
) -> RelativeError | None:
    if len(pairs) == 0:
        return None
    translation, rotation = pair_errors(T_ref, T_est, pairs)
    return RelativeError(
        delta_m=float(delta_m),
        delta_s=float(delta_s),
        n_pairs=len(pairs),
        translation_rmse_m=math.sqrt(float(np.mean(translation**2))),
        translation_max_m=float(translation.max()),
        rotation_rmse_deg=math.sqrt(float(np.mean(rotation**2))),
        rotation_max_deg=float(rotation.max()),
    )


def relative_pose_error(
    stamps_ns: IntArray, T_map_base_ref: SE3, T_map_base_est: SE3, *, delta_m: float = 1.0
) -> RelativeError | None:
    """RPE per ``delta_m`` metres of reference path (pairs by distance, module docstring).

    Parameters
    ----------
    stamps_ns : (N,) int64
    T_map_base_ref, T_map_base_est : SE3 batches of N
        Reference and estimate at the same stamps.
    delta_m : float
        Reference path between the poses of a pair, metres.

    Returns
    -------
    RelativeError or None
        None when the path is shorter than ``delta_m``.

    Raises
    ------
    EvaluationError
        Lengths differ or ``delta_m`` is not a finite positive number.
    """
    return _relative_error(stamps_ns, T_map_base_ref, T_map_base_est, delta_m, "m")


def relative_pose_error_per_time(
    stamps_ns: IntArray, T_map_base_ref: SE3, T_map_base_est: SE3, *, delta_s: float = 1.0
) -> RelativeError | None:
    """RPE per ``delta_s`` seconds (pairs by time, module docstring); None if the run is shorter.

    Raises ``EvaluationError`` where lengths differ, stamps are not increasing, or ``delta_s`` is
    not finite and positive.
    """
    return _relative_error(stamps_ns, T_map_base_ref, T_map_base_est, delta_s, "s")


def _relative_error(
    stamps_ns: IntArray, T_ref: SE3, T_est: SE3, delta: float, unit: str
) -> RelativeError | None:
    """Pairs ``delta`` metres (``unit`` ``"m"``) or seconds (``"s"``) apart, summarized."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    _check(stamps, T_ref, T_est, delta, unit)
    if unit == "m":
        return _summarize(pairs_by_path(T_ref.translation, delta), T_ref, T_est, delta, math.nan)
    if np.any(np.diff(stamps) < 0):
        raise EvaluationError("relative_pose_error_per_time: stamps are not increasing")
    pairs = pairs_by_time(stamps, round(delta * 1e9))
    return _summarize(pairs, T_ref, T_est, math.nan, delta)
