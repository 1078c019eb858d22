"""The dimos adapter is optional: importing tagloc (or its adapter package) never imports dimos."""

from __future__ import annotations

import subprocess
import sys


def test_importing_tagloc_and_the_adapter_package_imports_no_dimos() -> None:
    code = (
        "import sys, tagloc.cli, tagloc.io, tagloc.adapters.dimos\n"
        "print(sorted(m for m in sys.modules if m == 'dimos' or m.startswith('dimos.')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
