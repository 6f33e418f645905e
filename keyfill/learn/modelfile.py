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
:func:`load_model` checks both files (the config against the one schema of
:mod:`keyfill.learn.config_schema`) and raises :class:`ModelError` with one
clear line for anything that is not an intact keyfill model.
"""

from __future__ import annotations

import contextvars
import functools
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from keyfill.errors import ModelError, UsageError
from keyfill.limits import json_finite as _finite
from keyfill.limits import json_int64 as _int64
from keyfill.limits import json_no_constant as _no_constant
from keyfill.motion import Skeleton

FORMAT = "keyfill-model"
VERSION = 1
CONFIG = "config.json"
WEIGHTS = "weights.safetensors"
#: a config.json larger than this is not read (the shipped ones are a few kB)
MAX_CONFIG_BYTES = 16 * 2**20
#: numbers of the weights file :func:`load_model` read last (in this context), which the network that
#: :func:`build_for_loading` builds must match before it is given memory
_LOADED_NUMEL: contextvars.ContextVar = contextvars.ContextVar("keyfill_loaded_numel", default=None)


def bounded_array(values, what: str, shape: tuple | None = None, above: float | None = None) -> np.ndarray:
    """``values`` (numbers of a model config) as a float64 array, or a ``ValueError`` naming ``what``.

    Every value must be at most ``keyfill.limits.max_abs()`` in size and, where ``above`` is given,
    greater than it; the array must have ``shape`` where given. Statistics and limits that training
    stores are far inside these bounds; beyond them the arithmetic that uses them overflows.
    """
    from keyfill.limits import max_abs

    a = np.asarray(values, dtype=np.float64)
    if shape is not None and a.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, not {a.shape}")
    if not np.all(np.abs(a) <= max_abs()) or (above is not None and not np.all(a > above)):
        raise ValueError(f"{what} must be numbers of at most {max_abs():g} in size"
                         + (f" and over {above:g}" if above is not None else ""))
    return a


def check_skeleton(config: dict, skeleton: Skeleton, path: str | os.PathLike = "the model") -> None:
    """Raise :class:`ModelError` unless ``skeleton`` is the one the model was trained for."""
    model_sk = Skeleton.from_json({k: config["skeleton"][k] for k in ("names", "parents", "offsets")})
    diff = model_sk.difference(skeleton, atol=1e-4 * max(1.0, float(np.abs(model_sk.offsets).max(initial=0))))
    if diff is not None:
        raise ModelError(f"{path}: the model was made for another skeleton ({diff})")


def save_model(path: str | os.PathLike, kind: str, tensors: dict, config: dict) -> Path:
    """Write a model folder atomically; replaces an existing model at ``path``.

    Args:
        kind: architecture family, e.g. ``"arnn"``.
        tensors: name -> torch tensor (a ``state_dict``).
        config: JSON-ready settings; must include ``"skeleton"`` (:meth:`Skeleton.to_json`).
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


_CHECKED: dict[bytes, None] = {}  # the SHA-256 of config bytes that passed the schema check (insertion order)


def read_config(path: str | os.PathLike, kind: str | None = None) -> dict:
    """The validated ``config.json`` of the model at ``path`` (parsed afresh each call).

    Bytes that passed the schema check before are not checked again (the check takes a few ms, and one
    completion through the rig bridge asks for the config three times)."""
    folder = model_folder(path)
    try:
        size = (folder / CONFIG).stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ModelError(f"{folder}: its {CONFIG} is {size} bytes; a model config is at most {MAX_CONFIG_BYTES}")
        data = (folder / CONFIG).read_bytes()
    except OSError as e:
        raise ModelError(f"{folder}: damaged model config ({' '.join(str(e).split())[:200]})") from None
    config = _parse_config(data, folder)
    if kind is not None and config.get("kind") != kind:  # before the schema: a model of another kind is that
        raise ModelError(f"{folder}: a {config.get('kind')!r} model, not a {kind!r} model")
    digest = hashlib.sha256(data).digest()
    if digest not in _CHECKED:
        from keyfill.learn.config_schema import check_config

        check_config(config, folder / CONFIG)  # every field the loaders use, by the one schema of every kind
        if len(_CHECKED) >= 64:
            _CHECKED.pop(next(iter(_CHECKED)))
        _CHECKED[digest] = None
    return config


def _parse_config(data: bytes, folder: Path) -> dict:
    """The config of :func:`read_config` from the bytes of ``folder``'s ``config.json``: parsed, of the keyfill
    model format and version, naming its kind (not yet checked against its kind's schema)."""
    try:
        # NaN, Infinity, 1e999 and integers beyond 64 bits are refused; deep nesting raises RecursionError
        config = json.loads(data.decode("utf-8"), parse_constant=_no_constant, parse_int=_int64, parse_float=_finite)
    except (UnicodeDecodeError, ValueError) as e:
        raise ModelError(f"{folder}: damaged model config ({' '.join(str(e).split())[:200]})") from None
    except RecursionError:
        raise ModelError(f"{folder}: damaged model config (nested too deeply)") from None
    if not isinstance(config, dict) or config.get("format") != FORMAT:
        raise ModelError(f"{folder}: not a keyfill model (its {CONFIG} has no format '{FORMAT}')")
    if config.get("version") != VERSION:
        raise ModelError(f"{folder}: model format version {config.get('version')!r}; this keyfill reads {VERSION}")
    if not isinstance(config.get("kind"), str):
        raise ModelError(f"{folder}: the model config names no kind (the method that made it)")
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
    except (SafetensorError, OSError, ValueError, RuntimeError) as e:
        raise ModelError(f"{weights}: damaged or truncated weights ({' '.join(str(e).split())[:300]})") from None
    bad = next((k for k, t in tensors.items() if t.is_floating_point() and not bool(t.isfinite().all())), None)
    if bad is not None:
        raise ModelError(f"{weights}: the weights {bad!r} hold values that are not finite")
    _LOADED_NUMEL.set((str(weights.parent), sum(t.numel() for t in tensors.values())))
    return tensors, config


