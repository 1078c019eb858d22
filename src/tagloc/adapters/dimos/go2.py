"""Go2 blueprints with tagloc's relocalization (need ``dimos[unitree]``, the Go2 connection).

- ``tagloc-go2``: dimos's Go2 3D navigation stack (Point-LIO odometry in ``odom``, the ray
  tracer, the MLS planner) with tagloc *instead of* the lidar relocalizer: the Go2 front camera
  is switched on and tagloc publishes ``odom -> map``. With ``map_file`` (a ``.pc2.lcm``
  premap: the Go2 team's, or ``tagloc map build --premap-format pc2.lcm``) tagloc's own lidar
  fixes join the tag fixes.
- ``tagloc-go2-lidar``: the same *beside* dimos's lidar relocalizer, whose fixes move to the
  ``lidar_relocalization_tf`` stream (for comparison) so that ``odom -> map`` has one publisher.

The stack's tree is ``odom -> mid360_link -> front_camera -> base_link`` and ``front_camera ->
camera_optical`` (Point-LIO and the mount publisher): the module follows the chain for the
odometry and finds the camera's mounting in it.
"""

from __future__ import annotations

from dimos.core.coordination.blueprints import autoconnect
from dimos.mapping.relocalization.lidar.module import LocalMapRelocalization
from dimos.robot.unitree.go2.blueprints.navigation.unitree_go2_nav_3d import (
    unitree_go2_nav_3d,
    unitree_go2_nav_3d_relocalization,
)
from dimos.robot.unitree.go2.connection import GO2Connection

from tagloc.adapters.dimos.module import TaglocRelocalization

__all__ = ["tagloc_go2", "tagloc_go2_lidar"]

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
