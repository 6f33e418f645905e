"""Reading and writing motion files: ``load(path) -> Motion``, ``save(motion, path)``.

The format comes from the suffix (``.bvh``, ``.usda``, ``.usdc``, ``.usd``) or
from ``format=`` (required for ``-``, standard input or output). Each format
has a reader ``read(path, label=None) -> Motion`` (``label`` names the file in
error messages) and a writer ``write(motion, path, **options)``: BVH in
:mod:`keyfill.io.bvh`; USD in :mod:`keyfill.io.usd` (UsdSkel), read through
:func:`keyfill.io.usd_curves.read_motion` so that a keyfill curves file gives
its Bezier curves baked at every frame. Saving is atomic: the file appears
complete or not at all (see :func:`keyfill.files.atomic_output`).
"""

from __future__ import annotations

import importlib
import os
import sys
import tempfile
from pathlib import Path

from keyfill.errors import FormatError, UsageError
from keyfill.files import atomic_output
from keyfill.motion import Motion

_USD = ("keyfill.io.usd_curves:read_motion", "keyfill.io.usd:write")
#: format name -> its (reader, writer) as "module:function", imported on first use
FORMATS = {"bvh": ("keyfill.io.bvh:read", "keyfill.io.bvh:write"), "usda": _USD, "usdc": _USD, "usd": _USD}
STDIO = "-"


def format_of(path: str | os.PathLike, format: str | None = None, option: str = "--format") -> str:
    """The format name for ``path``: ``format`` when given, else from the suffix.

    ``option`` is the command-line option that gives the format, named in the
    error for ``-`` (``--in-format`` for inputs).
    """
    if format is not None:
        fmt = format.lower().lstrip(".")
        if fmt not in FORMATS:
            raise UsageError(f"unknown format {format!r}; expected one of {', '.join(FORMATS)}")
        return fmt
    if str(path) == STDIO:
        reading = option == "--in-format"
        raise UsageError(f"{'reading' if reading else 'writing'} '-' needs {option} (bvh, usda or usdc)")
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        raise UsageError(f"{path}: unknown file type {Path(path).suffix or '(no suffix)'!r}; expected .bvh, .usda, .usdc or .usd")
    return suffix


def _function(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def load(path: str | os.PathLike, format: str | None = None) -> Motion:
    """Read a motion file (``"-"``: standard input, with ``format``)."""
    fmt = format_of(path, format, option="--in-format")
    read = _function(FORMATS[fmt][0])
    if str(path) == STDIO:
        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / ("stdin." + fmt)
            p.write_bytes(sys.stdin.buffer.read())
            return read(p, label="<stdin>")
    p = Path(path)
    if not p.is_file():
        raise FormatError("no such file" if not p.exists() else "not a file", p)
    return read(p)


def save(motion: Motion, path: str | os.PathLike, format: str | None = None, **options) -> None:
    """Write ``motion`` atomically (``"-"``: standard output, with ``format``).

    ``options`` go to the format's writer (e.g. ``sparse=True`` for USD key files).
    """
    fmt = format_of(path, format)
    write = _function(FORMATS[fmt][1])
    if str(path) == STDIO:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / ("stdout." + fmt)
            write(motion, out, **options)
            sys.stdout.flush()
            sys.stdout.buffer.write(out.read_bytes())
            sys.stdout.buffer.flush()
        return
    with atomic_output(path) as tmp:
        write(motion, tmp, **options)
