"""The live status line: what it shows is what the run's own record says."""

from __future__ import annotations

import io

from rich.console import Console

from tagloc.cli.status import StatusLine
from tagloc.localize.pipeline import LocalizationPipeline
from tagloc.sim.scenarios import ScenarioSource, build_scenario, calibrated_config, scenario_config


def _run(console: Console) -> tuple[StatusLine, LocalizationPipeline, object]:
    scenario = build_scenario("default", seed=0, duration_s=4.0)
    source = ScenarioSource(scenario)
    config = calibrated_config(scenario, scenario_config()).model_copy(
        update={"lidar": scenario_config().lidar.model_copy(update={"enabled": False})}
    )
    pipeline = LocalizationPipeline(scenario.tag_map, config, frame_truth=source.frame_truth)
    status = StatusLine(pipeline.node.skipped, console=console)
    pipeline.node.sinks.append(status)
    run = pipeline.run(source)
    return status, pipeline, run


def test_the_status_line_counts_what_the_run_records() -> None:
    out = io.StringIO()
    status, pipeline, run = _run(Console(file=out, force_terminal=True, width=200))
    line = status.line()
    accepted = sum(f.accepted for f in run.fixes)  # type: ignore[attr-defined]
    assert f"fixes {accepted}/{len(run.fixes)} accepted" in line  # type: ignore[attr-defined]
    last = pipeline.recorder.status[-1]
    assert f"ladder {int(last.level)} {last.level.label}" in line
    t = (run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9  # type: ignore[attr-defined]
    assert f"t {t:.1f} s" in line
    assert f"dropped {sum(pipeline.skipped.values())}" in line
    status.close()
    assert "accepted" in out.getvalue()  # it was drawn while the run streamed


def test_no_status_line_without_a_terminal() -> None:
    out = io.StringIO()
    status, _, _ = _run(Console(file=out, force_terminal=False))
    status.close()
    assert out.getvalue() == ""
