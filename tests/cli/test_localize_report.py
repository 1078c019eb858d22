"""``tagloc localize``'s ``report.html``: its verdict states the run's own numbers."""

from __future__ import annotations

import json
import re
from pathlib import Path

from cli_runner import run_tagloc


def test_localize_writes_a_report_with_the_summary_numbers(tmp_path: Path) -> None:
    out = tmp_path / "run"
    done = run_tagloc("localize", "--scenario", "default", "--duration", "10", "--no-bag",
                      "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    page = (out / "report.html").read_text()
    summary = json.loads((out / "summary.json").read_text())
    ate_cm = summary["ate_unaligned_m"]["fused"] * 100
    found = re.search(r"fused position RMSE ([0-9.]+) cm against truth", page)
    assert found is not None and float(found.group(1)) == round(ate_cm, 1)
    word = "PASS" if ate_cm <= 5.0 else "FAIL"
    assert f"<b>{word}</b>" in page
    for section in ("Trajectory (top-down)", "Degradation ladder", "Fix decisions"):
        assert section in page
    assert page.count("data:image/png;base64,") == 3
    accepted = summary["fixes_accepted"]
    decisions = dict(re.findall(r"<tr><td>([a-z_:]+)</td><td>(\d+)</td></tr>", page))
    assert int(decisions.get("accepted", 0)) + int(decisions.get("initialized", 0)) == accepted
