"""The record of how a batch's outputs were made, and the items it is kept for.

:class:`Item` is one input of a batch and its output. **How each output was made** is kept in the output folder's record,
``OUTDIR/.keyfill-outputs.json`` (:class:`Record`, docs/batch.md): per output,
the SHA-256 of its input's bytes, the digest of the *recipe* (everything that
shapes the result: command, method, the model's identity, keys, seed, format,
options, keyfill's version; the recipes themselves are kept too, so a re-run
can say which option changed) and the output's size and mtime when it was
written. A re-run skips an output only when all of these are unchanged; it
redoes one whose record differs or is missing (an output an interrupted run
wrote but did not record yet), and ``force`` redoes all. The record is
rewritten atomically as chunks complete, so an interrupted run keeps what it
finished. A record keyfill cannot read is a :class:`UsageError` naming it
(``force`` starts a new one).

The record also holds what makes an output up (a ``.gltf`` and its ``.bin``: :func:`output_files`) and the
stamps of those files; :func:`folder_lock` keeps two batches out of one output folder at a time.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from keyfill.errors import FormatError, OutputError, UsageError
from keyfill.io import FORMATS, SUFFIXES


@dataclass(frozen=True)
class Item:
    """One input and its output."""

    src: str
    dst: str
    #: do it even if the output is up to date (set by :func:`run` for the chunks it sends)
    write: bool = True
    #: the output folder whose record (:class:`Record`) keeps how ``dst`` was made; None: not recorded
    root: str | None = None


# --- the record of how outputs were made -------------------------------------------------------------

#: the record's file name in an output folder
RECORD = ".keyfill-outputs.json"
RECORD_FORMAT = "keyfill-outputs"
RECORD_VERSION = 1

#: (real path, size, mtime_ns) -> SHA-256: a file is read once per process while it is unchanged
_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_sha256(path: str | os.PathLike) -> str | None:
    """SHA-256 (hex) of the bytes of ``path``, or None when it cannot be read or is no regular file (a FIFO
    would wait for a writer, ``/dev/zero`` never end)."""
    try:
        real = os.path.realpath(path)
        st = os.stat(real)
        if not stat.S_ISREG(st.st_mode):
            return None
        key = (real, st.st_size, st.st_mtime_ns)
        if key not in _DIGESTS:
            h = hashlib.sha256()
            with open(real, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            _DIGESTS[key] = h.hexdigest()
        return _DIGESTS[key]
    except OSError:
        return None


def input_sha256(path: str | os.PathLike) -> str | None:
    """SHA-256 of the bytes that make up the motion file ``path``: the file; for USD also the layers its stage
    composes (sublayers, references, payloads); for a ``.gltf`` also the files its buffers and images name (the ``.bin`` beside it) where the reader follows them (inside the file's folder:
    :func:`keyfill.io.gltf_buffers.resolve_uri`; the reader refuses the others); None when the file cannot be
    read."""
    digest = file_sha256(path)
    family = FORMATS[SUFFIXES[Path(path).suffix.lower()]].family if Path(path).suffix.lower() in SUFFIXES else None
    if digest is not None and family == "usd":
        return _usd_sha256(path, digest)
    if digest is None or Path(path).suffix.lower() != ".gltf":
        return digest
    try:
        doc = json.loads(Path(path).read_bytes())
    except (OSError, ValueError):
        return digest  # the reader reports it
    from keyfill.io.gltf_buffers import resolve_uri

    parts = [digest]
    for key in ("buffers", "images"):
        entries = doc.get(key) if isinstance(doc, dict) else None
        for entry in entries if isinstance(entries, list) else ():
            uri = entry.get("uri") if isinstance(entry, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                try:
                    named = file_sha256(resolve_uri(Path(path).parent, uri, path, key))
                except FormatError:  # outside the folder, missing, not a file: the reader says so for this input
                    named = None
                parts.append(f"{uri}\0{named}")
    return digest if len(parts) == 1 else hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _usd_sha256(path: str | os.PathLike, digest: str) -> str:
    """The digest of a USD file ``path`` (whose own is ``digest``) and of the layers its stage composes
    (:func:`keyfill.io.usd_layers.layer_files`): a changed sublayer or reference changes the input."""
    from keyfill.io.usd_layers import layer_files

    try:
        layers = layer_files(path, path)[1:]
    except Exception:  # noqa: BLE001 - not USD, or a layer that is no regular file: the reader says so
        return digest
    if not layers:
        return digest
    parts = [digest] + [f"{p}\0{file_sha256(p)}" for p in layers]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def recipe_digest(recipe: dict) -> str:
    """The digest of a recipe (its canonical JSON); equal recipes, equal digests."""
    text = json.dumps(recipe, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def output_stamp(path: str) -> list[int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def output_files(dst: str) -> list[str]:
    """The files the output ``dst`` consists of: itself, then the file its format writes beside it (a
    ``.gltf``'s ``.bin``, :attr:`keyfill.io.Format.sidecar`)."""
    fmt = SUFFIXES.get(Path(dst).suffix.lower())
    sidecar = FORMATS[fmt].sidecar if fmt is not None else None
    return [dst] if sidecar is None else [dst, str(Path(dst).with_suffix(sidecar))]


def _read_only(path: str) -> bool:
    """Whether the existing file ``path`` may not be written (no write permission bit: so also for root)."""
    try:
        return Path(path).is_file() and (not os.stat(path).st_mode & 0o222 or not os.access(path, os.W_OK))
    except OSError:
        return False


def refuse_read_only(output: str | os.PathLike | None, force: bool = False) -> None:
    """An :class:`OutputError` (exit 1) when a file of the existing output ``output`` (:func:`output_files`) is
    read-only, unless ``force``: replacing it would make it writable again. Checked before anything is
    written; names the parameter ``force``."""
    if force or output is None or str(output) == "-":
        return
    for path in output_files(str(output)):
        if _read_only(path):
            raise OutputError(path, "a read-only file; give force to replace it", params="force")


def written_since(dst: str, before: list) -> bool:
    """Whether every file of the output ``dst`` exists and changed since ``before`` (their stamps then)."""
    now = [output_stamp(f) for f in output_files(dst)]
    return all(s is not None and s != b for s, b in zip(now, before))


def _file_stamp(path: str) -> list[int] | None:
    """A companion file's stamp: its size, modification time and inode (a file moved in from elsewhere keeps
    its time, not its inode)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns, st.st_ino]


def _is_stamp(stamp, length: int = 2) -> bool:
    return isinstance(stamp, list) and len(stamp) == length and all(type(v) is int for v in stamp)


def _entry_ok(entry) -> bool:
    """Whether ``entry`` has the shape :meth:`Record.put` writes (one of another shape: a damaged record)."""
    files = entry.get("files", {}) if isinstance(entry, dict) else None
    return (isinstance(entry, dict) and isinstance(entry.get("input"), str)
            and isinstance(entry.get("input_sha256"), str) and isinstance(entry.get("recipe"), str)
            and _is_stamp(entry.get("output")) and isinstance(files, dict)
            and all(isinstance(k, str) and _is_stamp(v, 3) for k, v in files.items()))


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike) -> Iterator[None]:
    """Hold the output folder ``folder`` for one batch (an exclusive ``flock`` of the folder itself: nothing
    is written for it): a second run into it waits until the first ends, saying so in a note, and then reads
    the record the first left. The folder is created if missing, and removed again, if still empty, when the
    block fails. On a file system without ``flock`` (some network file systems) runs are not serialised.
    """
    import fcntl

    from keyfill import progress

    folder = Path(folder)
    made = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(folder, e.strerror or str(e)) from None
    fd = None
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            progress.note(f"{folder}: another keyfill run is writing into this folder; waiting for it to end")
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # no flock here
            pass
        yield
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty: what this run made and did not fill
        raise
    finally:
        if fd is not None:
            os.close(fd)


class Record:
    """How the outputs of one output folder were made: ``OUTDIR/.keyfill-outputs.json``.

    ``{"format": "keyfill-outputs", "version": 1, "recipes": {digest: recipe}, "outputs": {name: entry}}``
    where ``name`` is the output's path relative to the folder (``/``-separated) and ``entry`` is
    ``{"input": path, "input_sha256": hex, "recipe": digest, "output": [size, mtime_ns]}``
    (``input_sha256``: :func:`input_sha256`), with ``"files": {name: [size, mtime_ns, inode]}`` for the other
    files of an output (:func:`output_files`: a ``.gltf``'s ``.bin``), so that a changed, truncated or swapped
    one makes it stale too.
    Entries of outputs a run does not touch are kept.
    """

    def __init__(self, folder: str | os.PathLike, recipes: dict | None = None, outputs: dict | None = None):
        self.folder = Path(folder)
        self.path = self.folder / RECORD
        self.recipes: dict[str, dict] = recipes or {}
        self.outputs: dict[str, dict] = outputs or {}

    @classmethod
    def read(cls, folder: str | os.PathLike, force: bool = False) -> Record:
        """The record of ``folder`` (empty when it has none); one that cannot be read is a :class:`UsageError`
        naming it, unless ``force`` (then a new record replaces it)."""
        path = Path(folder) / RECORD
        try:
            text = path.read_bytes()
        except FileNotFoundError:
            return cls(folder)
        except OSError as e:
            if force:
                return cls(folder)
            raise UsageError(f"{path}: cannot read the record of this output folder ({e.strerror}); "
                             "fix it, or give force to redo every output and write a new record",
                             params="force") from None
        try:
            data = json.loads(text)
            if not isinstance(data, dict) or data.get("format") != RECORD_FORMAT:
                raise ValueError("not a keyfill output record")
            if data.get("version") != RECORD_VERSION:
                raise ValueError(f"a record of version {data.get('version')!r}, not {RECORD_VERSION}")
            recipes, outputs = data.get("recipes"), data.get("outputs")
            if not isinstance(recipes, dict) or not all(isinstance(r, dict) for r in recipes.values()):
                raise ValueError("its recipes are not a JSON object of objects")
            if not isinstance(outputs, dict) or not all(_entry_ok(e) for e in outputs.values()):
                raise ValueError("its outputs are not entries with input, input_sha256, recipe and output")
        except (ValueError, UnicodeDecodeError, RecursionError) as e:  # json.JSONDecodeError is a ValueError
            if force:
                return cls(folder)
            line = e.lineno if isinstance(e, json.JSONDecodeError) else None
            reason = (f"not valid JSON at line {line}" if line is not None else
                      "nested too deeply" if isinstance(e, RecursionError) else str(e))
            error = UsageError(f"{path}: damaged or foreign record of this output folder ({reason}); "
                               "remove it, or give force to redo every output and write a new record",
                               params="force")
            error.path, error.line = str(path), line  # --json names the record (docs/json.md)
            raise error from None
        return cls(folder, recipes, outputs)

    def name(self, item: Item) -> str:
        return Path(os.path.relpath(item.dst, self.folder)).as_posix()

    def stale(self, item: Item, input_sha: str | None, digest: str, recipe: dict) -> list[str]:
        """Why the existing output of ``item`` is not known to be made from this input by ``recipe``: an empty
        list when it is."""
        entry = self.outputs.get(self.name(item))
        if entry is None:
            return ["no record of how the output was made"]
        why = []
        if input_sha is None or entry.get("input_sha256") != input_sha:
            why.append("input changed")
        if entry.get("recipe") != digest:
            old = self.recipes.get(entry.get("recipe"), {})
            changed = sorted(k for k in set(old) | set(recipe) if old.get(k) != recipe.get(k))
            why.append("made with other " + (", ".join(changed) if changed and old else "options"))
        if entry.get("output") != output_stamp(item.dst) or entry.get("files", {}) != self._companions(item):
            why.append("output changed since it was written")
        return why

    def _companions(self, item: Item) -> dict[str, list[int] | None]:
        """The stamps of the files beside ``item``'s output that are part of it (a ``.gltf``'s ``.bin``)."""
        return {Path(os.path.relpath(f, self.folder)).as_posix(): _file_stamp(f) for f in output_files(item.dst)[1:]}

    def put(self, item: Item, input_sha: str | None, digest: str, recipe: dict) -> None:
        stamp, files = output_stamp(item.dst), self._companions(item)
        if input_sha is None or stamp is None or None in files.values():
            self.outputs.pop(self.name(item), None)
            return
        self.recipes[digest] = recipe
        self.outputs[self.name(item)] = {"input": item.src, "input_sha256": input_sha, "recipe": digest,
                                         "output": stamp, **({"files": files} if files else {})}

    def drop(self, item: Item) -> None:
        self.outputs.pop(self.name(item), None)

    def write(self) -> None:
        """Replace the record file atomically (the recipes no entry uses are left out)."""
        from keyfill.files import atomic_output

        used = {e["recipe"] for e in self.outputs.values()}
        data = {"format": RECORD_FORMAT, "version": RECORD_VERSION,
                "recipes": {k: v for k, v in self.recipes.items() if k in used}, "outputs": self.outputs}
        self.folder.mkdir(parents=True, exist_ok=True)
        with atomic_output(self.path) as tmp:
            tmp.write_text(json.dumps(data, sort_keys=True, separators=(",", ":"), default=str) + "\n")
