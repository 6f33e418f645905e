"""Many files in, one folder out: the plan and the run of a batch command (``complete``, ``convert``).

:func:`plan` turns the inputs of ``keyfill complete IN... -o OUTDIR/`` (files,
folders, globs) into :class:`Item` s, one output per input under ``OUTDIR``
with the same relative name (``--format`` changes the suffix). It refuses,
before any work, an output folder that is a file and two inputs that map to
the same output.

:func:`run` hands the items to an executor (:mod:`keyfill.parallel`: this
process, local processes or a Dask cluster) in *chunks*: a job function
``fn(chunk, spec) -> [outcome, ...]`` gets a list of items and does them
together (a learned method loads its model once per process and completes
a chunk as one batch). Chunks are cut from the whole sorted input list,
whatever is already done, so a file is always computed with the same
neighbours: the outputs are the same bytes in one run, a resumed run, with any
number of workers or on a cluster. Outputs that exist and are newer than their
input are skipped (``force`` redoes them); a chunk with nothing left to do is
not sent. Each item's outcome is a dict: ``input``, ``output``, ``status``
(``done``, ``skipped``, ``failed``), ``error`` for a failure (and ``params``, the
parameters its message names), and what the job reports. One failing input does not stop the others.
"""

from __future__ import annotations

import glob
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from keyfill.errors import FormatError, KeyfillError, UsageError
from keyfill.io import FORMATS, SUFFIXES

#: suffixes of motion files a folder input contributes (those of :data:`keyfill.io.FORMATS`)
MOTION_SUFFIXES = tuple(SUFFIXES)
#: inputs per chunk (the unit of work sent to a worker, and a learned method's batch)
CHUNK = 64


@dataclass(frozen=True)
class Item:
    """One input and its output."""

    src: str
    dst: str
    #: do it even if the output is up to date (set by :func:`run` for the chunks it sends)
    write: bool = True


def is_batch(inputs, output: str | None) -> bool:
    """Whether a command's inputs and ``-o`` ask for the many-in / folder-out form."""
    if output is None:
        return False
    if len(inputs) != 1 or output.endswith(("/", os.sep)) or Path(output).is_dir():
        return True
    src = inputs[0]
    return src != "-" and (Path(src).is_dir() or (not Path(src).exists() and glob.has_magic(src)))


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder)
        return True
    except ValueError:
        return False


def _expand(text: str, outdir: Path) -> list[tuple[Path, Path]]:
    """``(input file, relative name)`` pairs of one command-line input."""
    p = Path(text)
    if text == "-":
        raise UsageError("'-' (standard input) reads one file; give files, folders or globs for a batch")
    if p.is_dir():
        files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in MOTION_SUFFIXES
                       and not any(part.startswith(".") for part in f.relative_to(p).parts)
                       and not _inside(f, outdir))
        return [(f, f.relative_to(p)) for f in files]
    if p.exists() or not glob.has_magic(text):
        return [(p, Path(p.name))]  # a missing file is that input's failure, reported with the others
    base = Path(*_prefix(p.parts)) if _prefix(p.parts) else Path(".")
    files = sorted(Path(f) for f in glob.glob(text, recursive=True))
    files = [f for f in files if f.is_file() and not _inside(f, outdir)]
    if not files:
        raise UsageError(f"{text}: matches no file")
    return [(f, f.relative_to(base)) for f in files]


def _prefix(parts):
    """The leading parts of a glob's path without wildcards."""
    out = []
    for part in parts[:-1]:
        if glob.has_magic(part):
            break
        out.append(part)
    return out


def plan(inputs, outdir: str | os.PathLike, format: str | None = None) -> list[Item]:
    """The items of a batch, sorted by input; refuses what cannot work before any work is done.

    Args:
        inputs: files, folders (their motion files, recursively) and globs.
        outdir: the output folder (created later if missing).
        format: output format (a name of :data:`keyfill.io.FORMATS`): the outputs' suffix; None keeps the
            input's.

    Errors name the parameters ``outdir`` and ``format`` (in ``params``).
    """
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise UsageError(f"outdir {outdir}: is a file; a batch writes into an output folder", params="outdir")
    fmt = None
    if format is not None:
        fmt = format.lower().lstrip(".")
        if fmt not in FORMATS:
            raise UsageError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
    resolved_out = out.resolve()
    seen: dict[Path, Path] = {}  # output -> input
    items = []
    for text in inputs:
        for src, rel in _expand(str(text), resolved_out):
            dst = out / (rel.with_suffix(FORMATS[fmt].suffixes[0]) if fmt else rel)
            if dst.suffix.lower() not in MOTION_SUFFIXES:
                raise UsageError(f"{src}: unknown file type {src.suffix or '(no suffix)'!r}; give format",
                                 params="format")
            if src.resolve() == dst.resolve():
                raise UsageError(f"{src}: would be overwritten by its own output; choose another output folder")
            key = dst.resolve()
            if key in seen:
                if seen[key].resolve() == src.resolve():
                    continue  # the same input named twice
                raise UsageError(f"{seen[key]} and {src} would both be written to {dst}; "
                                 "rename one, or complete them into different folders")
            seen[key] = src
            items.append(Item(str(src), str(dst)))
    if not items:
        raise UsageError("no input files")
    return sorted(items, key=lambda i: i.src)


def up_to_date(item: Item) -> bool:
    """The output exists and is newer than its input."""
    try:
        return Path(item.dst).stat().st_mtime_ns > Path(item.src).stat().st_mtime_ns
    except OSError:
        return False


