"""Many files in, one folder out: the plan and the run of a batch command (``complete``, ``convert``).

:func:`plan` turns the inputs of ``keyfill complete IN... -o OUTDIR/`` (files,
folders, globs) into :class:`Item` s, one output per input under ``OUTDIR``
with the same relative name (``--format`` changes the suffix). It refuses,
before any work, an output folder that is a file (or named like one), an
input that does not exist, a folder input with no motion files, and two
inputs that map to the same output. A folder input never contributes the output folder, nor the output
folders of earlier runs (those holding a record), so ``complete . -o out/``
can be run again and again.

:func:`run` hands the items to an executor (:mod:`keyfill.parallel`: this
process, local processes or a Dask cluster) in *chunks*: a job function
``fn(chunk, spec) -> [outcome, ...]`` gets a list of items and does them
together (a learned method loads its model once per process and completes
a chunk as one batch). Chunks are cut from the whole sorted input list,
whatever is already done, so a file is always computed with the same
neighbours: the outputs are the same bytes in one run, a resumed run, with any
number of workers or on a cluster. A chunk with nothing left to do is not sent.

**How each output was made** is kept in the output folder's record
(:mod:`keyfill.io.batch_record`), so a re-run skips only what was made the same way.

Each item's outcome is a dict: ``input``, ``output``, ``status`` (``done``: a
new output; ``redone``: an existing output replaced, with ``stale``, the
reasons; ``skipped``; ``failed``), ``error`` for a failure (and ``params``, the
parameters its message names), and what the job reports. One failing input does
not stop the others.
"""

from __future__ import annotations

import contextlib
import glob
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from keyfill.errors import FormatError, KeyfillError, NoSuchFile, OutputError, UsageError
from keyfill.io import FORMATS, SUFFIXES, listing, writable
from keyfill.io.batch_record import (
    RECORD,
    Item,
    Record,
    folder_lock,
    input_sha256,
    output_files,
    output_stamp,
    recipe_digest,
    refuse_read_only,
    written_since,
)
from keyfill.limits import CONNECT_SECONDS

#: suffixes of motion files a folder input contributes (those of :data:`keyfill.io.FORMATS`)
MOTION_SUFFIXES = tuple(SUFFIXES)
#: inputs per chunk (the unit of work sent to a worker, and a learned method's batch)
CHUNK = 64


def is_batch(inputs, output: str | None) -> bool:
    """Whether a command's inputs and ``-o`` ask for the many-in / folder-out form."""
    if output is None:
        return False
    if len(inputs) != 1 or output.endswith(("/", os.sep)) or (output and _is_dir(output)):
        return True
    src = inputs[0]
    return src != "-" and (_is_dir(src) or (not os.path.lexists(src) and glob.has_magic(src)))


def _is_dir(path: str) -> bool:
    """Whether ``path`` is a folder; False for a name the file system cannot hold (too long), whose use
    says so later with the user's path."""
    try:
        return Path(path).is_dir()
    except OSError:
        return False


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
        made = [d for d in (r.parent for r in p.rglob(RECORD)) if d != p]  # output folders of earlier runs
        files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in MOTION_SUFFIXES
                       and not any(part.startswith(".") for part in f.relative_to(p).parts)
                       and not _inside(f, outdir) and not any(f.is_relative_to(d) for d in made))
        if not files:
            besides = f" outside keyfill's output folders ({', '.join(map(str, made))})" if made else ""
            raise UsageError(f"{text}: no motion files ({listing(SUFFIXES)}) in this folder{besides}")
        return [(f, f.relative_to(p)) for f in files]
    if p.exists():
        return [(p, Path(p.name))]  # a file that cannot be read is that input's failure, reported with the others
    if not glob.has_magic(text):
        raise NoSuchFile(text, "no such file or folder")
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


