"""The files a USD stage is made of: its root layer and the layers it composes, each a regular file.

:func:`keyfill.io.usd.open_stage` checks them before USD opens the stage (a sublayer that is a pipe would
hang inside USD, where no signal reaches), and a batch's input digest covers them
(:func:`keyfill.io.batch_record.input_sha256`), so a changed sublayer redoes its output.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from keyfill.errors import FormatError


def layer_files(path: str | Path, label=None) -> list[Path]:
    """The files of :func:`composed_layers`."""
    return [file for file, _ in composed_layers(path, label)]


def composed_layers(path: str | Path, label=None) -> list[tuple[Path, object]]:
    """``(file, Sdf.Layer)`` of each layer the stage of ``path`` composes (the layers open: a stage opened
    while they are held reuses them instead of parsing them again): the file, its sublayers, references and payloads,
    and theirs, as USD resolves them (relative to the layer that names them, or absolute: USD pipelines keep
    assets beside their shots). Each must be a regular file: a pipe would wait for a writer and a device never
    end, inside USD where no signal reaches (:class:`FormatError` naming it); a layer that cannot be found or
    read is left to USD. Inside a ``.usdz`` package only the package itself is a file."""
    from pxr import Sdf

    files: list[tuple[Path, object]] = []
    todo, seen = [os.path.abspath(path)], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            mode = os.stat(name).st_mode
        except (OSError, ValueError):  # missing, or a path inside a package ("x.usdz[y.usdc]")
            continue
        if not stat.S_ISREG(mode):
            raise FormatError(f"it composes {name!r}, which is not a regular file (a pipe, device or folder)", label)
        layer = Sdf.Layer.FindOrOpen(name)
        files.append((Path(name), layer))
        if layer is not None:
            todo.extend(layer.ComputeAbsolutePath(a) for a in layer.GetCompositionAssetDependencies() if a)
    return files
