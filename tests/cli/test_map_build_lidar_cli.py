"""``tagloc map build`` with lidar: tags.yaml, the premap and the occupancy grid, all in ``map``,
written all or none; ``--no-lidar`` writes the tags only."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from cli_runner import run_tagloc
from tagloc.io.map_server import read_map_server
from tagloc.io.pointcloud_files import read_pcd, read_ply
from tagloc.tags.tagmap import load_tag_map

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mapping"))
from survey_worlds import room_loop_world


def _world(tmp_path: Path) -> Path:
    path = tmp_path / "world.yaml"
    path.write_text(room_loop_world().to_yaml_text())
    return path


def test_sim_build_writes_tags_premap_and_grid(tmp_path: Path) -> None:
    out = tmp_path / "map" / "tags.yaml"
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_world(tmp_path)), "--camera-stride", "6",
        "--out", str(out), "--premap-format", "pcd",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "lidar:" in result.stdout and "in frame map" in result.stdout
    tags = load_tag_map(out)
    premap = read_pcd(out.parent / "premap.pcd")
    grid = read_map_server(out.parent / "map.yaml")
    assert (out.parent / "map.pgm").is_file() and not (out.parent / "premap.ply").exists()
    # one frame: every tag sits on a wall of the premap (its centre within 15 cm of a point)
    for entry in tags:
        p = entry.T_frame_tag().translation
        assert np.min(np.linalg.norm(premap - p, axis=1)) < 0.15, entry.id
        row, col = grid.cell_of(np.asarray(p[:2])[None])
        near = grid.occupied()[max(row[0] - 3, 0) : row[0] + 4, max(col[0] - 3, 0) : col[0] + 4]
        assert near.any(), f"tag {entry.id}: no occupied cell within 15 cm"


def test_no_lidar_writes_tags_only(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    result = run_tagloc(
        "map", "build", "--sim", "--world", str(_world(tmp_path)), "--camera-stride", "9",
        "--out", str(out), "--no-lidar",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert out.is_file() and "lidar:" not in result.stdout
    assert not any((tmp_path / name).exists() for name in ("premap.ply", "map.yaml", "map.pgm"))


def test_an_unwritable_product_fails_before_work_and_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    (tmp_path / "map.pgm").mkdir()  # the grid's image cannot be written
    result = run_tagloc("map", "build", "--sim", "--world", str(_world(tmp_path)),
                        "--out", str(out))  # fmt: skip
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "map.pgm" in result.stderr
    assert not out.exists() and not (tmp_path / "premap.ply").exists()
    assert not (tmp_path / "map.yaml").exists()


def test_bad_premap_format_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "tags.yaml"
    result = run_tagloc("map", "build", "--sim", "--out", str(out), "--premap-format", "las")
    assert result.returncode == 1 and "--premap-format" in result.stderr
    assert not out.exists()


def test_ply_premap_reads_back(tmp_path: Path) -> None:
    """The default format: premap.ply, float32 x y z in map (read back by the io reader)."""
    from tagloc.io.survey_files import write_survey_outputs
    from tagloc.lidar import OccupancyGrid

    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3))
    grid = OccupancyGrid(np.zeros((4, 5), np.float32), 0.05, (1.0, -2.0, 0.0, 0.0))
    write_survey_outputs({tmp_path / "tags.yaml": "x"}, (tmp_path / "premap.ply", points, "ply"),
                         (tmp_path / "map.yaml", grid))  # fmt: skip
    assert np.allclose(read_ply(tmp_path / "premap.ply"), points.astype(np.float32))
    assert read_map_server(tmp_path / "map.yaml").shape == (4, 5)
    assert "image: map.pgm" in (tmp_path / "map.yaml").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pgm", "map.yaml", "premap.ply",
                                                          "tags.yaml"]  # fmt: skip


def test_a_failing_write_leaves_none_of_the_outputs(tmp_path: Path) -> None:
    from tagloc.fileutil import OutputPathError
    from tagloc.io.survey_files import write_survey_outputs
    from tagloc.lidar import OccupancyGrid

    (tmp_path / "map.pgm").mkdir()  # fails at the last file
    grid = OccupancyGrid(np.zeros((4, 5), np.float32), 0.05, (0.0, 0.0, 0.0, 0.0))
    try:
        write_survey_outputs({tmp_path / "tags.yaml": "x"},
                             (tmp_path / "premap.ply", np.zeros((3, 3)), "ply"),
                             (tmp_path / "map.yaml", grid))  # fmt: skip
    except OutputPathError:
        pass
    else:
        raise AssertionError("expected OutputPathError")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pgm"]