def plan(inputs, outdir: str | os.PathLike, format: str | None = None, force: bool = False) -> list[Item]:
    """The items of a batch, sorted by input; refuses what cannot work before any work is done.

    Args:
        inputs: files, folders (their motion files, recursively, but for hidden files and the output folders
            of keyfill runs: folders holding a record, :data:`RECORD`) and globs.
        outdir: the output folder (created later if missing); a name that does not exist yet and ends in a
            motion file's suffix (``single.bvh``) is refused as a file name (``single.bvh/`` is a folder).
        format: output format (a name of :data:`keyfill.io.FORMATS`): the outputs' suffix; None keeps the
            input's.
        force: allow an output that is one of the inputs (the same file, through links too); refused otherwise.

    Errors name the parameters ``outdir``, ``format`` and ``force`` (in ``params``).
    """
    out = Path(outdir)
    if not str(outdir):
        raise UsageError("outdir is empty: give the output folder (OUTDIR/)", params="outdir")
    if out.exists() and not out.is_dir():
        raise UsageError(f"outdir {outdir}: is a file; a batch writes into an output folder", params="outdir")
    if not out.exists() and not str(outdir).endswith(("/", os.sep)) and out.suffix.lower() in SUFFIXES:
        raise UsageError(f"outdir {outdir}: a batch writes into an output folder, and this names a file; give "
                         f"{outdir}/ for a folder of that name, or one input for one output file", params="outdir")
    fmt = None
    if format is not None:
        fmt = format.lower().lstrip(".")
        if fmt not in FORMATS:
            raise UsageError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
        if FORMATS[fmt].writer is None:
            raise UsageError(f"format {fmt}: keyfill reads {fmt.upper()} but does not write it; give one of "
                             f"{listing(writable())}", params="format")
    resolved_out = out.resolve()
    seen: dict[Path, Path] = {}  # output -> input
    items = []
    for text in inputs:
        for src, rel in _expand(str(text), resolved_out):
            dst = out / (rel.with_suffix(FORMATS[fmt].suffixes[0]) if fmt else rel)
            if dst.suffix.lower() not in MOTION_SUFFIXES:
                raise UsageError(f"{src}: unknown file type {src.suffix or '(no suffix)'!r}; give format",
                                 params="format")
            if FORMATS[SUFFIXES[dst.suffix.lower()]].writer is None:  # an output in the input's read-only format
                raise UsageError(f"{src}: keyfill does not write {dst.suffix}; give format (one of "
                                 f"{listing(writable())}) for the outputs", params="format")
            key = dst.resolve()
            if key in seen:
                if seen[key].resolve() == src.resolve():
                    continue  # the same input named twice
                raise UsageError(f"{seen[key]} and {src} would both be written to {dst}; "
                                 "rename one, or complete them into different folders")
            seen[key] = src
            items.append(Item(str(src), str(dst), root=str(out)))
    if not items:
        raise UsageError("no inputs given")
    if not force:
        refuse_inputs_as_outputs(items)
    return sorted(items, key=lambda i: i.src)


def _file_id(path: str | os.PathLike) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def refuse_inputs_as_outputs(items: list[Item]) -> None:
    """A :class:`UsageError` (exit 2) when an item's output is the file of one of the inputs: its own input or
    another's, by name or through a symbolic or hard link."""
    inputs = {}
    for it in items:
        fid = _file_id(it.src)
        if fid is not None:
            inputs.setdefault(fid, it.src)
    for it in items:
        fid = _file_id(it.dst)
        if fid is not None and fid in inputs:
            raise UsageError(f"{it.dst}: the output of {it.src} is the input {inputs[fid]}; writing it would "
                             "overwrite that input: choose another output folder, or give force to overwrite it",
                             params="force")


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
        # docs/json.md: ``input`` the files read (one per outcome in ``files``), ``inputs`` their count
        return {"input": [f["input"] for f in self.files], "output": self.output, "inputs": len(self.files),
                "done": self.count("done"),
                "redone": self.count("redone"), "skipped": self.count("skipped"), "failed": self.count("failed"),
                "seconds": self.seconds, "files": self.files}

    def line(self, verb: str) -> str:
        """A one-line human summary."""
        written = self.count("done") + self.count("redone")
        parts = [f"{verb} {written} of {len(self.files)} files into {self.output} in {self.seconds:.1f} s"]
        if self.count("redone"):
            reasons = sorted({r for f in self.files if f["status"] == "redone" for r in f.get("stale", ())})
            parts.append(f"{self.count('redone')} of them redone ({'; '.join(reasons)})")
        if self.count("skipped"):
            parts.append(f"skipped {self.count('skipped')} made the same way before (--force redoes them)")
        if self.count("failed"):
            parts.append(f"{self.count('failed')} failed")
        return "; ".join(parts)


