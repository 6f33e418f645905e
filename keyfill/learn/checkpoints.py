"""The files a run of the one training loop keeps beside its model folder: the checkpoint and the JSONL loss log.

* A checkpoint (:func:`write_checkpoint`, :func:`read_checkpoint`) holds tensors, numbers and strings only, is
  written atomically, tagged with the model kind, and read back with ``torch.load(weights_only=True)``;
  :func:`check_resume` refuses one made with other settings or other data, naming the first difference.
* The loss log (:class:`LossLog`) has one JSON line per finished epoch. It is written from the first finished
  epoch of a run on, never before: a run interrupted before then leaves no (empty) log, and the log of an earlier
  run stays as it was. Its first write puts the rows a resumed checkpoint carries and the new row in place
  atomically; later rows are appended (``tail -f`` follows them).

torch is imported by the functions that need it, not at import.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from keyfill.errors import ModelError, UsageError

CHECKPOINT_FORMAT = "keyfill-checkpoint"


def write_checkpoint(path, task, nets, optimizers, epoch, seconds, cpu, config, fingerprint, history) -> None:
    """Atomically write a checkpoint: tensors, numbers and strings only (read back with ``weights_only=True``)."""
    import torch

    from keyfill.files import atomic_output

    state = {
        "format": CHECKPOINT_FORMAT,
        "kind": task.kind,
        "config": json.dumps(config, sort_keys=True),
        "data": fingerprint,
        "epoch": epoch,
        "seconds": seconds,
        "cpu_seconds": cpu,
        "history": json.dumps(history),
        "networks": {k: v.state_dict() for k, v in nets.items()},
        "optimizers": {k: v.state_dict() for k, v in optimizers.items()},
        "task": task.state_dict(),
    }
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def read_checkpoint(path, kind: str | None = None) -> dict:
    """A checkpoint written by :func:`write_checkpoint`; never unpickles objects (``weights_only=True``)."""
    import torch

    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many types for damaged or foreign files
        raise ModelError(f"{path}: not a readable keyfill checkpoint ({' '.join(str(e).split())[:200]})") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise ModelError(f"{path}: not a keyfill checkpoint")
    if kind is not None and state.get("kind") != kind:
        raise UsageError(f"resume: {path} is a checkpoint of a {state.get('kind')!r} model, not {kind!r}",
                         params="resume")
    return state


def check_resume(path, state: dict, config: dict, fingerprint: str) -> None:
    """Refuse a checkpoint made with another configuration or other data, naming the first difference."""
    saved = json.loads(state["config"])
    now = json.loads(json.dumps(config, sort_keys=True))
    for key in sorted(set(saved) | set(now)):
        if saved.get(key) != now.get(key):
            what = f"seed {saved.get(key)}, now {now.get(key)}" if key == "seed" else \
                f"{key}={saved.get(key)!r}, now {now.get(key)!r}"
            raise UsageError(f"resume: {path} was made with other settings ({what}); give the same options to resume",
                             params=("resume", "seed") if key == "seed" else "resume")
    if state["data"] != fingerprint:
        raise UsageError(f"resume: {path} was made with other training data", params="resume")


class LossLog:
    """The JSONL loss log at ``path``, written from the first finished epoch of this run on (see the module)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.written = False

    def record(self, history: list[dict]) -> None:
        """Log the last row of ``history`` (every row of the run so far, a resumed checkpoint's included)."""
        if self.written:
            with open(self.path, "a") as f:
                f.write(json.dumps(history[-1]) + "\n")
            return
        from keyfill.files import atomic_output

        with atomic_output(self.path) as tmp:
            tmp.write_text("".join(json.dumps(r) + "\n" for r in history))
        self.written = True
