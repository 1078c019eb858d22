"""The QA report of a map build: what a human reviews before committing ``tags.yaml``.

Per tag: observation count, outliers (factors whose Mahalanobis error exceeds
``outlier_sigma`` after optimization), RMS corner reprojection residual (pixels, inliers,
through the real camera model at the optimized poses), position 1-sigma from the marginal
covariance, and a flag when its outliers cluster on it (the signature of a tag that moved during
the survey or an id printed twice). Per camera: the RMS residual. The keyframe trajectory before
(odometry, aligned at the first keyframe) and after optimization.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3


@dataclass(frozen=True, slots=True)
class TagQA:
    """QA numbers of one mapped tag (see the module docstring); residuals in pixels."""

    family: str
    tag_id: int
    observations: int
    outliers: int
    reproj_rms_px: float
    position_sigma_m: float
    cameras: tuple[str, ...]
    anchor: bool
    disagreeing: bool
    tilt_ambiguous: bool = False
    rotation_sigma_deg: float = float("nan")
    uncertain: bool = False
    advice: str = ""


@dataclass(frozen=True, slots=True, eq=False)
class BuildReport:
    """Result summary of :func:`tagloc.mapping.build_tag_map`.

    Attributes
    ----------
    source : str
    tags : tuple of TagQA
    reproj_rms_px : float
        Over all inlier corners.
    reproj_rms_px_per_camera : dict of str to float
    observations, outliers, keyframes : int
    dropped : dict of str to int
        Detections left out, by reason.
    disagreeing_tags : tuple of int
        Ids flagged as moved or duplicated.
    keyframe_stamps_ns : (K,) int64
    T_map_base_odometry, T_map_base_optimized : SE3 batch of K
        Keyframe trajectory before (odometry) and after optimization.
    iterations : int
    error_initial, error_final : float
    timings_s : dict of str to float
        ``observations`` (PnP), ``initialize``, ``optimize`` (GTSAM LM, all rounds),
        ``graph`` (building graphs and reading results), ``covariance``, ``report``, ``total``;
        with lidar ``lidar_keyframes`` (de-skew, targets) and ``scan_matching`` (registrations).
    tilt_deg : float
        Angle between the map's z and the odometry frame's z carried into ``map`` by the
        optimized keyframes (:func:`tagloc.mapping.gravity.map_tilt_deg`): the map's tilt against
        gravity when the odometry is gravity-aligned.
    gravity_priors : bool
        Whether keyframes had gravity priors (a gravity-aligned ``MapBuildConfig.odometry_frame``).
    uncertainty_flag_m : float
        The position sigma above which a tag is flagged ``uncertain`` (with advice).
    factors : tuple of dict
        Every factor with its residual at the solution, header first
        (:mod:`tagloc.mapping.graph_export`); :meth:`graph_jsonl` writes them.
    scan_matching : dict of str to int
        With lidar: keyframe scans, consecutive and loop registrations accepted and rejected.
    scale : dict of str to float
        The scales the build found (fractions: 0.01 is 1 %): ``odometry`` (the correction of
        the odometry's distance scale, :mod:`tagloc.mapping.calibration`) and, with lidar,
        ``scan_matching`` with ``scan_matching_sigma``: the consecutive registrations' scale
        against the optimized keyframes (:func:`tagloc.mapping.scan_factors.scan_scale`).
    """

    source: str
    tags: tuple[TagQA, ...]
    reproj_rms_px: float
    reproj_rms_px_per_camera: dict[str, float]
    observations: int
    outliers: int
    keyframes: int
    dropped: dict[str, int]
    disagreeing_tags: tuple[int, ...]
    keyframe_stamps_ns: npt.NDArray[np.int64]
    T_map_base_odometry: SE3
    T_map_base_optimized: SE3
    iterations: int
    error_initial: float
    error_final: float
    timings_s: dict[str, float] = field(default_factory=dict)
    tilt_deg: float = float("nan")
    gravity_priors: bool = False
    uncertainty_flag_m: float = float("nan")
    factors: tuple[dict[str, Any], ...] = ()
    scan_matching: dict[str, int] = field(default_factory=dict)
    scale: dict[str, float] = field(default_factory=dict)
    #: What the build found wrong with its inputs (printed as ``WARNING:`` lines).
    warnings: tuple[str, ...] = ()

    @property
    def uncertain_tags(self) -> tuple[int, ...]:
        """Ids of the tags whose position sigma exceeds ``uncertainty_flag_m``."""
        return tuple(t.tag_id for t in self.tags if t.uncertain)

    def correction_m(self) -> FloatArray:
        """``(K,)`` distance between odometry and optimized keyframe positions, m."""
        return np.asarray(
            np.linalg.norm(
                self.T_map_base_odometry.translation - self.T_map_base_optimized.translation,
                axis=-1,
            )
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no trajectories)."""
        return {
            "source": self.source,
            "keyframes": self.keyframes,
            "observations": self.observations,
            "outliers": self.outliers,
            "dropped": self.dropped,
            "reproj_rms_px": round(self.reproj_rms_px, 4),
            "reproj_rms_px_per_camera": {
                k: round(v, 4) for k, v in self.reproj_rms_px_per_camera.items()
            },
            "disagreeing_tags": list(self.disagreeing_tags),
            "uncertain_tags": list(self.uncertain_tags),
            "uncertainty_flag_m": self.uncertainty_flag_m,
            "tilt_deg": round(self.tilt_deg, 4),
            "gravity_priors": self.gravity_priors,
            "warnings": list(self.warnings),
            "max_odometry_correction_m": round(float(self.correction_m().max()), 4),
            "iterations": self.iterations,
            "error_initial": self.error_initial,
            "error_final": self.error_final,
            "timings_s": {k: round(v, 4) for k, v in self.timings_s.items()},
            "scan_matching": dict(self.scan_matching),
            "scale": {k: round(v, 6) for k, v in self.scale.items()},
            "tags": [
                {
                    "id": t.tag_id,
                    "family": t.family,
                    "observations": t.observations,
                    "outliers": t.outliers,
                    "reproj_rms_px": round(t.reproj_rms_px, 4),
                    "position_sigma_mm": round(1000 * t.position_sigma_m, 3),
                    "rotation_sigma_deg": round(t.rotation_sigma_deg, 4),
                    "uncertain": t.uncertain,
                    "advice": t.advice,
                    "cameras": list(t.cameras),
                    "anchor": t.anchor,
                    "disagreeing": t.disagreeing,
                    "tilt_ambiguous": t.tilt_ambiguous,
                }
                for t in self.tags
            ],
        }

    def graph_jsonl(self) -> str:
        """:attr:`factors` as JSON lines (``tagloc map build --export-graph``)."""
        return "".join(json.dumps(f, separators=(",", ":")) + "\n" for f in self.factors)

    def to_json(self) -> str:
        """:meth:`to_dict` as indented JSON."""
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def summary_lines(self) -> list[str]:
        """A few lines for the terminal."""
        per_cam = ", ".join(f"{k} {v:.2f} px" for k, v in self.reproj_rms_px_per_camera.items())
        t = self.timings_s
        return [
            f"{self.source}: {len(self.tags)} tags from {self.observations} observations in "
            f"{self.keyframes} keyframes ({self.outliers} outliers)",
            f"reprojection RMS {self.reproj_rms_px:.2f} px ({per_cam})",
            f"odometry corrected by up to {self.correction_m().max():.2f} m; "
            f"{self.iterations} LM iterations, error {self.error_initial:.4g} -> "
            f"{self.error_final:.4g}",
            "disagreeing tags (moved or duplicated?): "
            + (", ".join(str(i) for i in self.disagreeing_tags) or "none"),
            "tilt ambiguous (seen only face-on or far; check their orientation): "
            + (", ".join(str(t.tag_id) for t in self.tags if t.tilt_ambiguous) or "none"),
            f"map tilt against the odometry's gravity {self.tilt_deg:.2f} deg ("
            + ("gravity priors on" if self.gravity_priors else "no gravity priors")
            + ")",
            f"uncertain tags (position sigma > {100 * self.uncertainty_flag_m:.0f} cm): "
            + (", ".join(str(i) for i in self.uncertain_tags) or "none"),
            *(f"  tag {t.tag_id}: {t.advice}" for t in self.tags if t.uncertain and t.advice),
            f"time {t.get('total', 0.0):.2f} s (PnP {t.get('observations', 0.0):.2f} s, "
            f"optimize {t.get('optimize', 0.0):.2f} s, "
            f"covariance {t.get('covariance', 0.0):.2f} s)",
            *self._scan_lines(),
            *self._scale_lines(),
            *(f"WARNING: {w}" for w in self.warnings),
        ]

    def _scale_lines(self) -> list[str]:
        c = self.scale
        if "odometry" not in c:
            return []
        line = f"scale: odometry corrected by {100 * c['odometry']:+.2f} %"
        if "scan_matching" in c:
            line += (
                f"; scan matching {100 * c['scan_matching']:+.3f} % "
                f"(+- {100 * c.get('scan_matching_sigma', float('nan')):.3f} %) against the map"
            )
        return [line]

    def _scan_lines(self) -> list[str]:
        m = self.scan_matching
        if not m:
            return []
        return [
            f"lidar: {m['keyframes']} keyframe scans; {m['sequential']} consecutive registrations "
            f"({m['sequential_rejected']} rejected), {m['loops']} loop closures "
            f"({m['loops_rejected']} rejected); scan matching "
            f"{self.timings_s.get('scan_matching', 0.0):.1f} s"
        ]

    def to_markdown(self) -> str:
        """The summary and a per-tag table, as Markdown."""
        lines = ["# Tag map build report", "", *(f"- {line}" for line in self.summary_lines())]
        lines += [
            "",
            "| tag | obs | outliers | reproj RMS px | sigma mm | sigma deg | cameras | note |",
            "|---:|---:|---:|---:|---:|---:|---|---|",
        ]
        for t in self.tags:
            note = "anchor" if t.anchor else ("DISAGREES" if t.disagreeing else "")
            note += " tilt ambiguous" if t.tilt_ambiguous else ""
            note += f" UNCERTAIN: {t.advice}" if t.uncertain else ""
            lines.append(
                f"| {t.tag_id} | {t.observations} | {t.outliers} | {t.reproj_rms_px:.2f} | "
                f"{1000 * t.position_sigma_m:.1f} | {t.rotation_sigma_deg:.2f} | "
                f"{' '.join(t.cameras)} | {note.strip()} |"
            )
        return "\n".join(lines) + "\n"


def tag_sigmas(cov: Mapping[int, FloatArray]) -> tuple[dict[int, float], dict[int, float]]:
    """Position sigma (m, the root of the trace of the x, y, z block) and rotation sigma (deg,
    the same of the rx, ry, rz block) of each covariance ``[x, y, z, rx, ry, rz]``."""
    pos = {j: float(np.sqrt(max(np.trace(c[:3, :3]), 0.0))) for j, c in cov.items()}
    rot = {j: float(np.degrees(np.sqrt(max(np.trace(c[3:, 3:]), 0.0)))) for j, c in cov.items()}
    return pos, rot
