"""Model files shared by every learned method.

A keyfill model is a folder holding two files:

* ``config.json``: ``{"format": "keyfill-model", "version": 1, "kind": ...,
  "skeleton": ..., ...}``; ``kind`` names the architecture family (``"arnn"``,
  ``"transformer"``), ``skeleton`` the skeleton the model serves (joint names,
  parents, rest offsets), and the rest is the method's own configuration
  (layer sizes, normalisation statistics, training settings).
* ``weights.safetensors``: the tensors. safetensors holds only arrays, so
  loading a model never executes code from the file.

:func:`save_model` writes the folder atomically (a finished model or none);
:func:`load_model` checks both files and raises :class:`ModelError` with one
clear line for anything that is not an intact keyfill model.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from keyfill.errors import ModelError, UsageError
from keyfill.motion import Skeleton

FORMAT = "keyfill-model"
VERSION = 1
CONFIG = "config.json"
WEIGHTS = "weights.safetensors"


def skeleton_to_json(skeleton: Skeleton) -> dict:
    """The parts of ``skeleton`` a model depends on, as JSON."""
    return {
        "names": list(skeleton.names),
        "parents": [int(p) for p in skeleton.parents],
        "offsets": skeleton.offsets.tolist(),
    }


def check_skeleton(config: dict, skeleton: Skeleton, path: str | os.PathLike = "the model") -> None:
    """Raise :class:`ModelError` unless ``skeleton`` is the one the model was trained for."""
    want = config["skeleton"]
    model_sk = Skeleton(
        names=tuple(want["names"]),
        parents=np.array(want["parents"]),
        offsets=np.array(want["offsets"]),
        channels=tuple(() for _ in want["names"]),
    )
    diff = model_sk.difference(skeleton, atol=1e-4 * max(1.0, float(np.abs(model_sk.offsets).max(initial=0))))
    if diff is not None:
        raise ModelError(f"{path}: the model was made for another skeleton ({diff})")


def save_model(path: str | os.PathLike, kind: str, tensors: dict, config: dict) -> Path:
    """Write a model folder atomically; replaces an existing model at ``path``.

    Args:
        kind: architecture family, e.g. ``"arnn"``.
        tensors: name -> torch tensor (a ``state_dict``).
        config: JSON-ready settings; must include ``"skeleton"`` (see :func:`skeleton_to_json`).
    """
    from safetensors.torch import save_file

    path = Path(path)
    if "skeleton" not in config:
        raise ValueError("a model config needs the skeleton it serves")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{path}: the folder {str(parent)!r} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", dir=parent))
    try:
        full = {"format": FORMAT, "version": VERSION, "kind": kind, **config}
        (tmp / CONFIG).write_text(json.dumps(full, indent=2, sort_keys=True) + "\n")
        save_file({k: v.detach().contiguous().cpu() for k, v in tensors.items()}, str(tmp / WEIGHTS))
        # mkdtemp makes the folder owner-only and safetensors the weights; give
        # both the modes of any new folder and file (subject to the umask).
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)
        os.chmod(tmp / WEIGHTS, 0o666 & ~umask)
        old = None
        if path.exists():
            if not (path / CONFIG).is_file():
                raise UsageError(f"{path}: exists and is not a keyfill model; refusing to replace it")
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old.", dir=parent))
            os.replace(path, old / "model")
        os.replace(tmp, path)
        if old is not None:
            shutil.rmtree(old)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def model_folder(path: str | os.PathLike) -> Path:
    """The model folder for ``path`` (the folder, or a file inside it)."""
    p = Path(path)
    if p.is_file() and p.name in (CONFIG, WEIGHTS):
        p = p.parent
    if not p.exists():
        raise ModelError(f"{p}: no such model")
    if not p.is_dir() or not (p / CONFIG).is_file():
        raise ModelError(f"{p}: not a keyfill model (expected a folder with {CONFIG} and {WEIGHTS})")
    return p


def read_config(path: str | os.PathLike, kind: str | None = None) -> dict:
    """The validated ``config.json`` of the model at ``path``."""
    folder = model_folder(path)
    try:
        config = json.loads((folder / CONFIG).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ModelError(f"{folder}: damaged model config ({e})") from None
    if not isinstance(config, dict) or config.get("format") != FORMAT:
        raise ModelError(f"{folder}: not a keyfill model (its {CONFIG} has no format '{FORMAT}')")
    if config.get("version") != VERSION:
        raise ModelError(f"{folder}: model format version {config.get('version')!r}; this keyfill reads {VERSION}")
    if kind is not None and config.get("kind") != kind:
        raise ModelError(f"{folder}: a {config.get('kind')!r} model, not a {kind!r} model")
    if "skeleton" not in config:
        raise ModelError(f"{folder}: the model config names no skeleton")
    return config


def load_model(path: str | os.PathLike, kind: str | None = None) -> tuple[dict, dict]:
    """Read a model folder: ``(tensors: name -> torch tensor, config)``.

    Raises :class:`ModelError` for a missing, foreign, damaged or truncated
    model, or one of another ``kind``.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    config = read_config(path, kind)
    weights = model_folder(path) / WEIGHTS
    if not weights.is_file():
        raise ModelError(f"{weights.parent}: the model has no {WEIGHTS}")
    try:
        tensors = load_file(str(weights))
    except (SafetensorError, OSError, ValueError) as e:
        raise ModelError(f"{weights}: damaged or truncated weights ({' '.join(str(e).split())})") from None
    return tensors, config


def build_for_loading(factory):
    """``factory()``, a network whose weights are about to be loaded, built without
    drawing from torch's global generator (its initial weights are thrown away, so
    loading a model leaves the caller's random stream as it was)."""
    import torch

    with torch.random.fork_rng(devices=[]):
        return factory()


def load_state(module, tensors: dict, path: str | os.PathLike) -> None:
    """``module.load_state_dict(tensors)``, with a :class:`ModelError` when the tensors do not fit."""
    try:
        module.load_state_dict(tensors, strict=True)
    except RuntimeError as e:
        first = str(e).strip().splitlines()[0]
        raise ModelError(f"{path}: the weights do not fit the model's configuration ({first})") from None
