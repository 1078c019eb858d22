"""The desk blueprint through dimos's ``ModuleCoordinator``, tagloc's module in a worker process.

``tagloc-desk`` with its camera and fixed base replaced by a player of the simulated drive (JPEG
images, tf, camera info), as dimos's replay blueprints replace hardware: the coordinator deploys
the modules to worker processes and wires them over LCM; the test reads the module's status over
RPC and its poses off the bus, and checks them against the simulator's ground truth.
"""

from __future__ import annotations

import pickle
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from dimos.core.coordination.blueprints import autoconnect
from dimos.core.coordination.module_coordinator import ModuleCoordinator
from dimos.core.transport import LCMTransport
from dimos.hardware.sensors.camera.module import CameraModule
from dimos.msgs.geometry_msgs.PoseWithCovarianceStamped import PoseWithCovarianceStamped
from drive import drive
from player import DrivePlayer

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos.blueprints import FixedBase, tagloc_desk
from tagloc.adapters.dimos.module import TaglocRelocalization
from tagloc.messages import CameraInfoMsg, ImageMsg, TransformMsg
from tagloc.tags import save_tag_map

#: Seconds of the drive skipped (no tag in view yet).
SKIP_S = 6.0
#: The last pose against the truth, m (the fused error of the office route is a few cm).
TOL_M = 0.15


def test_the_desk_blueprint_runs_tagloc_in_a_worker_process(tmp_path: Path) -> None:
    d = drive("world")
    start = next(r.stamp_ns for r in d.records if isinstance(r, ImageMsg)) + round(SKIP_S * 1e9)
    records = [r for r in d.records if isinstance(r, (TransformMsg, ImageMsg))
               and (r.stamp_ns >= start or (isinstance(r, TransformMsg) and r.static))]  # fmt: skip
    info = next(r for r in d.records if isinstance(r, CameraInfoMsg))
    plain = {k: dict(v) if isinstance(v, Mapping) else v for k, v in info.info.items()}
    recording = {"camera_info": (info.stamp_ns, info.frame_id, plain), "records": records}
    (tmp_path / "drive.pickle").write_bytes(pickle.dumps(recording))
    save_tag_map(d.tag_map, tmp_path / "tags.yaml")
    (tmp_path / "localizer.yaml").write_text(d.config_yaml, encoding="utf-8")
    blueprint = autoconnect(
        tagloc_desk.disabled_modules(CameraModule, FixedBase),
        DrivePlayer.blueprint(records_file=str(tmp_path / "drive.pickle"), speed=1.0),
        TaglocRelocalization.blueprint(world_frame="world", tag_map=str(tmp_path / "tags.yaml"),
                                       localizer_config=str(tmp_path / "localizer.yaml")),
    ).global_config(n_workers=2)
    poses: list[PoseWithCovarianceStamped] = []
    bus = LCMTransport("/tagloc_pose", PoseWithCovarianceStamped)
    bus.subscribe(poses.append)
    coordinator = ModuleCoordinator.build(blueprint)
    try:
        player = coordinator.get_instance(DrivePlayer)
        deadline = time.monotonic() + 300
        while not player.finished() and time.monotonic() < deadline:
            time.sleep(0.5)
        time.sleep(2.0)
        status = coordinator.get_instance(TaglocRelocalization).status()
    finally:
        coordinator.stop()
        bus.stop()

    assert player is not None and status["localizing"] and status["problems"] == []
    assert status["received"]["image"] > 100 and status["initialized"]
    assert len(poses) > 50
    last = poses[-1]
    truth = d.truth[convert.stamp_ns(last.ts)]
    p = last.pose.position
    assert np.linalg.norm(np.array([p.x, p.y, p.z]) - truth.translation) < TOL_M
