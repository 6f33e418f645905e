"""Exported graphs of learned models (ONNX): their metadata, finding one, and running it without torch.

``keyfill export MODEL`` writes a method's network as an ONNX graph (the
method's ``export_onnx``, which needs torch). The graph carries, in its
``metadata_props`` (see docs/onnx.md, the contract):

* ``keyfill.format`` = ``keyfill-onnx``, ``keyfill.version`` = ``1``;
* ``keyfill.kind``: the method (``arnn``, ``transformer``);
* ``keyfill.config``: the model folder's ``config.json`` (normalisation
  statistics, skeleton, architecture), so a graph is usable on its own;
* ``keyfill.weights_sha256``: the SHA-256 of the ``weights.safetensors`` it
  was exported from, which binds the graph to its model folder: a graph
  beside other weights is refused;
* ``keyfill.contract``: the inputs and outputs as JSON.

This module imports no torch: ``keyfill complete --runtime onnx`` runs the
graph through onnxruntime, with the method's numpy pre- and post-processing.
"""

from __future__ import annotations

import functools
import importlib.util
import json
import os
from pathlib import Path

from keyfill.errors import ModelError, UsageError

#: the graph's file name in a model folder
GRAPH = "model.onnx"
FORMAT = "keyfill-onnx"
VERSION = "1"
RUNTIMES = ("auto", "torch", "onnx")


def weights_digest(folder: str | os.PathLike) -> str:
    """SHA-256 (hex) of a model folder's ``weights.safetensors``."""
    from keyfill.files import sha256_file
    from keyfill.learn.modelfile import WEIGHTS

    return sha256_file(Path(folder) / WEIGHTS)


def metadata(kind: str, folder: str | os.PathLike, config: dict, contract: dict) -> dict[str, str]:
    """The ``metadata_props`` of a graph exported from the model folder ``folder``."""
    return {"keyfill.format": FORMAT, "keyfill.version": VERSION, "keyfill.kind": kind,
            "keyfill.config": json.dumps(config, sort_keys=True), "keyfill.weights_sha256": weights_digest(folder),
            "keyfill.contract": json.dumps(contract, sort_keys=True)}


def available() -> bool:
    """Whether onnxruntime is installed."""
    return importlib.util.find_spec("onnxruntime") is not None


class Graph:
    """An exported graph opened with onnxruntime (one thread, like keyfill's numpy work)."""

    def __init__(self, path: str | os.PathLike):
        if not available():
            raise UsageError("running an exported graph needs onnxruntime: pip install 'keyfill[onnx]'")
        import onnxruntime as ort

        self.path = str(path)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        opts.enable_cpu_mem_arena = False
        try:
            self.session = ort.InferenceSession(self.path, opts, providers=["CPUExecutionProvider"])
        except Exception as e:  # noqa: BLE001 - onnxruntime raises its own exception types, not a hierarchy
            raise ModelError(f"{path}: not a readable ONNX graph ({' '.join(str(e).split())[:200]})") from None
        meta = self.session.get_modelmeta().custom_metadata_map
        if meta.get("keyfill.format") != FORMAT:
            raise ModelError(f"{path}: an ONNX graph that keyfill did not export (no keyfill metadata)")
        if meta.get("keyfill.version") != VERSION:
            raise ModelError(f"{path}: keyfill graph version {meta.get('keyfill.version')!r}; this keyfill reads {VERSION}")
        try:
            self.kind = meta["keyfill.kind"]
            self.config = json.loads(meta["keyfill.config"])
            self.weights_sha256 = meta["keyfill.weights_sha256"]
            self.contract = json.loads(meta["keyfill.contract"])
            self.metadata = dict(meta)  # a method's own keys too (the gan's keyfill.dna_bank)
        except (KeyError, ValueError) as e:
            raise ModelError(f"{path}: damaged keyfill metadata ({e})") from None

    def run(self, inputs: dict) -> list:
        """The graph's outputs for ``inputs`` (name -> numpy array)."""
        return self.session.run(None, inputs)


@functools.lru_cache(maxsize=4)
def _open(path: str, stamp: tuple) -> Graph:
    return Graph(path)


def open_graph(path: str | os.PathLike) -> Graph:
    """:class:`Graph`, kept open while the file stays unchanged (a batch opens it once per process)."""
    st = os.stat(path)
    return _open(str(path), (st.st_mtime_ns, st.st_size))


def is_graph(model: str | os.PathLike | None) -> bool:
    """Whether ``--model`` names a graph file rather than a model folder."""
    return model is not None and str(model).lower().endswith(".onnx") and not Path(model).is_dir()


