"""Where the shipped models are: inside keyfill, or in an installed model distribution.

keyfill's own wheel is MIT only, so it holds only models trained on keyfill's own
data (the lamp's, ``keyfill/learn/models/lamp-arnn``). Models trained on data
under other licences come in their own distributions: the Bandai-Namco human
models (CC BY-NC 4.0) in ``keyfill-models-bandai``, the ``models/bandai`` folder
of a keyfill checkout (``pip install ./models/bandai``; ``make`` installs it).

A model distribution announces its models as entry points of the group
:data:`GROUP`, one per model: the entry point's name is the model's name (the
folder name keyfill reports, ``bandai2-transformer``) and its object a path
(``str`` or ``os.PathLike``) of the model folder::

    [project.entry-points."keyfill.models"]
    bandai2-transformer = "keyfill_models_bandai:BANDAI2_TRANSFORMER"

:func:`shipped` resolves a name (built-in folders first); the entry points are
read once per process (:func:`installed`). A method whose shipped model is not
installed has ``DEFAULT_MODEL`` None, and completing with it without a model
folder raises :func:`missing`'s error, which says how to get it.
"""

from __future__ import annotations

import functools
import importlib
import os
import re
import sys
from pathlib import Path

from keyfill.errors import ModelError

#: the entry-point group of model distributions: model name -> its folder
GROUP = "keyfill.models"
#: the models inside keyfill itself (MIT, like the code)
BUILTIN = Path(__file__).resolve().parent / "models"
#: how to get the shipped models that are not part of keyfill's own wheel
HOW_TO_GET = ("they are CC BY-NC 4.0 (non-commercial use) and come in their own distribution, "
              "keyfill-models-bandai: pip install ./models/bandai from a keyfill checkout "
              "(make installs it)")


#: an entry point's value, ``module:attr.attr [extras]`` (``importlib.metadata.EntryPoint.pattern``)
_VALUE = re.compile(r"(?P<module>[\w.]+)\s*(:\s*(?P<attr>[\w.]+)\s*)?((?P<extras>\[.*\])\s*)?$")


@functools.cache
def installed() -> dict[str, Path]:
    """Model name -> folder of every model an installed distribution announces (:data:`GROUP`), read once.

    An entry point that cannot be loaded or names no folder is left out (the model is then not installed).
    """
    found: dict[str, Path] = {}
    for name, value in sorted(entry_points(GROUP), key=lambda e: e[0]):
        folder = _folder(value)
        if folder is not None and folder.is_dir():
            found.setdefault(name, folder)
    return found


def entry_points(group: str) -> list[tuple[str, str]]:
    """``(name, value)`` of each entry point of ``group``, as ``importlib.metadata.entry_points(group=group)``
    finds them: in the ``entry_points.txt`` of the ``.dist-info`` and ``.egg-info`` folders on ``sys.path``, the
    first distribution of a name hiding later ones. Read without importing :mod:`importlib.metadata`, whose
    email, zipfile and csv modules cost a learned command about 50 ms of its start."""
    seen: set[str] = set()
    found: list[tuple[str, str]] = []
    for entry in sys.path:
        try:
            names = sorted(os.listdir(entry or "."))
        except OSError:  # not a folder (a zip file), or gone
            continue
        for name in names:
            stem, _, suffix = name.rpartition(".")
            dist = re.sub(r"[-_.]+", "_", stem.partition("-")[0]).lower()
            if suffix not in ("dist-info", "egg-info") or dist in seen:
                continue
            seen.add(dist)
            try:
                text = Path(entry or ".", name, "entry_points.txt").read_text(encoding="utf-8")
            except (OSError, UnicodeDecodeError):
                continue
            found.extend(_section(text, group))
    return found


def _section(text: str, group: str) -> list[tuple[str, str]]:
    """The ``(name, value)`` lines of section ``[group]`` of an ``entry_points.txt``."""
    pairs, inside = [], False
    for line in filter(None, map(str.strip, text.splitlines())):
        if line.startswith("#"):
            continue
        if line.startswith("[") and line.endswith("]"):
            inside = line[1:-1].strip() == group
        elif inside:
            name, _, value = line.partition("=")
            pairs.append((name.strip(), value.strip()))
    return pairs


def _folder(value: str) -> Path | None:
    """The folder the entry point ``value`` names, or None when it cannot be loaded or is no path (a broken
    model distribution is a missing one, not a crash of every command)."""
    match = _VALUE.match(value)
    try:
        if match is None:
            raise ValueError(value)
        target = importlib.import_module(match["module"])
        for attr in filter(None, (match["attr"] or "").split(".")):
            target = getattr(target, attr)
        return Path(os.fspath(target))
    except (ImportError, AttributeError, TypeError, ValueError):
        return None


def shipped(name: str) -> Path | None:
    """The folder of the shipped model ``name``: keyfill's own (:data:`BUILTIN`) or an installed
    distribution's; None when neither has it."""
    own = BUILTIN / name
    if own.is_dir():
        return own
    return installed().get(name)


def missing(method: str, option: bool = True) -> ModelError:
    """The error of using ``method``'s shipped model when it is not installed: the alternative is the ``model``
    option (``option``) or a model folder in its place (``keyfill evaluate``/``export`` take one for the name)."""
    other = "model FOLDER, one of your own" if option else "a model folder of your own instead"
    return ModelError(f"the shipped {method} models are not installed: {HOW_TO_GET}; or give {other} "
                      f"(train one with 'keyfill train {method}')", params="model" if option else ())


def require(folder: str | os.PathLike | None, method: str) -> Path:
    """``folder`` as a :class:`~pathlib.Path`; :func:`missing`'s error for ``method`` when it is None."""
    if folder is None:
        raise missing(method)
    return Path(folder)
