"""The binary buffer of a glTF file being written (for :mod:`keyfill.io.gltf_write`), made as it is written.

A :class:`Blob` places pieces at their offsets before any of their bytes exist: ranges of a template's
buffers and images (:class:`~keyfill.io.gltf_buffers.Stored`, copied :data:`~keyfill.io.gltf_buffers.BLOCK`
bytes at a time), small arrays (times, inverse bind matrices) and accessors whose values a function gives
when they are written, one channel at a time. So the JSON, which needs only the offsets and lengths, is
known first, and a long take's buffer is never held whole beside the motion (issue 44).
:class:`BufferWriter` adds accessors and buffer views to a pygltflib document; :func:`write_glb`,
:func:`write_bin` and :func:`write_gltf` write the blob as a ``.glb``'s BIN chunk, a ``.bin`` or a base64
``data:`` URI (encoded a block at a time). The bytes are those of the whole buffer made at once.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from keyfill.io.gltf_buffers import CHUNK_BIN, CHUNK_JSON, FLOAT, MAGIC, WIDTHS, Stored

#: a piece's bytes: a range of a file or of memory, float32 values, or a function giving them when written
Source = Stored | np.ndarray | Callable[[], np.ndarray]
#: the prefix of an embedded buffer's URI
DATA_URI = "data:application/octet-stream;base64,"


class Blob:
    """The bytes of a buffer as pieces ``(offset, length, source)`` (:data:`Source`), zeros between them."""

    def __init__(self):
        self.size = 0
        self.pieces: list[tuple[int, int, Source]] = []

    def put(self, source: Source, length: int, residue: int = 0, modulus: int = 4) -> int:
        """Place ``length`` bytes of ``source`` after the others, at the first offset that is ``residue`` modulo
        ``modulus``; returns that offset."""
        at = self.size + (residue - self.size) % modulus
        self.pieces.append((at, length, source))
        self.size = at + length
        return at

    def extend(self, other: Blob, modulus: int = 8) -> int:
        """Place all of ``other`` after the others, from the first offset that is a multiple of ``modulus``;
        returns that offset."""
        start = self.size + -self.size % modulus
        self.pieces += [(start + at, n, source) for at, n, source in other.pieces]
        self.size = start + other.size
        return start

    def hold(self, outputs: list[Path]) -> None:
        """Read into memory now the pieces that come from one of the files ``outputs`` (a template written over
        itself), which opening them for writing would empty first."""
        for k, (at, n, source) in enumerate(self.pieces):
            if isinstance(source, Stored) and source.data is None and any(_same(source.path, o) for o in outputs):
                self.pieces[k] = (at, n, Stored(n, source.what, source.label, data=source.read(0, n)))

    def chunks(self) -> Iterator[np.ndarray]:
        """Its bytes in order, ``(n,)`` uint8 arrays: each piece's made now (a function's called), and the
        zeros between."""
        at = 0
        for offset, length, source in self.pieces:
            if offset > at:
                yield np.zeros(offset - at, dtype=np.uint8)
            made = 0
            for chunk in source.blocks() if isinstance(source, Stored) else [_float32(source)]:
                made += len(chunk)
                yield chunk
            if made != length:
                raise RuntimeError(f"a piece of a glTF buffer gave {made} bytes, {length} were placed for it")
            at = offset + length


def _float32(source: np.ndarray | Callable[[], np.ndarray]) -> np.ndarray:
    values = source() if callable(source) else source
    return np.ascontiguousarray(values, dtype="<f4").reshape(-1).view(np.uint8)


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # no such output yet
        return False


class BufferWriter:
    """The accessors and buffer views of the pygltflib document ``gltf``, their bytes placed in :attr:`blob`
    (its buffer 0)."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.blob = Blob()

    def add_bytes(self, source: Stored) -> int:
        """A buffer view holding ``source``'s bytes, 4-byte aligned; returns its index."""
        from pygltflib import BufferView

        at = self.blob.put(source, source.length)
        self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=at, byteLength=source.length))
        return len(self.gltf.bufferViews) - 1

    def add(self, values: np.ndarray | Callable[[], np.ndarray], kind: str, count: int | None = None,
            bounds: bool = False) -> int:
        """An accessor of float32 ``values (count, width)`` of glTF type ``kind``, in a buffer view of its own,
        4-byte aligned; returns its index.

        ``values``: an array, or a function that gives it when the buffer is written (``count`` then says its
        rows), so that a long take's channels are made one at a time and never all held. ``bounds`` (an array
        only) gives ``min`` and ``max`` (required for animation inputs).
        """
        from pygltflib import Accessor, BufferView

        source = values
        if not callable(values):
            source = np.ascontiguousarray(values, dtype="<f4").reshape(len(values), -1)
            count = len(source)
        length = count * WIDTHS[kind] * 4
        self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=self.blob.put(source, length),
                                                byteLength=length))
        acc = Accessor(bufferView=len(self.gltf.bufferViews) - 1, componentType=FLOAT, count=count, type=kind)
        if bounds:
            acc.min = [float(v) for v in source.min(axis=0)]
            acc.max = [float(v) for v in source.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1


def write_glb(path: Path, json_text: str, blob: Blob) -> None:
    """``path`` as a ``.glb``: header, the JSON chunk (padded with spaces) and ``blob`` as the BIN chunk (padded
    with zeros; none for an empty blob)."""
    text = json_text.encode("utf-8")
    text += b" " * (-len(text) % 4)
    binary = blob.size + -blob.size % 4
    total = 12 + 8 + len(text) + (8 + binary if binary else 0)
    with open(path, "wb") as f:
        f.write(MAGIC + struct.pack("<II", 2, total) + struct.pack("<II", len(text), CHUNK_JSON) + text)
        if binary:
            f.write(struct.pack("<II", binary, CHUNK_BIN))
            f.writelines(blob.chunks())
            f.write(bytes(binary - blob.size))


def write_bin(path: Path, blob: Blob) -> None:
    """``path`` holding the bytes of ``blob`` (a ``.gltf``'s ``.bin``)."""
    with open(path, "wb") as f:
        f.writelines(blob.chunks())


def write_gltf(path: Path, doc: dict, blob: Blob, uri: str | None) -> None:
    """``path`` as a ``.gltf``: ``doc`` as JSON indented by one, whose one buffer is ``blob``: in the file that
    ``uri`` names (written apart: :func:`write_bin`), or, with ``uri`` None, embedded as a base64 ``data:`` URI,
    encoded a block at a time where the URI goes."""
    doc["buffers"] = [{"uri": uri, "byteLength": blob.size}]
    if uri is not None:
        path.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        return
    token = "keyfill-buffer"
    while True:  # a URI no other string of the document equals
        doc["buffers"][0]["uri"] = token
        text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
        if text.count(f'"{token}"') == 1:
            break
        token += "-"
    before, _, after = text.partition(f'"{token}"')
    with open(path, "w", encoding="utf-8") as f:
        f.write(before + '"' + DATA_URI)
        rest = b""
        for chunk in blob.chunks():
            chunk = rest + chunk.tobytes()
            cut = len(chunk) - len(chunk) % 3  # whole groups of 3 bytes encode alone
            f.write(base64.b64encode(chunk[:cut]).decode("ascii"))
            rest = chunk[cut:]
        f.write(base64.b64encode(rest).decode("ascii") + '"' + after)
