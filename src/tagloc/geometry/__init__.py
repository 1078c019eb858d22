"""Lie-group value types for poses: :class:`SO3`, :class:`SE3`, :class:`SE2` (pure numpy).

Conventions
-----------
These hold everywhere in tagloc (they are the contract of ``docs/CONVENTIONS.md``).

Frames in names
    ``T_a_b`` maps points from frame ``b`` into frame ``a``: ``points_a = T_a_b.act(points_b)``.
    Adjacent frames cancel: ``T_map_cam = T_map_base @ T_base_cam``; ``T_a_b.inverse()`` is
    ``T_b_a``; ``T_a_b.between(T_a_c)`` is ``T_b_c``. Rotations are ``R_a_b``.
Right perturbation
    ``X (+) tau = X @ Exp(tau)`` and ``Y (-) X = Log(X^-1 @ Y)``: tangent vectors and covariances
    live in the *body* (local, right) frame of the element, as in GTSAM and manif's default.
Tangent orders
    SO(3): ``[rx, ry, rz]`` (rotation vector, radians). SE(3): ``[x, y, z, rx, ry, rz]``
    (translation first, like ROS ``PoseWithCovariance``); every public 6x6 covariance uses this
    order. GTSAM orders rotation first: only the GTSAM bridge (and tests against GTSAM) permute.
    SE(2): ``[x, y, theta]``.
Quaternions
    ``quat_xyzw`` (ROS and scipy order), unit norm, returned with ``w >= 0``.
Euler angles
    Display and human-edited files only (:meth:`SO3.as_euler`, :meth:`SO3.from_euler`).
Jacobians
    Named ``J_out_in`` and returned by the same call as the value when asked
    (``T3, J_T3_T1, J_T3_T2 = T1.compose(T2, jacobians=True)``), manif style. ``J_out_in`` maps a
    right perturbation of the input to the right perturbation of the output:
    ``f(X (+) d) = f(X) (+) J_out_in d + o(|d|)``.
Batches
    A value holds one element or ``N`` (``SE3`` of ``(N, 3, 3)`` rotations and ``(N, 3)``
    translations). Binary operations broadcast single with batch; ``len``, indexing, iteration
    and :meth:`SE3.stack` work on batches. All batched operations are vectorized.
Immutability
    ``@dataclass(frozen=True, slots=True)`` with read-only arrays; every operation returns a new
    value. Equality is identity: compare values with ``allclose``.

The formulas follow J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in
robotics" (2018, arXiv:1812.01537), and T. Barfoot, "State Estimation for Robotics" (2017),
Ch. 7. Covariance transport is in :mod:`tagloc.geometry.covariance`, the right Jacobians of
``Exp`` in :mod:`tagloc.geometry.jacobians`, the helpers on raw ``(N, 4, 4)`` stacks (``hat``,
``inverse_h``, ``adjoint_h``, ``log_h``) in :mod:`tagloc.geometry.matrices`.
"""

from tagloc.geometry.covariance import (
    cov_between,
    cov_compose,
    cov_inverse,
    cov_left_to_right,
    cov_right_to_left,
)
from tagloc.geometry.jacobians import (
    se2_right_jacobian,
    se2_right_jacobian_inv,
    se3_right_jacobian,
    se3_right_jacobian_inv,
    so3_right_jacobian,
    so3_right_jacobian_inv,
)
from tagloc.geometry.matrices import adjoint_h, hat, inverse_h, log_h, vee
from tagloc.geometry.se2 import SE2
from tagloc.geometry.se3 import SE3
from tagloc.geometry.so3 import SO3

__all__ = [
    "SE2",
    "SE3",
    "SO3",
    "adjoint_h",
    "cov_between",
    "cov_compose",
    "cov_inverse",
    "cov_left_to_right",
    "cov_right_to_left",
    "hat",
    "inverse_h",
    "log_h",
    "se2_right_jacobian",
    "se2_right_jacobian_inv",
    "se3_right_jacobian",
    "se3_right_jacobian_inv",
    "so3_right_jacobian",
    "so3_right_jacobian_inv",
    "vee",
]