def check_binding(graph: Graph, folder: Path) -> None:
    """:class:`ModelError` unless ``graph`` was exported from the model folder ``folder``: the folder's weights
    must hash to the graph's ``keyfill.weights_sha256`` (:func:`keyfill.files.verified`: hashed once per state
    of the file, not on every run)."""
    from keyfill.files import verified
    from keyfill.learn.modelfile import WEIGHTS, read_config

    kind = read_config(folder)["kind"]
    if graph.kind != kind:
        raise ModelError(f"{graph.path}: a graph of a {graph.kind!r} model in a {kind!r} model folder; "
                         f"export it again with 'keyfill export {folder}'")
    if not (folder / WEIGHTS).is_file() or not verified(folder / WEIGHTS, graph.weights_sha256):
        raise ModelError(f"{graph.path}: exported from other weights than {folder / WEIGHTS}; "
                         f"export it again with 'keyfill export {folder}'")
    if read_config(folder) != graph.config:  # the graph runs with the settings it was exported with
        raise ModelError(f"{graph.path}: exported with another config.json than {folder}'s; "
                         f"export it again with 'keyfill export {folder}'")


def select(method, model: str | None, runtime: str, device: str = "cpu") -> Graph | None:
    """The graph that completes with ``method`` (a registry entry), or None for the torch path.

    ``runtime``: ``torch`` never uses a graph; ``onnx`` requires one (the
    ``--model`` graph file, or ``model.onnx`` in the model folder); ``auto``
    uses one when onnxruntime is installed and the folder holds a graph.
    Graphs run on the CPU: a ``device`` other than ``"cpu"`` takes the torch
    path under ``auto`` (unless ``model`` is a graph file) and is refused under ``onnx``.
    """
    if runtime not in RUNTIMES:
        raise UsageError(f"runtime is one of {', '.join(RUNTIMES)}, not {runtime!r}", params="runtime")
    if device != "cpu" and method.learned:
        if runtime == "onnx":
            raise UsageError(f"device {device} needs runtime torch: an ONNX graph runs on the CPU",
                             params=("device", "runtime"))
        if runtime == "auto" and not is_graph(model):
            return None
    if is_graph(model):
        if runtime == "torch":
            raise UsageError(f"{model}: an ONNX graph runs with runtime onnx (or auto), not torch", params="runtime")
        if not Path(model).is_file():
            raise ModelError(f"{model}: no such graph")
        graph = open_graph(model)
        if graph.kind != method.name:
            raise UsageError(f"{model}: a graph of a {graph.kind!r} model, not {method.name!r}; "
                             f"complete with method {graph.kind}", params="method")
        return graph
    if runtime == "torch" or not method.learned or method.onnx is None:
        if runtime == "onnx" and (not method.learned or method.onnx is None):
            raise UsageError(f"the {method.name} method has no ONNX runtime")
        return None
    if model is not None:
        folder, label = Path(model), str(model)
    else:
        folder, label = method.default_model(), f"the built-in {method.name} model"
        if folder is None:
            return None  # the method reports its missing model itself
    from keyfill.learn.modelfile import model_folder

    folder = model_folder(folder)
    path = folder / GRAPH
    if not path.is_file():
        if runtime == "onnx":
            target = method.name if model is None else str(folder)
            out = f" -o {method.name}.onnx" if model is None else ""
            hint = f" and give --model {method.name}.onnx" if model is None else ""
            raise ModelError(f"{label} has no exported graph ({path.name}); export one with "
                             f"'keyfill export {target}{out}'{hint}")
        return None
    if not available():
        if runtime == "onnx":
            raise UsageError("runtime onnx needs onnxruntime: pip install 'keyfill[onnx]'", params="runtime")
        return None
    graph = open_graph(path)
    check_binding(graph, folder)
    return graph


def write_graph(path: str | os.PathLike, meta: dict[str, str]) -> None:
    """Add ``meta`` to the ``metadata_props`` of the graph file ``path`` (with the onnx package)."""
    import onnx

    graph = onnx.load(str(path))
    del graph.metadata_props[:]
    for key, value in meta.items():
        graph.metadata_props.append(onnx.StringStringEntryProto(key=key, value=value))
    graph.producer_name = "keyfill"
    onnx.save(graph, str(path))


def export_module(module, args: tuple, path: str | os.PathLike, inputs: list[str], outputs: list[str],
                  dynamic_shapes: tuple, meta: dict[str, str]) -> None:
    """``torch.onnx.export`` of ``module`` (one file, weights inside) with ``meta``, written atomically.

    The one place keyfill calls the exporter (torch's dynamo exporter with
    onnxscript); its log lines and warnings are kept quiet.
    """
    import logging
    import warnings

    import torch

    from keyfill.files import atomic_output

    log = logging.getLogger("torch.onnx")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        with atomic_output(path) as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with torch.no_grad():
                torch.onnx.export(module.eval(), args, str(tmp), input_names=inputs, output_names=outputs,
                                  dynamo=True, external_data=False, dynamic_shapes=dynamic_shapes, verbose=False)
            write_graph(tmp, meta)
    finally:
        log.setLevel(level)
