"""The MOTION block of a BVH file, read a chunk at a time into channel values.

:class:`Layout` is what :mod:`keyfill.io.bvh` read of a file's header (skeleton, frame rate, where the motion
block starts and how many frames it says); :func:`value_chunks` yields the block's ``(n, C)`` channel values
about :data:`CHUNK_BYTES` of text at a time (numpy's C ``loadtxt`` per chunk; the text is never held whole when
it comes from a file), and names the line to blame when a chunk does not read.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill.errors import FormatError
from keyfill.motion import Skeleton


@dataclass(frozen=True)
class Layout:
    """A BVH file's header, read: its skeleton and frame rate, and where and how long its motion block is."""

    head: bytes  #: the text up to somewhere in the motion block (all of it when parsed from memory)
    file: Path | None  #: the file the rest of the motion block streams from (None: ``head`` is everything)
    label: object
    skeleton: Skeleton
    fps: float
    num_frames: int
    num_channels: int
    size: int  #: bytes of the whole text
    data_start: int  #: byte offset of the first motion line
    first_data_line: int  #: its 1-based line number
    frames_line_no: int  #: the line of 'Frames:'


#: bytes per chunk of the motion block parsed at once (bounds the parser's working memory)
CHUNK_BYTES = 1 << 22
_ALLOWED = np.zeros(256, dtype=bool)
_ALLOWED[list(limits.NUMBER_BYTES)] = True


def _diagnose(chunk: bytes, num_channels: int, label, first_line: int) -> None:
    """Raise the :class:`FormatError` for the first bad line of ``chunk`` (the slow path)."""
    limit = limits.max_abs()
    for i, line in enumerate(chunk.split(b"\n")):
        toks = line.split()
        if not toks:
            continue
        if len(toks) != num_channels:
            raise FormatError(
                f"{len(toks)} values on this line, expected {num_channels} (one per channel)", label, first_line + i
            )
        for tok in toks:
            text = tok.decode("utf-8", "replace")
            if text.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                raise FormatError(f"a value is NaN or infinite ({text!r})", label, first_line + i)
            if not limits.is_number(text):
                raise FormatError(f"{text!r} is not a number", label, first_line + i)
            if not abs(float(text)) <= limit:
                raise FormatError(
                    f"{text!r} is beyond {limit:g} (set KEYFILL_MAX_ABS to read larger values)", label, first_line + i
                )
    raise FormatError("the motion data cannot be read", label, first_line)  # pragma: no cover - a parser disagreement


def _nonempty_lines(data: bytes) -> int:
    return sum(1 for line in data.split(b"\n") if line.strip())


def _text_blocks(layout: Layout):
    """``(byte offset, text)`` of the motion block, about :data:`CHUNK_BYTES` at a time, each ending at a line
    end (or the end of the text): from memory, or read from the file as it goes."""
    if layout.file is None:
        raw, pos = layout.head, layout.data_start
        while pos < len(raw):
            end = raw.find(b"\n", min(pos + CHUNK_BYTES, len(raw)))
            end = len(raw) if end < 0 else end + 1
            yield pos, raw[pos:end]
            pos = end
        return
    with open(layout.file, "rb") as f:
        f.seek(layout.data_start)
        pos, rest = layout.data_start, b""
        while True:
            more = f.read(CHUNK_BYTES)
            text = rest + more
            cut = text.rfind(b"\n") + 1 if more else len(text)
            if cut == 0 and more:  # a line longer than a chunk: read on
                rest = text
                continue
            if cut:
                yield pos, text[:cut]
            pos, rest = pos + cut, text[cut:]
            if not more:
                return


def _rest_of(layout: Layout, pos: int) -> bytes:
    """The motion block's text from byte ``pos`` on (for an error message that counts its lines)."""
    if layout.file is None:
        return layout.head[pos:]
    with open(layout.file, "rb") as f:
        f.seek(pos)
        return f.read()


def value_chunks(layout: Layout):
    """``(first row, (n, C) channel values)`` of the motion block of ``layout``, chunk after chunk.

    The block is read in chunks of about :data:`CHUNK_BYTES` (one C-level pass
    each; the text is never held whole when it comes from a file); a bad chunk is
    read again line by line to name the line to blame.
    """
    label, num_frames, num_channels = layout.label, layout.num_frames, layout.num_channels
    if num_channels == 0:
        if num_frames:
            yield 0, np.zeros((num_frames, 0))
        return
    if layout.file is None and layout.head.count(b"\n", layout.data_start) + 1 < num_frames:
        # too few lines: refuse before allocating (a file is checked as it streams; its rows are not touched)
        raise FormatError(f"'Frames: {num_frames}' but {_nonempty_lines(layout.head[layout.data_start:])} lines "
                          f"of motion data follow", label, layout.frames_line_no)
    limit = limits.max_abs()
    row, line_no = 0, layout.first_data_line
    with progress.task("reading BVH", layout.size - layout.data_start, "B") as update:
        for pos, chunk in _text_blocks(layout):
            arr = None
            if _ALLOWED[np.frombuffer(chunk, dtype=np.uint8)].all():
                try:
                    arr = np.loadtxt(chunk.split(b"\n"), dtype=np.float64, comments=None, ndmin=2)
                except ValueError:
                    arr = None
            if arr is not None and arr.size == 0:
                arr = arr.reshape(0, num_channels)
            if arr is None or arr.shape[1] != num_channels or not (np.abs(arr) <= limit).all():
                _diagnose(chunk, num_channels, label, line_no)
            if row + len(arr) > num_frames:
                rest = _rest_of(layout, pos)
                extra = [i for i, line in enumerate(rest.split(b"\n")) if line.strip()][num_frames - row]
                raise FormatError(
                    f"'Frames: {num_frames}' but {row + _nonempty_lines(rest)} lines of motion data follow",
                    label,
                    line_no + extra,
                )
            if len(arr):
                yield row, arr
            row += len(arr)
            line_no += chunk.count(b"\n")
            update(len(chunk))
    if row != num_frames:
        raise FormatError(f"'Frames: {num_frames}' but {row} lines of motion data follow", label,
                          layout.frames_line_no)