#: initialisers whose work is thrown away on the meta device (on it, torch decomposes some of them
#: in Python, importing torch._refs: 10 s the first time on a busy 2-core machine)
_INITS = frozenset({"normal_", "uniform_", "trunc_normal_", "orthogonal_", "xavier_normal_", "xavier_uniform_",
                    "kaiming_normal_", "kaiming_uniform_", "sparse_", "constant_", "zeros_", "ones_", "eye_",
                    "dirac_", "bernoulli_", "exponential_", "geometric_", "log_normal_", "cauchy_", "random_"})


def _skip_init():
    """A torch function mode in which initialisers of meta tensors do nothing (their values never exist)."""
    import torch
    from torch.overrides import TorchFunctionMode

    class SkipInit(TorchFunctionMode):
        def __torch_function__(self, func, types, args=(), kwargs=None):
            kwargs = kwargs or {}
            if getattr(func, "__name__", "") in _INITS:
                target = args[0] if args else kwargs.get("tensor")
                if isinstance(target, torch.Tensor) and target.is_meta:
                    return target
            return func(*args, **kwargs)

    return SkipInit()


def build_for_loading(factory):
    """``factory()``, a network whose weights are about to be loaded, built without
    drawing from torch's global generator (its initial weights are thrown away, so
    loading a model leaves the caller's random stream as it was)."""
    import torch

    loaded = _LOADED_NUMEL.get()
    _LOADED_NUMEL.set(None)
    if loaded is not None:
        # Build it first on the meta device (no memory): a config whose sizes ask for more numbers than
        # the weights file holds (hidden_size 30000: tens of GB) is refused before it is allocated.
        folder, numel = loaded
        try:
            with torch.device("meta"), torch.random.fork_rng(devices=[]), _skip_init():
                shape = factory()
            modules = [shape] if isinstance(shape, torch.nn.Module) else [
                m for m in vars(shape).values() if isinstance(m, torch.nn.Module)]  # a wrapper holding its network
            wanted = sum(t.numel() for m in modules for t in m.state_dict().values()) if modules else None
        except (KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError, NotImplementedError,
                OverflowError):
            wanted = None  # not buildable on meta: the real build below reports what is wrong
        if wanted is not None and wanted != numel:
            raise ModelError(
                f"{folder}: the weights do not fit the model's configuration "
                f"(it describes a network of {wanted} numbers, the weights hold {numel})"
            )
    with torch.random.fork_rng(devices=[]):
        return factory()


def load_state(module, tensors: dict, path: str | os.PathLike) -> None:
    """``module.load_state_dict(tensors)``, with a :class:`ModelError` when the tensors do not fit."""
    try:
        module.load_state_dict(tensors, strict=True)
    except (RuntimeError, ValueError, TypeError) as e:
        first = str(e).strip().splitlines()[0]
        raise ModelError(f"{path}: the weights do not fit the model's configuration ({first})") from None


def load_cached(loader, path: str | os.PathLike, device: str = "cpu"):
    """``loader(path, device)``, remembering the last few models while their two files stay unchanged
    (modification time and size), so a batch or a repeated call loads a model folder once."""
    folder = model_folder(path)
    stamp = tuple((f.stat().st_mtime_ns, f.stat().st_size) if f.is_file() else None
                  for f in (folder / CONFIG, folder / WEIGHTS))
    return _load_cached(loader, str(path), device, stamp)


@functools.lru_cache(maxsize=8)
def _load_cached(loader, path: str, device: str, stamp: tuple):
    return loader(path, device)


#: the torch device types keyfill runs its networks on (``meta`` holds no data, ``xla``, ``mps`` and the
#: others are not in the torch keyfill installs)
DEVICE_TYPES = ("cpu", "cuda")


def torch_device(name: str):
    """``torch.device(name)``, or a :class:`UsageError` (naming the parameter ``device``) when it is not a
    device keyfill can run on here: ``cpu``, or ``cuda`` / ``cuda:N`` with such a GPU."""
    import torch

    try:
        dev = torch.device(name)
    except (RuntimeError, ValueError):
        raise UsageError(f"unknown torch device {name!r}; use cpu, cuda or cuda:N") from None
    if dev.type not in DEVICE_TYPES:
        raise UsageError(f"device {name!r} is not one keyfill runs on; use cpu, cuda or cuda:N", params="device")
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise UsageError(f"{name!r} was asked for, but torch sees no CUDA GPU here; use device cpu", params="device")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise UsageError(f"{name!r} was asked for, but torch sees {torch.cuda.device_count()} CUDA GPU(s) here "
                         f"(cuda:0 to cuda:{torch.cuda.device_count() - 1})", params="device")
    return dev
