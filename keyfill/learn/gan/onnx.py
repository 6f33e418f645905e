"""The gan as an exported ONNX graph: export (torch) and the graph runtime (no torch).

``keyfill export`` writes the generator (with its Motion DNA encoder and the
RC-FK layer, output smoothing included) and the global path predictor as one
graph with :func:`export_onnx` (a model with a spline base: the generator alone, the
spline an input); ``keyfill complete --method gan --runtime onnx``
runs it with :func:`complete_graph`: the same numpy pre- and post-processing as
the torch path (:func:`keyfill.learn.gan.model.generate` and around it: the dense
or sparse input, re-centred keys, the root moved onto the key roots, joints in
range at the keys, undriven joints interpolated, exact keys), the networks
replaced by the graph. The contract an engine follows is :data:`CONTRACT`
(and docs/onnx.md).

Only noise-free models (``GanConfig.noise_dim`` 0, the second recipe) export:
the torch path draws its noise from ``torch.Generator().manual_seed(seed)``,
which no other runtime reproduces, so a graph of a noisy model could not give
torch's motion for a seed. ``--runtime auto`` runs such a model with torch.
A Motion DNA model's bank of representative poses travels in the graph's
metadata (``keyfill.dna_bank``), so a graph file completes on its own.
"""

from __future__ import annotations

import base64
import json

import numpy as np

from keyfill.errors import KeyfillError, ModelError, UsageError
from keyfill.learn.gan import KIND
from keyfill.learn.gan.dna import DnaBank
from keyfill.learn.gan.model import FRAME_MULTIPLE, GanModel, complete_with, config_parts

#: what a gan graph takes and gives (written into its metadata; docs/onnx.md)
CONTRACT = {
    "graph": "generator (Motion DNA encoder, RC-FK with output smoothing) and global path predictor: "
             "the dense (or sparse) key input of the key range -> local rotations and the root path",
    "inputs": {
        "dense": ["batch", "6 * joints", "frames", "float32",
                  ("keyfill.learn.gan.features dense_input (sparse_input for a partial_keys model); "
                   "frames a multiple of 64")],
        "dna": ["batch", "poses", "joints - 1", 3, "float32",
                "root-free representative poses (metres); only for a model with Motion DNA"],
        "dna_valid": ["batch", "poses", "bool", "which poses are real (padding: false); only with dna"],
        "base": ["batch", "6 + 3 * driven joints", "frames", "float32",
                 ("keyfill.learn.gan.spline_base spline_values of the keys' rotations; only for a model with "
                  "base (GanConfig.base)")],
    },
    "outputs": {
        "quats": ["batch", "frames", "joints", 4, "float32",
                  "local unit quaternions (w, x, y, z); root first; joints not driven hold the identity"],
        "root": ["batch", "frames", 3, "float32",
                 ("root path (metres) from 0 at frame 0, before it is moved onto the key roots; not given by a "
                  "model with a base (GanConfig.base), whose root path is its interpolation of the key roots")],
    },
}


class GraphGenerator:
    """The gan networks as an exported graph, in the place of a :class:`GanModel`'s torch generator."""

    def __init__(self, graph):
        self.graph = graph

    def run_numpy(self, model: GanModel, x: np.ndarray, seed: int, style, dna, base=None):
        """As :func:`keyfill.learn.gan.model._run_torch`: ``(quats (B, T', J, 4), root (B, T', 3) or None)`` float32."""
        if style is not None:
            raise UsageError("an exported gan graph takes a Motion DNA, not a style vector; use runtime torch")
        feed = {"dense": np.ascontiguousarray(x, dtype=np.float32)}
        if model.config.dna:
            if dna is None:
                raise UsageError("this gan model's graph needs a Motion DNA (its poses, or its bank's)")
            d = np.asarray(dna, dtype=np.float32)
            d = np.broadcast_to(d[None] if d.ndim == 3 else d, (len(x), *d.shape[-3:]))
            feed["dna"] = np.ascontiguousarray(d)
            feed["dna_valid"] = np.ones(d.shape[:2], dtype=bool)
        if base is not None:
            feed["base"] = np.ascontiguousarray(base, dtype=np.float32)
            return self.graph.run(feed)[0], None
        quats, root = self.graph.run(feed)
        return quats, root


def _bank_text(bank: DnaBank) -> str:
    return json.dumps({"shape": list(bank.poses.shape),
                       "poses": base64.b64encode(np.ascontiguousarray(bank.poses, "<f4").tobytes()).decode(),
                       "clips": base64.b64encode(np.ascontiguousarray(bank.clips, "<i8").tobytes()).decode()})


def _bank(text: str) -> DnaBank:
    data = json.loads(text)
    shape = tuple(int(n) for n in data["shape"])
    poses = np.frombuffer(base64.b64decode(data["poses"]), "<f4").reshape(shape).astype(np.float32)
    clips = np.frombuffer(base64.b64decode(data["clips"]), "<i8").astype(np.int64)
    if len(clips) != shape[0]:
        raise ValueError("the DNA bank's poses and clips differ in length")
    return DnaBank(poses, clips)


