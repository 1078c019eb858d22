"""Write the evaluation of a run: ``summary.json``, a self-contained ``report.html``, TUM files.

:func:`write_report` is what ``tagloc demo`` and ``tagloc eval run`` call. Files in ``out_dir``,
each written atomically (temporary file beside it, then rename):

- ``summary.json``: :func:`~tagloc.eval.summary.summary_to_dict` of the :class:`EvalSummary`;
- ``report.html``: tables (checks with pass/fail, per-estimator scores, fixes, acceptance vs
  range and angle, suspect sources, kidnaps) and the figures of :mod:`tagloc.eval.report_plots`
  embedded as base64 PNGs (no external files);
- ``truth.tum`` (when known), ``odometry.tum``, ``fused.tum``, ``baseline.tum``: ``T_map_base`` of
  each estimate at every odometry stamp, written by the :class:`TrajectoryWriter` the caller
  passes (the CLI passes :func:`tagloc.io.write_tum`, exact to the nanosecond and to float
  repr), so ``evo_ape tum truth.tum fused.tum`` reproduces the report's ATE.
"""

from __future__ import annotations

import html
import json
import logging
from pathlib import Path
from typing import Protocol

import numpy as np
import numpy.typing as npt

from tagloc.eval.fixstats import AcceptanceBin
from tagloc.eval.protocol import EvalConfig, Reliability
from tagloc.eval.report_rides import rides_section
from tagloc.eval.report_style import CSS as _CSS
from tagloc.eval.report_style import figure as _img
from tagloc.eval.report_style import table as _table
from tagloc.eval.summary import evaluate, summary_to_dict
from tagloc.eval.summary_types import EvalSummary, Evaluation
from tagloc.fileutil import atomic_write_text
from tagloc.geometry import SE3
from tagloc.localize.run import LocalizationRun

logger = logging.getLogger(__name__)

TUM_FILES = {"truth": "truth.tum", "odometry": "odometry.tum", "fused": "fused.tum",
             "baseline": "baseline.tum"}  # fmt: skip
#: Every file :func:`write_report` may write into its directory.
REPORT_FILES = (*TUM_FILES.values(), "summary.json", "report.html")


class TrajectoryWriter(Protocol):
    """Writes one trajectory file atomically (:func:`tagloc.io.write_tum` is one)."""

    def __call__(
        self, path: Path, stamps_ns: npt.NDArray[np.int64], T_map_base: SE3, /
    ) -> None: ...


def write_report(
    run: LocalizationRun,
    out_dir: Path,
    *,
    write_trajectory: TrajectoryWriter,
    config: EvalConfig | None = None,
) -> EvalSummary:
    """Evaluate ``run`` and write ``summary.json``, ``report.html`` and the TUM files.

    Parameters
    ----------
    run : LocalizationRun
    out_dir : Path
        Created if missing; existing files of the same names are replaced.
    write_trajectory : TrajectoryWriter
        Writes each trajectory file (``tagloc.io.write_tum``).
    config : EvalConfig, optional
        Protocol thresholds and targets (defaults: Z = 3 m, X = 5 cm, Y = 2 deg).

    Returns
    -------
    EvalSummary

    Raises
    ------
    EvaluationError
        If the run's trajectories cannot be compared.
    """
    ev = evaluate(run, config)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    export_tum(ev, out_dir, write_trajectory)
    atomic_write_text(
        out_dir / "summary.json", json.dumps(summary_to_dict(ev.summary), indent=2) + "\n"
    )
    atomic_write_text(out_dir / "report.html", render_html(ev, run.metadata))
    logger.info("evaluation of %s written to %s", run.name, out_dir)
    return ev.summary


def export_tum(
    ev: Evaluation, out_dir: Path, write_trajectory: TrajectoryWriter
) -> list[Path]:
    """Write each compared trajectory with ``write_trajectory`` (module docstring); the paths."""
    traj = ev.trajectories
    series = {"truth": traj.T_map_base_truth, **traj.estimates()}
    written = []
    for name, T_map_base in series.items():
        if T_map_base is not None:
            written.append(out_dir / TUM_FILES[name])
            write_trajectory(written[-1], traj.stamps_ns, T_map_base)
    return written


