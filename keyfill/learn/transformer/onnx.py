"""The transformer as an exported ONNX graph: export (torch) and the graph runtime (no torch).

``keyfill export`` writes the whole network with :func:`export_onnx`; ``keyfill
complete --method transformer --runtime onnx`` runs it with :func:`complete_graph`:
the same numpy pre- and post-processing as the torch path
(:mod:`keyfill.learn.transformer.features`), the network replaced by the graph.
The contract an engine follows is :data:`CONTRACT` (and docs/onnx.md).
"""

from __future__ import annotations

import numpy as np

from keyfill.errors import KeyfillError, ModelError
from keyfill.learn.transformer.model import KIND, CompletionModel, complete_many_with, config_parts, features_for

#: what a transformer graph takes and gives (written into its metadata; docs/onnx.md)
CONTRACT = {
    "graph": "the whole network: pre-filled, encoded frames of windows and the kind of each frame -> "
             "completed encoded frames",
    "inputs": {
        "features": ["batch", "frames", "feature_size", "float32",
                     "frames in the canonical frame, unknown frames pre-filled by LERP/SLERP, encoded by Features"],
        "kinds": ["batch", "frames", "int64", "0 key, 1 unknown (to fill), 2 ignored (outside the keys)"],
    },
    "outputs": {"completed": ["batch", "frames", "feature_size", "float32", "completed encoded frames"]},
}


class GraphNetwork:
    """The transformer network as an exported graph: ``(x (B, T, F) float64, kinds (B, T)) -> (B, T, F) float64``."""

    numpy_io = True  # CompletionModel feeds it numpy arrays instead of torch tensors

    def __init__(self, graph):
        self.graph = graph

    def __call__(self, x: np.ndarray, kinds: np.ndarray) -> np.ndarray:
        y = self.graph.run({"features": np.ascontiguousarray(x, dtype=np.float32),
                            "kinds": np.ascontiguousarray(kinds, dtype=np.int64)})[0]
        return y.astype(np.float64)


def model_from_graph(graph) -> CompletionModel:
    """A :class:`CompletionModel` whose network is an exported graph (:class:`keyfill.learn.onnx.Graph`)."""
    model = getattr(graph, "_transformer_model", None)
    if model is None:
        try:
            cfg, skel, st, folded, training = config_parts(graph.config)
            model = CompletionModel(cfg, skel, features_for(skel, cfg, st["pos_mean"], st["pos_std"]),
                                    GraphNetwork(graph), folded, dict(training or {}))
        except (KeyError, TypeError, ValueError, KeyfillError) as e:
            raise ModelError(f"{graph.path}: damaged transformer model metadata ({e})") from None
        graph._transformer_model = model
    return model


def complete_graph(jobs, options, graph):
    """``keyfill complete --method transformer`` through an exported graph: a Completion or the error, per job."""
    return complete_many_with(model_from_graph(graph), jobs, options, {"runtime": "onnx"})


def export_onnx(model: CompletionModel, folder, path) -> None:
    """Write ``model``'s network (loaded from the model folder ``folder``) as a graph to ``path`` (atomically).

    Batch and frame counts are free (frames up to the model's window).
    """
    import torch

    from keyfill.learn.modelfile import read_config
    from keyfill.learn.onnx import export_module, metadata

    T = min(30, model.config.max_frames)
    args = (torch.zeros(2, T, model.features.size), torch.zeros(2, T, dtype=torch.int64))
    batch, frames = torch.export.Dim("batch"), torch.export.Dim("frames", min=2, max=model.config.max_frames)
    contract = {**CONTRACT, "feature_size": model.features.size, "max_frames": model.config.max_frames}
    export_module(model.network.cpu(), args, path, list(CONTRACT["inputs"]), list(CONTRACT["outputs"]),
                  ({0: batch, 1: frames}, {0: batch, 1: frames}), metadata(KIND, folder, read_config(folder), contract))
