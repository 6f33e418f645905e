"""Batch completion: the job that ``keyfill complete IN... -o OUTDIR/`` runs on each chunk of files.

:func:`complete_chunk` reads a chunk of inputs, completes them together with
:func:`keyfill.learn.registry.complete_many` (a learned method's model is
loaded once per process and kept; the ARNN runs the chunk as one batch) and
writes each output atomically. The planning, skipping, workers and cluster
are :mod:`keyfill.io.batch`'s.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

from keyfill.errors import FormatError, KeyfillError
from keyfill.io.batch import Item, failure
from keyfill.learn.completion import CompleteOptions


@dataclass(frozen=True)
class CompleteSpec:
    """What every file of a batch completion shares (sent to the workers)."""

    method: str
    options: CompleteOptions
    keys_text: str | None = None
    key_every: int | None = None
    fmt: str | None = None


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
    if not m.learned or select(m, spec.options.model, spec.options.runtime) is not None:
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
            io.save(result.motion, it.dst, spec.fmt)
        except (KeyfillError, OSError) as e:
            outcomes[i] = failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e)))
            continue
        outcomes[i] = {"input": it.src, "output": it.dst, "status": "done", **result.info}
    return [o if it.write else None for o, it in zip(outcomes, chunk)]
