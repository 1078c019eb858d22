"""An evaluation engine on an existing Ray cluster (``pip install 'tagloc[fleet]'``).

:class:`RayEngine` is an :class:`~tagloc.eval.engine.Engine`: each item becomes one Ray task of
one CPU, results come back in the items' order. The cluster's workers must have the same tagloc
installed and see the logs at the same paths (a shared file system).

The address is checked before anything runs: a ``host:port`` (or ``ray://host:port``) that does
not accept a connection within a few seconds is one :class:`~tagloc.adapters.AdapterError` line,
without waiting for Ray's own retries.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from tagloc.adapters import AdapterError, missing_extra
from tagloc.errors import TaglocError
from tagloc.eval.engine import Progress

__all__ = ["RayEngine", "check_reachable"]

logger = logging.getLogger(__name__)
T = TypeVar("T")
R = TypeVar("R")


def check_reachable(address: str, timeout_s: float = 3.0) -> None:
    """Raise :class:`AdapterError` unless ``address`` (``host:port``, ``ray://host:port`` or
    ``auto``) accepts a TCP connection within ``timeout_s``."""
    if address == "auto":
        return
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise AdapterError(f"--ray {address}: expected host:port (or ray://host:port, or auto)")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as exc:
        raise AdapterError(f"--ray {address}: no Ray cluster reachable there ({exc})") from None


class RayEngine:
    """Runs items as Ray tasks on the cluster at ``address`` (module docstring).

    Parameters
    ----------
    address : str
        The cluster's GCS ``host:port``, ``ray://host:port`` (Ray client) or ``auto``.

    Raises
    ------
    AdapterError
        If ray is not installed or the cluster is not reachable.
    """

    def __init__(self, address: str) -> None:
        try:
            import ray
        except ImportError:
            raise missing_extra("ray", "fleet") from None
        check_reachable(address)
        self._ray: Any = ray
        try:
            ray.init(address=address, ignore_reinit_error=True, log_to_driver=False,
                     logging_level=logging.WARNING, configure_logging=False)  # fmt: skip
        except (ConnectionError, RuntimeError) as exc:
            raise AdapterError(f"--ray {address}: {str(exc).splitlines()[0]}") from None
        self.jobs = max(1, int(self._ray.cluster_resources().get("CPU", 1)))
        logger.info("ray cluster at %s: %d CPUs", address, self.jobs)

    def map(
        self, fn: Callable[[T], R], items: Sequence[T], progress: Progress | None = None
    ) -> list[R]:
        ray = self._ray
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        refs = [remote.remote(item) for item in items]
        pending = list(refs)
        try:
            while pending:
                _, pending = ray.wait(pending, num_returns=1)
                if progress is not None:
                    progress(len(refs) - len(pending), len(refs))
            return list(ray.get(refs))
        except ray.exceptions.RayTaskError as exc:
            for ref in pending:
                ray.cancel(ref)
            cause = getattr(exc, "cause", None)
            if isinstance(cause, TaglocError):
                raise cause from None
            raise

    def close(self) -> None:
        """Disconnect from the cluster (the cluster keeps running)."""
        self._ray.shutdown()
