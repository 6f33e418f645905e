"""The hop dataset folder: its files, and reading it back.

A folder made by ``keyfill simulate -o DIR`` holds::

    simulate.json    the configuration: file format, seed, annealing iterations, every Settings value
    manifest.jsonl   one JSON record per accepted sequence, in run order
    runs.jsonl       one line per finished annealing run, accepted or not (what a re-run resumes from)
    seq_00000.usda   one motion file per accepted sequence (``.bvh`` with --format bvh); the number is
                     the run index, so numbers have gaps where runs were rejected

A manifest record (all lengths in m, angles in rad, times in s)::

    id, file, run, seed          the sequence, its motion file, and where its randomness comes from
    w_e                          the run's energy weight, E = -(1 - w_e) D - w_e H_max
    controller                   {"durations": [4], "poses": [[leg, neck, head] x 4]}
    energy, distance, max_height the best episode's energy, forward travel of the base, base clearance
    hops, frames, fps            hop count (3), frames in the sequence (87), nominal frame rate
    keys                         key frame indices: per hop liftoff, in-air pose, landing
    liftoff_frames, landing_frames, air_frames
    frame_times                  simulation time of every frame (frames are even per hop, not in time)
    liftoff_times, landing_times simulation times of the hop events
    iterations, episodes         annealing iterations and energy evaluations of the run
    settings                     the simulation settings (as in simulate.json)

:func:`read_dataset` returns every sequence with its motion (keys set from
the manifest, whatever the file format) and its record.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, FormatError, KeyfillError
from keyfill.motion import Keys, Motion

CONFIG_FILE = "simulate.json"
MANIFEST_FILE = "manifest.jsonl"
RUNS_FILE = "runs.jsonl"
#: --format -> motion file suffix
SUFFIXES = {"usd": ".usda", "bvh": ".bvh"}


def sequence_id(run: int) -> str:
    """The id (and file stem) of the sequence made by run ``run``: ``seq_00042``."""
    return f"seq_{run:05d}"


@dataclass(frozen=True, eq=False)
class Sequence:
    """One accepted hop sequence: ``id``, its ``motion`` (with keys) and its manifest ``record``."""

    id: str
    motion: Motion
    record: dict
    path: Path


def read_jsonl(path: Path) -> list[dict]:
    """Records of a JSON-lines file; a last line cut short by an interrupted build is ignored."""
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    if lines and lines[-1] != "":
        lines = lines[:-1]  # no newline at the end: the writer was interrupted in the middle of it
    out = []
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as e:
            raise FormatError(f"not a JSON record ({e.msg})", path, i) from None
        if not isinstance(rec, dict):
            raise FormatError("not a JSON object", path, i)
        out.append(rec)
    return out


def append_jsonl(path: Path, record: dict) -> None:
    """Append one record as one line, with a single ``write`` (a kill cannot leave half a record behind)."""
    data = (json.dumps(record, sort_keys=True) + "\n").encode("utf-8")
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)


def read_manifest(folder: str | os.PathLike) -> list[dict]:
    """The manifest records of a dataset folder, in run order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: no such dataset folder")
    path = folder / MANIFEST_FILE
    if not path.is_file():
        raise DataError(f"{folder} holds no simulated sequences (no {MANIFEST_FILE}); make some with 'keyfill simulate -o {folder}'")
    records = read_jsonl(path)
    for i, rec in enumerate(records, 1):
        missing = [k for k in ("id", "file", "run", "keys") if k not in rec]
        if missing:
            raise FormatError(f"record without {', '.join(missing)}", path, i)
    return sorted(records, key=lambda r: r["run"])


def read_dataset(folder: str | os.PathLike) -> list[Sequence]:
    """Every sequence of a ``keyfill simulate`` folder, in run order.

    Raises :class:`DataError` for a folder without sequences or a missing file.
    """
    from keyfill import io

    folder = Path(folder)
    records = read_manifest(folder)
    if not records:
        raise DataError(f"{folder} holds no simulated sequences yet ({MANIFEST_FILE} is empty)")
    out = []
    for rec in records:
        path = folder / rec["file"]
        if not path.is_file():
            raise DataError(f"{path}: listed in {MANIFEST_FILE} but missing")
        motion = io.load(path)
        try:
            keys = Keys(np.array(rec["keys"], dtype=np.int64))
        except (KeyfillError, TypeError, ValueError, OverflowError) as e:
            why = str(e) if isinstance(e, KeyfillError) else "they must be whole frame numbers"
            raise DataError(f"{folder / MANIFEST_FILE}: the keys of {rec['id']!r} are wrong: {why}") from None
        if len(keys) and keys.frames[-1] >= motion.num_frames:
            raise DataError(f"{path}: key {int(keys.frames[-1])} of {MANIFEST_FILE} is beyond its {motion.num_frames} frames")
        out.append(Sequence(id=rec["id"], motion=motion.replace(keys=keys), record=rec, path=path))
    return out
