"""The bytes of a glTF 2.0 file: the ``.glb`` container, buffers, accessors (for :mod:`keyfill.io.gltf`).

Reading trusts nothing: a ``.glb``'s header and chunk lengths must agree with
the file; the JSON must be strict JSON (no ``NaN``) whose ``asset.version`` is
2.x; a buffer is the ``.glb``'s BIN chunk, a ``data:`` URI or a file in the
``.gltf``'s own folder (a URI that leaves the folder, is absolute or names a
scheme is never followed); every accessor must lie inside its buffer view and
every view inside its buffer, so what is allocated is never more than the file
holds, and every number read is counted, each time an accessor is read (channels
may share one, a sparse one is mostly zeros), against what the file's size allows
(:func:`keyfill.limits.check_reads`). Values read are finite and within
:func:`keyfill.limits.max_abs`; JSON numbers are finite 64-bit floats and whole
numbers fit in 64 bits (:func:`keyfill.limits.json_int64`).
A buffer in a file (the ``.glb``'s BIN chunk, a ``.bin``) is never read whole:
:class:`Stored` names its bytes, and each accessor reads its own range,
:data:`BLOCK` bytes at a time, straight into its float64 array, so reading a long
take holds little beside the motion's own arrays (issue 44).
The JSON is read as JSON and its types checked against :data:`SCHEMA` (the
properties keyfill uses) rather than through pygltflib, whose decoder coerces
wrong types silently (a ``count`` of 3.5 becomes 3) and fails on valid files
(``extras`` that are not objects).

Writing is :mod:`keyfill.io.gltf_blob`'s.
"""

from __future__ import annotations

import base64
import json
import os
import struct
import urllib.parse
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from keyfill import limits
from keyfill.errors import FormatError

MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
#: accessor componentType -> numpy dtype (little-endian)
COMPONENTS = {5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"), 5123: np.dtype("<u2"),
              5125: np.dtype("<u4"), 5126: np.dtype("<f4")}
FLOAT = 5126
#: accessor type -> number of components
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: image suffix -> MIME type, for embedding a template's images
IMAGE_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
               ".ktx2": "image/ktx2"}
#: bytes of a buffer's file read (or copied into an output) at a time: what a long take holds beside its arrays
BLOCK = 1 << 22


_INT, _STR, _BOOL, _OBJ, _NUMS, _INTS, _OBJS = "int", "str", "bool", "obj", "nums", "ints", "objs"
#: collection (or nested object) -> property -> kind; only what keyfill reads
SCHEMA = {
    "nodes": {"children": _INTS, "translation": _NUMS, "rotation": _NUMS, "scale": _NUMS, "matrix": _NUMS,
              "name": _STR, "skin": _INT, "mesh": _INT},
    "skins": {"joints": _INTS, "inverseBindMatrices": _INT, "skeleton": _INT, "name": _STR},
    "animations": {"channels": _OBJS, "samplers": _OBJS, "name": _STR},
    "channels": {"sampler": _INT, "target": _OBJ},
    "target": {"node": _INT, "path": _STR},
    "samplers": {"input": _INT, "output": _INT, "interpolation": _STR},
    "accessors": {"bufferView": _INT, "byteOffset": _INT, "componentType": _INT, "normalized": _BOOL,
                  "count": _INT, "type": _STR, "sparse": _OBJ},
    "sparse": {"count": _INT, "indices": _OBJ, "values": _OBJ},
    "indices": {"bufferView": _INT, "byteOffset": _INT, "componentType": _INT},
    "values": {"bufferView": _INT, "byteOffset": _INT},
    "bufferViews": {"buffer": _INT, "byteOffset": _INT, "byteLength": _INT, "byteStride": _INT},
    "buffers": {"uri": _STR, "byteLength": _INT},
    "scenes": {"nodes": _INTS},
    "images": {"uri": _STR, "bufferView": _INT, "mimeType": _STR},
    "meshes": {"primitives": _OBJS},
    "primitives": {"attributes": _OBJ, "indices": _INT, "targets": _OBJS},
}
_KINDS = {
    _INT: lambda v: type(v) is int,
    _STR: lambda v: isinstance(v, str),
    _BOOL: lambda v: isinstance(v, bool),
    _OBJ: lambda v: isinstance(v, dict),
    _NUMS: lambda v: isinstance(v, list) and all(type(x) in (int, float) for x in v),
    _INTS: lambda v: isinstance(v, list) and all(type(x) is int for x in v),
    _OBJS: lambda v: isinstance(v, list) and all(isinstance(x, dict) for x in v),
}
_WORDS = {_INT: "a whole number", _STR: "a string", _BOOL: "true or false", _OBJ: "an object",
          _NUMS: "a list of numbers", _INTS: "a list of whole numbers", _OBJS: "a list of objects"}