def prepare_outputs(items: list[Item]) -> None:
    """Create the output folders of ``items``, check that they take files (an :class:`OutputError` naming the
    folder), and remove what a killed run left of their outputs.

    An interrupted write (Ctrl-C) removes its temporary file itself; a run
    killed outright (SIGKILL, a lost node) cannot, and leaves
    ``.NAME.XXXX.partSUFFIX`` beside the output (:func:`keyfill.files.atomic_output`).
    """
    from keyfill.files import interrupts_deferred

    folders: dict[Path, set[str]] = {}
    for it in items:
        dst = Path(it.dst)
        folders.setdefault(dst.parent, set()).add(dst.stem + "\0" + dst.suffix)
    for folder, names in folders.items():
        try:  # a folder that cannot take files is one error before any work, not one per output
            folder.mkdir(parents=True, exist_ok=True)
            with interrupts_deferred():  # the probe goes whenever a signal comes
                os.close(os.open(probe := folder / f".keyfill-probe.k{os.getpid()}", os.O_CREAT | os.O_WRONLY,
                                 0o600))
                os.unlink(probe)
        except OSError as e:
            raise OutputError(folder, e.strerror or str(e)) from None
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
        force: bool = False, chunk: int = CHUNK, connect_timeout: float = CONNECT_SECONDS,
        on_chunk: Callable[[list[dict]], None] | None = None, recipe: dict | None = None) -> Summary:
    """Do ``items`` with the job function ``fn(chunk, spec) -> outcomes``; see the module docstring.

    ``recipe``: what shapes the outputs (JSON-ready), kept in the output folder's record; None takes
    ``spec.recipe()`` where the spec has one, else the job's name and ``repr(spec)``. Items without a ``root``
    (not planned by :func:`plan`) are not recorded and always done.

    The executor is started only when there is work; a Dask scheduler that
    cannot be reached is one :class:`KeyfillError` before any file is written.
    One run at a time writes into an output folder (:func:`folder_lock`: a
    second waits). An existing output that must be redone but is read-only
    fails (that input's error names ``force``) unless ``force``. When the run
    is interrupted (or fails), the workers are stopped, what they had finished
    is recorded (an output whose files were all written by this run), their
    temporary files are removed, and the exception goes on.
    """
    from keyfill.parallel import check_options

    check_options(workers, connect_timeout)  # before an output folder is made
    if chunk < 1:
        raise UsageError(f"chunk must be at least 1, got {chunk}", params="chunk")
    with contextlib.ExitStack() as locks:
        for root in sorted({it.root for it in items if it.root is not None}):
            locks.enter_context(folder_lock(root))
        return _run(items, fn, spec, workers, scheduler, force, chunk, connect_timeout, on_chunk, recipe)


