"""A dimos module that plays a recorded tagloc stream (a test's stand-in for a camera robot).

It publishes the records of a pickle file (``{"camera_info": CameraInfoMsg fields as
``(stamp_ns, frame_id, info dict)``, "records": [TransformMsg | ImageMsg, ...]}``: a camera info's
read-only mapping does not pickle) at ``speed`` times their own pace: odometry and mounts
on ``tf`` (the mounts again with every tenth odometry sample, as dimos's robots republish theirs),
the images as JPEG ``CompressedImage`` on ``image`` (as the Go2 over DDS serves its camera) and
the camera info on ``camera_info`` (again every second).
"""

from __future__ import annotations

import pickle
import threading
import time

import cv2
from dimos.core.core import rpc
from dimos.core.module import Module, ModuleConfig
from dimos.core.stream import Out
from dimos.msgs.sensor_msgs.CameraInfo import CameraInfo
from dimos.msgs.sensor_msgs.CompressedImage import CompressedImage
from dimos.msgs.tf2_msgs.TFMessage import TFMessage

from tagloc.adapters.dimos import convert
from tagloc.messages import CameraInfoMsg, ImageMsg, TransformMsg


class PlayerConfig(ModuleConfig):
    records_file: str = ""
    speed: float = 2.0
    jpeg_quality: int = 95


class DrivePlayer(Module):
    config: PlayerConfig
    tf: Out[TFMessage]
    image: Out[CompressedImage]
    camera_info: Out[CameraInfo]

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    @rpc
    def start(self) -> None:
        super().start()
        self._thread = threading.Thread(target=self._play, daemon=True)
        self._thread.start()

    @rpc
    def finished(self) -> bool:
        return self._done.is_set()

    def _play(self) -> None:
        with open(self.config.records_file, "rb") as f:
            recording = pickle.load(f)
        records = recording["records"]
        mounts = [r for r in records if isinstance(r, TransformMsg) and r.static]
        info = CameraInfoMsg(*recording["camera_info"])
        t0, start, n_odom, last_info = None, time.monotonic(), 0, -1e9
        for r in records:
            t0 = r.stamp_ns if t0 is None else t0
            due = start + (r.stamp_ns - t0) / 1e9 / self.config.speed
            time.sleep(max(0.0, due - time.monotonic()))
            ts = convert.stamp_s(r.stamp_ns)
            if time.monotonic() - last_info > 1.0:
                self.camera_info.publish(convert.camera_info(info))
                last_info = time.monotonic()
            if isinstance(r, TransformMsg) and not r.static:
                edges = [convert.transform(r.T_parent_child, r.parent, r.child, ts)]
                if n_odom % 10 == 0:
                    edges += [convert.transform(m.T_parent_child, m.parent, m.child, ts)
                              for m in mounts]  # fmt: skip
                self.tf.publish(TFMessage(*edges))
                n_odom += 1
            elif isinstance(r, ImageMsg):
                ok, jpeg = cv2.imencode(".jpg", r.image, [cv2.IMWRITE_JPEG_QUALITY,
                                                          self.config.jpeg_quality])  # fmt: skip
                assert ok
                self.image.publish(CompressedImage(data=jpeg.tobytes(), format="jpeg",
                                                   frame_id=r.frame_id, ts=ts))  # fmt: skip
        self._done.set()
