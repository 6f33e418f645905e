"""SIGINT, SIGTERM and SIGHUP at any moment of a command: it ends with 128 + the signal and one line.

While a command runs (:func:`catching`), a signal raises :class:`Interrupted`, a :class:`KeyboardInterrupt`,
so that every cleanup runs as for Ctrl-C (temporary files, worker processes, a batch's record). Not while a
module is being imported: an exception raised there may be swallowed (usd-core's module set-up prints it as
a warning and goes on, and the command finished with exit 0) or leave a module half made. There the signal is
noted and raised as soon as no import is running (checked every 10 ms with SIGALRM).

Every signal is noted in :data:`received`, so one that something swallowed anyway still decides the exit code
(:func:`ending`). The ``keyfill`` program notes signals from the moment its command module is imported
(:func:`catch_early`, before click and the rest load); a signal before that, while Python itself starts, kills
it as the signal does (a shell reports 128 + the signal; nothing has been written by then).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: how often a signal noted during an import is retried, in seconds
RETRY_S = 0.01

#: the signals received during this command, in order (the first decides the exit code)
received: list[int] = []
#: whether a signal raises now (in :func:`catching`, before :func:`ending`); otherwise it is only noted
_raising = False


class Interrupted(KeyboardInterrupt):
    """The signal ``signum`` (SIGINT, SIGTERM or SIGHUP), raised like Ctrl-C. ``detail``, set by whoever knows
    it, completes the error line (a batch: how many of its files were done)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum
        self.detail: str | None = None


def _importing(frame) -> bool:
    while frame is not None:
        if frame.f_globals.get("__name__", "").startswith("importlib._bootstrap"):
            return True
        frame = frame.f_back
    return False


def _on_signal(signum, frame) -> None:
    received.append(signum)
    _raise_unless_importing(frame)


def _retry(signum, frame) -> None:
    _raise_unless_importing(frame)


def _raise_unless_importing(frame) -> None:
    if not _raising or not received:
        return
    if _importing(frame):
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)
        return
    raise Interrupted(received[0])


def _is_program() -> bool:
    """Whether this process is the ``keyfill`` program (its script, or ``python -m keyfill``)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    return getattr(spec, "name", None) == "keyfill.__main__" or os.path.basename(sys.argv[0]) == "keyfill"


def catch_early() -> None:
    """In the ``keyfill`` program, note the signals from now on (they are raised once the command runs); in
    any other process (a test, a library user's program) do nothing."""
    if _is_program() and threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, _on_signal)


@contextlib.contextmanager
def catching() -> Iterator[None]:
    """Signals raise :class:`Interrupted` inside the block (main thread only; one noted before it is raised by
    :func:`check`). The handlers before it, and an empty :data:`received`, are back after it."""
    global _raising
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {sig: signal.signal(sig, _on_signal) for sig in SIGNALS}
    old_alarm = signal.signal(signal.SIGALRM, _retry)
    _raising = True
    try:
        yield
    finally:
        _raising = False
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old_alarm)
        for sig, handler in old.items():
            signal.signal(sig, handler)
        received.clear()


def check() -> None:
    """Raise :class:`Interrupted` for the first signal received, if one was (while the program started)."""
    if received:
        raise Interrupted(received[0])


def ending() -> int | None:
    """The command has decided how it ends: from now on signals are only noted. Returns the first signal
    received during it (one that was swallowed, or came after its work), or None."""
    global _raising
    _raising = False
    signal.setitimer(signal.ITIMER_REAL, 0)
    return received[0] if received else None
