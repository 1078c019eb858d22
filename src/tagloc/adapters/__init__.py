"""Optional integrations, each in its own module and imported only when used.

- :mod:`tagloc.adapters.rerun`: the live view, a sink of the node's outputs (extra ``view``).
- :mod:`tagloc.adapters.ray`: an evaluation engine on a Ray cluster (extra ``fleet``).
- :mod:`tagloc.adapters.dimos`: a dimos relocalization module driven by tagloc's node, and the
  Go2 and desk blueprints (extras ``dimos``, ``dimos-go2``; its tests run with
  ``make test-dimos``).

Nothing here is imported by ``import tagloc``; a default install never needs the extras.
"""

from tagloc.errors import TaglocError

__all__ = ["AdapterError", "missing_extra"]


class AdapterError(TaglocError):
    """An optional integration that cannot be used (not installed, not reachable)."""


def missing_extra(package: str, extra: str) -> AdapterError:
    """The one-line error for an optional package that is not installed."""
    return AdapterError(
        f"{package} is not installed: pip install 'tagloc[{extra}]' (or pip install {package})"
    )
