"""tagloc inside dimos (``pip install 'tagloc[dimos]'``; written against dimos 0.0.15).

- :class:`~tagloc.adapters.dimos.module.TaglocRelocalization`: dimos's relocalization module
  driven by tagloc's streaming node (camera, TF odometry, optional lidar in; ``world -> map``,
  pose with covariance and status out).
- :mod:`tagloc.adapters.dimos.blueprints`: ``tagloc-go2``, ``tagloc-go2-lidar`` and
  ``tagloc-desk``, registered for ``dimos run`` through the ``dimos.blueprints`` entry points.
- :mod:`tagloc.adapters.dimos.convert`: dimos messages <-> tagloc's stream records.

Premaps need no dimos: :mod:`tagloc.io.dimos_premap` reads and writes ``.pc2.lcm``. Importing this
package imports nothing of dimos; its modules do (docs/dimos.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tagloc.adapters.dimos.module import TaglocConfig, TaglocRelocalization

__all__ = ["TaglocConfig", "TaglocRelocalization"]


def __getattr__(name: str) -> Any:
    """The module's classes, imported (with dimos) on first use."""
    if name in __all__:
        from tagloc.adapters.dimos import module

        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
