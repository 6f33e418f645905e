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
import os
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


@functools.cache
def installed() -> dict[str, Path]:
    """Model name -> folder of every model an installed distribution announces (:data:`GROUP`), read once.

    An entry point that cannot be loaded or names no folder is left out (the model is then not installed).
    """
    from importlib.metadata import entry_points

    found: dict[str, Path] = {}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        folder = _folder(ep)
        if folder is not None and folder.is_dir():
            found.setdefault(ep.name, folder)
    return found


def _folder(ep) -> Path | None:
    """The folder entry point ``ep`` names, or None when it cannot be loaded or is no path (a broken model
    distribution is a missing one, not a crash of every command)."""
    try:
        return Path(os.fspath(ep.load()))
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
