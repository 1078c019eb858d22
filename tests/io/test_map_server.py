"""map_server PGM + YAML: written grids load with map_server's documented semantics."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from tagloc.errors import ConfigError
from tagloc.io.map_server import MapFileError, read_map_server, write_map_server
from tagloc.lidar import OccupancyGrid

SEED = 23


@pytest.fixture
def grid() -> OccupancyGrid:
    rng = np.random.default_rng(SEED)
    log_odds = rng.choice([-2.0, -1.0, 0.0, 0.3, 0.7, 3.0], size=(30, 50)).astype(np.float32)
    return OccupancyGrid(log_odds, 0.05, (-1.25, 2.5, 0.0, 0.0))


def _map_server_load(yaml_path: Path) -> tuple[dict, np.ndarray]:
    """map_server's reading, from its documentation (wiki.ros.org/map_server, "YAML format",
    "Value Interpretation"), with OpenCV reading the image: ``p = (255 - v) / 255`` (``negate:
    0``), occupied when ``p > occupied_thresh`` (100), free when ``p < free_thresh`` (0), else
    unknown (-1); the image path is relative to the YAML's directory."""
    meta = yaml.safe_load(yaml_path.read_text())
    image = cv2.imread(str(yaml_path.parent / meta["image"]), cv2.IMREAD_UNCHANGED)
    p = (255.0 - image) / 255.0 if meta["negate"] == 0 else image / 255.0
    occupancy = np.full(image.shape, -1)
    occupancy[p > meta["occupied_thresh"]] = 100
    occupancy[p < meta["free_thresh"]] = 0
    return meta, occupancy


def test_written_map_loads_with_map_server_semantics(tmp_path: Path, grid: OccupancyGrid) -> None:
    write_map_server(tmp_path / "map.yaml", grid)
    meta, occupancy = _map_server_load(tmp_path / "map.yaml")
    assert meta == {
        "image": "map.pgm", "resolution": 0.05, "origin": [-1.25, 2.5, 0.0], "negate": 0,
        "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary",
    }  # fmt: skip
    np.testing.assert_array_equal(occupancy == 100, grid.occupied())
    np.testing.assert_array_equal(occupancy == 0, grid.free())
    assert ((occupancy == -1) == (~grid.occupied() & ~grid.free())).all()
    assert set(np.unique(cv2.imread(str(tmp_path / "map.pgm"), cv2.IMREAD_UNCHANGED))) <= {
        0, 205, 254
    }  # fmt: skip


def test_origin_is_the_lower_left_pixel(tmp_path: Path) -> None:
    """One occupied cell at map (x, y) = (0.32, 0.11): map_server puts pixel (row r, col c) at
    ``origin + ((c + 0.5) res, (H - 1 - r + 0.5) res)``."""
    log_odds = np.zeros((20, 30), dtype=np.float32)
    grid = OccupancyGrid(log_odds, 0.1, (-0.5, -0.6, 0.0, 0.0))
    row, col = grid.cell_of(np.array([[0.32, 0.11]]))
    log_odds[row, col] = 3.0
    write_map_server(tmp_path / "m.yaml", grid)
    meta, occupancy = _map_server_load(tmp_path / "m.yaml")
    (r,), (c,) = np.nonzero(occupancy == 100)
    x = meta["origin"][0] + (c + 0.5) * meta["resolution"]
    y = meta["origin"][1] + (occupancy.shape[0] - 1 - r + 0.5) * meta["resolution"]
    assert abs(x - 0.32) <= 0.05 and abs(y - 0.11) <= 0.05


def test_round_trip_keeps_the_classes(tmp_path: Path, grid: OccupancyGrid) -> None:
    write_map_server(tmp_path / "map.yaml", grid)
    back = read_map_server(tmp_path / "map.yaml")
    np.testing.assert_array_equal(back.occupied(), grid.occupied())
    np.testing.assert_array_equal(back.free(), grid.free())
    assert back.resolution_m == grid.resolution_m and back.origin_xyz_yaw == grid.origin_xyz_yaw
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pgm", "map.yaml"]


