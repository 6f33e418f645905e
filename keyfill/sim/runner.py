"""Building a hop dataset: many annealing runs, in parallel, resumable.

:func:`simulate` fills a folder (format in :mod:`keyfill.io.hops`) with
the first ``count`` accepted runs in run order. Run ``r`` depends only on
``(seed, r)``, so the folder comes out byte-identical whether the runs go to
one process, several local processes (``workers``) or a Dask cluster
(``scheduler``), and whatever order they finish in.

Each finished run is written at once: its motion file (atomically), its
manifest record and its line in ``runs.jsonl`` (each one appended with a
single write). A build that is killed loses only the runs in flight; running
the same command again reads ``runs.jsonl`` and goes on from there. When the
build completes, ``manifest.jsonl`` and ``runs.jsonl`` are rewritten in run
order and runs that finished beyond the last needed one are dropped.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from keyfill.errors import DataError, OutputError, UsageError
from keyfill.io import hops as ds
from keyfill.limits import CONNECT_SECONDS, check_seed
from keyfill.motion import Motion
from keyfill.parallel import check_options
from keyfill.parallel import executor as make_executor
from keyfill.sim.extract import extract
from keyfill.sim.search import anneal, run_generator
from keyfill.sim.settings import DEFAULT_SETTINGS, Settings


@dataclass(frozen=True)
class Job:
    """What every run of one dataset shares (sent to the workers)."""

    seed: int
    iterations: int
    settings: Settings = DEFAULT_SETTINGS


@dataclass(frozen=True, eq=False)
class Outcome:
    """A finished run: its ``runs.jsonl`` line and, when accepted, its manifest record (without
    the file name) and motion."""

    run: int
    line: dict
    record: dict | None = None
    motion: Motion | None = None

    @property
    def accepted(self) -> bool:
        return self.record is not None


def run_job(job: Job, run: int) -> Outcome:
    """Anneal run ``run`` of ``job`` and extract its sequence (runs in a worker)."""
    s = job.settings
    result = anneal(job.seed, run, job.iterations, s)
    line = {"run": run, "accepted": result.accepted, "w_e": result.w_e, "episodes": result.episodes}
    if not result.accepted:
        return Outcome(run, {**line, "reason": result.reason})
    hops = result.hops
    seq = extract(result.episode, hops, run_generator(job.seed, run, stream=1), s)
    t = result.episode.times
    record = {
        "id": ds.sequence_id(run),
        "run": run,
        "seed": job.seed,
        "w_e": result.w_e,
        "controller": result.controller.to_dict(),
        "energy": result.energy,
        "distance": hops.distance,
        "max_height": hops.max_height,
        "hops": hops.count,
        "frames": seq.motion.num_frames,
        "fps": seq.motion.fps,
        "keys": seq.motion.keys.to_list(),
        "liftoff_frames": seq.liftoff_frames.tolist(),
        "landing_frames": seq.landing_frames.tolist(),
        "air_frames": seq.air_frames.tolist(),
        "frame_times": seq.frame_times.tolist(),
        "liftoff_times": t[hops.liftoffs].tolist(),
        "landing_times": t[hops.landings].tolist(),
        "iterations": job.iterations,
        "episodes": result.episodes,
        "settings": s.to_dict(),
    }
    return Outcome(run, {**line, "id": record["id"], "energy": result.energy}, record, seq.motion)


def config_of(job: Job, fmt: str) -> dict:
    """The configuration a folder is made with (``simulate.json``): what makes its files what they are."""
    return {"format": fmt, "seed": job.seed, "iterations": job.iterations, "settings": job.settings.to_dict()}


def check_arguments(
    count: int, seed: int, iterations: int, workers: int | None, fmt: str,
    max_runs: int | None = None, connect_timeout: float = CONNECT_SECONDS,
) -> None:
    """Raise :class:`UsageError` for values ``simulate`` cannot work with, naming the parameter."""
    if count < 1:
        raise UsageError(f"count must be at least 1, got {count}", params="count")
    check_seed(seed)
    if iterations < 1:
        raise UsageError(f"iterations must be at least 1, got {iterations}", params="iterations")
    if fmt not in ds.SUFFIXES:
        raise UsageError(f"unknown format {fmt!r}; expected one of {', '.join(ds.SUFFIXES)}")
    if max_runs is not None and max_runs < 1:
        raise UsageError(f"max_runs must be at least 1, got {max_runs}", params="max_runs")
    check_options(workers, connect_timeout)


# --- the folder -----------------------------------------------------------------------------------


def _ours(name: str) -> bool:
    """Files a build writes (and ``--force`` may remove)."""
    if name in (ds.CONFIG_FILE, ds.MANIFEST_FILE, ds.RUNS_FILE):
        return True
    stem, _, suffix = name.partition(".")
    if name.startswith(".") and ".part" in name:  # temporary file of an interrupted atomic write
        return True
    return stem.startswith("seq_") and stem[4:].isdigit() and "." + suffix in ds.SUFFIXES.values()


def prepare_folder(folder: Path, config: dict, force: bool) -> None:
    """Create ``folder`` or check that it holds a dataset of ``config`` (refused otherwise without ``force``)."""
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{folder} exists and is not a folder")
    cfg_path = folder / ds.CONFIG_FILE
    if folder.is_dir() and any(folder.iterdir()) and not force:
        if not cfg_path.is_file():
            raise UsageError(
                f"{folder} is not empty and is not a keyfill simulate folder (no {ds.CONFIG_FILE}); "
                "choose a new or empty folder, or use force to build in it anyway", params="force"
            )
        try:
            old = json.loads(cfg_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            old = None
        if old != config:
            raise UsageError(f"{folder} holds a dataset of a different configuration ({_difference(old, config)}); "
                             "use force to replace it, or choose another folder", params="force")
        return
    if folder.is_dir() and force:
        for p in folder.iterdir():
            if p.is_file() and _ours(p.name):
                p.unlink()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(folder, e.strerror or str(e)) from None
    from keyfill.files import atomic_output

    with atomic_output(cfg_path) as tmp:
        tmp.write_text(json.dumps(config, indent=2, sort_keys=True) + "\n", encoding="utf-8")


def _difference(old, new: dict) -> str:
    if not isinstance(old, dict):
        return f"{ds.CONFIG_FILE} cannot be read"
    for key in ("format", "seed", "iterations"):
        if old.get(key) != new[key]:
            return f"{key} {old.get(key)!r} there, {new[key]!r} now"
    old_s, new_s = old.get("settings") or {}, new["settings"]
    for key in new_s:
        if old_s.get(key) != new_s[key]:
            return f"simulation setting {key} {old_s.get(key)!r} there, {new_s[key]!r} now"
    return "its simulation settings differ"


def _finished_runs(folder: Path) -> tuple[dict[int, dict], dict[int, dict]]:
    """Runs already done (``runs.jsonl`` lines) and manifest records of the accepted ones, checked.

    An accepted run whose record or motion file is missing counts as not done.
    """
    lines: dict[int, dict] = {}
    if (folder / ds.RUNS_FILE).is_file():
        for line in ds.read_jsonl(folder / ds.RUNS_FILE):
            lines[int(line["run"])] = line
    records: dict[int, dict] = {}
    if (folder / ds.MANIFEST_FILE).is_file():
        for rec in ds.read_jsonl(folder / ds.MANIFEST_FILE):
            records[int(rec["run"])] = rec
    for run, line in list(lines.items()):
        if line.get("accepted") and (run not in records or not (folder / records[run]["file"]).is_file()):
            del lines[run]
    records = {r: rec for r, rec in records.items() if r in lines and lines[r].get("accepted")}
    return lines, records


def _rewrite(folder: Path, lines: dict[int, dict], records: dict[int, dict]) -> None:
    """``runs.jsonl`` and ``manifest.jsonl`` in run order (atomically)."""
    from keyfill.files import atomic_output

    for name, items in ((ds.RUNS_FILE, lines), (ds.MANIFEST_FILE, records)):
        with atomic_output(folder / name) as tmp:
            tmp.write_text("".join(json.dumps(items[r], sort_keys=True) + "\n" for r in sorted(items)), encoding="utf-8")


def _drop_unlisted(folder: Path, records: dict[int, dict]) -> None:
    """Remove sequence files no manifest record lists (a killed build wrote them, then lost its record).

    A run that is needed again writes the same bytes, so the folder ends as an
    uninterrupted build leaves it.
    """
    listed = {rec["file"] for rec in records.values()}
    for p in folder.iterdir():
        if p.name not in listed and p.name.startswith("seq_") and p.is_file() and _ours(p.name):
            p.unlink(missing_ok=True)


# --- the build ------------------------------------------------------------------------------------


@dataclass
class Summary:
    """What a build did (``--json`` prints it)."""

    folder: str
    count: int
    sequences: int = 0
    runs: int = 0
    new_runs: int = 0
    new_episodes: int = 0
    seconds: float = 0.0
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        accepted_rate = self.sequences / self.runs if self.runs else 0.0
        return {
            "folder": self.folder,
            "count": self.count,
            "sequences": self.sequences,
            "runs": self.runs,
            "acceptance_rate": accepted_rate,
            "new_runs": self.new_runs,
            "new_episodes": self.new_episodes,
            "seconds": self.seconds,
            "episodes_per_second": self.new_episodes / self.seconds if self.seconds > 0 else 0.0,
            **self.details,
        }


def simulate(
    folder: str | os.PathLike,
    count: int,
    seed: int = 0,
    iterations: int = 200,
    workers: int | None = None,
    fmt: str = "usd",
    scheduler: str | None = None,
    force: bool = False,
    settings: Settings = DEFAULT_SETTINGS,
    max_runs: int | None = None,
    connect_timeout: float = CONNECT_SECONDS,
    on_run: Callable[[Outcome, int, int], None] | None = None,
) -> Summary:
    """Build (or resume) a hop dataset of ``count`` sequences in ``folder``.

    Args:
        workers: local worker processes (default: one per available core; 1 runs
            everything in this process); with
            ``scheduler``, the number of runs kept in flight on the cluster
            (default: its thread count).
        scheduler: a Dask scheduler address (``tcp://host:8786``); runs then go
            to that cluster.
        force: replace a folder of another configuration (only the files a
            build writes are removed).
        max_runs: give up after this many runs (default ``20 * count + 20``).
        on_run: called after every finished run with ``(outcome, sequences, runs)``.

    Raises :class:`DataError` when ``max_runs`` runs do not give ``count`` sequences
    (the ones found are kept).
    """
    check_arguments(count, seed, iterations, workers, fmt, max_runs, connect_timeout)
    folder = Path(folder)
    job = Job(seed=seed, iterations=iterations, settings=settings)
    config = config_of(job, fmt)
    max_runs = 20 * count + 20 if max_runs is None else max_runs
    # Reach the cluster before touching the folder: an unreachable scheduler leaves nothing behind.
    executor, window = make_executor(workers, scheduler, connect_timeout) if scheduler else (None, None)
    try:
        prepare_folder(folder, config, force)
        if executor is None:
            executor, window = make_executor(workers)
        summary = _build(folder, job, fmt, count, max_runs, executor, window, on_run)
    except BaseException:
        if executor is not None:
            executor.close(cancel=True)
        raise
    executor.close()
    return summary


def _build(folder, job, fmt, count, max_runs, executor, window, on_run) -> Summary:
    from keyfill import io
    from keyfill.files import remove_stale

    start = time.perf_counter()
    remove_stale(folder)  # temporary files of a killed build
    lines, records = _finished_runs(folder)
    _drop_unlisted(folder, records)
    _rewrite(folder, lines, records)
    summary = Summary(folder=str(folder), count=count)
    accepted = sum(1 for line in lines.values() if line.get("accepted"))
    if accepted >= count:
        summary.sequences, summary.runs = accepted, len(lines)
        summary.details["already_done"] = True
        return summary
    in_flight: dict = {}
    next_run = 0
    suffix = ds.SUFFIXES[fmt]
    while True:
        while len(in_flight) < window and accepted + len(in_flight) < count and len(lines) + len(in_flight) < max_runs:
            while next_run in lines:
                next_run += 1
            in_flight[executor.submit(run_job, job, next_run)] = next_run
            next_run += 1
        if not in_flight:
            break
        for fut in executor.wait(list(in_flight)):
            run = in_flight.pop(fut)
            out: Outcome = fut.result()
            if out.accepted:
                record = {**out.record, "file": out.record["id"] + suffix}
                io.save(out.motion, folder / record["file"])
                ds.append_jsonl(folder / ds.MANIFEST_FILE, record)
                records[run] = record
                accepted += 1
            ds.append_jsonl(folder / ds.RUNS_FILE, out.line)  # the run is done once this line is written
            lines[run] = out.line
            summary.new_runs += 1
            summary.new_episodes += int(out.line["episodes"])
            if on_run is not None:
                on_run(out, accepted, len(lines))
    # The first ``count`` accepted runs in run order, and every run before the last of them.
    kept = sorted(records)[:count]
    last = kept[-1] if len(kept) == count else max(lines, default=-1)
    for run in [r for r in records if r > last]:
        (folder / records.pop(run)["file"]).unlink(missing_ok=True)
    lines = {r: line for r, line in lines.items() if r <= last}
    _drop_unlisted(folder, records)
    _rewrite(folder, lines, records)
    summary.sequences, summary.runs = len(records), len(lines)
    summary.seconds = time.perf_counter() - start
    if len(records) < count:
        raise DataError(
            f"only {len(records)} of {count} sequences were accepted in {len(lines)} runs (the limit); "
            f"they are kept in {folder}: raise the run limit or iterations and run again", params="iterations"
        )
    return summary
