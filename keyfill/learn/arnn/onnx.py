"""The lamp ARNN family run from an exported step graph with onnxruntime: no torch.

:class:`OnnxLampModel` has the ``predict(sequences)`` of a torch
:class:`keyfill.learn.arnn.model.LampModel`: the same numpy encoding and key
conditioning (:mod:`keyfill.learn.arnn.features`), then the step graph run
once per frame over the whole batch, each step fed the previous output and
state. :func:`complete_graph` is ``keyfill complete --method arnn --runtime onnx``.
"""

from __future__ import annotations

import numpy as np

from keyfill.errors import ModelError
from keyfill.learn.arnn.features import batch_arrays, conditioning
from keyfill.learn.arnn.model import KIND
from keyfill.learn.lamp_data import NUM_VARIABLES, LampSequence, Normalizer, origin


class OnnxLampModel:
    """A lamp model whose network is an exported step graph (:class:`keyfill.learn.onnx.Graph`)."""

    def __init__(self, graph):
        self.graph = graph
        self.config = graph.config
        self.path = graph.path
        try:
            self.normalizer = Normalizer.from_json(self.config["normalizer"])
            self.arch = self.config["arch"]
            self.state_size = int(graph.contract["state_size"])
        except (KeyError, TypeError, ValueError) as e:
            raise ModelError(f"{graph.path}: damaged lamp model metadata ({e})") from None

    def predict(self, sequences: list[LampSequence]) -> list[np.ndarray]:
        """As :meth:`keyfill.learn.arnn.model.LampModel.predict`."""
        frames, is_key, _, lengths = batch_arrays(sequences, self.normalizer)
        x_prev, x_next, t_rel, _ = conditioning(frames, is_key)
        B, T = is_key.shape
        y = frames[:, 0]
        state = np.zeros((B, 2, self.state_size), dtype=np.float32)
        pred = np.empty((B, T - 1, frames.shape[-1]), dtype=np.float32)
        for t in range(T - 1):
            y, state = self.graph.run({"y_prev": y, "key_before": np.ascontiguousarray(x_prev[:, t]),
                                       "key_after": np.ascontiguousarray(x_next[:, t]),
                                       "t_rel": np.ascontiguousarray(t_rel[:, t]), "state": state})
            pred[:, t] = y
        out = []
        for b, s in enumerate(sequences):
            n = int(lengths[b])
            z = np.concatenate([frames[b, :1], pred[b, : n - 1]]).astype(np.float64)
            out.append(self.normalizer.decode(z, origin(s.values[s.keys[0]])))
        return out


def complete_graph(jobs, options, graph):
    """``keyfill complete --method arnn`` through the graph: a Completion or the error, per job."""
    from keyfill.learn.arnn.model import complete_lamp_many

    name = "lamp-arnn"  # the built-in model's name, as the torch path reports it
    results = complete_lamp_many(jobs, options, lambda: OnnxLampModel(graph), name)
    for r in results:
        if not isinstance(r, Exception):
            r.info["runtime"] = "onnx"
            if options.model is None:
                r.info["model"] = graph.path
    return results


#: what a lamp step graph takes and gives (written into its metadata; docs/onnx.md explains the loop)
STEP_CONTRACT = {
    "graph": "one step of the autoregressive loop: frame t from frame t-1, the keys around t and a state",
    "inputs": {
        "y_prev": ["batch", 6, "float32", "encoded frame t-1 (frame 0: the first key)"],
        "key_before": ["batch", 6, "float32", "encoded key X_K at or before t-1 (the last key before t)"],
        "key_after": ["batch", 6, "float32", "encoded key X_K+1 at or after t"],
        "t_rel": ["batch", 1, "float32", "(t - T_K) / (T_K+1 - T_K), 1 on a key's own frame"],
        "state": ["batch", 2, "state_size", "float32", "recurrent state: zeros at t = 1, then state_out"],
    },
    "outputs": {
        "y": ["batch", 6, "float32", "encoded frame t"],
        "state_out": ["batch", 2, "state_size", "float32", "the state for frame t+1"],
    },
    "encoding": "variables base_x, base_y (m), base/leg/neck/head angle (rad); relative: base_x minus the first "
                "key's, angles less the whole turns of the first key's; then (v - normalizer.mean) / normalizer.std",
}


def export_onnx(model, folder, path) -> None:
    """Write ``model`` (loaded from the model folder ``folder``) as a step graph to ``path`` (atomically)."""
    import torch

    from keyfill.learn.arnn.network import StepGraph, state_size
    from keyfill.learn.modelfile import read_config
    from keyfill.learn.onnx import export_module, metadata

    H = state_size(model.net)
    args = (torch.zeros(2, NUM_VARIABLES), torch.zeros(2, NUM_VARIABLES), torch.zeros(2, NUM_VARIABLES),
            torch.ones(2, 1), torch.zeros(2, 2, H))
    batch = torch.export.Dim("batch")
    contract = {**STEP_CONTRACT, "state_size": H}
    export_module(StepGraph(model.net), args, path, list(STEP_CONTRACT["inputs"]), list(STEP_CONTRACT["outputs"]),
                  tuple({0: batch} for _ in STEP_CONTRACT["inputs"]), metadata(KIND, folder, read_config(folder), contract))
