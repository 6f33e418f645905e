"""One record per benchmark run, written to ``benchmarks/results/<name>.json``; ``make_page.py`` builds the page.

A record says what ran and where, and holds the figures and the goals they are judged by::

    {
      "name": "bvh_io",                      # the file's stem: the script's stem without "bench_", plus a part
      "script": "benchmarks/bench_bvh_io.py",
      "command": ".venv/bin/python benchmarks/bench_bvh_io.py --repeat 7",    # as run, from the repo root
      "commit": "<40 hex>", "dirty": [],     # keyfill's commit, and the files under keyfill/ that differ from it
      "date": "2026-12-01T18:49:35Z",        # UTC, when the run ended
      "machine": {"cpu": "AMD EPYC", "cores": 2, "python": "3.11.7", "numpy": "2.4.6", ...},
      "load_average": {"before": [1, 5, 15 min], "after": [...]},
      "wall_seconds": 12.3,
      "source": "run",                       # or "transcribed from docs/benchmarks.md, measured <date>"
      "goals": [{"issue": "2", "goal": "...", "measured": "...", "met": true}],
      "figures": {...}                       # the script's own figures (see its docstring)
    }

The JSON is stable (sorted keys, indent 2, a trailing newline; dict keys are strings, NaN is null) and is
written atomically (a temporary file in the same folder, then a rename), so a page built from a folder of
records never sees half a file. Scripts call :class:`Run` at their start and :meth:`Run.record` at the end;
``--no-record`` (:func:`add_option`) skips the write for a quick check.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

from timing import cpu_name

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().parent / "results"
#: the keys every record has (``note`` is optional)
FIELDS = ("name", "script", "command", "commit", "dirty", "date", "machine", "load_average", "wall_seconds",
          "source", "goals", "figures")
VERSIONED = ("numpy", "torch", "onnxruntime", "matplotlib", "bvhio")


def add_option(parser) -> None:
    """Add ``--no-record`` to an ``argparse`` parser: the run then writes nothing to ``benchmarks/results/``."""
    parser.add_argument("--no-record", action="store_true",
                        help="do not write the record to benchmarks/results/ (a quick check)")


def goal(issue: int | str, text: str, measured: str, met: bool) -> dict:
    """One goal of a record: the issue that set it, what it asks, what was measured, and whether it is met."""
    return {"issue": str(issue), "goal": text, "measured": measured, "met": bool(met)}


def repo_path(path: str) -> str:
    """``path`` relative to the repository root when it lies inside it, else as given (links are kept:
    ``.venv/bin/python`` stays itself)."""
    try:
        return str(Path(os.path.abspath(path)).relative_to(ROOT))
    except ValueError:
        return path


def command_line(argv: list[str]) -> str:
    """The command as run, runnable from the repository root: this interpreter and ``argv``, script made relative."""
    return shlex.join([repo_path(sys.executable), repo_path(argv[0]), *argv[1:]])


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), *args], check=False, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def commit() -> tuple[str | None, list[str] | None]:
    """keyfill's commit (``HEAD``) and the files under ``keyfill/`` that differ from it; ``None`` outside git."""
    head = _git("rev-parse", "HEAD")
    changed = _git("diff", "--name-only", "HEAD", "--", "keyfill")
    return head, (None if changed is None else sorted(changed.splitlines()))


def machine() -> dict:
    """The processor's name, the core count, Python's version and those of the measured libraries loaded."""
    info = {"cpu": cpu_name(), "cores": os.cpu_count(), "python": platform.python_version()}
    for name in VERSIONED:
        if name in sys.modules:
            try:
                info[name] = metadata.version(name)
            except metadata.PackageNotFoundError:
                continue
    return info


class Run:
    """One benchmark run: made at the start (the load average before, the clock), recorded at the end."""

    def __init__(self, argv: list[str] | None = None):
        self.argv = list(sys.argv if argv is None else argv)
        self.load_before = list(os.getloadavg())
        self.started = time.perf_counter()

    def record(self, name: str, figures: dict, goals: list[dict], write: bool = True,
               directory: Path = RESULTS) -> dict:
        """The record of this run; written to ``directory/<name>.json`` unless ``write`` is false."""
        head, dirty = commit()
        record = {
            "name": name,
            "script": repo_path(self.argv[0]),
            "command": command_line(self.argv),
            "commit": head,
            "dirty": dirty,
            "date": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "machine": machine(),
            "load_average": {"before": self.load_before, "after": list(os.getloadavg())},
            "wall_seconds": round(time.perf_counter() - self.started, 1),
            "source": "run",
            "goals": goals,
            "figures": figures,
        }
        record = plain(record)
        if write:
            path = write_record(record, directory)
            print(f"recorded {repo_path(str(path))}", file=sys.stderr)
        return record


def print_goals(record: dict) -> None:
    """One line per goal of ``record`` for a script's text output: ``goal: <goal>: <measured> met|MISSED``."""
    for g in record["goals"]:
        print(f"goal: {g['goal']}: {g['measured']} {'met' if g['met'] else 'MISSED'}")


def summary(record: dict) -> str:
    """One line for a script's text output: the machine and the 1-minute load before and after the run."""
    m = record["machine"]
    before, after = record["load_average"]["before"][0], record["load_average"]["after"][0]
    return f"machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}; load average {before:.2f} -> {after:.2f}"


def _default(value):
    """JSON for what ``json`` does not know: numpy scalars and arrays, paths, sets."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (Path, os.PathLike)):
        return os.fspath(value)
    if isinstance(value, (set, frozenset)):
        return sorted(value)
    raise TypeError(f"{type(value).__name__} is not JSON: {value!r}")


def _finite(value):
    """``value`` with every NaN or infinity replaced by ``None`` (JSON has neither)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def plain(value):
    """``value`` as JSON reads it back: string keys, lists for tuples and arrays, ``None`` for NaN."""
    return _finite(json.loads(json.dumps(value, default=_default)))


def dumps(record: dict) -> str:
    """The stable text of a record: sorted keys, indent 2, a trailing newline."""
    return json.dumps(plain(record), indent=2, sort_keys=True, allow_nan=False) + "\n"


def write_record(record: dict, directory: Path = RESULTS) -> Path:
    """Write ``record`` to ``directory/<name>.json`` atomically (temporary file, then rename); return the path."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{record['name']}.json"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(dumps(record))
        os.chmod(tmp, 0o644)  # mkstemp makes it owner-only
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_records(directory: Path = RESULTS) -> dict[str, dict]:
    """Every record of ``directory``, by name (sorted)."""
    return {p.stem: json.loads(p.read_text(encoding="utf-8")) for p in sorted(directory.glob("*.json"))}
