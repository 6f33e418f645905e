"""Batch completion: the job that ``keyfill complete IN... -o OUTDIR/`` runs on each chunk of files.

:func:`complete_chunk` reads a chunk of inputs, completes them together with
:func:`keyfill.learn.registry.complete_many` (a learned method's model is
loaded once per process and kept; the ARNN runs the chunk as one batch) and
writes each output atomically. The planning, skipping, workers and cluster
are :mod:`keyfill.io.batch`'s.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

from keyfill.errors import FormatError, KeyfillError
from keyfill.io.batch import bvh_layout, failure
from keyfill.io.batch_record import Item
from keyfill.learn.completion import CompleteOptions


@dataclass(frozen=True)
class CompleteSpec:
    """What every file of a batch completion shares (sent to the workers)."""

    method: str
    options: CompleteOptions
    keys_text: str | None = None
    key_every: int | None = None
    fmt: str | None = None
    #: the layout of BVH outputs (``--bvh-layout``; None: auto)
    bvh_layout: str | None = None

    def recipe(self) -> dict:
        """What shapes every output of the batch, for the output folder's record (:mod:`keyfill.io.batch`): the
        method, the model's identity (the SHA-256 of its config, weights and graph, not its path), the runtime
        that will run it, the keys and every option; files the options name (rig map, Motion DNA) by their
        SHA-256."""
        from keyfill.io.batch_record import file_sha256, input_sha256
        from keyfill.learn.registry import get

        m, o = get(self.method), self.options
        recipe = {"command": "complete", "method": m.name, "keys": self.keys_text, "key_every": self.key_every,
                  "seed": o.seed, "exact_keys": o.exact_keys, "feet": o.feet, "ground": o.ground,
                  "rig_map": None if o.rig_map is None else file_sha256(o.rig_map), "dna_count": o.dna_count,
                  "format": self.fmt, **({"bvh_layout": self.bvh_layout} if self.bvh_layout else {})}
        if o.dna is not None:
            path, frames = o.dna, None
            if not os.path.exists(path) and ":" in path:
                path, _, frames = path.rpartition(":")
            recipe["dna"] = {"sha256": input_sha256(path), "frames": frames}
        if m.learned:
            recipe.update(model_identity(m, o.model, o.runtime), device=o.device)
        return recipe


def model_identity(method, model: str | None, runtime: str = "auto") -> dict:
    """``{"model": {...}, "runtime": ...}``: the content of the model a learned ``method`` (a registry entry)
    completes with (``model``: a folder, a graph file or None for the shipped one) and the runtime that runs
    it; reads no weights into a network."""
    from keyfill.io.batch_record import file_sha256
    from keyfill.learn import onnx

    if onnx.is_graph(model):
        return {"model": {"graph": file_sha256(model)}, "runtime": "onnx"}
    folder = Path(model) if model is not None else method.default_model()
    if folder is None:
        return {"model": None, "runtime": runtime}
    if folder.is_file():
        folder = folder.parent
    from keyfill.learn.modelfile import CONFIG, WEIGHTS

    graph = folder / onnx.GRAPH
    ident = {"config": file_sha256(folder / CONFIG), "weights": file_sha256(folder / WEIGHTS),
             "graph": file_sha256(graph) if graph.is_file() else None}
    if runtime == "auto":
        runtime = "onnx" if graph.is_file() and method.onnx is not None and onnx.available() else "torch"
    return {"model": ident, "runtime": runtime}


@contextlib.contextmanager
def one_torch_thread(spec: CompleteSpec):
    """One torch thread while a chunk is completed (restored after), when the method runs on torch.

    Batches run in parallel as processes, one per core; torch's own thread pool
    on top of that oversubscribes the cores (on a loaded 2-core machine 128
    lamp files took 14.0 s with torch's default threads, 4.8 s with one), and
    one thread everywhere keeps a file's bytes independent of the machine
    that completes it.
    """
    from keyfill.learn.onnx import select
    from keyfill.learn.registry import get

    m = get(spec.method)
    if not m.learned or select(m, spec.options.model, spec.options.runtime, spec.options.device) is not None:
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def complete_chunk(chunk: list[Item], spec: CompleteSpec) -> list[dict | None]:
    """Complete the inputs of ``chunk``; write the outputs of the items marked ``write``.

    Items not marked ``write`` (already done) are still read and completed, so
    that every file is computed in the same batch as in an uninterrupted run;
    their outcome is None.
    """
    from keyfill import io
    from keyfill.learn.registry import complete_many
    from keyfill.motion import Keys

    outcomes: list = [None] * len(chunk)
    jobs, where = [], []
    for i, it in enumerate(chunk):
        try:
            motion = io.load(it.src)
            jobs.append((motion, Keys.resolve(motion, spec.keys_text, spec.key_every)))
            where.append(i)
        except (KeyfillError, OSError) as e:
            outcomes[i] = failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e)))
    with one_torch_thread(spec):
        results = complete_many(jobs, spec.method, spec.options) if jobs else []
    for i, result in zip(where, results):
        it = chunk[i]
        if isinstance(result, KeyfillError):
            outcomes[i] = failure(it, result)
            continue
        if not it.write:
            continue
        try:
            io.save(result.motion, it.dst, spec.fmt, source=it.src, bvh_layout=bvh_layout(it.dst, spec.bvh_layout))  # as a single completion writes it
        except (KeyfillError, OSError) as e:
            outcomes[i] = failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e)))
            continue
        outcomes[i] = {"input": it.src, "output": it.dst, "status": "done", **result.info}
    return [o if it.write else None for o, it in zip(outcomes, chunk)]
