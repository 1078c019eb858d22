"""Run the ``tagloc`` command in a subprocess, as a user would (shared by the CLI tests)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import tagloc

_MAIN = "from tagloc.cli import main; main()"
#: The subprocess imports the same tagloc as the tests (a checkout's src, not an installed copy).
_SRC = str(Path(tagloc.__file__).resolve().parents[1])


def run_tagloc(*args: str, timeout_s: float = 300.0) -> subprocess.CompletedProcess[str]:
    """``tagloc ARGS`` with a bare environment (no PATH, Agg plots, a wide terminal; the
    machine's ``OPENBLAS_*`` settings kept, since they choose OpenBLAS's kernels and so the last
    digits of a result, which a test comparing with a run in this process must share); a hang
    is a failure after ``timeout_s``."""
    blas = {k: v for k, v in os.environ.items() if k.startswith("OPENBLAS_")}
    return subprocess.run(
        [sys.executable, "-c", _MAIN, *args],
        capture_output=True,
        text=True,
        env={"MPLBACKEND": "Agg", "PATH": "", "COLUMNS": "200", "PYTHONPATH": _SRC, **blas},
        check=False,
        timeout=timeout_s,
    )


def one_error_line(done: subprocess.CompletedProcess[str]) -> str:
    """The single stderr line of a failed command (asserting exit code 1, one line, and the
    ``tagloc: error: `` prefix)."""
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr)
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tagloc: error: "), done.stderr
    return lines[0]
