"""dimos blueprints with tagloc's relocalization (``dimos run tagloc.<name>``).

Registered through the ``dimos.blueprints`` entry points of ``pyproject.toml``; each module's
settings are dimos config (``--taglocrelocalization.tag-map=tags.yaml`` on ``dimos run``, or the
blueprint's config file):

- ``tagloc-go2``: dimos's Go2 3D navigation stack (Point-LIO odometry in ``odom``, the ray
  tracer, the MLS planner) with tagloc *instead of* the lidar relocalizer: the Go2 front camera
  is switched on and tagloc publishes ``odom -> map``. With ``map_file`` (a ``.pc2.lcm``
  premap: the Go2 team's, or ``tagloc map build --premap-format pc2.lcm``) tagloc's own lidar
  fixes join the tag fixes.
- ``tagloc-go2-lidar``: the same *beside* dimos's lidar relocalizer, whose fixes move to the
  ``lidar_relocalization_tf`` stream (for comparison) so that ``odom -> map`` has one publisher.
- ``tagloc-desk``: a camera on a desk (dimos's ``CameraModule``, a webcam by default) that does
  not move: :class:`FixedBase` publishes an identity ``world -> base_link``, tagloc ``world ->
  map``: where the camera is in the tag map, live.
"""

from __future__ import annotations

import time
from typing import Any

from dimos.core.coordination.blueprints import autoconnect
from dimos.core.core import rpc
from dimos.core.module import Module, ModuleConfig
from dimos.core.stream import Out
from dimos.hardware.sensors.camera.module import CameraModule
from dimos.mapping.relocalization.lidar.module import LocalMapRelocalization
from dimos.msgs.tf2_msgs.TFMessage import TFMessage
from dimos.robot.unitree.go2.blueprints.navigation.unitree_go2_nav_3d import (
    unitree_go2_nav_3d,
    unitree_go2_nav_3d_relocalization,
)
from dimos.robot.unitree.go2.connection import GO2Connection
from reactivex import interval

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos.module import TaglocRelocalization
from tagloc.geometry import SE3

__all__ = ["FixedBase", "tagloc_desk", "tagloc_go2", "tagloc_go2_lidar"]

#: The Go2 connection of the navigation stack with the front camera on (the stack turns it off;
#: a later atom of the same module replaces the earlier one, the stack's remappings still hold).
_GO2_WITH_CAMERA = GO2Connection.blueprint(
    obstacle_avoidance=False, lidar=False, camera=True, motion_mode="mcf",
    odom_frame_id="go2_odom", publish_tf=False,
)  # fmt: skip

tagloc_go2 = autoconnect(
    unitree_go2_nav_3d, _GO2_WITH_CAMERA, TaglocRelocalization.blueprint(world_frame="odom")
).global_config(n_workers=12)

tagloc_go2_lidar = autoconnect(
    unitree_go2_nav_3d_relocalization.remappings(
        [(LocalMapRelocalization, "tf", "lidar_relocalization_tf")]
    ),
    _GO2_WITH_CAMERA,
    TaglocRelocalization.blueprint(world_frame="odom"),
).global_config(n_workers=13)


class FixedBaseConfig(ModuleConfig):
    world_frame: str = "world"
    base_frame: str = "base_link"
    rate_hz: float = 30.0


class FixedBase(Module):
    """The odometry of a robot that does not move: identity ``world -> base_link`` at
    ``rate_hz``, stamped with the wall clock (a desk camera has no odometry of its own)."""

    config: FixedBaseConfig
    tf: Out[TFMessage]

    @rpc
    def start(self) -> None:
        super().start()
        c = self.config
        self.register_disposable(interval(1.0 / c.rate_hz).subscribe(lambda _: self._publish()))

    def _publish(self, *_: Any) -> None:
        c = self.config
        edge = convert.transform(SE3.identity(), c.world_frame, c.base_frame, time.time())
        self.tf.publish(TFMessage(edge))


tagloc_desk = autoconnect(
    CameraModule.blueprint(),
    FixedBase.blueprint(),
    TaglocRelocalization.blueprint(world_frame="world"),
)
