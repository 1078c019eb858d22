"""Shared helpers for the geometry tests: GTSAM bridges, hypothesis strategies, settings.

GTSAM orders SE(3) tangents rotation first (``[rx, ry, rz, x, y, z]``); tagloc orders translation
first. ``P`` maps tagloc to GTSAM order: ``xi_gtsam = P @ xi_tagloc``, and
``Ad_tagloc = P.T Ad_gtsam P``.
"""

from __future__ import annotations

import gtsam
import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from tagloc.geometry import SE2, SE3, SO3

#: Deterministic hypothesis settings used by every property test here.
PROPERTY_SETTINGS = settings(
    derandomize=True,
    database=None,
    deadline=None,
    max_examples=60,
    suppress_health_check=[HealthCheck.too_slow],
)

P = np.zeros((6, 6))
P[:3, 3:] = np.eye(3)
P[3:, :3] = np.eye(3)

SEED = 20240611


def to_gtsam(T: SE3) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3(T.rotation.as_matrix()), T.translation.copy())


def to_gtsam_tangent(xi: np.ndarray) -> np.ndarray:
    return P @ xi


def from_gtsam_tangent(xi: np.ndarray) -> np.ndarray:
    return P.T @ xi


def from_gtsam_matrix6(matrix: np.ndarray) -> np.ndarray:
    return P.T @ matrix @ P


def rotvec_with_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    return axis / np.linalg.norm(axis) * angle


# ----- hypothesis strategies -------------------------------------------------------------------
_unit = st.floats(-1.0, 1.0, allow_nan=False)
_axes = st.tuples(_unit, _unit, _unit).filter(lambda v: float(np.linalg.norm(v)) > 0.1)
#: Rotation angles in [0, pi), with the hard regions (near 0, near pi) drawn often.
angles = st.one_of(
    st.floats(0.0, 1e-6),
    st.floats(0.0, np.pi - 1e-6),
    st.floats(np.pi - 1e-5, np.pi - 1e-7),
    st.sampled_from([0.0, 1e-9, 1e-3, np.pi / 2, np.pi - 1e-6]),
)
coords = st.floats(-10.0, 10.0, allow_nan=False)


@st.composite
def rotvecs(draw: st.DrawFn) -> np.ndarray:
    axis = np.array(draw(_axes))
    return rotvec_with_angle(axis, draw(angles))


@st.composite
def se3_tangents(draw: st.DrawFn) -> np.ndarray:
    rho = np.array(draw(st.tuples(coords, coords, coords)))
    return np.concatenate([rho, draw(rotvecs())])


@st.composite
def rotations(draw: st.DrawFn) -> SO3:
    return SO3.exp(draw(rotvecs()))


@st.composite
def poses(draw: st.DrawFn) -> SE3:
    return SE3.exp(draw(se3_tangents()))


@st.composite
def poses_2d(draw: st.DrawFn) -> SE2:
    return SE2(draw(coords), draw(coords), draw(st.floats(-4.0, 4.0)))
