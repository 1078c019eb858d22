"""Camera models from calibration records: a ROS ``CameraInfo`` and one Kalibr camchain entry.

Pure constructors from already-parsed mappings; reading files is :mod:`tagloc.io`'s job
(:func:`tagloc.io.kalibr.load_kalibr_cameras`). Every error is a
:class:`~tagloc.errors.CameraModelError` whose message starts with the field path, e.g.
``"cam0.distortion_coeffs: expected 4 values for equidistant, got 5"``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from tagloc.camera import _fields
from tagloc.camera.equidistant import PinholeEquidistant
from tagloc.camera.model import CameraModel
from tagloc.camera.radtan import PinholeRadtan
from tagloc.config import short_repr
from tagloc.errors import CameraModelError

_ROS_SUPPORTED = "supported: plumb_bob, equidistant"
_KALIBR_SUPPORTED = "supported: radtan, equidistant, none"


def _mapping(value: object, name: str, what: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise CameraModelError(f"{name}: expected a mapping ({what}), got {type(value).__name__}")
    return value


def _build(
    equidistant: bool,
    size: tuple[int, int],
    focal: tuple[float, float],
    center: tuple[float, float],
    k: list[float],
) -> CameraModel:
    """The model for validated values (radtan: ``k`` holds 0, 4 or 5 coefficients)."""
    (width, height), (fx, fy), (cx, cy) = size, focal, center
    if equidistant:
        return PinholeEquidistant(
            width=width,
            height=height,
            fx=fx,
            fy=fy,
            cx=cx,
            cy=cy,
            k1=k[0],
            k2=k[1],
            k3=k[2],
            k4=k[3],
        )
    k1, k2, p1, p2, k3 = k + [0.0] * (5 - len(k))
    return PinholeRadtan(
        width=width, height=height, fx=fx, fy=fy, cx=cx, cy=cy, k1=k1, k2=k2, p1=p1, p2=p2, k3=k3
    )  # fmt: skip


def _check_full_frame(info: Mapping[str, Any], name: str, width: int, height: int) -> None:
    """Reject binning and a region of interest: the model would not describe the image."""
    for key in ("binning_x", "binning_y"):
        binning = info.get(key, 0)
        if binning not in (0, 1):
            raise CameraModelError(
                f"{name}.{key}: binning {short_repr(binning)} is not supported; use the "
                f"full-resolution CameraInfo and camera.scaled(1 / binning)"
            )
    roi = info.get("roi")
    if roi is None:
        return
    roi = _mapping(roi, f"{name}.roi", "RegionOfInterest fields")
    offsets = (roi.get("x_offset", 0), roi.get("y_offset", 0))
    size = (roi.get("width", 0), roi.get("height", 0))
    if offsets != (0, 0) or size not in ((0, 0), (width, height)):
        raise CameraModelError(
            f"{name}.roi: a region of interest ({offsets[0]}, {offsets[1]}, {size[0]}x{size[1]}) "
            f"is not supported; crop after undistorting, or use the full-frame CameraInfo"
        )


def from_camera_info(info: Mapping[str, Any], name: str = "camera_info") -> CameraModel:
    """Build a model from a ROS ``sensor_msgs/CameraInfo``-shaped mapping.

    Parameters
    ----------
    info : Mapping
        Keys ``width``, ``height``, ``distortion_model``, ``D`` and ``K`` (9 values, row-major);
        ROS 2's lower-case ``d`` and ``k`` are accepted too. ``R`` and ``P`` describe the
        *rectified* image and are not needed for the raw image the model describes; they are
        ignored. ``binning_x``/``binning_y`` must be 0 or 1 and ``roi`` full-frame if present.
    name : str
        Prefix of the field paths in messages (a topic name, for instance).

    Returns
    -------
    CameraModel
        :class:`PinholeRadtan` for ``plumb_bob`` (D = k1, k2, p1, p2[, k3]) or
        :class:`PinholeEquidistant` for ``equidistant`` (D = k1..k4).

    Raises
    ------
    CameraModelError
        On a missing field, an unsupported model (``rational_polynomial`` included), a wrong
        number of coefficients, an invalid camera matrix (zero, skewed, non-positive focal
        length), binning or a region of interest.
    """
    info = _mapping(info, name, "CameraInfo fields")
    width = _fields.positive_int(_fields.get(info, ("width",), name), f"{name}.width")
    height = _fields.positive_int(_fields.get(info, ("height",), name), f"{name}.height")
    model = _fields.get(info, ("distortion_model",), name)
    D = _fields.get(info, ("D", "d"), name)
    K = _fields.get(info, ("K", "k"), name)
    _check_full_frame(info, name, width, height)
    fx, fy, cx, cy = _fields.camera_matrix_values(K, f"{name}.K")
    if model in ("plumb_bob", "equidistant"):
        counts = (4, 5) if model == "plumb_bob" else (4,)
        k = _fields.float_list(D, f"{name}.D", counts, model)
        return _build(model == "equidistant", (width, height), (fx, fy), (cx, cy), k)
    if model == "rational_polynomial":
        raise CameraModelError(
            f"{name}.distortion_model: 'rational_polynomial' (8 coefficients, k4..k6 in a "
            f"denominator) is not supported; {_ROS_SUPPORTED}"
        )
    raise CameraModelError(
        f"{name}.distortion_model: unknown model {short_repr(model)}; {_ROS_SUPPORTED}"
    )


def from_kalibr(entry: Mapping[str, Any], name: str = "cam0") -> CameraModel:
    """Build a model from one camera entry of a Kalibr camchain yaml (already parsed).

    Parameters
    ----------
    entry : Mapping
        ``camera_model: pinhole``, ``intrinsics: [fu, fv, pu, pv]``,
        ``distortion_model: radtan | equidistant | none``, ``distortion_coeffs`` (4, 4, 0
        values) and ``resolution: [width, height]``. Other keys (``rostopic``, ``T_cn_cnm1``,
        ``cam_overlaps``, ...) are ignored.
    name : str
        The entry's key in the camchain (``cam0``), used as the prefix of field paths.

    Returns
    -------
    CameraModel
        :class:`PinholeRadtan` (``radtan``: k1, k2, r1, r2 = OpenCV's k1, k2, p1, p2; ``none``:
        no distortion) or :class:`PinholeEquidistant` (``equidistant``: k1..k4).

    Raises
    ------
    CameraModelError
        On a missing field, a projection other than pinhole (``omni``, ``ds``, ``eucm``), an
        unsupported distortion model (``fov``), a wrong number of values or a non-positive focal
        length or image size.
    """
    entry = _mapping(entry, name, "a Kalibr camera entry")
    camera_model = _fields.get(entry, ("camera_model",), name)
    if camera_model != "pinhole":
        raise CameraModelError(
            f"{name}.camera_model: {short_repr(camera_model)} is not supported (expected 'pinhole')"
        )
    where = f"{name}.intrinsics"
    fu, fv, pu, pv = _fields.float_list(
        _fields.get(entry, ("intrinsics",), name), where, (4,), "pinhole [fu, fv, pu, pv]"
    )
    size = _fields.float_list(
        _fields.get(entry, ("resolution",), name), f"{name}.resolution", (2,), "[width, height]"
    )
    width = _fields.positive_int(size[0], f"{name}.resolution[0] (width)")
    height = _fields.positive_int(size[1], f"{name}.resolution[1] (height)")
    fx = _fields.positive_float(fu, f"{where}[0] (fu)")
    fy = _fields.positive_float(fv, f"{where}[1] (fv)")
    model = _fields.get(entry, ("distortion_model",), name)
    if model not in ("radtan", "equidistant", "none"):
        raise CameraModelError(
            f"{name}.distortion_model: {short_repr(model)} is not supported; {_KALIBR_SUPPORTED}"
        )
    coeffs = entry.get("distortion_coeffs", []) if model == "none" else None
    if coeffs is None:
        coeffs = _fields.get(entry, ("distortion_coeffs",), name)
    count = 0 if model == "none" else 4
    k = _fields.float_list(coeffs, f"{name}.distortion_coeffs", (count,), model)
    return _build(model == "equidistant", (width, height), (fx, fy), (pu, pv), k)
