"""Files of a tag-sensor sweep: ``tag_sweep.csv``, ``tag_sweep_joint.csv``, ``tag_sweep.md``,
the config and the plots.

:func:`format_csv` and :func:`format_markdown` are pure (text in, text out);
:func:`write_tag_sweep` writes every file atomically (temporary file beside it, then rename).

Markdown columns (one table per blur/noise condition): ``dist`` (m) and ``angle`` (deg) of the
cell; ``det`` and ``acc``: detection and acceptance rate of its views; ``pos med`` / ``pos p95``
(cm) and ``rot med`` / ``rot p95`` (deg): error of the accepted ``T_cam_tag``; ``cam pos med``
(cm): error of the camera's position in the tag frame, i.e. of a fix; ``flips``: accepted
ambiguity flips; ``NEES/dof``: mean NEES of the accepted estimates over 6 (1 is honest, below 1
conservative); ``corner px``: RMS corner error of the detections; ``detect`` / ``rest`` (ms):
median time per frame of detection, and of PnP + covariance + gates; ``rejected``: why the other
views were not accepted. The joint table: ``joint acc``, the fraction of frames with an accepted
joint estimate; its errors (of ``T_map_cam``); the best single tag's rotation error; NEES/dof.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path

from tagloc.eval.summary_types import Check
from tagloc.eval.tag_sweep import JointRow, TagSweepResult
from tagloc.eval.tag_sweep_config import save_tag_sweep_config
from tagloc.eval.tag_sweep_plots import plot_tag_sweep_errors, plot_tag_sweep_rates
from tagloc.eval.tag_sweep_stats import TagSweepRow, conditions
from tagloc.fileutil import atomic_write_text

#: Files :func:`write_tag_sweep` writes, in order.
SWEEP_FILES = (
    "tag_sweep.csv",
    "tag_sweep_joint.csv",
    "tag_sweep.md",
    "tag_sweep_config.yaml",
    "tag_sweep_errors.png",
    "tag_sweep_rates.png",
)

CSV_COLUMNS = (
    "distance_m", "angle_deg", "blur_px", "noise_dn", "n_views", "n_detected", "n_accepted",
    "detection_rate", "acceptance_rate", "position_error_median_m", "position_error_p95_m",
    "rotation_error_median_deg", "rotation_error_p95_deg", "camera_position_error_median_m",
    "camera_position_error_p95_m", "flips", "nees_per_dof",
    "corner_rms_px", "detect_ms", "rest_ms", "false_detections", "rejections",
)  # fmt: skip


def _num(value: float, digits: int, scale: float = 1.0) -> str:
    return f"{value * scale:.{digits}f}" if math.isfinite(value) else "-"


def format_rejections(rejections: Sequence[tuple[str, int]]) -> str:
    """``"ambiguous:3 missed:1"`` (empty if none)."""
    return " ".join(f"{reason}:{n}" for reason, n in rejections)


def format_csv(rows: Sequence[TagSweepRow]) -> str:
    """One line per cell, columns :data:`CSV_COLUMNS` (SI units as named; NaN empty)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for r in rows:
        values = [getattr(r, c) for c in CSV_COLUMNS[:-1]]
        cells = [
            "" if isinstance(v, float) and math.isnan(v) else (f"{v:.6g}" if isinstance(v, float)
                                                                 else str(v))
            for v in values
        ]  # fmt: skip
        writer.writerow([*cells, format_rejections(r.rejections)])
    return buffer.getvalue()


JOINT_CSV_COLUMNS = tuple(f.name for f in dataclasses.fields(JointRow))


