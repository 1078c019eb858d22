"""The dimos adapter's tests, against the real dimos 0.0.15 (``make test-dimos``; never collected
by ``make test``: they live outside ``tests/`` and need the ``.venv-dimos`` virtualenv).

dimos reads its transport settings at import: this file sets them first. Streams between modules
of one process run over LCM's in-memory provider (``memq://``, no sockets); the RPC of modules and
the worker processes of :class:`ModuleCoordinator` need a real bus, LCM over UDP multicast on a
port of this run's own, so that other runs on the machine are not heard.
"""

from __future__ import annotations

import os
import random

_PORT = random.Random(os.getpid()).randrange(20000, 40000)
os.environ["DIMOS_TRANSPORT"] = "lcm"
os.environ["LCM_DEFAULT_URL"] = f"udpm://239.255.76.67:{_PORT}?ttl=0"
os.environ.setdefault("MPLBACKEND", "Agg")
