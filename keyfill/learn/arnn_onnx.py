"""The lamp ARNN family run from an exported step graph with onnxruntime: no torch.

:class:`OnnxLampModel` has the ``predict(sequences)`` of a torch
:class:`keyfill.learn.arnn.LampModel`: the same numpy encoding and key
conditioning (:mod:`keyfill.learn.lamp_features`), then the step graph run
once per frame over the whole batch, each step fed the previous output and
state. :func:`complete_graph` is ``keyfill complete --method arnn --runtime onnx``.
"""

from __future__ import annotations

import numpy as np

from keyfill.errors import ModelError
from keyfill.learn.lamp_features import LampSequence, Normalizer, batch_arrays, conditioning, origin


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
        """As :meth:`keyfill.learn.arnn.LampModel.predict`."""
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
    from keyfill.learn.lamp_features import complete_lamp_many

    name = "lamp-arnn"  # the built-in model's name, as the torch path reports it
    results = complete_lamp_many(jobs, options, lambda: OnnxLampModel(graph), name)
    for r in results:
        if not isinstance(r, Exception):
            r.info["runtime"] = "onnx"
            if options.model is None:
                r.info["model"] = graph.path
    return results
