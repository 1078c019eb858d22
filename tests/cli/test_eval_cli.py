"""``tagloc eval run`` and ``tagloc eval files``: outputs, printed numbers, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_runner import one_error_line, run_tagloc
from tagloc.eval.compare import compare_trajectories
from tagloc.geometry import SE3
from tagloc.io import read_tum, write_tum


def test_eval_run_writes_the_report(tmp_path: Path) -> None:
    done = run_tagloc("eval", "run", "--scenario", "default", "--duration", "12", "--out",
                   str(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "fused ATE RMSE" in done.stdout and "baseline" in done.stdout
    names = {p.name for p in tmp_path.iterdir()}
    assert {"report.html", "summary.json", "truth.tum", "fused.tum", "baseline.tum"} <= names
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["name"].endswith("default") and data["has_truth"] is True
    assert data["estimators"]["fused"]["ate_rmse_m"] < data["estimators"]["baseline"]["ate_rmse_m"]


def test_eval_files_matches_the_pure_function(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    n = 400
    stamps_ns = np.arange(n, dtype=np.int64) * 20_000_000
    xyz = np.cumsum(np.c_[np.full(n, 0.02), rng.normal(0, 0.002, (n, 2))], axis=0)
    truth = SE3.from_rotvec(np.zeros((n, 3)), xyz)
    est = truth @ SE3.exp(rng.normal(0.0, 0.01, (n, 6)))
    write_tum(tmp_path / "truth.tum", stamps_ns, truth)
    write_tum(tmp_path / "est.tum", stamps_ns, est)
    done = run_tagloc("eval", "files", "--truth", str(tmp_path / "truth.tum"), "--est",
                   str(tmp_path / "est.tum"))  # fmt: skip
    assert done.returncode == 0, done.stderr
    expected = compare_trajectories(
        *read_tum(tmp_path / "truth.tum"), *read_tum(tmp_path / "est.tum")
    )
    assert expected.n_matched == n
    assert f"{expected.ate.rmse:.6f}" in done.stdout
    errors = np.linalg.norm(np.asarray(est.translation) - xyz, axis=1)
    assert expected.ate.rmse == pytest.approx(float(np.sqrt(np.mean(errors**2))), rel=1e-9)


def test_errors_are_one_line(tmp_path: Path) -> None:
    assert "unknown scenario" in one_error_line(
        run_tagloc("eval", "run", "--scenario", "no_such_scenario", "--out", str(tmp_path))
    )
    missing = tmp_path / "missing.tum"
    assert "missing.tum" in one_error_line(
        run_tagloc("eval", "files", "--truth", str(missing), "--est", str(missing))
    )
    (tmp_path / "a.tum").write_text("0.0 0 0 0 0 0 0 1\n")
    far = tmp_path / "b.tum"
    write_tum(far, np.array([5_000_000_000, 6_000_000_000]), SE3.identity(2))
    line = one_error_line(run_tagloc("eval", "files", "--truth", str(tmp_path / "a.tum"),
                                   "--est", str(far)))  # fmt: skip
    assert "associate" in line or "poses" in line