def check_schema(raw: dict, label) -> None:
    """:class:`FormatError` unless every property of :data:`SCHEMA` in ``raw`` has its kind."""
    if "scene" in raw and type(raw["scene"]) is not int:
        raise FormatError("not glTF: 'scene' is not a whole number", label)
    todo = [(key, f"{key}[{i}]", item) for key in ("nodes", "skins", "animations", "accessors", "bufferViews",
                                                     "buffers", "scenes", "images", "meshes")
            for i, item in enumerate(_objects(raw, key, label))]
    while todo:
        kind, where, obj = todo.pop()
        for prop, want in SCHEMA[kind].items():
            if prop not in obj:
                continue
            if not _KINDS[want](obj[prop]):
                raise FormatError(f"not glTF: {where}.{prop} is not {_WORDS[want]}", label)
            if prop in SCHEMA and want == _OBJ:
                todo.append((prop, f"{where}.{prop}", obj[prop]))
            elif prop in SCHEMA and want == _OBJS:
                todo.extend((prop, f"{where}.{prop}[{i}]", x) for i, x in enumerate(obj[prop]))


def _objects(raw: dict, key: str, label) -> list:
    items = raw.get(key, [])
    if not _KINDS[_OBJS](items):
        raise FormatError(f"not glTF: {key!r} is not a list of objects", label)
    return items


@dataclass(frozen=True)
class Stored:
    """``length`` bytes of a buffer or an image: ``data`` held in memory (a ``data:`` URI), or else those of
    the file ``path`` from byte ``start``, read only where they are asked for (:meth:`read`, :meth:`blocks`).
    ``what`` (``"buffer 0"``) and ``label`` name them in errors."""

    length: int
    what: str
    label: object
    path: Path | None = None
    start: int = 0
    data: bytes | memoryview | np.ndarray | None = None

    def part(self, at: int, size: int) -> Stored:
        """Its bytes ``at`` to ``at + size`` (inside it) as a :class:`Stored` of their own."""
        if self.data is not None:
            return replace(self, length=size, data=memoryview(self.data)[at: at + size])
        return replace(self, length=size, start=self.start + at)

    def read(self, at: int, size: int) -> np.ndarray:
        """``(size,)`` uint8: its bytes ``at`` to ``at + size``; a :class:`FormatError` when its file cannot
        give them (removed, cut short since it was opened)."""
        if self.data is not None:
            return np.frombuffer(self.data, dtype=np.uint8, count=size, offset=at)
        out = np.empty(size, dtype=np.uint8)
        view, got = memoryview(out), 0
        try:
            with open(self.path, "rb") as f:
                f.seek(self.start + at)
                while got < size:
                    n = f.readinto(view[got:])
                    if not n:
                        break
                    got += n
        except OSError as e:
            raise FormatError(f"{self.what}: the file {self.path.name[:60]!r} it names cannot be read "
                              f"({e.strerror or e})", self.label) from None
        if got < size:
            raise FormatError(f"{self.what}: the file {self.path.name[:60]!r} it names ends before byte "
                              f"{self.start + at + size} (changed while it was read?)", self.label)
        return out

    def blocks(self) -> Iterator[np.ndarray]:
        """All its bytes, ``(n,)`` uint8 arrays of at most :data:`BLOCK`, in order."""
        for at in range(0, self.length, BLOCK):
            yield self.read(at, min(BLOCK, self.length - at))


@dataclass
class Document:
    """A glTF file as read: its JSON (checked by :func:`check_schema`), where each buffer's bytes are, its
    folder."""

    json: dict
    #: per buffer where its bytes are, or None for a buffer without data (no URI and no BIN chunk: an extension's)
    buffers: list[Stored | None]
    folder: Path
    label: object
    size: int  #: bytes of the file and of the buffer files it names (the bound of what it may describe)
    reads: int = 0  #: accessor numbers read so far, every use counted (:func:`read_accessor` checks it)

    def items(self, key: str) -> list[dict]:
        """The objects of a top-level collection (``"nodes"``), ``[]`` when absent."""
        return self.json.get(key, [])


