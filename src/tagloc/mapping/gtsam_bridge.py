"""The one place where tagloc values meet GTSAM's (rotation-first tangent order).

tagloc orders SE(3) tangents and covariances ``[x, y, z, rx, ry, rz]``; GTSAM's ``Pose3`` orders
them ``[rx, ry, rz, x, y, z]``. Both perturb on the right (``T (+) d = T @ Exp(d)``), so a
covariance only needs the block permutation :data:`PERM`.

GTSAM reports an unsolvable graph with a ``RuntimeError`` (``IndeterminateSystemException`` and
its kin); :func:`solver_errors` turns it into a one-line :class:`SolverError` (a
``MappingError``) where tagloc calls a solver.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator, Sequence

import gtsam
import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3
from tagloc.mapping.survey import MappingError

#: ``v_gtsam = v_tagloc[PERM]`` and ``C_gtsam = C_tagloc[PERM][:, PERM]``; the permutation is
#: its own inverse.
PERM = np.array([3, 4, 5, 0, 1, 2])


def to_pose3(T: SE3) -> gtsam.Pose3:
    """A single :class:`SE3` as a ``gtsam.Pose3``."""
    return gtsam.Pose3(gtsam.Rot3(np.asarray(T.rotation.as_matrix())), np.asarray(T.translation))


def from_pose3(pose: gtsam.Pose3) -> SE3:
    """A ``gtsam.Pose3`` as a single :class:`SE3`."""
    return SE3.from_matrix(pose.matrix(), normalize=True)


def cov_to_gtsam(cov: npt.ArrayLike) -> FloatArray:
    """``(6, 6)`` covariance ``[x, y, z, rx, ry, rz]`` to GTSAM's ``[rx, ry, rz, x, y, z]``."""
    c = np.asarray(cov, dtype=np.float64)
    return np.ascontiguousarray(c[PERM][:, PERM])


cov_from_gtsam = cov_to_gtsam  # the permutation is an involution


def diagonal_sigmas(sigmas: npt.ArrayLike) -> gtsam.noiseModel.Base:
    """A GTSAM diagonal noise model from tagloc-ordered ``(6,)`` standard deviations."""
    s = np.asarray(sigmas, dtype=np.float64)
    return gtsam.noiseModel.Diagonal.Sigmas(np.ascontiguousarray(s[PERM]))


#: What each GTSAM key letter stands for in tagloc's graphs.
_VARIABLES = {"x": "keyframe", "l": "tag", "c": "odometry calibration"}
_SYMBOL = re.compile(r"Symbol: ([a-z])(\d+)")


class SolverError(MappingError):
    """GTSAM could not solve a graph (under-constrained or too poorly conditioned).

    Attributes
    ----------
    what : str
        The graph, e.g. ``"the survey graph"``.
    detail : str
        GTSAM's first words, for a failure other than an indeterminate system.
    variable : (str, int) or None
        Key letter and index of the variable GTSAM names (``("l", 15)``: tag index 15).
    """

    def __init__(
        self,
        what: str,
        detail: str = "",
        variable: tuple[str, int] | None = None,
        tag_names: Sequence[str] = (),
    ) -> None:
        self.what, self.detail, self.variable = what, detail, variable
        near = ""
        if variable is not None:
            letter, index = variable
            named = letter == "l" and 0 <= index < len(tag_names)
            kind = _VARIABLES.get(letter, "variable")
            near = f" near tag {tag_names[index]}" if named else f" near {kind} {index}"
        reason = detail or (
            f"the system is under-constrained or too poorly conditioned{near}; check the camera "
            "extrinsics (--camera-poses), the anchors and that every tag is seen from more than "
            "one place"
        )
        super().__init__(f"cannot solve {what}: {reason}")

    def naming(self, tag_names: Sequence[str]) -> SolverError:
        """The same error naming the tag by ``tag_names[index]`` instead of its index."""
        return SolverError(self.what, self.detail, self.variable, tag_names)


@contextlib.contextmanager
def solver_errors(what: str) -> Iterator[None]:
    """Turn a GTSAM solver failure inside the block into one line naming the variable at fault.

    Raises
    ------
    SolverError
        ``"cannot solve <what>: ..."``, for an under-constrained or ill-conditioned graph.
    """
    try:
        yield
    except RuntimeError as exc:
        text = " ".join(str(exc).split())
        if "ndeterminate" not in text:
            raise SolverError(what, text[:200] or exc.__class__.__name__) from None
        found = _SYMBOL.search(text)
        raise SolverError(what, variable=(found[1], int(found[2])) if found else None) from None
