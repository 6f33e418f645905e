"""What a source file holds beyond its motion, for the note that an output of another family does not carry it.

Each function takes a file's path and gives words for a person (``["2 meshes", "1 material"]``), or ``[]``
when the file holds nothing beyond the skeleton and its animation (nothing then is said). They read as little
as they can (a ``.glb``'s JSON chunk, not its buffer) and never fail: the file has been read already, so
anything they cannot make out is taken as nothing to say. :attr:`keyfill.io.Format.contents` names them.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

#: glTF top-level arrays that hold what keyfill's motion does not, in the order the note names them
_GLTF = (("meshes", "mesh", "meshes"), ("materials", "material", "materials"), ("textures", "texture", "textures"),
         ("cameras", "camera", "cameras"))


def counted(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"


def gltf(path: str | Path) -> list[str]:
    """The meshes, materials, textures and cameras of a ``.glb`` or ``.gltf`` file."""
    try:
        with open(path, "rb") as f:
            head = f.read(20)
            if head[:4] == b"glTF":  # the JSON chunk alone: its length is in the chunk header
                (size,) = struct.unpack_from("<I", head, 12)
                text = head[20:] + f.read(size)
            else:
                text = head + f.read()
        doc = json.loads(text.decode("utf-8-sig"))
    except (OSError, ValueError, struct.error):
        return []
    if not isinstance(doc, dict):
        return []
    return [counted(len(doc[key]), one, many) for key, one, many in _GLTF
            if isinstance(doc.get(key), list) and doc[key]]
