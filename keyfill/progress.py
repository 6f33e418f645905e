"""Progress of long reads and writes, reported to whoever listens.

The library never draws progress bars itself (it is used from scripts and
tests); it reports through :func:`task`, and the CLI installs a listener
(:func:`listen`) that draws a tqdm bar on a terminal once a task has run for
about two seconds. Without a listener :func:`task` costs nothing.
"""

from __future__ import annotations

import contextlib
from typing import Callable, Iterator

#: ``factory(description, total, unit)`` -> an object with ``update(n)`` and ``close()``
_factory: Callable | None = None


def listen(factory: Callable | None) -> None:
    """Install (or with None remove) the progress listener."""
    global _factory
    _factory = factory


def _nothing(n: int = 1) -> None:
    pass


@contextlib.contextmanager
def task(description: str, total: int, unit: str = "") -> Iterator[Callable[[int], None]]:
    """Yield ``update(n)``: call it as ``n`` of ``total`` units are done."""
    if _factory is None or total <= 0:
        yield _nothing
        return
    bar = _factory(description, total, unit)
    try:
        yield bar.update
    finally:
        bar.close()
