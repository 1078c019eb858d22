"""The raw graph of a map build: every factor with its residual at the solution, as records.

``tagloc map build --export-graph graph.jsonl`` writes these, one JSON object per line, so a
person (or a script) can find the factors that pull the map: sort by ``whitened``, look at a
tag's observations over time, then leave the bad ones out with ``--exclude``
(:mod:`tagloc.mapping.exclude`) and build again. Times ``t_s`` are seconds from the survey start
(the first camera frame), the origin ``--exclude`` uses. Records, by ``type``:

- ``header``: ``format`` (``"tagloc-graph"``), ``version`` (1), ``source``, ``t0_ns`` (the
  survey start), ``keyframes``, ``factors`` (count of the lines that follow);
- ``observation``: one tag seen in one camera frame: ``keyframe``, ``stamp_ns``, ``t_s``,
  ``camera``, ``family``, ``tag``, ``residual_px`` (4 corners x ``[du, dv]``, projected minus
  detected, tagloc corner order), ``rms_px``, ``whitened`` (the norm of the 8 corner residuals
  over the pixel sigma; the Mahalanobis norm of the pose error with ``factors="pose"``),
  ``outlier`` (``whitened`` > ``outlier_sigma``);
- ``odometry``: between consecutive keyframes ``keyframe`` - 1 and ``keyframe``: ``stamp_ns``,
  ``t0_s``, ``t1_s``, ``residual`` (``Log(Z^-1 x_{k-1}^-1 x_k)``, ``[x, y, z, rx, ry, rz]`` m
  and rad, Z the step corrected by the odometry calibration), ``translation_m``,
  ``rotation_deg`` (their norms), ``whitened`` (norm of the residual over its sigmas);
- ``anchor``: a prior on a held tag: ``family``, ``tag``, ``residual`` (``Log(prior^-1 T)``),
  ``translation_m``, ``rotation_deg``, ``sigma`` (6 numbers, m and rad), ``whitened``;
- ``gravity``: a keyframe's attitude prior (only with gravity priors): ``keyframe``,
  ``stamp_ns``, ``t_s``, ``tilt_deg`` (angle between the map's and the odometry's "up" in that
  keyframe), ``whitened``;
- ``scan_match``: a lidar registration between keyframes ``keyframe_a`` and ``keyframe_b`` (only
  with lidar, :mod:`tagloc.mapping.scan_factors`): ``t_a_s``, ``t_b_s``, ``loop`` (a loop
  closure rather than consecutive keyframes), ``residual`` (``Log(Z^-1 x_a^-1 x_b)``),
  ``translation_m``, ``rotation_deg``, ``whitened`` (the norm of the residual in the
  registration's information, zero along its unconstrained directions).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import inverse_h, log_h
from tagloc.mapping.calibration import calibration_from_vector, corrected_steps
from tagloc.mapping.gravity import gravity_residuals, keyframe_tilts_deg
from tagloc.mapping.scan_factors import RelativePoseFactors
from tagloc.mapping.whitening import AxisWhitening

IntArray = npt.NDArray[np.int64]
FORMAT, VERSION = "tagloc-graph", 1


@dataclass(frozen=True, slots=True, eq=False)
class GraphAtSolution:
    """What the records are computed from (arrays of the build at its solution).

    Attributes
    ----------
    source : str
    t0_ns : int
        The survey start.
    keyframe_stamps_ns : (K,) int
    M_map_base : (K, 4, 4) float
    M_map_tag : mapping of int to (4, 4) float
    tag_keys : sequence of (family, id)
    keyframe, tag : (M,) int
    camera : sequence of M str
    corner_residual_px : (M, 4, 2) float
    whitened : (M,) float
    outlier_sigma : float
    step_raw : (K-1, 4, 4) float
        Raw odometry steps.
    c : (4,) float
        Odometry calibration vector.
    odometry_noise : AxisWhitening
        The odometry steps' noise (:mod:`tagloc.mapping.odometry_noise`).
    held : mapping of int to (4, 4) float
    held_noise : mapping of int to AxisWhitening
        Each held tag's prior (:func:`tagloc.mapping.anchors.anchor_whitening`).
    up_base : (K, 3) float or None
        Gravity priors' "up" (None: no gravity priors).
    gravity_sigma_rad : float
    relative : RelativePoseFactors or None
        The lidar scan-matching factors (None: a survey without lidar).
    """

    source: str
    t0_ns: int
    keyframe_stamps_ns: IntArray
    M_map_base: FloatArray
    M_map_tag: Mapping[int, FloatArray]
    tag_keys: Sequence[tuple[str, int]]
    keyframe: IntArray
    tag: IntArray
    camera: Sequence[str]
    corner_residual_px: FloatArray
    whitened: FloatArray
    outlier_sigma: float
    step_raw: FloatArray
    c: FloatArray
    odometry_noise: AxisWhitening
    held: Mapping[int, FloatArray]
    held_noise: Mapping[int, AxisWhitening]
    up_base: FloatArray | None
    gravity_sigma_rad: float
    relative: RelativePoseFactors | None = None


def _num(x: float | np.floating[Any], digits: int = 6) -> float | None:
    """A JSON-safe float (None for NaN)."""
    return None if not np.isfinite(x) else round(float(x), digits)


def _vec(v: FloatArray, digits: int = 6) -> list[Any]:
    return [_num(float(x), digits) for x in np.ravel(v)]


def factor_records(g: GraphAtSolution) -> list[dict[str, Any]]:
    """The records of the module docstring, header first."""
    t_s = (g.keyframe_stamps_ns - g.t0_ns) * 1e-9
    records: list[dict[str, Any]] = []
    rms = np.sqrt(np.mean(np.sum(g.corner_residual_px**2, axis=2), axis=1))
    for m in range(len(g.keyframe)):
        k, j = int(g.keyframe[m]), int(g.tag[m])
        records.append({
            "type": "observation", "keyframe": k, "stamp_ns": int(g.keyframe_stamps_ns[k]),
            "t_s": _num(t_s[k], 4), "camera": g.camera[m], "family": g.tag_keys[j][0],
            "tag": g.tag_keys[j][1],
            "residual_px": [_vec(c, 3) for c in g.corner_residual_px[m]],
            "rms_px": _num(rms[m], 4), "whitened": _num(g.whitened[m], 4),
            "outlier": bool(g.whitened[m] > g.outlier_sigma),
        })  # fmt: skip
    if len(g.step_raw):
        Z = corrected_steps(g.step_raw, calibration_from_vector(g.c))
        B = inverse_h(g.M_map_base[:-1]) @ g.M_map_base[1:]
        e = log_h(inverse_h(Z) @ B)
        w = np.linalg.norm(g.odometry_noise.whiten(e), axis=1)
        for k in range(1, len(g.M_map_base)):
            r = e[k - 1]
            records.append({
                "type": "odometry", "keyframe": k, "stamp_ns": int(g.keyframe_stamps_ns[k]),
                "t0_s": _num(t_s[k - 1], 4), "t1_s": _num(t_s[k], 4), "residual": _vec(r),
                "translation_m": _num(np.linalg.norm(r[:3])),
                "rotation_deg": _num(np.degrees(np.linalg.norm(r[3:])), 4),
                "whitened": _num(w[k - 1], 4),
            })  # fmt: skip
    for j, M in sorted(g.held.items()):
        r = log_h((inverse_h(M) @ g.M_map_tag[j])[None])[0]
        noise = g.held_noise[j]
        records.append({
            "type": "anchor", "family": g.tag_keys[j][0], "tag": g.tag_keys[j][1],
            "residual": _vec(r), "translation_m": _num(np.linalg.norm(r[:3])),
            "rotation_deg": _num(np.degrees(np.linalg.norm(r[3:])), 4),
            "sigma": _vec(noise.sigmas[0], 9),
            "whitened": _num(np.linalg.norm(noise.whiten(r[None])[0]), 4),
        })  # fmt: skip
    if g.up_base is not None:
        tilt = keyframe_tilts_deg(g.M_map_base, g.up_base)
        w = np.linalg.norm(gravity_residuals(g.M_map_base, g.up_base, g.gravity_sigma_rad), axis=1)
        for k in range(len(g.M_map_base)):
            records.append({
                "type": "gravity", "keyframe": k, "stamp_ns": int(g.keyframe_stamps_ns[k]),
                "t_s": _num(t_s[k], 4), "tilt_deg": _num(tilt[k], 4), "whitened": _num(w[k], 4),
            })  # fmt: skip
    records += _scan_records(g, t_s)
    header = {
        "type": "header", "format": FORMAT, "version": VERSION, "source": g.source,
        "t0_ns": int(g.t0_ns), "keyframes": len(g.M_map_base), "factors": len(records),
    }  # fmt: skip
    return [header, *records]


def _scan_records(g: GraphAtSolution, t_s: npt.NDArray[np.floating[Any]]) -> list[dict[str, Any]]:
    """The ``scan_match`` records (none without lidar)."""
    f = g.relative
    if f is None or len(f) == 0:
        return []
    B = inverse_h(g.M_map_base[f.a]) @ g.M_map_base[f.b]
    e = log_h(inverse_h(f.M_a_b) @ B)
    w = np.linalg.norm(np.einsum("nij,nj->ni", f.sqrt_information, e), axis=1)
    records = []
    for a, b, loop, r, wi in zip(f.a, f.b, f.loop, e, w, strict=True):
        records.append({
            "type": "scan_match", "keyframe_a": int(a), "keyframe_b": int(b),
            "t_a_s": _num(t_s[a], 4), "t_b_s": _num(t_s[b], 4), "loop": bool(loop),
            "residual": _vec(r), "translation_m": _num(np.linalg.norm(r[:3])),
            "rotation_deg": _num(np.degrees(np.linalg.norm(r[3:])), 4), "whitened": _num(wi, 4),
        })  # fmt: skip
    return records
