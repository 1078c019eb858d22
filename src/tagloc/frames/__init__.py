"""Transforms between named frames over time: :class:`TransformBuffer` (a pure-numpy tf).

Frame tree
    Frames are named by strings (configuration, never literals in algorithms). Each edge
    ``parent -> child`` holds ``T_parent_child`` (maps points from ``child`` into ``parent``);
    every frame has at most one parent, so the frames form a forest. Self-edges, a second
    parent and cycles are refused (:class:`~tagloc.errors.FrameTreeError`). An edge is either
    *static* (:meth:`TransformBuffer.set_static`, valid at every stamp; setting it again
    replaces the value) or *dynamic* (:meth:`~TransformBuffer.set_transform`, samples over
    time); an edge never changes kind.
Lookup
    ``lookup(target, source, stamp_ns)`` returns ``T_target_source``, e.g.
    ``lookup("map", "camera", t)`` is ``T_map_camera``: the edges up from both frames to their
    common ancestor, composed, the target side inverted. Any connected pair works (source above
    target, siblings, a frame with itself gives the identity). The path between a pair is
    cached, with consecutive static edges pre-multiplied; any topology or static change clears
    the cache.
Time
    Integer nanoseconds everywhere (``int`` or numpy integer; ``int64`` arrays); a float is
    refused with :class:`~tagloc.frames.errors.StampError` rather than rounded. Messages print
    stamps as seconds with 9 decimals and as ns.
Interpolation
    Between the two samples around the stamp: slerp on the rotation, linear on the translation
    (as ROS tf and GTSAM ``interpolateRt``; not the SE(3) geodesic, which would bend the
    translation along a screw). A stamp equal to a sample returns that sample.
Window
    Per dynamic edge, inserting drops samples older than that edge's newest stamp minus
    ``window_ns`` (default 10 s; the boundary stamp is kept), so memory is bounded by the rate
    times the window whatever the stream length. Late samples inside the window are inserted in
    order; a sample older than the window is refused (:class:`~tagloc.frames.errors.
    StaleSampleError`), naming the edge, its stamp and the oldest accepted one.
Duplicate stamps
    A sample at a stamp the edge already holds *replaces* it (last writer wins; also within a
    ``set_transforms`` batch). A correction published again for the same stamp (e.g. the
    ``map -> odom`` filter after a second fix at the same time) thus needs no bookkeeping, and the
    buffer stays a function of time. Replaying the same stream twice is harmless.
Extrapolation tolerance
    ``extrapolation_tolerance_ns`` (default 0): a lookup up to that far before an edge's oldest
    or after its newest sample returns that end sample (held, never extrapolated); further out
    it raises :class:`~tagloc.errors.ExtrapolationError` naming each edge that failed with its
    buffered range.
Thread safety
    None: a buffer is not thread safe (lookups update the path cache). Share one between threads
    only behind a lock held for every call.

Errors are the :mod:`tagloc.errors` classes plus :class:`~tagloc.frames.errors.StampError`
(a ``TypeError``) and :class:`~tagloc.frames.errors.StaleSampleError` (a ``ValueError``).
"""

from tagloc.frames.buffer import DEFAULT_WINDOW_NS, TransformBuffer
from tagloc.frames.errors import StaleSampleError, StampError
from tagloc.frames.odometry_frame import OdometryFrameConfig, axis_vector, base_tilt_deg

__all__ = [
    "DEFAULT_WINDOW_NS",
    "OdometryFrameConfig",
    "StaleSampleError",
    "StampError",
    "TransformBuffer",
    "axis_vector",
    "base_tilt_deg",
]