def _strict_json(text: str, label):
    def refuse(name):
        raise FormatError(f"the JSON holds {name}, which is not a JSON number", label)

    try:
        return json.loads(text, parse_constant=refuse, parse_int=limits.json_int64, parse_float=limits.json_finite)
    except json.JSONDecodeError as e:
        raise FormatError(f"not glTF: the JSON is not valid at line {e.lineno} ({e.msg})", label) from None
    except ValueError as e:  # a number the hooks refuse (json gives no line for it)
        raise FormatError(f"not glTF: the JSON holds a number keyfill cannot read ({e})", label) from None
    except RecursionError:
        raise FormatError("not glTF: the JSON is nested too deeply", label) from None


def split_glb(f, size: int, label) -> tuple[bytes, tuple[int, int] | None]:
    """``(JSON chunk, (offset, length) of the BIN chunk in the file, or None)`` of the ``.glb`` open as ``f``
    (binary, ``size`` bytes); :class:`FormatError` for a broken container. Only the chunk headers and the JSON
    are read."""
    f.seek(0)
    head = f.read(12)
    if size < 12:
        raise FormatError(f"not a glTF binary: {size} bytes, shorter than the 12-byte header", label)
    if head[:4] != MAGIC:
        raise FormatError(f"not a glTF binary: the file starts with {head[:4]!r}, not b'glTF'", label)
    version, length = struct.unpack_from("<II", head, 4)
    if version != 2:
        raise FormatError(f"glTF binary version {version}; keyfill reads version 2", label)
    if length != size:
        raise FormatError(f"the glTF header gives a length of {length} bytes, the file has {size} "
                          "(cut short or padded?)", label)
    chunks = []  # (kind, offset, length) of each chunk's data
    at = 12
    while at < length:
        if at + 8 > length:
            raise FormatError(f"a chunk header at byte {at} runs past the end of the file", label)
        f.seek(at)
        chunk, kind = struct.unpack("<II", f.read(8))
        if at + 8 + chunk > length:
            raise FormatError(f"a chunk at byte {at} gives a length of {chunk} bytes, past the end of the file", label)
        chunks.append((kind, at + 8, chunk))
        at += 8 + chunk
    if not chunks or chunks[0][0] != CHUNK_JSON:
        raise FormatError("the first chunk of a glTF binary must be its JSON", label)
    f.seek(chunks[0][1])
    text = f.read(chunks[0][2])
    binary = chunks[1][1:] if len(chunks) > 1 and chunks[1][0] == CHUNK_BIN else None
    return text, binary


def load_document(path: Path, label) -> Document:
    """Read and check a ``.glb`` or ``.gltf`` file's JSON and find its buffers (:class:`Stored`: their bytes
    are read where accessors ask)."""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        head = f.read(4)
        binary = None
        if head == MAGIC or path.suffix.lower() == ".glb":
            text_bytes, binary = split_glb(f, size, label)
        else:
            text_bytes = head + f.read()
    try:
        text = text_bytes.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise FormatError("not glTF: the JSON is not UTF-8 text", label) from None
    raw = _strict_json(text, label)
    if not isinstance(raw, dict):
        raise FormatError("not glTF: the JSON is not an object", label)
    asset = raw.get("asset")
    version = asset.get("version") if isinstance(asset, dict) else None
    if not isinstance(version, str) or not version.startswith("2."):
        raise FormatError(f"not glTF 2.0: asset.version is {version!r}", label)
    check_schema(raw, label)
    specs = raw.get("buffers", [])
    chunk = None if binary is None else Stored(binary[1], "buffer 0", label, path=path, start=binary[0])
    buffers = [_buffer(b, i, chunk, path.parent, label) for i, b in enumerate(specs)]
    # what the file brings: its own bytes and those of the buffer files it names (a .gltf's .bin)
    outside = sum(b.length for b, spec in zip(buffers, specs) if b is not None and "uri" in spec)
    return Document(raw, buffers, path.parent, label, size + outside)


def _whole(value, what: str, label, low: int = 0) -> int:
    if type(value) is not int or value < low:
        raise FormatError(f"{what} must be a whole number of at least {low}, not {value!r:.40}", label)
    return value


