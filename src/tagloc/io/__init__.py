"""Reading and writing files and messages; the only layer that touches the file system.

- :mod:`tagloc.io.kalibr`: Kalibr camchain yaml -> camera models (:func:`load_kalibr_cameras`).
"""

from tagloc.io.kalibr import load_kalibr_cameras

__all__ = ["load_kalibr_cameras"]
