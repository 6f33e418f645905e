"""The registry of in-betweening methods behind ``keyfill complete``.

A method is a function ``(motion, keys, options) -> Completion``. It reads only
the key frames of ``motion`` (and, for learned methods, a model) and returns a
motion with every frame filled and ``keys`` attached. Register new methods in
:data:`METHODS` as ``"module:function"`` so that importing this module stays
cheap (torch is imported only by the methods that need it).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

from keyfill.errors import UsageError
from keyfill.motion import Keys, Motion

#: method name -> "module:function"
METHODS: dict[str, str] = {
    "linear": "keyfill.learn.methods:_linear",
    "cubic": "keyfill.learn.methods:_cubic",
    "transformer": "keyfill.learn.transformer:complete_method",
    "arnn": "keyfill.learn.arnn:complete",
}
#: methods that need no model file
SPLINES = ("linear", "cubic")


@dataclass(frozen=True)
class CompleteOptions:
    """Options of a completion.

    Attributes:
        model: path of a model file or folder (learned methods), or None for the default.
        exact_keys: make frames at keys equal the input keys exactly.
        seed: seed for any randomness (e.g. dropout sampling, GAN noise).
        device: torch device for learned methods (``"cpu"``, ``"cuda"``).
    """

    model: str | None = None
    exact_keys: bool = True
    seed: int = 0
    device: str = "cpu"


@dataclass
class Completion:
    """The result of a completion: the filled motion and a JSON-ready report."""

    motion: Motion
    info: dict = field(default_factory=dict)


def _linear(motion: Motion, keys: Keys, options: CompleteOptions) -> Completion:
    from keyfill.learn.baselines import linear

    return Completion(linear(motion, keys), {"exact_keys": True})


def _cubic(motion: Motion, keys: Keys, options: CompleteOptions) -> Completion:
    from keyfill.learn.baselines import cubic

    return Completion(cubic(motion, keys), {"exact_keys": True})


def get(name: str):
    """The completion function registered as ``name``."""
    if name not in METHODS:
        raise UsageError(f"unknown method {name!r}; methods are: {', '.join(METHODS)}")
    module, attr = METHODS[name].split(":")
    return getattr(importlib.import_module(module), attr)


def _check_kind(model: str, method: str) -> None:
    """A model folder made for another method is a usage error that names the right method."""
    from keyfill.learn.modelfile import read_config

    kind = read_config(model)["kind"]
    if kind != method:
        hint = f"; complete with --method {kind}" if kind in METHODS else ""
        raise UsageError(f"{model}: a model of kind {kind!r}, not {method!r}{hint}")


def complete(motion: Motion, keys: Keys, method: str = "cubic", options: CompleteOptions | None = None) -> Completion:
    """Fill the frames between ``keys`` of ``motion`` with ``method``."""
    options = options or CompleteOptions()
    keys = keys.check(motion.num_frames, min_keys=2)
    if method in SPLINES and options.model is not None:
        raise UsageError(f"--model applies to learned methods, not to {method!r}")
    if options.model is not None:
        _check_kind(options.model, method)
    result = get(method)(motion, keys, options)
    result.info = {"method": method, "keys": keys.to_list(), "frames": motion.num_frames, **result.info}
    return result
