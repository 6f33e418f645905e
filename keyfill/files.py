"""Files that appear whole or not at all, and a quiet stderr for chatty C libraries.

:func:`atomic_output` is the one way keyfill writes an output file: motion
files, model checkpoints, pictures, dataset records. It lives here, beside the
core types, so that every package can use it without importing another one.
:func:`quiet_stderr` silences what C and C++ libraries (pxr, pybullet) print
straight to file descriptor 2, where Python's ``sys.stderr`` cannot catch it.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Iterator

from keyfill.errors import UsageError


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    The temporary file keeps ``path``'s suffix (writers such as USD pick their
    format from it). On any error it is removed, so no partial output remains.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise UsageError(f"{path}: the output folder {str(folder)!r} does not exist")
    if path.is_dir():
        raise UsageError(f"{path}: is a folder, not a file")
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}", dir=folder)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Send writes to file descriptor 2 (C-level stderr) to the null device inside the block."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)

