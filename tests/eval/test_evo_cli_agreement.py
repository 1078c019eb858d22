"""The report's ATE equals evo's own command line on the exported TUM files.

Runs ``evo_ape tum truth.tum <estimate>.tum`` (the evo console script installed beside this
Python) with a temporary HOME (evo writes its settings there) and the Agg backend, and compares
the RMSE it saves (``--save_results``: full precision, to 1e-9 m) and prints (6 decimals) with
``summary.json``.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tagloc.eval import write_report
from tagloc.geometry import SE3
from tagloc.io import write_tum
from tagloc.localize.run import FixAttempt, LocalizationRun

EVO_APE = Path(sys.executable).with_name("evo_ape")
N = 1500


def _random_walk(rng: np.random.Generator, n: int) -> SE3:
    yaw = np.cumsum(rng.normal(0.0, 0.01, n))
    step = np.c_[0.01 * np.cos(yaw), 0.01 * np.sin(yaw), rng.normal(0.0, 1e-4, n)]
    return SE3.from_rotvec(np.c_[np.zeros((n, 2)), yaw], np.cumsum(step, axis=0))


def _run() -> LocalizationRun:
    rng = np.random.default_rng(11)
    truth = _random_walk(rng, N)
    T_odom_base = (
        SE3.exp(np.r_[0.3, -0.2, 0.0, 0.0, 0.0, 0.05])
        @ truth
        @ SE3.exp(rng.normal(0.0, 0.01, (N, 6)))
    )
    fused = truth @ SE3.exp(rng.normal(0.0, 0.02, (N, 6)))
    stamps = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * 10_000_000 + 123
    fixes = [
        FixAttempt(int(stamps[i]), "tag:2", (2,), truth[i] @ SE3.exp(rng.normal(0, 0.03, 6)),
                   np.eye(6) * 1e-3, "accepted", 2.0, 0.2, False)
        for i in range(20, N, 15)
    ]  # fmt: skip
    return LocalizationRun(
        name="evo agreement",
        stamps_ns=stamps,
        T_odom_base=T_odom_base,
        T_map_odom=fused @ T_odom_base.inverse(),
        cov_map_base=np.full((N, 6, 6), 1e-4),
        initialized=np.ones(N, dtype=bool),
        T_map_base_truth=truth,
        fixes=fixes,
    )


def _evo_ape(out: Path, estimate: str, tmp_home: Path) -> tuple[float, float]:
    """evo's (saved, printed) RMSE of ``estimate`` against ``truth.tum``."""
    results = tmp_home / f"{estimate}.zip"
    env = {**os.environ, "HOME": str(tmp_home), "MPLBACKEND": "Agg"}
    done = subprocess.run(
        [str(EVO_APE), "tum", str(out / "truth.tum"), str(out / estimate),
         "--save_results", str(results), "--no_warnings"],
        capture_output=True, text=True, env=env, timeout=120, check=True,
    )  # fmt: skip
    printed = re.search(r"^\s*rmse\s+([0-9.eE+-]+)\s*$", done.stdout, re.MULTILINE)
    assert printed is not None, done.stdout
    with zipfile.ZipFile(results) as archive:
        saved = json.loads(archive.read("stats.json"))["rmse"]
    return float(saved), float(printed.group(1))


@pytest.mark.skipif(not EVO_APE.exists(), reason="evo_ape console script not installed")
def test_report_ate_equals_evo_ape_cli(tmp_path: Path) -> None:
    out = tmp_path / "report"
    summary = write_report(_run(), out, write_trajectory=write_tum)
    data = json.loads((out / "summary.json").read_text())
    for name in ("fused", "odometry", "baseline"):
        ours = data["estimators"][name]["ate_rmse_m"]
        assert ours == summary.estimators[name].ate_rmse_m
        saved, printed = _evo_ape(out, f"{name}.tum", tmp_path)
        assert saved == pytest.approx(ours, rel=0.0, abs=1e-9), name
        assert printed == pytest.approx(ours, abs=1e-6), name


@pytest.mark.skipif(not EVO_APE.exists(), reason="evo_ape console script not installed")
def test_files_comparison_associates_like_evo_ape(tmp_path: Path) -> None:
    # an estimate on every 3rd stamp, 2 ms late: association by nearest stamp within 10 ms
    from tagloc.eval.compare import compare_trajectories

    run = _run()
    assert run.T_map_base_truth is not None
    keep = np.arange(0, N, 3)
    write_tum(tmp_path / "truth.tum", run.stamps_ns, run.T_map_base_truth)
    write_tum(tmp_path / "sparse.tum", run.stamps_ns[keep] + 2_000_000, run.T_map_base[keep])
    ours = compare_trajectories(
        run.stamps_ns, run.T_map_base_truth, run.stamps_ns[keep] + 2_000_000, run.T_map_base[keep]
    )
    assert ours.n_matched == len(keep)
    saved, _ = _evo_ape(tmp_path, "sparse.tum", tmp_path)
    assert saved == pytest.approx(ours.ate.rmse, rel=0.0, abs=1e-9)