def resolve_uri(folder: Path, uri: str, label, what: str) -> Path:
    """The file a relative ``uri`` names inside ``folder``; never a path outside it, absolute or with a scheme."""
    name = urllib.parse.unquote(uri)
    if "\0" in name:
        raise FormatError(f"{what} has the URI {uri[:60]!r}, which holds a NUL byte (%00); no file has that name",
                          label)
    parts = Path(name).parts
    if (not name or "\\" in name or urllib.parse.urlsplit(uri).scheme or Path(name).is_absolute()
            or ".." in parts):
        raise FormatError(f"{what} has the URI {uri[:60]!r}, outside the file's folder; keyfill does not follow it",
                          label)
    target = folder / name
    try:
        inside = target.resolve().is_relative_to(folder.resolve())
        is_file = target.is_file()
    except OSError as e:  # a name too long for the file system, a loop of links
        raise FormatError(f"{what} has the URI {uri[:60]!r}, which names no file that can be read "
                          f"({e.strerror or e})", label) from None
    if not inside:
        raise FormatError(f"{what} has the URI {uri[:60]!r}, which leads outside the file's folder", label)
    if not is_file:
        why = "is not a regular file (a folder, pipe or device)" if target.exists() else "is missing"
        raise FormatError(f"{what}: the file {name[:60]!r} it names {why}", label)
    return target


