"""Progress of long reads and writes, and notes about the work, reported to whoever listens.

The library never draws progress bars itself (it is used from scripts and
tests); it reports through :func:`task`, and the CLI installs a listener
(:func:`listen`) that draws a tqdm bar on a terminal once a task has run for
about two seconds. Without a listener :func:`task` costs nothing. Notes
(:func:`note`, e.g. "reading the first of 2 skins") go to the listener of
:func:`listen_notes`; the CLI prints them as ``keyfill: note: ...`` lines.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator

#: ``factory(description, total, unit)`` -> an object with ``update(n)`` and ``close()``
_factory: Callable | None = None
#: ``callback(message)`` for one-line notes to a person
_notes: Callable[[str], None] | None = None


def listen(factory: Callable | None) -> None:
    """Install (or with None remove) the progress listener."""
    global _factory
    _factory = factory


def listen_notes(callback: Callable[[str], None] | None) -> None:
    """Install (or with None remove) the listener of :func:`note`."""
    global _notes
    _notes = callback


def note(message: str) -> None:
    """Tell a person one line about the work (e.g. that a file's first of two skins was read); the CLI prints
    it on stderr, and without a listener it is dropped."""
    if _notes is not None:
        _notes(message)


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
