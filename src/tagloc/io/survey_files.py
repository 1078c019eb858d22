"""The map builder's outputs written all or none: tags.yaml, QA report, premap, occupancy grid.

Each file goes to a temporary file beside its target first (the map_server pair to a temporary
directory beside it, so that ``map.yaml`` names the final ``map.pgm``); only when every one is
written are they renamed into place, so a failure leaves none of them changed (a rename failing
half-way is the one case that leaves some renamed, as :func:`tagloc.fileutil.atomic_write_texts`).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from tagloc.fileutil import atomic_path
from tagloc.io.dimos_premap import write_pc2_lcm
from tagloc.io.map_server import write_map_server
from tagloc.io.pointcloud_files import write_pcd, write_ply
from tagloc.lidar import OccupancyGrid


def write_survey_outputs(
    texts: Mapping[Path, str],
    premap: tuple[Path, npt.NDArray[np.floating], Literal["ply", "pcd", "pc2.lcm"]] | None = None,
    grid: tuple[Path, OccupancyGrid] | None = None,
) -> None:
    """Write ``texts`` (UTF-8), the premap ``(path, points_map (N, 3), format)`` (``pc2.lcm``: a
    dimos premap, :mod:`tagloc.io.dimos_premap`) and the grid
    ``(map.yaml path, grid)`` (with its ``.pgm`` beside it), all or none."""
    with contextlib.ExitStack() as stack:
        for path, text in texts.items():
            stack.enter_context(atomic_path(path)).write_text(text, encoding="utf-8")
        if premap is not None:
            path, points, fmt = premap
            tmp = stack.enter_context(atomic_path(path))
            writer = {"ply": write_ply, "pcd": write_pcd, "pc2.lcm": write_pc2_lcm}[fmt]
            writer(tmp, points, "map")
        if grid is not None:
            yaml_path, occupancy = grid
            yaml_path = Path(yaml_path)
            pgm_path = yaml_path.with_suffix(".pgm")
            tmp_yaml = stack.enter_context(atomic_path(yaml_path))
            tmp_pgm = stack.enter_context(atomic_path(pgm_path))
            with tempfile.TemporaryDirectory(dir=yaml_path.parent, prefix=".map.") as tmp_dir:
                staged = Path(tmp_dir) / yaml_path.name
                write_map_server(staged, occupancy)
                os.replace(staged, tmp_yaml)
                os.replace(staged.with_suffix(".pgm"), tmp_pgm)
