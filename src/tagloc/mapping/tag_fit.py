"""One tag's pose fitted to its corners with the keyframes held: the tilt test's local solver.

Minimizes the robust negative log-likelihood of the tag's corner observations,

.. math:: \\mathrm{NLL}(T) = \\sum_{m,i} \\tfrac{k^2}{2}\\,\\ln\\!\\left(1 + \\frac{\\lVert
   (\\pi_m(T_{cam_m,map}\\, T\\, p_i) - z_{m,i}) / \\sigma \\rVert^2}{k^2}\\right)

over ``T = T_map_tag`` (Cauchy kernel of width ``k`` sigmas on each corner's 2-D residual; for
small residuals the term is the Gaussian ``r^2 / 2``), by Levenberg-Marquardt on iteratively
reweighted normal equations, with a right perturbation ``T @ Exp(xi)``, ``xi = [x, y, z, rx, ry,
rz]``. Costs of two fits are comparable: their difference is a log-likelihood ratio.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.mapping.corner_graph import (
    corner_squares,
    kernel_cost,
    kernel_weights,
    linearize_corners,
)
from tagloc.mapping.observations import Observations

IntArray = npt.NDArray[np.int64]
#: Width of the Cauchy kernel on a corner's whitened 2-D residual (sigmas).
KERNEL_K = 3.0


def _nll(r: FloatArray) -> float:
    """The module docstring's NLL of corner residuals ``r (n, 4, 2)`` (no cap)."""
    return float(np.sum(kernel_cost(corner_squares(r), "cauchy", KERNEL_K)))


@dataclass(frozen=True, slots=True)
class HeldViews:
    """One tag's observations ``idx`` (``(n,)`` int) of ``obs``, from the keyframes
    ``M_map_base`` (``(K, 4, 4)``, held fixed), through the camera models and extrinsics by name,
    with corner noise ``sigma_px`` (pixels per axis)."""

    obs: Observations
    idx: IntArray
    M_map_base: FloatArray
    cameras: Mapping[str, CameraModel]
    T_base_cam: Mapping[str, SE3]
    sigma_px: float

    def linearize(self, M_map_tag: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Whitened corner residuals and Jacobians at the tag pose ``M_map_tag`` (``(4, 4)``)."""
        tags = np.broadcast_to(M_map_tag, (len(self.idx), 4, 4))
        r, J, _ = linearize_corners(self.obs, self.idx, self.M_map_base, tags, self.cameras,
                                    self.T_base_cam, self.sigma_px)  # fmt: skip
        return r, J


def fit_tag_pose(
    views: HeldViews, M_map_tag: FloatArray, max_iterations: int = 20
) -> tuple[FloatArray, float]:
    """Fit ``T_map_tag`` of one tag to the corners of its ``views``, from the starting pose
    ``M_map_tag`` (``(4, 4)``) (module docstring).

    Returns
    -------
    (M_map_tag, nll) : ((4, 4) float, float)
        The local optimum reached from the start and its robust negative log-likelihood.
    """
    linearize = views.linearize
    M = np.array(M_map_tag, dtype=np.float64)
    r, J = linearize(M)
    cost, lam = _nll(r), 1e-3
    for _ in range(max_iterations):
        weight = kernel_weights(np.sum(r**2, axis=2), "cauchy", KERNEL_K)  # (n, 4)
        H = np.einsum("mn,mnai,mnaj->ij", weight, J, J)
        g = np.einsum("mn,mnai,mna->i", weight, J, np.nan_to_num(r))
        improved = False
        while lam < 1e8:
            xi = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
            M_new = M @ SE3.exp(xi).as_matrix()
            r_new, J_new = linearize(M_new)
            cost_new = _nll(r_new)
            if cost_new <= cost:
                improved = cost - cost_new > 1e-7 * max(cost, 1.0)
                M, r, J, cost = M_new, r_new, J_new, cost_new
                lam = max(0.1 * lam, 1e-9)
                break
            lam *= 10.0
        if not improved:
            break
    return M, cost
