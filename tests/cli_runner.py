"""Run the ``tagloc`` command in a subprocess, as a user would (shared by the CLI tests)."""

from __future__ import annotations

import subprocess
import sys

_MAIN = "from tagloc.cli import main; main()"


def run_tagloc(*args: str) -> subprocess.CompletedProcess[str]:
    """``tagloc ARGS`` with a bare environment (no PATH, Agg plots, a wide terminal)."""
    return subprocess.run(
        [sys.executable, "-c", _MAIN, *args],
        capture_output=True,
        text=True,
        env={"MPLBACKEND": "Agg", "PATH": "", "COLUMNS": "200"},
        check=False,
        timeout=300.0,
    )


def one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    """The single stderr line of a failed command (asserting exit code 1, one line, and the
    ``tagloc: error: `` prefix)."""
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tagloc: error: "), done.stderr
    return lines[0]
