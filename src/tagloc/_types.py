"""Array type aliases, defined once for every module of tagloc."""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
import numpy.typing as npt

#: A float64 array of any shape (shapes and frames are in each docstring).
FloatArray: TypeAlias = npt.NDArray[np.float64]

__all__ = ["FloatArray"]
