"""The live view: a short run recorded with ``--view-save`` and read back with rerun's own
reader (``rerun.chunk.RrdReader``), against the map and the run's own files.

rerun stores positions as float32: positions agree to 1e-5 m (at tens of metres).
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from cli_runner import run_tagloc

rr_chunk = pytest.importorskip("rerun.chunk")
pa = pytest.importorskip("pyarrow")

DURATION_S = 8.0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list]]:
    """The scenario localized with the view saved; the .rrd read back as entity -> rows of
    ``(stamp_ns or None, {component: value})``."""
    d = tmp_path_factory.mktemp("view")
    done = run_tagloc(
        "localize", "--scenario", "default", "--duration", str(DURATION_S), "--no-bag",
        "--out", str(d / "run"), "--view-save", str(d / "run.rrd"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in d.iterdir()) == ["run", "run.rrd"]  # renamed into place
    rows: dict[str, list] = defaultdict(list)
    for chunk in rr_chunk.RrdReader(d / "run.rrd").stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        stamps = (batch.column("stream").cast(pa.int64()).to_pylist() if "stream" in names
                  else [None] * batch.num_rows)  # fmt: skip
        values = {n: batch.column(n).to_pylist() for n in names if ":" in n}
        for i, stamp in enumerate(stamps):
            rows[chunk.entity_path].append((stamp, {n: v[i] for n, v in values.items()}))
    for entity in rows:
        rows[entity].sort(key=lambda r: -1 if r[0] is None else r[0])
    return d / "run", rows


def test_the_view_draws_every_tag_of_the_map(recorded: tuple[Path, dict[str, list]]) -> None:
    from tagloc.sim.scenarios import build_scenario

    tag_map = build_scenario("default", seed=0, duration_s=DURATION_S).tag_map
    entries = [e for e in tag_map if e.frame == "map"]
    [(_, tags)] = recorded[1]["/map/tags"]
    assert tags["Boxes3D:labels"] == [str(e.id) for e in entries]
    centres = np.array(tags["Boxes3D:centers"])
    truth = np.array([e.T_frame_tag().translation for e in entries])
    np.testing.assert_allclose(centres, truth, atol=1e-5)
    np.testing.assert_allclose(np.array(tags["Boxes3D:half_sizes"])[:, 0],
                               [e.size / 2 for e in entries], atol=1e-7)  # fmt: skip


def test_the_fused_pose_is_the_published_one(recorded: tuple[Path, dict[str, list]]) -> None:
    from tagloc.io import read_tum

    out, rows = recorded
    stamps_ns, T_map_base = read_tum(out / "fused.tum")
    by_stamp = {int(s): i for i, s in enumerate(stamps_ns)}
    fused = rows["/map/fused"]
    stamps = np.array([s for s, _ in fused])
    assert len(fused) >= 5 and np.diff(stamps).min() >= 0.1e9 - 1  # at up to 10 Hz
    assert stamps[-1] >= stamps_ns[-1] - 0.2e9  # from initialization to the end
    xyz = np.asarray(T_map_base.translation)
    for stamp, values in fused:
        np.testing.assert_allclose(values["Transform3D:translation"][0], xyz[by_stamp[stamp]],
                                   atol=1e-5)  # fmt: skip
    # each with its covariance ellipsoid
    assert len(rows["/map/fused/cov"]) == len(fused)


def test_every_fix_is_drawn_with_its_decision(recorded: tuple[Path, dict[str, list]]) -> None:
    out, rows = recorded
    fixes = [json.loads(line) for line in (out / "fixes.jsonl").read_text().splitlines()]
    drawn = rows["/map/fixes"]
    assert len(drawn) == len(fixes) > 0
    expected = sorted((f["stamp_ns"], f"{f['source']}: {f['decision']}") for f in fixes)
    assert sorted((s, v["Points3D:labels"][0]) for s, v in drawn) == expected
    accepted = sum(f["decision"] in ("accepted", "initialized") for f in fixes)
    assert max(v["Scalars:scalars"][0] for _, v in rows["/status/fixes_accepted"]) == accepted


def test_the_ladder_level_is_the_status(recorded: tuple[Path, dict[str, list]]) -> None:
    out, rows = recorded
    logged = defaultdict(set)  # a ladder move and the status may share a stamp
    for stamp, v in rows["/status/ladder_level"]:
        logged[stamp].add(v["Scalars:scalars"][0])
    status = [json.loads(line) for line in (out / "status.jsonl").read_text().splitlines()]
    assert status
    for s in status:
        assert float(s["level"]) in logged[s["stamp_ns"]]


def test_lidar_points_lie_on_the_premap(recorded: tuple[Path, dict[str, list]]) -> None:
    from scipy.spatial import cKDTree

    rows = recorded[1]
    if "/map/premap" not in rows:
        pytest.skip("the scenario's robot has no lidar")
    [(_, premap)] = rows["/map/premap"]
    tree = cKDTree(np.array(premap["Points3D:positions"]))
    sweeps = rows["/map/lidar"]
    assert sweeps
    points = np.concatenate([np.array(v["Points3D:positions"]) for _, v in sweeps])
    distance, _ = tree.query(points)
    # drawn through the fused pose: on the premap's surfaces to within its voxel and the pose's
    # error (a few cm), apart from people and glass
    assert np.median(distance) < 0.15