@dataclass
class Summary:
    """What a batch did (``--json`` prints :meth:`to_dict`)."""

    output: str
    files: list[dict] = field(default_factory=list)
    seconds: float = 0.0

    def count(self, status: str) -> int:
        return sum(1 for f in self.files if f["status"] == status)

    @property
    def failed(self) -> list[dict]:
        return [f for f in self.files if f["status"] == "failed"]

    def to_dict(self) -> dict:
        return {"output": self.output, "inputs": len(self.files), "done": self.count("done"),
                "skipped": self.count("skipped"), "failed": self.count("failed"), "seconds": self.seconds,
                "files": self.files}

    def line(self, verb: str) -> str:
        """A one-line human summary."""
        parts = [f"{verb} {self.count('done')} of {len(self.files)} files into {self.output} in {self.seconds:.1f} s"]
        if self.count("skipped"):
            parts.append(f"skipped {self.count('skipped')} whose output is newer than the input (--force redoes them)")
        if self.count("failed"):
            parts.append(f"{self.count('failed')} failed")
        return "; ".join(parts)


def prepare_outputs(items: list[Item]) -> None:
    """Create the output folders of ``items`` and remove what a killed run left of their outputs.

    An interrupted write (Ctrl-C) removes its temporary file itself; a run
    killed outright (SIGKILL, a lost node) cannot, and leaves
    ``.NAME.XXXX.partSUFFIX`` beside the output (:func:`keyfill.files.atomic_output`).
    """
    folders: dict[Path, set[str]] = {}
    for it in items:
        dst = Path(it.dst)
        folders.setdefault(dst.parent, set()).add(dst.stem + "\0" + dst.suffix)
    for folder, names in folders.items():
        folder.mkdir(parents=True, exist_ok=True)
        for entry in os.scandir(folder):
            name = entry.name
            if not (name.startswith(".") and ".part" in name and entry.is_file()):
                continue
            body, _, suffix = name[1:].rpartition(".part")
            stem = body.rpartition(".")[0]
            if stem + "\0" + suffix in names:
                os.unlink(entry.path)


def failure(item: Item, error: BaseException) -> dict:
    """The outcome of an item that failed with ``error``; ``params`` keeps the parameters its message names
    (:attr:`KeyfillError.params`), when it names any."""
    message = " ".join(str(error).split())
    if not isinstance(error, KeyfillError):
        message = f"internal error: {type(error).__name__}: {message}"
    if not message.startswith(item.src):
        message = f"{item.src}: {message}"
    outcome = {"input": item.src, "output": item.dst, "status": "failed", "error": message}
    if getattr(error, "params", ()):
        outcome["params"] = list(error.params)
    return outcome


def run(items: list[Item], fn: Callable, spec, workers: int | None = None, scheduler: str | None = None,
        force: bool = False, chunk: int = CHUNK, connect_timeout: float = 10.0,
        on_chunk: Callable[[list[dict]], None] | None = None) -> Summary:
    """Do ``items`` with the job function ``fn(chunk, spec) -> outcomes``; see the module docstring.

    The executor is started only when there is work; a Dask scheduler that
    cannot be reached is one :class:`KeyfillError` before any file is written.
    """
    from keyfill.parallel import check_options
    from keyfill.parallel import executor as make_executor

    check_options(workers, connect_timeout)
    if chunk < 1:
        raise UsageError(f"chunk must be at least 1, got {chunk}", params="chunk")
    start = time.perf_counter()
    summary = Summary(output="")
    outcomes: dict[str, dict] = {}
    jobs = []
    for i in range(0, len(items), chunk):
        part = items[i: i + chunk]
        todo = [force or not up_to_date(it) for it in part]
        for it, t in zip(part, todo):
            if not t:
                outcomes[it.src] = {"input": it.src, "output": it.dst, "status": "skipped"}
        if any(todo):
            jobs.append([Item(it.src, it.dst, t) for it, t in zip(part, todo)])
    skipped = [outcomes[it.src] for it in items if it.src in outcomes]
    if skipped and on_chunk is not None:
        on_chunk(skipped)
    if jobs:
        # Reach the cluster before touching the output folder: an unreachable scheduler leaves nothing behind.
        executor, window = make_executor(workers if workers is not None else (1 if len(jobs) == 1 else None),
                                         scheduler, connect_timeout)
        try:
            prepare_outputs([it for job in jobs for it in job if it.write])
            in_flight: dict = {}
            pending = list(jobs)
            while pending or in_flight:
                while pending and len(in_flight) < window:
                    job = pending.pop(0)
                    in_flight[executor.submit(fn, job, spec)] = job
                for fut in executor.wait(list(in_flight)):
                    job = in_flight.pop(fut)
                    try:
                        results = fut.result()
                    except KeyfillError:
                        raise
                    except Exception as e:  # noqa: BLE001 (a worker that died: its inputs failed, the others go on)
                        results = [failure(it, e) for it in job]
                    for it, res in zip(job, results):
                        if it.write:
                            outcomes[it.src] = res
                    if on_chunk is not None:
                        on_chunk([r for it, r in zip(job, results) if it.write])
        except BaseException:
            executor.close(cancel=True)
            raise
        executor.close()
    summary.files = [outcomes[it.src] for it in items]
    summary.seconds = time.perf_counter() - start
    return summary


# --- convert ----------------------------------------------------------------------------------------


def convert_chunk(chunk: list[Item], spec=None) -> list[dict]:
    """Job function of ``keyfill convert IN... -o OUTDIR/``: read each input, write its output."""
    from keyfill import io

    out = []
    for it in chunk:
        if not it.write:
            out.append(None)
            continue
        try:
            motion = io.load(it.src)
            io.save(motion, it.dst, source=it.src)
            out.append({"input": it.src, "output": it.dst, "status": "done", "frames": motion.num_frames,
                        "joints": motion.num_joints})
        except (KeyfillError, OSError) as e:
            out.append(failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e))))
    return out
