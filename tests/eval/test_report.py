"""``write_report``: summary.json keys and numbers, a self-contained report.html, TUM files, all
written atomically; numbers checked against a hand-built run with known errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tagloc.eval import EvalConfig, write_report
from tagloc.eval.metrics import EvaluationError
from tagloc.eval.summary import SUMMARY_SCHEMA_VERSION
from tagloc.geometry import SE3
from tagloc.io import read_tum, write_tum
from tagloc.localize.events import EventKind, FilterEvent
from tagloc.localize.run import CameraFrameRecord, FixAttempt, LocalizationRun

DT_NS = 10_000_000
N = 2001  # 20 s at 100 Hz


def synthetic_run(seed: int = 3) -> LocalizationRun:
    """Truth on a circle; odometry drifting in yaw; fused = truth + 2 cm noise-free offset in y
    except a 10 cm excursion in [12 s, 13 s); fixes every 0.1 s (every 10th one false, gated).
    """
    rng = np.random.default_rng(seed)
    t_s = np.arange(N) * DT_NS * 1e-9
    yaw = 0.1 * t_s
    zeros = np.zeros(N)
    rotvec = np.c_[zeros, zeros, yaw]
    truth = SE3.from_rotvec(rotvec, np.c_[5 * np.sin(yaw), 5 - 5 * np.cos(yaw), zeros])
    drift = SE3.from_rotvec(np.c_[zeros, zeros, 0.01 * t_s], np.c_[0.02 * t_s, zeros, zeros])
    T_odom_base = drift @ truth
    dy = np.where((t_s >= 12.0) & (t_s < 13.0), 0.10, 0.02)
    fused = SE3.from_rotvec(rotvec, np.asarray(truth.translation) + np.c_[zeros, dy, zeros])
    stamps = np.arange(N, dtype=np.int64) * DT_NS
    T_base_wrong = SE3.from_rotvec([0, 0, 0.5], [1.0, 0, 0])
    fixes, frames = [], []
    for k, stamp in enumerate(stamps[50::10]):
        i, false, range_m = 50 + 10 * k, k % 10 == 9, 1.0 + 0.3 * (k % 10)
        T_fix = truth[i] @ (T_base_wrong if false else SE3.exp(rng.normal(0, 0.01, 6)))
        decision = "gated_chi2" if false else ("initialized" if k == 0 else "accepted")
        angle_rad = math.radians(7.0 * (k % 10))
        fixes.append(
            FixAttempt(int(stamp), "tag:7", (7,), T_fix, np.eye(6) * 1e-4, decision, range_m,
                       angle_rad, false)
        )  # fmt: skip
        frames.append(CameraFrameRecord(int(stamp), range_m, 1, int(not false)))
    initialized = stamps >= stamps[50]
    return LocalizationRun(
        name="synthetic circle",
        stamps_ns=stamps,
        T_odom_base=T_odom_base,
        T_map_odom=fused @ T_odom_base.inverse(),
        cov_map_base=np.full((N, 6, 6), 1e-4),
        initialized=initialized,
        T_map_base_truth=truth,
        fixes=fixes,
        frames=frames,
        events=[FilterEvent(int(stamps[50]), EventKind.INITIALIZED, "tag:7")],
        metadata={"scenario": "synthetic", "cap_translation_m": 0.25, "cap_rotation_deg": 5.0},
    )


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, LocalizationRun, object]:
    out = tmp_path_factory.mktemp("report")
    run = synthetic_run()
    summary = write_report(run, out, write_trajectory=write_tum)
    return out, run, summary


def test_files_written_atomically(written: tuple[Path, LocalizationRun, object]) -> None:
    out, _, _ = written
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["summary.json", "report.html", "truth.tum", "odometry.tum", "fused.tum", "baseline.tum"]
    )  # fmt: skip (no temporary left over)


def test_summary_json_keys_and_numbers(written: tuple[Path, LocalizationRun, object]) -> None:
    out, run, _ = written
    data = json.loads((out / "summary.json").read_text())
    assert data["schema_version"] == SUMMARY_SCHEMA_VERSION
    assert set(data) >= {
        "name", "has_truth", "passed", "estimators", "fixes", "acceptance_vs_range",
        "acceptance_vs_angle", "suspect_sources", "kidnaps", "checks", "config",
        "cap_translation_m", "n_jump_steps_over_cap", "duration_s", "distance_m",
    }  # fmt: skip
    assert set(data["estimators"]) == {"odometry", "fused", "baseline"}
    fused = data["estimators"]["fused"]
    # oracle: the hand-built error, 2 cm everywhere but 10 cm during 1 s of 20 s
    t_s = np.arange(N) * DT_NS * 1e-9
    dy = np.where((t_s >= 12.0) & (t_s < 13.0), 0.10, 0.02)
    assert fused["ate_rmse_m"] == pytest.approx(math.sqrt(np.mean(dy**2)), rel=1e-9)
    assert fused["ate_max_m"] == pytest.approx(0.10, rel=1e-9)
    assert fused["rotation_rmse_deg"] == pytest.approx(0.0, abs=1e-5)
    # reliability: 195 frames within 3 m are those with range 1.0 .. 2.8 m (k % 10 <= 6)
    rel = fused["reliability"]
    ks = range(len(run.frames))
    opps = [k for k in ks if 1.0 + 0.3 * (k % 10) <= 3.0]
    ok = [k for k in opps if k % 10 != 9 and not (12.0 <= 0.5 + 0.1 * k < 13.0)]
    assert (rel["n_opportunities"], rel["n_success"]) == (len(opps), len(ok))
    assert fused["false_fixes_accepted"] == 0
    assert data["estimators"]["baseline"]["false_fixes_accepted"] == sum(k % 10 == 9 for k in ks)
    assert data["estimators"]["odometry"]["reliability"] is None
    assert data["fixes"]["n_false_attempts"] == data["fixes"]["n_false_offered"] == 19
    checks = {c["name"]: c for c in data["checks"]}
    assert checks["false fixes accepted"]["passed"] is True
    assert checks["fused ATE RMSE (m)"]["passed"] is True  # 2.8 cm <= 5 cm
    assert checks["reliability (fraction of opportunities)"]["passed"] is False
    assert data["passed"] is False
    json.dumps(data, allow_nan=False)  # strict JSON: no NaN / inf


def test_tum_exports_are_the_run(written: tuple[Path, LocalizationRun, object]) -> None:
    out, run, _ = written
    stamps_ns, T_map_base = read_tum(out / "fused.tum")
    np.testing.assert_array_equal(stamps_ns, run.stamps_ns)
    np.testing.assert_allclose(T_map_base.translation, run.T_map_base.translation, atol=1e-15)


def test_report_html_is_self_contained(written: tuple[Path, LocalizationRun, object]) -> None:
    out, _, _ = written
    text = (out / "report.html").read_text()
    assert text.count("data:image/png;base64,") == 5
    assert "http://" not in text and "https://" not in text
    assert "synthetic circle" in text and "FAIL" in text and "baseline" in text


def test_config_changes_the_protocol(tmp_path: Path) -> None:
    summary = write_report(synthetic_run(), tmp_path, config=EvalConfig(position_tol_m=0.2),
                           write_trajectory=write_tum)
    fused = summary.estimators["fused"]
    assert fused.reliability is not None and fused.reliability.position_tol_m == 0.2
    assert json.loads((tmp_path / "summary.json").read_text())["config"]["position_tol_m"] == 0.2


def test_run_without_truth(tmp_path: Path) -> None:
    run = synthetic_run()
    run.T_map_base_truth = None
    summary = write_report(run, tmp_path, write_trajectory=write_tum)
    assert not summary.has_truth and math.isnan(summary.estimators["fused"].ate_rmse_m)
    assert all(c.passed is None for c in summary.checks if "ATE" in c.name)
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data["estimators"]["fused"]["ate_rmse_m"] is None
    assert not (tmp_path / "truth.tum").exists() and (tmp_path / "report.html").exists()


def test_nan_pose_is_an_evaluation_error(tmp_path: Path) -> None:
    run = synthetic_run()
    matrices = np.asarray(run.T_odom_base.as_matrix())
    run.T_map_base_truth = SE3.from_matrix(matrices)
    bad = SE3.stack([run.T_map_odom[0]] * N)
    run.T_map_odom = bad
    run.stamps_ns = run.stamps_ns.copy()
    run.stamps_ns[5] = run.stamps_ns[4]
    with pytest.raises(EvaluationError):
        write_report(run, tmp_path, write_trajectory=write_tum)
    assert not (tmp_path / "summary.json").exists()


def test_kidnap_run_keeps_the_ate_check_by_name_unjudged(tmp_path: Path) -> None:
    run = synthetic_run()
    run.kidnaps_ns = [int(run.stamps_ns[1000])]
    summary = write_report(run, tmp_path, write_trajectory=write_tum)
    checks = {c["name"]: c for c in json.loads((tmp_path / "summary.json").read_text())["checks"]}
    ate = checks["fused ATE RMSE (m)"]  # same name as in a run without a kidnap
    assert ate["passed"] is None and "kidnap" in ate["target"]
    assert ate["value"] == pytest.approx(summary.estimators["fused"].ate_rmse_m)