# ----- HTML ------------------------------------------------------------------------------------
def render_html(ev: Evaluation, metadata: dict[str, object]) -> str:
    """The report as one self-contained HTML page."""
    s = ev.summary
    parts = [f"<h1>tagloc evaluation: {html.escape(s.name)}</h1>", _overview(s, metadata)]
    parts += ["<h2>Checks</h2>", _checks_table(s), rides_section(s.rides)]
    parts += ["<h2>Estimates of T_map_base</h2>", _estimators_table(s)]
    if s.has_truth:
        from tagloc.eval import report_plots as plots

        parts += [_img(plots.trajectories_png(ev), "trajectories")]
        parts += ["<h2>Error over time</h2>", _img(plots.errors_over_time_png(ev), "errors")]
        parts += ["<h2>Error histogram</h2>", _img(plots.error_histogram_png(ev), "histogram")]
        parts += ["<h2>Correction jumps</h2>", _img(plots.jumps_png(ev), "jumps")]
        parts += ["<h2>Fix acceptance</h2>", _img(plots.acceptance_png(ev), "acceptance")]
    parts += [_ladder_section(ev), _bounds_section(s)]
    parts += [_fixes_section(s), _events_section(s)]
    config = html.escape(json.dumps(s.config.model_dump(mode="json"), indent=1))
    parts += [f"<h2>Evaluation config</h2><pre>{config}</pre>"]
    title = f"tagloc evaluation: {html.escape(s.name)}"
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"
        f"<style>{_CSS}</style></head><body>{''.join(parts)}</body></html>\n"
    )


def _ladder_section(ev: Evaluation) -> str:
    from tagloc.eval import report_plots as plots

    lad = ev.summary.ladder
    at = [[k, f"{v:.1f}"] for k, v in lad.seconds_at_level.items()]
    moves = [[f"{t:.2f}", f"{a} -> {b}", why] for t, a, b, why in lad.transitions]
    return (
        "<h2>Degradation ladder</h2><p>1 lidar nominal, 2 markers carry, 3 markers alone, "
        "4 on-board odometry only (the status says stale).</p>"
        + (_img(plots.ladder_png(ev), "ladder") if ev.ladder_steps is not None else "")
        + _table(["level", "time (s)"], at)
        + _table(["t (s)", "move", "reason"], moves[:200])
    )


def _bounds_section(s: EvalSummary) -> str:
    b = s.bounds
    rows = [
        ["largest jump, unclipped estimate", b.largest_unclipped_m, b.largest_unclipped_deg],
        ["largest jump, published", b.largest_published_m, b.largest_published_deg],
    ]
    return (
        "<h2>Correction bounds</h2>"
        + _table(["per odometry step", "m", "deg"], rows)
        + f"<p>Publications bound by the per-update cap: {b.n_capped}; by the speed limit: "
        f"{b.n_speed_limited}.</p>"
    )


def _overview(s: EvalSummary, metadata: dict[str, object]) -> str:
    facts: list[list[object]] = [
        ["run", s.name],
        ["duration (s)", s.duration_s],
        ["distance (m)", s.distance_m],
        ["odometry stamps", s.n_stamps],
        ["ground truth", s.has_truth],
        ["overall", "PASS" if s.passed else "FAIL"],
    ]
    for key in ("scenario", "description", "seed", "world", "map"):
        if key in metadata:
            facts.append([key, metadata[key]])
    return _table(["", "value"], facts)


def _checks_table(s: EvalSummary) -> str:
    rows = [[c.name, c.value, c.target, {True: "pass", False: "FAIL", None: "n/a"}[c.passed]]
            for c in s.checks]  # fmt: skip
    classes = [{True: "pass", False: "fail", None: "unknown"}[c.passed] for c in s.checks]
    return _table(["check", "value", "target", "result"], rows, classes)


def _estimators_table(s: EvalSummary) -> str:
    header = ["estimate", "ATE RMSE (m)", "ATE max (m)", "rot RMSE (deg)",
              f"RPE/{s.config.rpe_delta_m:g} m trans (m)", "RPE rot (deg)",
              "largest jump (m)", "largest jump (deg)", "false fixes accepted", "reliability",
              "successes / opportunities"]  # fmt: skip
    rows = []
    for name, e in s.estimators.items():
        r = e.reliability
        rows.append([
            name, e.ate_rmse_m, e.ate_max_m, e.rotation_rmse_deg,
            e.rpe.translation_rmse_m if e.rpe else None, e.rpe.rotation_rmse_deg if e.rpe else None,
            e.largest_jump_m, e.largest_jump_deg, e.false_fixes_accepted,
            r.fraction if r else None, _successes(r) if r else None,
        ])  # fmt: skip
    note = (
        "<p>ATE: APE, translation part, unaligned (odom = map at the start). Reliability: "
        f"camera frames with a tag truly in view within {s.config.opportunity_range_m:g} m "
        "where a fix was accepted and the published pose right after is within "
        f"{s.config.position_tol_m * 100:g} cm / {s.config.rotation_tol_deg:g} deg of truth. "
        "A frame that sees only an elevator cab's tags (cab) is judged against the cab: a fix "
        "of the cab's tags accepted and the published pose relative to the cab right after "
        "within the same tolerance of the true one. "
        "Baseline: map -> odom snapped to every single-tag fix that passed the per-observation "
        "gates (nothing in a cab). Jumps exclude (re)initialization snaps.</p>"
    )
    return _table(header, rows) + note


