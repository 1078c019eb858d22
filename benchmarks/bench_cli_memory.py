"""Peak memory of the ``tagloc`` command against the length of the drive.

Each case runs the command in a fresh subprocess at a short and a long duration of the same
drive and reads the child's peak resident set size (``ru_maxrss`` of ``os.wait4``, what
``/usr/bin/time -v`` reports); the ratio long / short is the growth with the drive (target:
at most 1.15, the node alone being flat, ``bench_soak.py``). The short run is the reference,
measured in the same run of this script.

- ``bag``: ``tagloc localize drive.mcap --tags tags.yaml --duration D`` on one simulated
  drive recorded first (``tagloc sim record --duration LONG``), its first D seconds;
- ``scenario``: ``tagloc localize --scenario default --duration D``;
- ``eval``: ``tagloc eval run --scenario default --duration D``.

    python benchmarks/bench_cli_memory.py                 # 30 s against 100 s (a few minutes)
    python benchmarks/bench_cli_memory.py --long          # 100 s against 700 s (the whole route)
    python benchmarks/bench_cli_memory.py --cases bag,eval
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASES = ("bag", "scenario", "eval")
TARGET = 1.15


def tagloc(*args: str) -> list[str]:
    """The command line of ``tagloc ARGS`` with this interpreter."""
    return [sys.executable, "-c", "from tagloc.cli import main; main()", *args]


def peak_rss_mb(argv: list[str]) -> tuple[float, float]:
    """Run ``argv`` to its end; its peak RSS (MB) and wall time (s). Raises on failure."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise SystemExit(f"{' '.join(argv[3:])} failed ({proc.returncode}):\n{err.decode()}")
    return usage.ru_maxrss / 1024.0, time.perf_counter() - t0


def case_argv(case: str, seconds: float, work: Path, bag: Path) -> list[str]:
    out = str(work / f"{case}_{seconds:g}")
    duration = ("--duration", f"{seconds:g}")
    if case == "bag":
        return tagloc("localize", str(bag), "--tags", str(bag.parent / "tags.yaml"), "--out", out,
                      *duration)  # fmt: skip
    if case == "scenario":
        return tagloc("localize", "--scenario", "default", "--out", out, *duration)
    return tagloc("eval", "run", "--scenario", "default", "--out", out, *duration)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--long", action="store_true", help="100 s against 700 s")
    parser.add_argument("--cases", default=",".join(CASES), help="of " + ",".join(CASES))
    args = parser.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"--cases: unknown {', '.join(unknown)} (known: {', '.join(CASES)})")
    short, long = (100.0, 700.0) if args.long else (30.0, 100.0)
    with tempfile.TemporaryDirectory(prefix="tagloc-bench-mem-") as tmp:
        work = Path(tmp)
        bag = work / "drive.mcap"
        if "bag" in cases:
            rss, wall = peak_rss_mb(tagloc("sim", "record", "--scenario", "default", "--out",
                                           str(bag), "--duration", f"{long:g}"))  # fmt: skip
            print(f"recorded the {long:g} s drive: {wall:.0f} s, peak {rss:.0f} MB", flush=True)
        header = (f"{'case':<10} | {'peak MB at ' + f'{short:g} s':>16} | "
                  f"{'peak MB at ' + f'{long:g} s':>16} | {'ratio':>6} | target <= {TARGET:g}"
                  f" | wall s")  # fmt: skip
        print(header)
        print("-" * len(header))
        for case in cases:
            at_short, wall_short = peak_rss_mb(case_argv(case, short, work, bag))
            at_long, wall_long = peak_rss_mb(case_argv(case, long, work, bag))
            ratio = at_long / at_short
            verdict = "met" if ratio <= TARGET else "NOT met"
            print(f"{case:<10} | {at_short:16.0f} | {at_long:16.0f} | {ratio:6.2f} | "
                  f"{verdict:>{len(f'target <= {TARGET:g}')}} | {wall_short:.0f} / {wall_long:.0f}",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
