"""The live status line: what it shows is what the run's own record says."""

from __future__ import annotations

import io

from rich.console import Console

from tagloc.cli.status import StatusLine
from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.localize import driver
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import RunRecorder
from tagloc.sim.scenarios import ScenarioSource, build_scenario


def _run(console: Console) -> tuple[StatusLine, RunRecorder, LocalizerNode, object]:
    scenario = build_scenario("default", seed=0, duration_s=4.0)
    source = ScenarioSource(scenario)
    config = calibrated_config(scenario, scenario_config()).model_copy(
        update={"lidar": scenario_config().lidar.model_copy(update={"enabled": False})}
    )
    status = StatusLine(console=console)
    recorder = RunRecorder("status")

    def node(sinks):  # type: ignore[no-untyped-def]
        built = LocalizerNode(scenario.tag_map, config, sinks, frame_truth=source.frame_truth)
        status.skipped = built.skipped
        return built

    done = driver.run(node, source, [recorder, status])
    status.skipped = done.node.skipped  # the final counts
    return status, recorder, done.node, recorder.run(done.node.metadata())


def test_the_status_line_counts_what_the_run_records() -> None:
    out = io.StringIO()
    status, recorder, node, run = _run(Console(file=out, force_terminal=True, width=200))
    line = status.line()
    accepted = sum(f.accepted for f in run.fixes)  # type: ignore[attr-defined]
    assert f"fixes {accepted}/{len(run.fixes)} accepted" in line  # type: ignore[attr-defined]
    last = recorder.status[-1]
    assert f"ladder {int(last.level)} {last.level.label}" in line
    t = (run.stamps_ns[-1] - run.stamps_ns[0]) * 1e-9  # type: ignore[attr-defined]
    assert f"t {t:.1f} s" in line
    assert f"dropped {sum(node.skipped.values())}" in line
    status.close()
    assert "accepted" in out.getvalue()  # it was drawn while the run streamed


def test_no_status_line_without_a_terminal() -> None:
    out = io.StringIO()
    status, _, _, _ = _run(Console(file=out, force_terminal=False))
    status.close()
    assert out.getvalue() == ""
