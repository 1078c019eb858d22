"""The run recorder's spool: what is read back is what the node wrote, nothing stays on disk, and
a spool that does not read back says so."""

from __future__ import annotations

import errno
import io
import math
import pickle
import tempfile
from pathlib import Path

import numpy as np
import pytest
from list_sink import ListSink

from tagloc.eval.scenarios import localize_scenario
from tagloc.localize.events import FilterEvent
from tagloc.localize.outputs import Estimate
from tagloc.localize.run import CameraFrameRecord, FixAttempt, LocalizationRun
from tagloc.localize.spool import RecordSpool, RowSpool, SpoolError
from tagloc.sim.scenarios import build_scenario


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[LocalizationRun, ListSink, Path]:
    """A 20 s scenario recorded with the spool in a directory of its own, beside a sink that
    keeps every output object in a list (the oracle)."""
    spool_dir = tmp_path_factory.mktemp("spool")
    before = tempfile.tempdir
    tempfile.tempdir = str(spool_dir)
    try:
        oracle = ListSink()
        run = localize_scenario(build_scenario("default", 0, 20.0), sinks=[oracle], lidar=False)
        assert list(spool_dir.iterdir()) == []  # unnamed files: nothing in the directory
    finally:
        tempfile.tempdir = before
    return run, oracle, spool_dir


def test_series_read_back_exactly(recorded: tuple[LocalizationRun, ListSink, Path]) -> None:
    run, oracle, _ = recorded
    estimates: list[Estimate] = oracle.of(Estimate)
    assert len(estimates) > 1000
    np.testing.assert_array_equal(run.stamps_ns, [e.stamp_ns for e in estimates])
    for got, want in ((run.T_odom_base, [e.T_odom_base for e in estimates]),
                      (run.T_map_odom, [e.T_map_odom for e in estimates])):  # fmt: skip
        np.testing.assert_array_equal(got.rotation.matrix, [w.rotation.matrix for w in want])
        np.testing.assert_array_equal(got.translation, [w.translation for w in want])
    np.testing.assert_array_equal(run.initialized, [e.initialized for e in estimates])
    assert run.initialized.any() and not run.initialized.all()
    nan6 = np.full((6, 6), np.nan)
    want_cov = [nan6 if e.cov_map_base is None else e.cov_map_base for e in estimates]
    np.testing.assert_array_equal(run.cov_map_base, want_cov)  # NaN where not initialized
    assert run.floors == [e.floor for e in estimates]
    assert run.T_map_base_truth is not None and len(run.T_map_base_truth) == len(estimates)


def test_records_read_back_equal(recorded: tuple[LocalizationRun, ListSink, Path]) -> None:
    run, oracle, _ = recorded
    fixes: list[FixAttempt] = oracle.of(FixAttempt)
    assert len(fixes) > 50 and len(run.fixes) == len(fixes)
    for got, want in zip(run.fixes, fixes, strict=True):  # iteration, block by block
        assert (got.stamp_ns, got.source, got.tag_ids, got.decision, got.camera) == (
            want.stamp_ns, want.source, want.tag_ids, want.decision, want.camera)
        for a, b in ((got.range_m, want.range_m), (got.view_angle_rad, want.view_angle_rad)):
            assert a == b or (math.isnan(a) and math.isnan(b))
        np.testing.assert_array_equal(got.T_map_base.rotation.matrix,
                                      want.T_map_base.rotation.matrix)  # fmt: skip
        np.testing.assert_array_equal(got.T_map_base.translation, want.T_map_base.translation)
        np.testing.assert_array_equal(got.cov, want.cov)
    assert run.fixes[-1].stamp_ns == fixes[-1].stamp_ns  # indexing, from the end too
    assert [f.stamp_ns for f in run.fixes[3:9:2]] == [f.stamp_ns for f in fixes[3:9:2]]
    assert list(run.frames) == oracle.of(CameraFrameRecord)
    assert list(run.events) == oracle.of(FilterEvent)


def test_a_run_pickles_its_records_as_lists(
    recorded: tuple[LocalizationRun, ListSink, Path],
) -> None:
    run, _, _ = recorded
    copy = pickle.loads(pickle.dumps(run))
    assert isinstance(copy.frames, list) and copy.frames == list(run.frames)


def test_eval_run_leaves_only_its_outputs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    from tagloc.cli.app import app
    from tagloc.eval.report import REPORT_FILES

    spool_dir = tmp_path / "tmp"
    spool_dir.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(spool_dir))
    out = tmp_path / "out"
    args = ["eval", "run", "--scenario", "default", "--duration", "10", "--no-lidar", "--out",
            str(out)]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert {p.name for p in out.iterdir()} <= set(REPORT_FILES)
    assert list(spool_dir.iterdir()) == []


def _spool_of(n: int) -> tuple[RecordSpool[CameraFrameRecord], io.BytesIO]:
    store = io.BytesIO()
    spool: RecordSpool[CameraFrameRecord] = RecordSpool("frames", store)
    for i in range(n):
        spool.append(CameraFrameRecord(i, 1.5 * i, i % 3, i % 2))
    return spool, store


def test_records_round_trip_and_index_errors() -> None:
    spool, _ = _spool_of(5)
    records = spool.records()
    assert list(records) == [CameraFrameRecord(i, 1.5 * i, i % 3, i % 2) for i in range(5)]
    assert records[-1].stamp_ns == 4 and len(records) == 5
    with pytest.raises(IndexError, match="index 5 of 5"):
        records[5]
    spool.append(CameraFrameRecord(5, 0.0, 0, 0))  # later records do not change a read-back
    assert len(records) == 5 and len(spool.records()) == 6


def test_a_truncated_spool_is_refused() -> None:
    spool, store = _spool_of(4)
    spool.records()
    store.truncate(store.getbuffer().nbytes - 3)
    with pytest.raises(SpoolError, match=r"run spool 'frames': truncated: \d+ bytes of \d+"):
        spool.records()


def test_a_damaged_record_is_named() -> None:
    spool, store = _spool_of(4)
    records = spool.records()
    view = store.getbuffer()
    start = pickle.dumps(CameraFrameRecord(0, 0.0, 0, 0), protocol=pickle.HIGHEST_PROTOCOL)
    view[4 + len(start) + 4 + 2 : 4 + len(start) + 4 + 12] = b"\xff" * 10  # record 1's payload
    del view
    assert records[0].stamp_ns == 0
    with pytest.raises(SpoolError, match="record 1 of 4 is damaged"):
        list(records)


def test_a_short_row_spool_is_refused() -> None:
    store = io.BytesIO()
    rows = RowSpool("stamps", 2, np.int64, store)
    for i in range(5000):  # past one buffer of rows
        rows.append([i, -i])
    np.testing.assert_array_equal(rows.read()[:, 0], np.arange(5000))
    store.truncate(16 * 4000)
    with pytest.raises(SpoolError, match="run spool 'stamps': truncated: 64000 bytes of 80000"):
        rows.read()


class _FullDisk(io.BytesIO):
    def write(self, data: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_is_one_line() -> None:
    spool: RecordSpool[int] = RecordSpool("fixes", _FullDisk())
    spool.append(1)
    with pytest.raises(SpoolError, match="run spool 'fixes': cannot write: No space left"):
        spool.records()
