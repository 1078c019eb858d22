"""The explicit registry of detection backends and :func:`make_detector`.

Backends are registered by name with the options they accept; nothing is discovered by probing.
Built in:

========== ========================================= =========================================
name       library                                    families
========== ========================================= =========================================
apriltag   AprilTag 3 (pupil-apriltags), the default  tag36h11, tag25h9, tag16h5
aruco      OpenCV 5 ``cv2.aruco.ArucoDetector``       every known family (ArUco and AprilTag)
========== ========================================= =========================================

Both report corners in the one convention of :mod:`tagloc.tags.detection`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from tagloc.tags.apriltag_backend import APRILTAG_OPTIONS, AprilTagDetector
from tagloc.tags.aruco_backend import ARUCO_OPTIONS, ArucoTagDetector
from tagloc.tags.detection import TagDetector
from tagloc.tags.errors import TagBackendError

DetectorFactory = Callable[..., TagDetector]


@dataclass(frozen=True, slots=True)
class BackendEntry:
    """A registered backend.

    Attributes
    ----------
    factory : callable
        ``factory(family, **options) -> TagDetector``.
    options : frozenset of str
        Option names the factory accepts (checked before calling it).
    """

    factory: DetectorFactory
    options: frozenset[str]


_REGISTRY: dict[str, BackendEntry] = {
    "apriltag": BackendEntry(AprilTagDetector, APRILTAG_OPTIONS),
    "aruco": BackendEntry(ArucoTagDetector, ARUCO_OPTIONS),
}


def register_backend(
    name: str, factory: DetectorFactory, options: frozenset[str], *, replace: bool = False
) -> None:
    """Add a backend to the registry.

    Parameters
    ----------
    name : str
        Registry name (what configs put in ``backend:``).
    factory : callable
        ``factory(family, **options) -> TagDetector``.
    options : frozenset of str
        Option names ``factory`` accepts.
    replace : bool
        Allow replacing an existing entry.

    Raises
    ------
    TagBackendError
        If ``name`` is taken and ``replace`` is false.
    """
    if name in _REGISTRY and not replace:
        raise TagBackendError(f"backend {name!r} is already registered")
    _REGISTRY[name] = BackendEntry(factory, frozenset(options))


def available_backends() -> tuple[str, ...]:
    """Registered backend names."""
    return tuple(_REGISTRY)


def make_detector(
    backend: str = "apriltag", family: str = "tag36h11", **options: Any
) -> TagDetector:
    """Build a detector for one family.

    Parameters
    ----------
    backend : str
        A registered backend: ``"apriltag"`` (default) or ``"aruco"``.
    family : str
        Tag family (``"tag36h11"``, ``"aruco_4x4_50"``, ...).
    **options
        Backend options: ``quad_decimate``, ``quad_sigma``, ``refine_edges``,
        ``decode_sharpening``, ``nthreads`` for ``apriltag``; ``corner_refinement``,
        ``corner_refinement_win_size``, ``relative_corner_refinement_win_size``,
        ``error_correction_rate``, ``min_marker_distance_rate`` for ``aruco``.

    Returns
    -------
    TagDetector

    Raises
    ------
    TagBackendError
        If the backend is unknown, cannot detect ``family``, or an option is unknown or bad.
    """
    entry = _REGISTRY.get(backend)
    if entry is None:
        raise TagBackendError(
            f"unknown detector backend {backend!r}; registered: {', '.join(_REGISTRY)}"
        )
    _check_options(backend, entry, options)
    return entry.factory(family, **options)


def _check_options(backend: str, entry: BackendEntry, options: Mapping[str, Any]) -> None:
    unknown = sorted(set(options) - entry.options)
    if unknown:
        raise TagBackendError(
            f"backend {backend!r}: unknown option(s) {', '.join(unknown)}; "
            f"accepted: {', '.join(sorted(entry.options))}"
        )
