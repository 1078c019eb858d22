"""The fix sources the node builds: an explicit registry, name -> factory, in build order.

``factory(config, inputs)`` returns the source, or None when the configuration or the inputs
leave it out (the lidar without a premap or with ``lidar.enabled: false``). A new kind of fix
(an AMCL pose, visual odometry) is a class that satisfies
:class:`~tagloc.localize.sources.FixSource` and one :func:`register_fix_source` call.
"""

from __future__ import annotations

from collections.abc import Callable

from tagloc.localize.config import LocalizerConfig
from tagloc.localize.fix import LocalizeError
from tagloc.localize.source_lidar import LIDAR, LidarSource
from tagloc.localize.source_tags import MARKERS, TagSource
from tagloc.localize.sources import FixSource, SourceInputs

__all__ = [
    "FixSourceFactory",
    "available_fix_sources",
    "build_fix_sources",
    "register_fix_source",
    "unregister_fix_source",
]

#: ``factory(config, inputs) -> FixSource | None``.
FixSourceFactory = Callable[[LocalizerConfig, SourceInputs], FixSource | None]


def _tags(config: LocalizerConfig, inputs: SourceInputs) -> FixSource:
    return TagSource(config, inputs)


def _lidar(config: LocalizerConfig, inputs: SourceInputs) -> FixSource | None:
    if not config.lidar.enabled or inputs.premap is None:
        return None
    return LidarSource(config, inputs)


_REGISTRY: dict[str, FixSourceFactory] = {MARKERS: _tags, LIDAR: _lidar}


def register_fix_source(name: str, factory: FixSourceFactory, *, replace: bool = False) -> None:
    """Add a fix source (built after those registered before it).

    Raises
    ------
    LocalizeError
        If ``name`` is taken and ``replace`` is false.
    """
    if name in _REGISTRY and not replace:
        raise LocalizeError(f"fix source {name!r} is already registered")
    _REGISTRY[name] = factory


def unregister_fix_source(name: str) -> None:
    """Remove a fix source from the registry (nodes built later do without it).

    Raises
    ------
    LocalizeError
        If ``name`` is not registered.
    """
    if _REGISTRY.pop(name, None) is None:
        raise LocalizeError(f"fix source {name!r} is not registered")


def available_fix_sources() -> tuple[str, ...]:
    """Registered fix source names, in build order."""
    return tuple(_REGISTRY)


def build_fix_sources(config: LocalizerConfig, inputs: SourceInputs) -> tuple[FixSource, ...]:
    """Every registered source the configuration and inputs call for, in registry order."""
    built = (factory(config, inputs) for factory in _REGISTRY.values())
    return tuple(source for source in built if source is not None)
