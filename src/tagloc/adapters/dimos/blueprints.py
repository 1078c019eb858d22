"""The desk blueprint (``dimos run tagloc.tagloc-desk``) and its fixed base.

``tagloc-desk``: a camera on a desk (dimos's ``CameraModule``, a webcam by default) that does not
move: :class:`FixedBase` publishes an identity ``world -> base_link``, tagloc ``world -> map``:
where the camera is in the tag map, live. The Go2 blueprints are in
:mod:`tagloc.adapters.dimos.go2` (they need ``dimos[unitree]``). Registered through the
``dimos.blueprints`` entry points of ``pyproject.toml``; each module's settings are dimos config
(``--taglocrelocalization.tag-map=tags.yaml`` on ``dimos run``, or the blueprint's config file).
"""

from __future__ import annotations

import time
from typing import Any

from dimos.core.coordination.blueprints import autoconnect
from dimos.core.core import rpc
from dimos.core.module import Module, ModuleConfig
from dimos.core.stream import Out
from dimos.hardware.sensors.camera.module import CameraModule
from dimos.msgs.tf2_msgs.TFMessage import TFMessage
from reactivex import interval

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos.module import TaglocRelocalization
from tagloc.geometry import SE3

__all__ = ["FixedBase", "tagloc_desk"]

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