def _run(items: list[Item], fn: Callable, spec, workers: int | None, scheduler: str | None, force: bool, chunk: int,
         connect_timeout: float, on_chunk: Callable[[list[dict]], None] | None, recipe: dict | None) -> Summary:
    import dataclasses

    from keyfill import __version__
    from keyfill.files import interrupts_deferred, remove_stale
    from keyfill.parallel import default_workers, input_bytes
    from keyfill.parallel import executor as make_executor

    start = time.perf_counter()
    if recipe is None:
        recipe = (spec.recipe() if hasattr(spec, "recipe")
                  else {"job": f"{fn.__module__}:{fn.__qualname__}", "spec": repr(spec)})
    recipe = {"keyfill": __version__, **recipe}
    digest = recipe_digest(recipe)
    records = {root: Record.read(root, force) for root in sorted({it.root for it in items if it.root is not None})}
    summary = Summary(output="")
    outcomes: dict[str, dict] = {}
    shas: dict[str, str | None] = {}
    why: dict[str, list[str]] = {}  # input -> why its existing output is replaced
    before: dict[str, list] = {}  # output -> the stamps of its files before the run
    jobs = []
    for i in range(0, len(items), chunk):
        part = items[i: i + chunk]
        todo = []
        for it in part:
            record = records.get(it.root)
            shas[it.src] = sha = input_sha256(it.src) if record is not None else None
            before[it.dst] = [output_stamp(f) for f in output_files(it.dst)]
            reasons = []
            if before[it.dst][0] is not None:
                if force:
                    reasons = ["force"]
                elif record is None:
                    reasons = ["not recorded"]
                else:
                    reasons = record.stale(it, sha, digest, recipe)
                if not reasons:
                    outcomes[it.src] = {"input": it.src, "output": it.dst, "status": "skipped"}
                else:
                    try:
                        refuse_read_only(it.dst, force)
                    except OutputError as e:
                        outcomes[it.src] = failure(it, e)
                if it.src in outcomes:
                    todo.append(False)
                    continue
                why[it.src] = reasons
            todo.append(True)
        if any(todo):
            jobs.append([dataclasses.replace(it, write=t) for it, t in zip(part, todo)])
    settled = [outcomes[it.src] for it in items if it.src in outcomes]
    if settled and on_chunk is not None:
        with interrupts_deferred():
            on_chunk(settled)
    dirty: set[str] = set()
    pace = {"last": time.perf_counter(), "cost": 0.0}

    def save_records(always: bool = False) -> None:
        # rewritten as chunks complete, but never more than a tenth of the time on it
        now = time.perf_counter()
        if not dirty or (not always and now - pace["last"] < 10 * pace["cost"]):
            return
        for root in sorted(dirty):
            records[root].write()
        dirty.clear()
        pace["last"] = time.perf_counter()
        pace["cost"] = pace["last"] - now

    def settle(it: Item, res: dict) -> dict:
        record = records.get(it.root)
        if res.get("status") == "done":
            if it.src in why:
                res = {**res, "status": "redone", "stale": why[it.src]}
            if record is not None:
                record.put(it, shas[it.src], digest, recipe)
        elif record is not None:
            record.drop(it)
        if record is not None:
            dirty.add(it.root)
        outcomes[it.src] = res
        return res

    if jobs:
        # Reach the cluster before touching the output folder: an unreachable scheduler leaves nothing behind.
        if workers is None and not scheduler:
            workers = default_workers(len(jobs), input_bytes(it.src for job in jobs for it in job if it.write))
        executor, window = make_executor(workers, scheduler, connect_timeout)
        sent = []
        try:
            prepare_outputs([it for job in jobs for it in job if it.write])
            in_flight: dict = {}
            pending = list(jobs)
            while pending or in_flight:
                while pending and len(in_flight) < window:
                    job = pending.pop(0)
                    sent.append(job)
                    in_flight[executor.submit(fn, job, spec)] = job
                for fut in executor.wait(list(in_flight)):
                    job = in_flight.pop(fut)
                    try:
                        results = fut.result()
                    except KeyfillError:
                        raise
                    except Exception as e:  # noqa: BLE001 (a worker that died: its inputs failed, the others go on)
                        results = [failure(it, e) for it in job]
                    # settled and reported together: a signal in between would leave the caller's count short
                    with interrupts_deferred():
                        reported = [settle(it, res) for it, res in zip(job, results) if it.write]
                        if on_chunk is not None:
                            on_chunk(reported)
                    save_records()
        except BaseException:
            with interrupts_deferred():  # a second Ctrl-C does not cut the clean-up short
                executor.close(cancel=True)
                # what the stopped jobs finished: outputs whose files were all written by this run
                finished = [settle(it, {"input": it.src, "output": it.dst, "status": "done"})
                            for job in sent for it in job
                            if it.write and outcomes.get(it.src, {}).get("status") not in ("done", "redone")
                            and written_since(it.dst, before[it.dst])]
                for folder in sorted({Path(it.dst).parent for job in sent for it in job}):
                    remove_stale(folder)  # of the stopped workers (their processes are gone)
                save_records(always=True)
                if finished and on_chunk is not None:
                    on_chunk(finished)
            raise
        save_records(always=True)
        executor.close()
    summary.files = [outcomes[it.src] for it in items]
    summary.seconds = time.perf_counter() - start
    return summary


# --- convert ----------------------------------------------------------------------------------------


def bvh_layout(dst: str, layout: str | None) -> str | None:
    """The ``bvh_layout`` for :func:`keyfill.io.save` of the output ``dst`` of a batch given ``--bvh-layout
    layout``: the layout for a BVH output, None for the others (a batch may write several formats)."""
    from keyfill import io

    return layout if layout is not None and io.FORMATS[io.format_of(dst)].family == "bvh" else None


def convert_chunk(chunk: list[Item], spec: str | None = None) -> list[dict]:
    """Job function of ``keyfill convert IN... -o OUTDIR/``: read each input, write its output; ``spec``: the
    layout of BVH outputs (``--bvh-layout``; None: auto)."""
    from keyfill import io
    from keyfill.io import usd_stage

    out = []
    for it in chunk:
        if not it.write:
            out.append(None)
            continue
        try:
            template = usd_stage.template_for(it.src, io.format_of(it.dst), None)  # before the motion is read
            motion = io.load(it.src)
            io.save(motion, it.dst, source=it.src, bvh_layout=bvh_layout(it.dst, spec), template=template)
            out.append({"input": it.src, "output": it.dst, "status": "done", "frames": motion.num_frames,
                        "joints": motion.num_joints})
        except (KeyfillError, OSError) as e:
            out.append(failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e))))
    return out
