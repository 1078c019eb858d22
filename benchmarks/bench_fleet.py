"""Many recorded drives evaluated at once: wall time in series against a local process pool.

Run: ``.venv/bin/python benchmarks/bench_fleet.py [--logs 8] [--seconds 20] [--hold-out 13]
[--jobs 1 2]``

Records ``--logs`` drives of the office route (odometry seeds 0..N-1, ``--seconds`` each) as
MCAP bags with the simulator's stream (what ``tagloc sim record`` writes), then evaluates them
all with :func:`tagloc.eval.fleet.evaluate_logs` (each log's whole-map pass and one pass per
held-out tag) on a :class:`~tagloc.eval.engine.ProcessEngine` of each ``--jobs``, and prints the
wall time, the CPU time (this process and the pool's workers) and the cores it kept busy, the
passes per minute and the speed-up against ``--jobs 1`` measured in the same run.
It also checks that every engine gave the same per-log numbers. The speed-up is bounded by the
free cores: on a machine shared with other work it is lower than the core count.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from tagloc.eval.engine import ProcessEngine
from tagloc.eval.fleet import LogSpec, evaluate_logs
from tagloc.io import BagSink
from tagloc.io.bag_stream import BagStream
from tagloc.localize.config import LocalizerConfig
from tagloc.sim.scenarios import ScenarioSource, build_scenario


def record(root: Path, n: int, seconds: float) -> list[LogSpec]:
    specs = []
    for seed in range(n):
        scenario = build_scenario("default", seed=seed, duration_s=seconds)
        path = root / f"drive{seed}.mcap"
        with BagSink(path, "mcap", overwrite=True) as sink:
            for topic, msg in ScenarioSource(scenario):
                sink.write(topic, msg)
        specs.append(LogSpec(path.name, BagStream(path), scenario.tag_map, LocalizerConfig()))
    return specs


def _cpu_s() -> float:
    """CPU time of this process and its finished children (the pool's workers), s."""
    me, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(
        resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--hold-out", type=int, nargs="*", default=[13])
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        specs = [
            LogSpec(s.name, s.stream, s.tag_map, s.config, hold_out=tuple(args.hold_out))
            for s in record(Path(tmp), args.logs, args.seconds)
        ]
        print(f"recorded {len(specs)} drives of {args.seconds:g} s in "
              f"{time.perf_counter() - t0:.1f} s; {os.cpu_count()} cores, load average "
              f"{os.getloadavg()[0]:.1f}")  # fmt: skip
        passes = len(specs) * (1 + len(args.hold_out))
        rows, reference, wall_1 = [], None, None
        for jobs in args.jobs:
            t0, cpu0 = time.perf_counter(), _cpu_s()
            results = evaluate_logs(specs, ProcessEngine(jobs))
            wall, cpu = time.perf_counter() - t0, _cpu_s() - cpu0
            numbers = [(r.run.to_dict() | {"wall_s": 0}, r.held_out and r.held_out.to_dict())
                       for r in results]  # fmt: skip
            reference = numbers if reference is None else reference
            same = numbers == reference
            wall_1 = wall if jobs == 1 else wall_1
            rows.append((jobs, wall, cpu, passes / wall * 60, same))
    print(f"{'jobs':>5} {'wall s':>8} {'cpu s':>8} {'cores used':>11} {'passes/min':>11} "
          f"{'speed-up':>9} {'same numbers':>13}")  # fmt: skip
    for jobs, wall, cpu, rate, same in rows:
        speedup = f"{wall_1 / wall:.2f}x" if wall_1 else "n/a"
        print(f"{jobs:>5} {wall:>8.1f} {cpu:>8.1f} {cpu / wall:>11.2f} {rate:>11.1f} "
              f"{speedup:>9} {('yes' if same else 'NO'):>13}")  # fmt: skip
    print(f"({len(specs)} logs x (1 + {len(args.hold_out)} held-out) = {passes} localizer passes)")


if __name__ == "__main__":
    main()
