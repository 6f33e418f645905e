"""Batch completion: the job that ``keyfill complete IN... -o OUTDIR/`` runs on each chunk of files.

:func:`complete_chunk` reads a chunk of inputs, completes them together with
:func:`keyfill.learn.registry.complete_many` (a learned method's model is
loaded once per process and kept; the ARNN runs the chunk as one batch) and
writes each output atomically. The planning, skipping, workers and cluster
are :mod:`keyfill.io.batch`'s.
"""

from __future__ import annotations

import os
import sys
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


def one_thread() -> None:
    """One torch thread in a batch job.

    Batches run in parallel as processes, one per core; torch's own thread pool
    on top of that oversubscribes the cores (on a loaded 2-core machine the
    ARNN's batch steps took 3x as long with torch's default threads), and
    one thread everywhere keeps a file's bytes independent of the machine
    that completes it. Set before torch is imported where possible.
    """
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    torch = sys.modules.get("torch")
    if torch is not None and torch.get_num_threads() != 1:
        torch.set_num_threads(1)


def complete_chunk(chunk: list[Item], spec: CompleteSpec) -> list[dict | None]:
    """Complete the inputs of ``chunk``; write the outputs of the items marked ``write``.

    Items not marked ``write`` (already done) are still read and completed, so
    that every file is computed in the same batch as in an uninterrupted run;
    their outcome is None.
    """
    from keyfill import io
    from keyfill.learn.registry import complete_many
    from keyfill.motion import Keys

    one_thread()
    outcomes: list = [None] * len(chunk)
    jobs, where = [], []
    for i, it in enumerate(chunk):
        try:
            motion = io.load(it.src)
            jobs.append((motion, Keys.resolve(motion, spec.keys_text, spec.key_every)))
            where.append(i)
        except (KeyfillError, OSError) as e:
            outcomes[i] = failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e)))
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
