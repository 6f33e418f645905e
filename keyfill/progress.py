"""Progress of long reads and writes, and notes about the work, reported to whoever listens.

The library never draws progress bars itself (it is used from scripts and
tests); it reports through :func:`task`, and the CLI installs a listener
(:func:`listen`) that draws a tqdm bar on a terminal once a task has run for
about two seconds. Without a listener :func:`task` costs nothing. Notes
(:func:`note`, e.g. "reading the first of 2 skins") go to the listener of
:func:`listen_notes`; the CLI prints them as ``keyfill: note: ...`` lines.

Where no bar can be drawn (stderr is not a terminal: a log file, CI, a pipe), work that runs for minutes
tells its progress as lines instead, through a :class:`Ticker` (the training loop does).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from typing import Self

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


def duration(seconds: float) -> str:
    """``seconds`` for a person: ``"42 s"``, ``"3 min 05 s"``, ``"2 h 07 min"``."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Ticker:
    """Progress told as lines: every ``every`` seconds, ``say`` gets one line with the work's latest state, how
    long it has run and about how long is left.

    The work calls :meth:`set` as it goes; the lines come from a background thread, so a long step (or a
    validation) does not hold them back. Use it as a context manager: the thread runs inside the block and is
    stopped (and joined) when the block ends, however it ends.

    Args:
        say: called with each line (from the ticker's thread).
        every: seconds between lines.
    """

    def __init__(self, say: Callable[[str], None], every: float = 20.0):
        self.say = say
        self.every = every
        self._state: tuple[float, str] = (0.0, "starting")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="keyfill-ticker", daemon=True)
        self._t0 = time.monotonic()

    def set(self, done: float, text: str) -> None:
        """The work's state: ``done`` the fraction finished (0 to 1), ``text`` what it is doing now."""
        self._state = (min(max(done, 0.0), 1.0), text)

    def line(self) -> str:
        """The line for now: the state's text, the time so far and, once some work is done, the time left."""
        done, text = self._state
        elapsed = time.monotonic() - self._t0
        left = f"about {duration(elapsed * (1 - done) / done)} left" if done > 0 else "time left not known yet"
        return f"{text}; {duration(elapsed)} so far, {left}"

    def _run(self) -> None:
        while not self._stop.wait(self.every):
            self.say(self.line())

    def __enter__(self) -> Self:
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