def model_from_graph(graph) -> GanModel:
    """A :class:`GanModel` whose networks are an exported graph (:class:`keyfill.learn.onnx.Graph`)."""
    model = getattr(graph, "_gan_model", None)
    if model is None:
        try:
            cfg, skel, ranges, fps, stage = config_parts(graph.config)
            if stage != "full":
                raise ValueError(f"a graph of stage {stage!r}")
            bank = _bank(graph.metadata["keyfill.dna_bank"]) if cfg.dna else None
            model = GanModel(cfg, skel, ranges, GraphGenerator(graph), None, bool(graph.config["folded_root"]),
                             fps, stage, dict(graph.config.get("training") or {}), bank)
        except (KeyError, TypeError, ValueError, KeyfillError) as e:
            raise ModelError(f"{graph.path}: damaged gan model metadata ({e})") from None
        graph._gan_model = model
    return model


def _graph_for(keys, options, graph):
    """The graph for ``keys``: without ``--model``, partial keys use the shipped partial-key model's (None:
    that folder has none, and torch completes them)."""
    from keyfill.learn.gan.model import PARTIAL_MODEL

    if options.model is not None or not keys.partial:
        return graph
    from keyfill.learn import installed_models
    from keyfill.learn.onnx import select
    from keyfill.learn.registry import get

    folder = installed_models.require(PARTIAL_MODEL, KIND)
    return select(get(KIND), str(folder), options.runtime)


def complete_graph(jobs, options, graph):
    """``keyfill complete --method gan`` through an exported graph: a Completion or the error, per job."""
    from pathlib import Path

    from keyfill.learn.gan.model import complete

    out = []
    for motion, keys in jobs:
        try:
            g = _graph_for(keys, options, graph)
            if g is None:
                out.append(complete(motion, keys, options))
                continue
            path = Path(options.model) if options.model is not None else Path(g.path).parent
            done = complete_with(model_from_graph(g), motion, keys, options, path)
            done.info["runtime"] = "onnx"
            out.append(done)
        except KeyfillError as e:
            out.append(e)
    return out


def export_onnx(model: GanModel, folder, path) -> None:
    """Write ``model`` (loaded from the model folder ``folder``) as a graph to ``path`` (atomically).

    Batch, frames (a multiple of 64) and DNA poses are free. A model with noise (``noise_dim`` > 0) is refused.
    """
    if model.config.noise_dim:
        raise UsageError(f"{folder}: a gan model with noise (noise_dim {model.config.noise_dim}) cannot be exported: "
                         f"its torch noise has no ONNX equivalent; models of the second recipe (noise_dim 0) export")
    import torch

    from keyfill.learn.modelfile import read_config
    from keyfill.learn.onnx import export_module, metadata

    J = model.skeleton.num_joints
    module = _module(model)
    steps = torch.export.Dim("steps", min=1, max=max(1, model.config.max_frames // FRAME_MULTIPLE + 1))
    batch = torch.export.Dim("batch")
    args = [torch.zeros(2, 6 * J, 2 * FRAME_MULTIPLE)]
    dims = [{0: batch, 2: FRAME_MULTIPLE * steps}]
    names = ["dense"]
    if model.config.dna:
        poses = torch.export.Dim("poses", min=1, max=max(2, model.config.max_frames))
        args += [torch.zeros(2, 3, J - 1, 3), torch.ones(2, 3, dtype=torch.bool)]
        dims += [{0: batch, 1: poses}, {0: batch, 1: poses}]
        names += ["dna", "dna_valid"]
    outputs = list(CONTRACT["outputs"])
    if model.config.base != "none":
        args.append(torch.zeros(2, model.generator.rcfk.channels, 2 * FRAME_MULTIPLE))
        dims.append({0: batch, 2: FRAME_MULTIPLE * steps})
        names.append("base")
        outputs = ["quats"]
    contract = {**CONTRACT, "inputs": {k: CONTRACT["inputs"][k] for k in names},
                "outputs": {k: CONTRACT["outputs"][k] for k in outputs}, "joints": J,
                "frame_multiple": FRAME_MULTIPLE, "max_frames": model.config.max_frames}
    meta = metadata(KIND, folder, read_config(folder), contract)
    if model.config.dna:
        meta["keyfill.dna_bank"] = _bank_text(model.bank)
    export_module(module, tuple(args), path, names, outputs, tuple(dims), meta)


def _module(model: GanModel):
    """The torch module the graph is exported from: ``(dense[, dna, dna_valid]) -> (quats, root)``, or with a spline
    base ``(dense[, dna, dna_valid], base) -> quats``."""
    from torch import nn

    from keyfill.learn.gan.network import joint_channels, root_path

    smoothing = model.config.output_smoothing

    class Networks(nn.Module):
        def __init__(self):
            super().__init__()
            self.generator, self.path = model.generator.cpu(), model.path.cpu()

        def forward(self, dense, dna=None, dna_valid=None):
            v = self.generator(dense, None, None, dna=dna, dna_valid=dna_valid)
            quats, rel = self.generator.rcfk(v, smoothing)
            return quats, root_path(self.path(joint_channels(rel)))

    class SplineNetworks(nn.Module):  # the root path is the caller's spline
        def __init__(self):
            super().__init__()
            self.generator = model.generator.cpu()

        def forward(self, dense, dna, dna_valid, base):
            v = self.generator(dense, None, None, dna=dna, dna_valid=dna_valid, base=base)
            return self.generator.rcfk.rotations(v, smoothing)

    class SplineNetworksNoDna(SplineNetworks):
        def forward(self, dense, base):
            return super().forward(dense, None, None, base)

    if model.config.base == "none":
        return Networks()
    return SplineNetworks() if model.config.dna else SplineNetworksNoDna()