def test_negate_and_scale_follow_map_server(tmp_path: Path, grid: OccupancyGrid) -> None:
    write_map_server(tmp_path / "map.yaml", grid)
    image = cv2.imread(str(tmp_path / "map.pgm"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(tmp_path / "neg.pgm"), 255 - image)
    text = (tmp_path / "map.yaml").read_text()
    text = text.replace("map.pgm", "neg.pgm").replace("negate: 0", "negate: 1")
    (tmp_path / "neg.yaml").write_text(text.replace("trinary", "scale"))
    back = read_map_server(tmp_path / "neg.yaml")
    _, occupancy = _map_server_load(tmp_path / "neg.yaml")
    np.testing.assert_array_equal(back.occupied(), occupancy == 100)
    np.testing.assert_array_equal(back.free(), occupancy == 0)


def _yaml(tmp_path: Path, **changes: object) -> Path:
    meta = {"image": "map.pgm", "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "trinary"}  # fmt: skip
    meta.update(changes)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({k: v for k, v in meta.items() if v is not None}))
    return path


@pytest.mark.parametrize(
    ("changes", "error", "message"),
    [
        ({"resolution": None}, ConfigError, "resolution"),
        ({"origin": [0.0, 0.0]}, ConfigError, "origin"),
        ({"negate": 2}, ConfigError, "negate"),
        ({"mode": "raw"}, MapFileError, "mode 'raw'"),
        ({"free_thresh": 0.7}, ConfigError, "free_thresh"),
        ({"image": "missing.pgm"}, MapFileError, "cannot read map image"),
        ({"image": "."}, MapFileError, "not a regular file"),
        ({"resolution": 1e-300}, ConfigError, "resolution"),
        ({"origin": [1e300, 0.0, 0.0]}, ConfigError, "origin[0]: input should be less"),
        ({"origin": [0.0, 0.0, 1e300]}, ConfigError, "origin[2]"),
    ],
)
def test_bad_yaml_fails_in_one_line(
    tmp_path: Path, grid: OccupancyGrid, changes: dict, error: type, message: str
) -> None:
    write_map_server(tmp_path / "map.yaml", grid)
    path = _yaml(tmp_path, **changes)
    with pytest.raises(error) as info:
        read_map_server(path)
    text = str(info.value)
    assert message in text and "\n" not in text


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"P5\n50 30\n255\n" + b"\0" * 100, "truncated PGM: 50x30 needs 1500 bytes, has 100"),
        (b"P2\n2 2\n255\n0 0 0 0\n", "not a binary PGM"),
        (b"P5\n# c\n50 x\n255\n", "malformed PGM header"),
        (b"P5\n2 2\n65535\n" + b"\0" * 8, "need 8-bit"),
        (b"P5\n100000 100000\n255\n" + b"\0" * 8, "more than 50000000 cells"),  # before reading
        (b"P5\n" + b"9" * 5000 + b" 1\n255\n", "malformed PGM header"),  # not a 5000-digit int
        (b"P5\n2 1\n255", "malformed PGM header"),
    ],
)
def test_bad_pgm_fails_in_one_line_naming_it(tmp_path: Path, data: bytes, message: str) -> None:
    (tmp_path / "map.pgm").write_bytes(data)
    with pytest.raises(MapFileError) as info:
        read_map_server(_yaml(tmp_path))
    text = str(info.value)
    assert text.startswith(str(tmp_path / "map.pgm")) and message in text


def test_comments_in_the_pgm_header_are_read(tmp_path: Path) -> None:
    (tmp_path / "map.pgm").write_bytes(b"P5\n# made by hand\n2 1\n# max\n255\n\x00\xfe")
    back = read_map_server(_yaml(tmp_path))
    assert back.occupied().tolist() == [[True, False]] and back.free().tolist() == [[False, True]]
