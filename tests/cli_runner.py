"""Run the ``tagloc`` command in a subprocess, as a user would (shared by the CLI tests)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

_MAIN = "from tagloc.cli import main; main()"


def run_tagloc(
    *args: str, cwd: Path | None = None, script: str = _MAIN, timeout_s: float = 300.0
) -> subprocess.CompletedProcess[str]:
    """``tagloc ARGS`` with a bare environment (no PATH, Agg plots, a wide terminal)."""
    return subprocess.run(
        [sys.executable, "-c", script, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={"MPLBACKEND": "Agg", "PATH": "", "COLUMNS": "200"},
        check=False,
        timeout=timeout_s,
    )


def one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    """The single stderr line of a failed command (asserting exit code 1 and one line)."""
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]
