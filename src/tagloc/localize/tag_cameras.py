"""The tag source's cameras: a rig of one or more cameras, each on its own topics.

A :class:`NodeCamera` names a camera, the topic of its tag corners (and, optionally, of its
images and ``CameraInfo``), its model and its extrinsics ``T_base_cam`` (None: from the first
``CameraInfoMsg`` / the stream's static ``base -> <frame_id>``). The node takes fixes from every
camera on its topic: each camera's frames are their own fix source
(:class:`~tagloc.localize.fiducial.FiducialFixSource`), so each fix keeps its camera's
extrinsics and its tag's id, and the filter decides the fixes of cameras that see tags at the
same instant one after the other at that stamp.

Why per-camera fixes rather than one PnP over all cameras of an instant: for independent
corner noise, sequential updates at one stamp are the joint update (to first order), so a
joint solve adds information only where a camera's own solve is refused; on the stereo rig of
``docs/dupont_localizer.yaml`` (0.20 m baseline) the two cameras see the same tags from nearly
the same place, and a joint solve would lose the per-tag books that single out a moved tag.

Without cameras given the node has one camera, ``""``, on the :class:`~tagloc.messages.
NodeTopics` roles (``detections``, ``image``, ``camera_info``), as before.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.localize.fix import LocalizeError
from tagloc.messages import NodeTopics

if TYPE_CHECKING:
    from tagloc.localize.fiducial import FiducialFixSource

__all__ = ["NodeCamera", "camera_slots"]

#: Frame stamps remembered per camera to refuse duplicates (a bounded set of the newest).
_RECENT_FRAMES = 1024


@dataclass(frozen=True, slots=True)
class NodeCamera:
    """One camera of the rig (module docstring).

    Attributes
    ----------
    name : str
        Carried by each of its fixes (:attr:`~tagloc.localize.run.FixAttempt.camera`).
    detections_topic : str
        Its ``TagDetectionsMsg`` topic.
    camera : CameraModel or None
        Model of the raw image the corners are in (None: from ``camera_info_topic``).
    T_base_cam : SE3 or None
        Its optical frame in the base (None: the stream's static transform).
    image_topic, camera_info_topic : str
        Its ``ImageMsg`` and ``CameraInfoMsg`` topics (``""``: none).
    """

    name: str
    detections_topic: str
    camera: CameraModel | None = None
    T_base_cam: SE3 | None = None
    image_topic: str = ""
    camera_info_topic: str = ""


class CameraSlot:
    """One camera's state in the tag source: its model (given, or from ``CameraInfo``), its fix
    source once built, and the stamps of its newest frames."""

    def __init__(self, spec: NodeCamera) -> None:
        self.spec = spec
        self.camera: CameraModel | None = spec.camera
        self.source: FiducialFixSource | None = None
        self._recent: OrderedDict[int, None] = OrderedDict()

    @property
    def name(self) -> str:
        return self.spec.name

    def seen(self, stamp_ns: int) -> bool:
        """Whether a frame of this stamp came before (else remember it)."""
        if stamp_ns in self._recent:
            return True
        self._recent[stamp_ns] = None
        if len(self._recent) > _RECENT_FRAMES:
            self._recent.popitem(last=False)
        return False

    def reset(self) -> None:
        """Forget the stamps and the extrinsics looked up on the old timeline."""
        self._recent.clear()
        self.source = None


def camera_slots(
    cameras: Sequence[NodeCamera], topics: NodeTopics, camera: CameraModel | None,
    T_base_cam: SE3 | None,
) -> tuple[CameraSlot, ...]:  # fmt: skip
    """The slots of ``cameras``, or of the one camera on ``topics`` when none are given.

    Raises
    ------
    LocalizeError
        If two cameras share a name or a topic, or ``camera`` / ``T_base_cam`` are given beside
        ``cameras`` (each camera carries its own).
    """
    if not cameras:
        one = NodeCamera("", topics.detections, camera, T_base_cam, topics.image,
                         topics.camera_info)  # fmt: skip
        return (CameraSlot(one),)
    if camera is not None or T_base_cam is not None:
        raise LocalizeError("give the camera model and extrinsics per camera (NodeCamera), "
                            "not beside the cameras")  # fmt: skip
    names = [c.name for c in cameras]
    used = [t for c in cameras for t in (c.detections_topic, c.image_topic, c.camera_info_topic)
            if t]  # fmt: skip
    if len(set(names)) != len(names):
        raise LocalizeError(f"cameras: a name is given twice ({', '.join(names)})")
    if len(set(used)) != len(used):
        raise LocalizeError(f"cameras: a topic is used twice ({', '.join(used)})")
    return tuple(CameraSlot(c) for c in cameras)
