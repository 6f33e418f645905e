"""``keyfill evaluate`` as one library call: choose the protocol, run it, report.

Protocols (each a ``run(method_or_model, data, **options) -> Evaluation``
function, imported on first use):

* ``lafan1`` (:func:`keyfill.learn.protocols.lafan1.run`): Harvey et al. 2020's
  in-betweening benchmark on BVH clips (L2Q, L2P, NPSS);
* ``keys`` (:func:`keyfill.learn.protocols.keys.run`): the hopping lamp's test
  split with all keys and with 1-2 keys deleted (Zhang & van de Panne 2018,
  Tables 1-2).

A model folder (or a learned method's name) is scored with the protocol its
method names in :mod:`keyfill.learn.registry`; a baseline name is scored with
the protocol asked for, by default ``keys`` for a ``keyfill simulate`` folder
and ``lafan1`` otherwise.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from keyfill.errors import UsageError

#: protocol name -> "module:function" running it
PROTOCOLS = {"lafan1": "keyfill.learn.protocols.lafan1:run", "keys": "keyfill.learn.protocols.keys:run"}


@dataclass
class Evaluation:
    """Scores of one method (and the baselines beside it) under one protocol.

    Attributes:
        protocol: the protocol's name.
        method: what was scored (a method name or a model folder).
        info: a JSON-ready summary of the data (windows, clips, split).
        results: JSON-ready scores, ``{label: {...}}``.
        lines: one-line summaries for a person (the CLI prints them on stderr).
        table: the scores as a text table.
    """

    protocol: str
    method: str
    info: dict
    results: dict
    lines: list[str] = field(default_factory=list)
    table: str = ""

    def as_json(self) -> dict:
        return {"protocol": self.protocol, "method": self.method, **self.info, "results": self.results}


def is_lamp_dataset(data: Sequence[str]) -> bool:
    """``data`` is one folder made by ``keyfill simulate`` (it has a manifest.jsonl)."""
    return len(data) == 1 and (Path(data[0]) / "manifest.jsonl").is_file()


def choose_protocol(method_or_model: str, data: Sequence[str], protocol: str | None = None) -> str:
    """The protocol to run: the one of the model's method, else as asked, else the one for ``data``."""
    from keyfill.learn import registry

    if protocol is not None and protocol not in PROTOCOLS:
        raise UsageError(f"unknown protocol {protocol!r}; protocols are {', '.join(PROTOCOLS)}")
    method = None
    if method_or_model in registry.METHODS:
        method = registry.METHODS[method_or_model] if registry.METHODS[method_or_model].learned else None
    elif Path(method_or_model).exists():
        method = registry.method_for_model(method_or_model)
    want = method.protocol if method is not None else None
    if protocol is None:
        return want or ("keys" if is_lamp_dataset(data) else "lafan1")
    if want is not None and protocol != want:
        raise UsageError(f"{method_or_model}: a model of kind {method.name!r} is scored with protocol {want}, "
                         f"not {protocol}", params="protocol")
    return protocol


def evaluate(method_or_model: str, data: Sequence[str], protocol: str | None = None, **options) -> Evaluation:
    """Score ``method_or_model`` on ``data`` (files or folders); ``options`` go to the protocol's ``run``."""
    name = choose_protocol(method_or_model, data, protocol)
    module, attr = PROTOCOLS[name].split(":")
    return getattr(importlib.import_module(module), attr)(method_or_model, data, **options)
