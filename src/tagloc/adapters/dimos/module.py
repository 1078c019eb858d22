"""``TaglocRelocalization``: dimos's relocalization module, driven by tagloc's streaming node.

A :class:`dimos.mapping.relocalization.module.RelocalizationModule` (dimos 0.0.15): it loads the
premap of ``map_file`` like every relocalizer, and hands each correction to ``submit``, which
publishes the ``world_frame -> map_frame`` transform on ``tf``. Unlike the lidar relocalizer it
never stops (``relocalize_once`` is off): the node's correction is submitted at the node's
publication rate (``output.publish_rate_hz`` of ``localizer.yaml``, 10 Hz by default).

Inputs (each optional, used when wired): ``tf`` (an ``IO``: the odometry ``world_frame ->
base_frame``, directly or as a chain such as ``odom -> mid360_link -> front_camera -> base_link``,
and the camera's and lidar's mountings below ``base_frame``), ``color_image`` (``Image``) or
``image`` (JPEG ``CompressedImage``), ``camera_info`` (or ``camera_info_file``, a ROS camera
YAML, for a camera that publishes none), ``lidar`` (``PointCloud2`` sweeps in the scanner's
frame, used with a premap when ``lidar.enabled``). Outputs: ``tf``, ``loaded_map`` (the base's),
``tagloc_pose`` (``PoseWithCovarianceStamped`` of ``base_frame`` in ``map_frame``, stamped with
the odometry sample it belongs to) and ``tagloc_status`` (a JSON ``String``: ladder level,
stale, sigmas, the node's skips, ``floor`` (null: floors are not tracked yet), ``problems``,
one line per bad input, and ``received``, the messages handled per input, the module's own
correction looped back on ``tf`` not counted; the same dict from the ``status()`` rpc).

Clocks. dimos re-stamps every submitted transform with the wall clock (``Transform.now()``) and
republishes it every ``tf_interval`` s, so the ``world -> map`` on ``tf`` carries the time it was
*published*, not the odometry stamp it was computed at. The node itself never sees a wall-clock
stamp: it runs on the stamps of the odometry and the images (its looped-back ``world -> map`` is
ignored), and ``tagloc_pose`` keeps the odometry stamp. Because the correction moves slowly (at
most ``cap`` per step), a consumer that looks ``map -> base_link`` up at an odometry stamp within
dimos's tolerance of the wall clock (a live robot) gets the right value; one replaying old stamps
should look the correction up at the latest time (``time_point=None``).

Bad input never stops the module: a missing tag map or ``localizer.yaml`` (the module runs and
publishes nothing but its status), a camera info of another resolution than the images, a camera
frame with no transform from ``base_frame`` in the tree, an undecodable image: one warning line
each, the frames are skipped, and ``problems`` says why until it is resolved.
"""

from __future__ import annotations

import json
import logging
from collections import Counter
from typing import Any

from dimos.core.core import rpc
from dimos.core.stream import IO, In, Out
from dimos.mapping.relocalization.module import Config, RelocalizationModule
from dimos.msgs.geometry_msgs.PoseWithCovarianceStamped import PoseWithCovarianceStamped
from dimos.msgs.sensor_msgs.CameraInfo import CameraInfo
from dimos.msgs.sensor_msgs.CompressedImage import CompressedImage
from dimos.msgs.sensor_msgs.Image import Image
from dimos.msgs.sensor_msgs.PointCloud2 import PointCloud2
from dimos.msgs.std_msgs.String import String
from dimos.msgs.tf2_msgs.TFMessage import TFMessage
from dimos.protocol.tf.tf import MultiTBuffer
from reactivex.disposable import Disposable

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos._node import LiveNode, live_config
from tagloc.errors import TaglocError
from tagloc.localize.outputs import Estimate
from tagloc.messages import CameraInfoMsg, TransformMsg
from tagloc.supervise import StatusReport
from tagloc.tags import load_tag_map

__all__ = ["TaglocConfig", "TaglocRelocalization"]

logger = logging.getLogger(__name__)
#: Odometry found through the tree (a chain) must be this close to the edge's stamp, s.
CHAIN_TOLERANCE_S = 0.05