def _successes(r: Reliability) -> str:
    """``successes / opportunities``, by population when some are the cab's."""
    text = f"{r.n_success} / {r.n_opportunities}"
    if r.in_cab.n_opportunities:
        m, c = r.in_map, r.in_cab
        text += (f" (map {m.n_success} / {m.n_opportunities}, "
                 f"cab {c.n_success} / {c.n_opportunities})")  # fmt: skip
    return text


def _bins_rows(bins: list[AcceptanceBin], unit: str) -> list[list[object]]:
    return [[f"[{b.low:g}, {b.high:g}) {unit}", b.n_attempts, b.n_offered, b.n_accepted,
             b.acceptance] for b in bins]  # fmt: skip


def _fixes_section(s: EvalSummary) -> str:
    f = s.fixes
    rows = [["attempts", f.n_attempts], ["offered to the filter", f.n_offered],
            ["accepted", f.n_accepted], ["false attempts (injected)", f.n_false_attempts],
            ["false offered", f.n_false_offered], ["false accepted", f.n_false_accepted],
            [f"true in range (<= {s.config.opportunity_range_m:g} m)", f.n_true_in_range],
            ["true in range accepted", f.n_true_in_range_accepted],
            ["true in range acceptance", f.true_in_range_acceptance]]  # fmt: skip
    header = ["bin", "attempts", "offered", "accepted", "acceptance"]
    return (
        "<h2>Fixes</h2>" + _table(["", "count"], rows)
        + "<h3>Acceptance vs range</h3>" + _table(header, _bins_rows(s.acceptance_vs_range, "m"))
        + f"<p>{s.n_unknown_range} attempts without a range.</p>"
        + "<h3>Acceptance vs viewing angle</h3>"
        + _table(header, _bins_rows(s.acceptance_vs_angle, "deg"))
        + f"<p>{s.n_unknown_angle} attempts without an angle (refused by a per-observation "
        "gate, before or after PnP: no pose is kept).</p>" + _decisions_section(s)
    )  # fmt: skip


def _decisions_section(s: EvalSummary) -> str:
    """The attempts by decision and reason, per camera, and the hint of a dominant refusal."""
    d = s.fix_decisions
    n = max(d.n_attempts, 1)
    rows = [[k, v, v / n] for k, v in d.by_decision.items()]
    out = "<h3>Fix attempts by decision</h3>"
    if d.hint:
        out += f"<p><b>{html.escape(d.hint)}</b></p>"
    out += _table(["decision", "attempts", "share"], rows)
    if len(d.by_camera) > 1:
        cams = [[c.camera, c.n_attempts, c.n_accepted, c.acceptance] for c in d.by_camera]
        out += _table(["camera", "attempts", "accepted", "acceptance"], cams)
    return out


def _events_section(s: EvalSummary) -> str:
    parts = ["<h2>Suspect (moved) sources</h2>"]
    if s.suspect_sources:
        rows = [[x.source, x.first_flagged_ns * 1e-9 if x.first_flagged_ns >= 0 else None,
                 x.n_rejected, x.n_accepted, x.cleared] for x in s.suspect_sources]  # fmt: skip
        parts.append(_table(["source", "flagged at (s)", "rejected", "accepted", "cleared"], rows))
    else:
        parts.append("<p>none</p>")
    parts.append("<h2>Kidnaps</h2>")
    if s.kidnaps:
        rows = [[k.kidnap_ns * 1e-9, k.first_sighting_ns * 1e-9 if k.first_sighting_ns >= 0
                 else None, k.relocalized_ns * 1e-9 if k.relocalized_ns >= 0 else None,
                 k.time_to_relocalize_s] for k in s.kidnaps]  # fmt: skip
        header = ["kidnap (s)", "first sighting (s)", "relocalized (s)", "time to relocalize (s)"]
        parts.append(_table(header, rows))
    else:
        parts.append("<p>none</p>")
    return "".join(parts)