def format_joint_csv(rows: Sequence[JointRow]) -> str:
    """One line per joint cell, columns :data:`JOINT_CSV_COLUMNS` (NaN empty)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(JOINT_CSV_COLUMNS)
    for r in rows:
        values = [getattr(r, c) for c in JOINT_CSV_COLUMNS]
        writer.writerow(
            ["" if isinstance(v, float) and math.isnan(v) else f"{v:.6g}" for v in values]
        )
    return buffer.getvalue()


#: Columns of :func:`sweep_cells` (the module docstring says what each means).
SWEEP_COLUMNS = (
    "dist (m)", "angle (deg)", "det", "acc", "pos med (cm)", "pos p95 (cm)", "rot med (deg)",
    "rot p95 (deg)", "cam pos med (cm)", "flips", "NEES/dof", "corner px", "detect (ms)",
    "rest (ms)", "rejected",
)  # fmt: skip
#: Columns of :func:`joint_cells`.
JOINT_COLUMNS = (
    "tags", "dist (m)", "joint acc", "rot med (deg)", "rot p95 (deg)", "pos med (cm)",
    "best single rot med (deg)", "NEES/dof",
)  # fmt: skip


def sweep_cells(r: TagSweepRow) -> list[str]:
    """One sweep cell as text, in :data:`SWEEP_COLUMNS` order (markdown and terminal)."""
    return [
        f"{r.distance_m:g}", f"{r.angle_deg:g}", _num(r.detection_rate, 2),
        _num(r.acceptance_rate, 2), _num(r.position_error_median_m, 2, 100),
        _num(r.position_error_p95_m, 2, 100), _num(r.rotation_error_median_deg, 2),
        _num(r.rotation_error_p95_deg, 2), _num(r.camera_position_error_median_m, 2, 100),
        str(r.flips), _num(r.nees_per_dof, 2), _num(r.corner_rms_px, 2), _num(r.detect_ms, 1),
        _num(r.rest_ms, 1), format_rejections(r.rejections),
    ]  # fmt: skip


def joint_cells(r: JointRow) -> list[str]:
    """One joint-PnP cell as text, in :data:`JOINT_COLUMNS` order."""
    return [
        str(r.n_tags), f"{r.distance_m:g}", _num(r.joint_rate, 2),
        _num(r.rotation_error_median_deg, 2), _num(r.rotation_error_p95_deg, 2),
        _num(r.position_error_median_m, 2, 100), _num(r.best_single_rotation_median_deg, 2),
        _num(r.nees_per_dof, 2),
    ]  # fmt: skip


def _markdown(columns: Sequence[str], aligns: Sequence[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(columns) + " |", "|" + "".join(aligns)]
    return lines + ["| " + " | ".join(cells) + " |" for cells in rows]


def joint_markdown_table(rows: Sequence[JointRow]) -> list[str]:
    """The joint cells as markdown table lines."""
    return _markdown(JOINT_COLUMNS, ["---:|"] * 8, [joint_cells(r) for r in rows])


def markdown_table(rows: Sequence[TagSweepRow]) -> list[str]:
    """The rows of one condition as markdown table lines (columns in the module docstring)."""
    return _markdown(SWEEP_COLUMNS, ["---:|"] * 14 + ["---|"], [sweep_cells(r) for r in rows])


def check_lines(checks: Sequence[Check]) -> list[str]:
    """The checks as a markdown table."""
    lines = ["| check | value | target | result |", "|---|---:|---|---|"]
    for c in checks:
        value = f"{c.value:.4g}" if math.isfinite(c.value) else "n/a"
        none = "inconclusive" if math.isfinite(c.value) else "n/a"
        result = {True: "pass", False: "**FAIL**", None: none}[c.passed]
        lines.append(f"| {c.name} | {value} | {c.target} | {result} |")
    return lines


def format_markdown(result: TagSweepResult) -> str:
    """The sweep as markdown: setup, one table per condition, summary and checks."""
    c = result.config
    noise = c.noise_model()
    lines = [
        f"Tag sweep: {c.tag_size_m:g} m {c.family}, {c.image_width}x{c.image_height} "
        f"pinhole with {c.hfov_deg:g} deg horizontal field of view, backend `{c.backend}`"
        + (f" ({c.detector_options})" if c.detector_options else "")
        + f", prior `{c.prior}`, noise model sigma {noise.sigma_px:g} px; "
        f"{c.trials} views a cell, seed {c.seed}.",
        "",
    ]
    for blur, read in conditions(result.rows):
        rows = [r for r in result.rows if (r.blur_px, r.noise_dn) == (blur, read)]
        reference = " (reference condition)" if (blur, read) == c.reference_condition else ""
        lines += [f"Blur {blur:g} px, read noise {read:g} DN{reference}:", ""]
        lines += [*markdown_table(rows), ""]
    if result.joint_rows:
        lines += [
            f"Joint PnP, tags {c.joint_spacing_m:g} m apart seen face-on, reference condition "
            "(best single: the frame's single-tag estimate nearest the truth, before gates):",
            "",
            *joint_markdown_table(result.joint_rows),
            "",
        ]
    lines += [
        f"{result.n_views} views in {result.elapsed_s:.0f} s; accepted ambiguity flips: "
        f"{result.flips}; mean NEES/dof of accepted estimates: {_num(result.nees_per_dof, 2)}; "
        f"median time per frame: detection {result.detect_ms:.1f} ms, PnP + covariance + "
        f"gates {result.rest_ms:.2f} ms.",
        "",
        *check_lines(result.checks),
        "",
    ]
    return "\n".join(lines)


def write_tag_sweep(result: TagSweepResult, out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write :data:`SWEEP_FILES` into ``out_dir`` (created if missing), each atomically.

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(out_dir)
    paths = [out / name for name in SWEEP_FILES]
    atomic_write_text(paths[0], format_csv(result.rows))
    atomic_write_text(paths[1], format_joint_csv(result.joint_rows))
    atomic_write_text(paths[2], format_markdown(result))
    save_tag_sweep_config(result.config, paths[3])
    plot_tag_sweep_errors(result.rows, paths[4])
    plot_tag_sweep_rates(result.rows, paths[5])
    return paths