class TaglocConfig(Config):
    """The module's configuration (dimos's relocalization ``Config`` plus tagloc's files)."""

    #: Keep submitting: the node corrects the drift continuously.
    relocalize_once: bool = False
    #: ``tags.yaml`` (None or missing: the module runs, does not localize, and says so).
    tag_map: str | None = None
    #: ``localizer.yaml`` (None: the defaults); its frame names are replaced by the module's.
    localizer_config: str | None = None
    #: The robot body the odometry moves (``world_frame -> base_frame``).
    base_frame: str = "base_link"
    #: A ROS camera YAML used when no ``camera_info`` stream is wired (or before it arrives).
    camera_info_file: str | None = None
    #: The optical frame of images that carry none (and of ``camera_info_file``).
    camera_frame: str = "camera_optical"


class TaglocRelocalization(RelocalizationModule):
    """Fiducial (and lidar) relocalization by tagloc's streaming node (module docstring)."""

    config: TaglocConfig
    tf: IO[TFMessage]
    color_image: In[Image]
    image: In[CompressedImage]
    camera_info: In[CameraInfo]
    lidar: In[PointCloud2]
    tagloc_pose: Out[PoseWithCovarianceStamped]
    tagloc_status: Out[String]

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._live: LiveNode | None = None
        self._tree: MultiTBuffer = MultiTBuffer()
        self._problems: dict[str, str] = {}
        self._counts: Counter[str] = Counter()
        self._report: dict[str, object] = {}
        self._camera_size: tuple[int, int] | None = None
        self._mounted: set[str] = set()
        self._waiting: dict[str, str] = {}  # sensor frame -> what waits for its mounting

    @rpc
    def start(self) -> None:
        super().start()
        self._live = self._build()
        if self._live is not None and self.config.camera_info_file:
            info = CameraInfo.from_yaml(self.config.camera_info_file, self.config.camera_frame)
            self._on_camera_info(info)
        handlers = {"tf": self._on_tf, "color_image": self._on_image, "image": self._on_image,
                    "camera_info": self._on_camera_info, "lidar": self._on_lidar}  # fmt: skip
        for name, handler in handlers.items():
            stream = getattr(self, name)
            if getattr(stream, "_transport", None) is not None:
                unsubscribe = stream.subscribe(self._guarded(name, handler))
                self.register_disposable(Disposable(unsubscribe))
        self._publish_status()

    @rpc
    def status(self) -> dict[str, object]:
        """The latest status (module docstring); also published on ``tagloc_status``."""
        live = self._live
        return {
            **self._report, "floor": None, "localizing": live is not None,
            "problems": sorted(self._problems.values()), "received": dict(self._counts),
            "skipped": {} if live is None else live.skipped,
        }  # fmt: skip

    # ----- set-up ------------------------------------------------------------------------
    def _build(self) -> LiveNode | None:
        c = self.config
        try:
            if not c.tag_map:
                raise TaglocError("no tag map configured (tag_map: path to tags.yaml)")
            tag_map = load_tag_map(c.tag_map)
            config = live_config(c.localizer_config, c.map_frame, c.world_frame, c.base_frame)
        except TaglocError as exc:
            self._problem("setup", f"not localizing: {exc}")
            return None
        premap = None
        if self.premap is not None and config.lidar.enabled:
            premap = self.premap.points_f32().astype(float)
        try:
            return LiveNode(tag_map, config, premap, self._on_estimate, self._on_report)
        except TaglocError as exc:
            self._problem("premap", f"premap not used: {exc}")
            return LiveNode(tag_map, config, None, self._on_estimate, self._on_report)

    def _guarded(self, name: str, handler: Any) -> Any:
        """``handler`` counting its messages, never raising into the transport's thread."""

        def on_message(msg: Any) -> None:
            if name == "tf" and self._own(msg):
                return  # our correction, looped back by the IO port
            live = self._live
            if live is None:
                self._counts[name] += 1
                return
            with live.lock:
                try:
                    handler(msg)
                except TaglocError as exc:
                    self._problem(name, f"{name}: {exc}")
                except Exception:  # a bug: its traceback, once per stream
                    if self._counts[f"{name}_errors"] == 0:
                        logger.exception("tagloc: %s handler failed", name)
                    self._counts[f"{name}_errors"] += 1
                finally:  # counted once handled: "received" is what the node has seen
                    self._counts[name] += 1

        return on_message

    def _own(self, msg: TFMessage) -> bool:
        """Whether ``msg`` holds nothing but the ``world -> map`` edge this module publishes."""
        edge = (self.config.world_frame, self.config.map_frame)
        return all((t.frame_id, t.child_frame_id) == edge for t in msg.transforms)

    # ----- inputs (called with the node's lock held) ---------------------------------------
    def _on_tf(self, msg: TFMessage) -> None:
        c, live = self.config, self._live
        assert live is not None
        self._tree.receive_tfmessage(msg)
        for edge in msg.transforms:
            if edge.frame_id == c.base_frame and edge.child_frame_id not in self._mounted:
                self._mount(edge.child_frame_id)  # a sensor's mounting: to the node at once
            if edge.frame_id != c.world_frame or edge.child_frame_id == c.map_frame:
                continue  # not odometry (our own correction, or another relocalizer's)
            if edge.child_frame_id != c.base_frame:  # odometry of another frame: the chain
                found = self._tree.get(c.world_frame, c.base_frame, edge.ts, CHAIN_TOLERANCE_S,
                                       warn=False)  # fmt: skip
                if found is None:
                    continue
                edge = found
            stamp = convert.stamp_ns(edge.ts)
            live.feed(TransformMsg(stamp, c.world_frame, c.base_frame, convert.se3(edge)))

    def _on_camera_info(self, info: CameraInfo) -> None:
        assert self._live is not None
        if self._camera_size is None:
            msg = convert.camera_info_msg(info)
            self._camera_size = (int(info.width), int(info.height))
            self._live.feed(CameraInfoMsg(msg.stamp_ns, msg.frame_id or self.config.camera_frame,
                                          msg.info))  # fmt: skip

    def _on_image(self, image: Image | CompressedImage) -> None:
        live, c = self._live, self.config
        assert live is not None
        msg = convert.image_msg(image, c.camera_frame)
        if self._camera_size is None:
            return self._problem("camera_info", "camera frames skipped: no camera info yet "
                                 "(wire camera_info or set camera_info_file)")  # fmt: skip
        width, height = self._camera_size
        if msg.image.shape[:2] != (height, width):
            h, w = msg.image.shape[:2]
            return self._problem("camera_info", f"camera frames skipped: camera info is "
                                 f"{width}x{height} but images are {w}x{h}")  # fmt: skip
        self._clear("camera_info")
        if not self._mount(msg.frame_id, "camera"):
            return None
        live.feed(msg)
        return None

    def _on_lidar(self, cloud: PointCloud2) -> None:
        assert self._live is not None
        msg = convert.point_cloud_msg(cloud)
        if self._mount(msg.frame_id, "lidar"):
            self._live.feed(msg)

    def _mount(self, frame: str, what: str = "") -> bool:
        """Whether ``base_frame -> frame`` is known (fed to the node once, as a static); a
        ``what`` (camera, lidar) whose frame is not in the tree is a problem."""
        if frame in self._mounted:
            return True
        base = self.config.base_frame
        found = self._tree.get(base, frame, None, warn=False) if frame else None
        if found is None:
            if what:
                self._waiting[frame] = what
                self._problem(what, f"{what} frames skipped: no transform {base} -> "
                              f"{frame or '?'} in the tf tree")  # fmt: skip
            return False
        assert self._live is not None
        stamp = convert.stamp_ns(found.ts)
        self._live.feed(TransformMsg(stamp, base, frame, convert.se3(found), static=True))
        self._mounted.add(frame)
        waiting = self._waiting.pop(frame, None)
        if waiting is not None:
            self._clear(waiting)
        return True

    # ----- outputs -----------------------------------------------------------------------
    def _on_estimate(self, estimate: Estimate) -> None:
        if not (estimate.initialized and estimate.publish):
            return
        c = self.config
        T_world_map = estimate.T_parent_child(c.map_frame)  # published edge: world -> map
        self.submit(convert.transform(T_world_map, c.world_frame, c.map_frame,
                                      convert.stamp_s(estimate.stamp_ns)), "tagloc")  # fmt: skip
        pose = convert.pose_with_covariance(estimate.stamp_ns, c.map_frame, estimate.T_map_base,
                                            estimate.cov_map_base)  # fmt: skip
        if getattr(self.tagloc_pose, "_transport", None) is not None:
            self.tagloc_pose.publish(pose)

    def _on_report(self, report: StatusReport) -> None:
        self._report = report.to_dict()
        self._publish_status()

    def _publish_status(self) -> None:
        if getattr(self.tagloc_status, "_transport", None) is not None:
            self.tagloc_status.publish(String(json.dumps(self.status())))

    def _problem(self, key: str, line: str) -> None:
        """Record a bad input: logged once (until it changes), in the status until cleared."""
        if self._problems.get(key) != line:
            logger.warning("tagloc: %s", line)
            self._problems[key] = line
            self._publish_status()

    def _clear(self, key: str) -> None:
        if self._problems.pop(key, None) is not None:
            self._publish_status()
