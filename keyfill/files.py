"""Files that appear whole or not at all, a quiet stderr for chatty C libraries, and JSON settings files.

:func:`atomic_output` is the one way keyfill writes an output file: motion
files, model checkpoints, pictures, dataset records. It lives here, beside the
core types, so that every package can use it without importing another one.
:func:`quiet_stderr` silences what C and C++ libraries (pxr, pybullet) print
straight to file descriptor 2, where Python's ``sys.stderr`` cannot catch it.
:func:`read_json_object` reads a user's settings file (``--config``) with
one-line errors, :func:`read_arrays` a training set of arrays (``.npz``) without pickles. :func:`sha256_file` and :func:`verified` check files against their
recorded SHA-256 (model weights, library arrays) without hashing an unchanged
file again; the marks of what was verified live under :func:`cache_dir`.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import signal
import stat
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from keyfill.errors import FormatError, KeyfillError, OutputError, UsageError

#: temporary files are ``.<stem>.k<pid>.<random>.part<suffix>``; a USD export adds its own
#: ``.<stem>.k<pid>.<random>.part.XXXXXX`` beside it. The pid tells a live writer from a dead one.
_PART = re.compile(r"\.(?P<stem>.*)\.k(?P<pid>[0-9]+)\.[A-Za-z0-9_]+\.part(?:\..*)?")
#: names of keyfill before the pid was part of them: ``.<stem>.<8 random>.part<suffix>``
_LEGACY_PART = re.compile(r"\.(?P<stem>.*)\.[a-z0-9_]{8}\.part(?:\..*)?")
#: a temporary file of the old naming is taken as abandoned after this many seconds
LEGACY_STALE_S = 3600.0
#: how USD's C++ writer reports an OS error (a full disk, a file-size limit) in the Tf.ErrorException it raises
_WRITER_FAILED = re.compile(r"Error occurred writing file: ([^'\n]+)")


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def remove_stale(folder: str | os.PathLike, stem: str | None = None) -> list[Path]:
    """Remove temporary files that killed keyfill runs left in ``folder`` (of output ``stem``, or all).

    A temporary file is stale when the process that made it no longer exists
    (its pid is in the name), or, for names without a pid, when it is older
    than :data:`LEGACY_STALE_S`. Returns the files removed.
    """
    import time

    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        name = entry.name
        if not name.startswith(".") or ".part" not in name:
            continue
        m = _PART.fullmatch(name)
        if m is not None:
            stale = not _alive(int(m.group("pid")))
        else:
            m = _LEGACY_PART.fullmatch(name)
            try:
                stale = m is not None and now - entry.stat(follow_symlinks=False).st_mtime > LEGACY_STALE_S
            except OSError:
                stale = False
        if not stale or (stem is not None and m.group("stem") != stem):
            continue
        try:
            if entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    The temporary file keeps ``path``'s suffix (writers such as USD pick their
    format from it). On any error it is removed, so no partial output remains;
    temporary files of ``path`` left by a killed run are removed first (see
    :func:`remove_stale`). An :class:`OSError` of the writing (a read-only
    folder, a full disk, a file-size limit) becomes an :class:`OutputError`
    naming ``path``, not the temporary file, and so does the error USD's writer
    raises for one (its text holds the OS's reason).
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        try:
            mode = os.stat(path).st_mode
        except FileNotFoundError:  # no file yet (or a link to none, which the output replaces)
            mode = None
        folder_ok = folder.is_dir()
    except OSError as e:  # a name the file system cannot hold (too long), a loop of links
        raise OutputError(path, e.strerror or str(e)) from None
    if not folder_ok:
        raise UsageError(f"{path}: the output folder {str(folder)!r} does not exist")
    if mode is not None and stat.S_ISDIR(mode):
        raise UsageError(f"{path}: is a folder, not a file")
    if mode is not None and not stat.S_ISREG(mode):  # renaming onto it would replace the device (/dev/null)
        raise UsageError(f"{path}: is a device or pipe, not a file; write to '-' for standard output")
    remove_stale(folder, path.stem)
    prefix = f".{path.stem}.k{os.getpid()}."
    try:  # from before the temporary file exists: an interrupt at any moment finds it below
        try:
            fd, name = tempfile.mkstemp(prefix=prefix, suffix=f".part{path.suffix}", dir=folder)
        except OSError as e:
            raise OutputError(path, e.strerror or str(e)) from None
        os.close(fd)
        tmp = Path(name)
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException as e:
        for extra in folder.glob(glob.escape(prefix) + "*.part*"):
            extra.unlink(missing_ok=True)  # this one's temporary file, and a USD export's own beside it
        if isinstance(e, OSError) and not isinstance(e, BrokenPipeError):
            raise OutputError(path, e.strerror or str(e)) from None
        failed = _WRITER_FAILED.search(str(e)) if not isinstance(e, KeyfillError) else None
        if failed is not None:
            raise OutputError(path, failed.group(1)) from None
        raise


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP that arrive inside the block (a clean-up that must not be cut short) are
    delivered, the first of them, when it ends; in the main thread only (elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    signals = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    old = {sig: signal.signal(sig, lambda signum, frame: caught.append(signum)) for sig in signals}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        if caught:
            signal.raise_signal(caught[0])


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


def read_regular(path: str | os.PathLike, limit: int, what: str) -> bytes:
    """The bytes of ``path``, a regular file of at most ``limit`` bytes (``what`` names it in errors: "the rig
    map"); a :class:`FormatError` naming the file for a device (``/dev/zero`` would fill the memory), a pipe,
    a folder, a longer file or one that cannot be read. The file is opened without blocking (a FIFO without
    a writer does not hang) and checked by its open descriptor."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise FormatError(f"{what} must be a regular file, not a device, pipe or folder", path)
            data = f.read(limit + 1)
    except OSError as e:
        raise FormatError(f"cannot read {what}: {e.strerror or e}", path) from None
    if len(data) > limit:
        raise FormatError(f"{what} is longer than {limit:,} bytes", path)
    return data


def read_json_object(path: str | os.PathLike) -> dict:
    """The JSON object in the settings file ``path``; a :class:`UsageError` of one line (with the line
    number for bad JSON) when it cannot be read, is not JSON or is not an object."""
    from keyfill import limits

    try:  # a regular file of bounded size: never /dev/zero or a FIFO
        data = json.loads(read_regular(path, limits.MAX_SETTINGS_BYTES, "the config").decode("utf-8"))
    except FormatError as e:
        raise UsageError(str(e)) from None
    except json.JSONDecodeError as e:
        raise UsageError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None
    except UnicodeDecodeError as e:
        raise UsageError(f"{path}: not valid JSON ({e.reason})") from None
    if not isinstance(data, dict):
        raise UsageError(f"{path}: the config must be a JSON object")
    return data


def read_arrays(path: str | os.PathLike, what: str, kind: str) -> dict:
    """The arrays of the ``.npz`` file ``path``, read without pickles; a :class:`UsageError` ``"{what}: ..."`` when it
    cannot be read or is no ``.npz`` of arrays (``kind`` says what it should be: ``"a matched set"``)."""
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except OSError as e:
        raise UsageError(f"{what}: {e.strerror or 'cannot be read'}") from None
    except (ValueError, EOFError):  # numpy takes bytes that are no zip for a pickle
        raise UsageError(f"{what}: not {kind} (an .npz of arrays)") from None


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether ``a`` and ``b`` are one existing file (by name, or through a symbolic or hard link)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def refuse_overwriting_input(output: str | os.PathLike | None, inputs, force: bool = False) -> None:
    """A :class:`UsageError` (exit 2) when ``output`` is one of the files ``inputs`` (``-`` and None are not
    files), unless ``force``; checked before anything is written. Names the parameters ``output`` and
    ``force``."""
    if force or output is None or str(output) == "-":
        return
    for src in inputs:
        if src is not None and str(src) != "-" and same_file(output, src):
            also = "" if os.path.abspath(output) == os.path.abspath(src) else f" (through a link: {src})"
            raise UsageError(f"output {output} is the input {src}{also}: writing it would overwrite the input; "
                             "choose another output, or give force to overwrite it", params=("output", "force"))


#: a file changed less than this long before it is hashed is not marked verified: file times advance in clock
#: ticks, so a change in the same tick as the one before would leave every time as it was (git's "racily
#: clean" entries)
RACY_S = 2.0


def cache_dir() -> Path:
    """The one folder keyfill caches in (preprocessed corpora; the marks of verified files): ``KEYFILL_CACHE``
    when it is set and not empty, else the user's cache folder (``platformdirs``: ``$XDG_CACHE_HOME/keyfill``
    or ``~/.cache/keyfill`` on Linux). Never inside the package; deleting it is safe."""
    if os.environ.get("KEYFILL_CACHE"):
        return Path(os.environ["KEYFILL_CACHE"])
    import platformdirs

    return Path(platformdirs.user_cache_dir("keyfill"))


def sha256_file(path: str | os.PathLike) -> str:
    """The SHA-256 (hex) of the bytes of ``path``, read in blocks of 1 MiB."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _state(st: os.stat_result) -> str:
    return f"{st.st_dev}:{st.st_ino}:{st.st_size}:{st.st_mtime_ns}:{st.st_ctime_ns}"


def verified(path: str | os.PathLike, sha256: str) -> bool:
    """Whether the bytes of ``path`` hash to ``sha256`` (hex); raises ``OSError`` when it cannot be read.

    A state of the file once verified is not hashed again: the state (device, inode, size, modification and
    change times) and ``sha256`` name an empty mark file under ``cache_dir()/verified``. That is sound because
    every change of a file's bytes (a write, a truncation, another file renamed in its place: a new inode) sets
    its change time to the present, and nothing but the system clock sets a change time back (``os.utime``
    restores the modification time only). A file changed within :data:`RACY_S` of its hash, or while it was
    being hashed, is not marked. An unwritable cache costs a hash each time, nothing more.
    """
    import hashlib

    path = Path(path)
    before = os.stat(path)
    mark = cache_dir() / "verified" / hashlib.sha256(f"{_state(before)}:{sha256}".encode()).hexdigest()
    if mark.is_file():
        return True
    if sha256_file(path) != sha256:
        return False
    settled = time.time_ns() - before.st_ctime_ns > RACY_S * 1e9
    if settled and _state(os.stat(path)) == _state(before):
        try:
            mark.parent.mkdir(parents=True, exist_ok=True)
            mark.touch()
        except OSError:
            pass
    return True