def stored_file(path: Path, label, what: str) -> Stored:
    """The file ``path`` that :func:`resolve_uri` found, as a :class:`Stored` (opened to learn its size, not
    read); a :class:`FormatError` when it cannot be opened (no permission, removed since)."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
    except OSError as e:
        raise FormatError(f"{what}: the file {path.name[:60]!r} it names cannot be read ({e.strerror or e})",
                          label) from None
    return Stored(size, what, label, path=path)


def data_uri(uri: str, label, what: str) -> bytes:
    """The bytes of a base64 ``data:`` URI."""
    head, _, body = uri.partition(",")
    if not head.endswith(";base64"):
        raise FormatError(f"{what} is a data URI without base64 data", label)
    try:
        return base64.b64decode(body, validate=True)
    except ValueError:
        raise FormatError(f"{what} is a data URI whose base64 data is broken", label) from None


def _buffer(buf: dict, i: int, binary: Stored | None, folder: Path, label) -> Stored | None:
    what = f"buffer {i}"
    length = _whole(buf.get("byteLength"), f"{what}'s byteLength", label, 1)
    uri = buf.get("uri")
    if uri is None:
        if i != 0 or binary is None:
            return None
        data = binary
    elif uri.startswith("data:"):
        decoded = data_uri(uri, label, what)
        data = Stored(len(decoded), what, label, data=decoded)
    else:
        data = stored_file(resolve_uri(folder, uri, label, what), label, what)
    if data.length < length:
        raise FormatError(f"{what} has {data.length} bytes; its byteLength says {length}", label)
    return data.part(0, length)


def read_accessor(doc: Document, index, what: str, types: tuple[str, ...], floats_only: bool = False) -> np.ndarray:
    """Accessor ``index`` as ``(count, width)`` float64, normalized integers scaled as glTF says.

    ``types``: the accessor types allowed (``("VEC4",)``); ``floats_only``:
    refuse integer components. Every element must lie inside its buffer view
    and buffer; the values must be finite and within the magnitude limit.
    """
    label = doc.label
    acc_list = doc.items("accessors")
    if type(index) is not int or not 0 <= index < len(acc_list):
        raise FormatError(f"{what} names accessor {index!r}, which does not exist", label)
    acc = acc_list[index]
    name = f"accessor {index} ({what})"
    kind, component = acc.get("type"), acc.get("componentType")
    if kind not in types:
        raise FormatError(f"{name} is of type {kind!r}; expected {' or '.join(types)}", label)
    if component not in COMPONENTS or (floats_only and component != FLOAT):
        raise FormatError(f"{name} has componentType {component!r}; expected "
                          f"{'5126 (float)' if floats_only else 'a glTF component type'}", label)
    if component != FLOAT and not acc.get("normalized", False):
        raise FormatError(f"{name} holds integers that are not normalized", label)
    width, dtype = WIDTHS[kind], COMPONENTS[component]
    count = _whole(acc.get("count"), f"{name}'s count", label, 1)
    problem = limits.check_size(count, width, doc.size)
    if problem:
        raise FormatError(f"{name}: {problem.replace('frames', 'elements').replace('joints', 'components')}", label)
    sparse = acc.get("sparse")
    n = sparse.get("count") if isinstance(sparse, dict) else None
    doc.reads += count * width + (n * (width + 1) if type(n) is int and n > 0 else 0)
    problem = limits.check_reads(doc.reads, doc.size)
    if problem:  # before this accessor is given memory: a few shared sparse accessors can ask for gigabytes
        raise FormatError(f"{name}: {problem}", label)
    if "bufferView" in acc:
        values = _view_elements(doc, acc["bufferView"], acc.get("byteOffset", 0), count, width, dtype, name)
    elif sparse is None:
        raise FormatError(f"{name} has neither a bufferView nor sparse values", label)
    else:
        values = np.zeros((count, width))
    if sparse is not None:
        _apply_sparse(doc, sparse, values, width, dtype, name)
    if dtype.kind in "iu":
        values = np.maximum(values / np.iinfo(dtype).max, -1.0)
    limit = limits.max_abs()
    if not (np.abs(values) <= limit).all():
        raise FormatError(f"{name} holds a value that is not finite or beyond {limit:g}", label)
    return values


def _view_elements(doc: Document, view_index, offset, count: int, width: int, dtype, name: str) -> np.ndarray:
    """``(count, width)`` float64 elements of a buffer view, every byte checked to be inside it; read from the
    buffer :data:`BLOCK` bytes at a time, each block widened into the array made for them."""
    label = doc.label
    views = doc.items("bufferViews")
    if type(view_index) is not int or not 0 <= view_index < len(views):
        raise FormatError(f"{name} names bufferView {view_index!r}, which does not exist", label)
    view = views[view_index]
    vname = f"bufferView {view_index}"
    buffer = view.get("buffer")
    if type(buffer) is not int or not 0 <= buffer < len(doc.buffers):
        raise FormatError(f"{vname} names buffer {buffer!r}, which does not exist", label)
    start = _whole(view.get("byteOffset", 0), f"{vname}'s byteOffset", label)
    length = _whole(view.get("byteLength"), f"{vname}'s byteLength", label, 1)
    data = doc.buffers[buffer]
    if data is None:
        raise FormatError(f"{vname} is in buffer {buffer}, which has no URI and no binary chunk", label)
    if start + length > data.length:
        raise FormatError(f"{vname} (bytes {start} to {start + length}) runs past the end of buffer {buffer} "
                          f"({data.length} bytes)", label)
    offset = _whole(offset, f"{name}'s byteOffset", label)
    element = width * dtype.itemsize
    stride = _whole(view.get("byteStride", element), f"{vname}'s byteStride", label, 1)
    if stride < element:
        raise FormatError(f"{vname}'s byteStride {stride} is shorter than one element of {name}", label)
    end = offset + stride * (count - 1) + element
    if end > length:
        raise FormatError(f"{name} needs {end} bytes of {vname}, which has {length}", label)
    out = np.empty((count, width))
    step = max(1, BLOCK // stride)  # rows a block
    for r in range(0, count, step):
        n = min(step, count - r)
        block = data.read(start + offset + r * stride, stride * (n - 1) + element)
        rows = np.lib.stride_tricks.as_strided(block, shape=(n, element), strides=(stride, 1))
        with np.errstate(invalid="ignore"):  # a signalling NaN warns as it widens; read_accessor refuses it next
            out[r: r + n] = np.ascontiguousarray(rows).view(dtype).reshape(n, width)
    return out


def _apply_sparse(doc: Document, sparse: dict, values: np.ndarray, width: int, dtype, name: str) -> None:
    label = doc.label
    n = _whole(sparse.get("count"), f"{name}'s sparse count", label, 1)
    indices, given = sparse.get("indices"), sparse.get("values")
    if n > len(values) or indices is None or given is None:
        raise FormatError(f"{name}'s sparse part is incomplete or longer than the accessor", label)
    kind = COMPONENTS.get(indices.get("componentType"))
    if kind is None or kind.kind != "u":
        raise FormatError(f"{name}'s sparse indices are not unsigned integers", label)
    idx = _view_elements(doc, indices.get("bufferView"), indices.get("byteOffset", 0), n, 1, kind,
                         name + " sparse indices")[:, 0].astype(np.int64)
    if np.any(idx >= len(values)) or np.any(np.diff(idx) <= 0):
        raise FormatError(f"{name}'s sparse indices are not increasing indices inside the accessor", label)
    values[idx] = _view_elements(doc, given.get("bufferView"), given.get("byteOffset", 0), n, width, dtype,
                                 name + " sparse values")
