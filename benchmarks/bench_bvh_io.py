"""BVH read and write speed: keyfill against bvhio, the ``bvh`` package and a bare numpy parse.

The test file (about 20 MB) is the frames of Bandai-Namco dataset-1's clips
concatenated under the first clip's hierarchy (all clips have the same 22
joints with 6 channels each), built once under ``data/bench/`` (git-ignored).
The corpus is read from ``data/bandai1/`` and unpacked there from
``../shared/data/corpora/`` when absent; without either the script says so
and exits 0 (skipped).

Measured, each the median of ``--repeat`` runs in this one process:

* keyfill read: ``keyfill.io.bvh.read`` (hierarchy, value-count checks,
  numbers, Euler -> quaternions: a complete ``Motion``);
* bvhio: ``bvhio.readAsBvh`` (its fastest reader: per-joint Euler values);
* bvh: ``bvh.Bvh(text)`` then the frames as a float array (optional: left out
  with ``--no-bvh`` or when the package is not installed);
* numpy floor: ``np.loadtxt`` of the motion lines (numbers only, no checks);
* keyfill write: ``keyfill.io.bvh.write`` (``dumps`` + file write) of the motion
  read above; bvhio write: ``bvhio.writeBvh`` of its container.

MB/s is the input file's size (for writers: the written file's size) over the
median time. Goals (issue 2): read >= 40 MB/s and >= 5x bvhio; write >= 20 MB/s.
The run is recorded in ``benchmarks/results/bvh_io.json`` (``results.py``; not with
``--no-record``); its figures are the file (``file``, ``bytes``, ``frames``, ``joints``,
``channels``), ``repeat`` and ``rows``: per reader or writer ``seconds``, ``cpu_seconds``,
``mb_per_s`` and ``x_keyfill_read`` (its time over keyfill's read).

    .venv/bin/python benchmarks/bench_bvh_io.py               # 5 repetitions
    .venv/bin/python benchmarks/bench_bvh_io.py --repeat 9 --json
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tarfile
import time
from pathlib import Path

import numpy as np
import results

ROOT = Path(__file__).resolve().parents[1]
CORPUS_TAR = ROOT.parent / "shared" / "data" / "corpora" / "bandai_namco_motiondataset1.tar.xz"
CORPUS_DIR = ROOT / "data" / "bandai1"
CLIPS = CORPUS_DIR / "Bandai-Namco-Research-Motiondataset-1" / "data"
BENCH_DIR = ROOT / "data" / "bench"

READ_GOAL_MBS = 40.0
BVHIO_GOAL_RATIO = 5.0
WRITE_GOAL_MBS = 20.0


class Skipped(Exception):
    """The data a benchmark needs is not here; the message says what is missing."""


def bandai1_clips() -> list[Path]:
    """The BVH clips of Bandai dataset-1, unpacking the shared corpus into ``data/bandai1/`` if needed."""
    if not CLIPS.is_dir():
        if not CORPUS_TAR.is_file():
            raise Skipped(f"Bandai dataset-1 is absent: neither {CLIPS} nor {CORPUS_TAR} exists")
        print(f"unpacking {CORPUS_TAR.name} into {CORPUS_DIR} ...", file=sys.stderr)
        CORPUS_DIR.mkdir(parents=True, exist_ok=True)
        with tarfile.open(CORPUS_TAR) as tar:
            tar.extractall(CORPUS_DIR, filter="data")
    clips = sorted(CLIPS.glob("*.bvh"))
    if not clips:
        raise Skipped(f"no .bvh clips in {CLIPS}")
    return clips


def _split_clip(raw: bytes) -> tuple[bytes, bytes, list[bytes]]:
    """``(hierarchy text up to MOTION, Frame Time value, non-empty motion lines)`` of one clip."""
    at = raw.index(b"\nMOTION") + 1
    lines = raw[at:].split(b"\n")
    frame_time = lines[2].split(b":", 1)[1].strip()
    return raw[:at], frame_time, [line.rstrip(b"\r") for line in lines[3:] if line.strip()]


def concatenated_bvh(min_bytes: int | None = None, frames: int | None = None) -> Path:
    """A BVH file of Bandai dataset-1 frames, clip after clip (sorted by name), built once.

    Stops after the first clip that brings the motion text to ``min_bytes``, or
    at exactly ``frames`` frames. Every clip's channel layout must equal the
    first clip's (the hierarchy text may differ in rest offsets only).
    """
    if (min_bytes is None) == (frames is None):
        raise ValueError("give min_bytes or frames")
    name = f"bandai1_concat_{min_bytes // 1_000_000}MB.bvh" if min_bytes else f"bandai1_concat_{frames}f.bvh"
    path = BENCH_DIR / name
    if path.is_file():
        return path
    header, frame_time, lines, size = None, None, [], 0
    layout = None
    for clip in bandai1_clips():
        head, ft, data = _split_clip(clip.read_bytes())
        this_layout = [ln.split() for ln in head.splitlines() if b"CHANNELS" in ln]
        if header is None:
            header, frame_time, layout = head, ft, this_layout
        elif this_layout != layout:
            raise ValueError(f"{clip.name} has another channel layout than the first clip")
        lines.extend(data)
        size += sum(len(ln) + 1 for ln in data)
        if (min_bytes and size >= min_bytes) or (frames and len(lines) >= frames):
            break
    if frames:
        if len(lines) < frames:
            raise Skipped(f"the corpus has only {len(lines)} frames, {frames} asked for")
        lines = lines[:frames]
    text = header + b"MOTION\nFrames: %d\nFrame Time: %s\n" % (len(lines), frame_time) + b"\n".join(lines) + b"\n"
    from keyfill.files import atomic_output

    BENCH_DIR.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_bytes(text)
    return path


def median_times(fn, repeat: int) -> tuple[float, float, object]:
    """Median wall and CPU time (seconds) of ``repeat`` calls of ``fn()``, and the last result.

    On a shared machine the CPU time (this process's user + system time) is
    the steadier figure; the wall time is the one a user waits.
    """
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        start, cpu = time.perf_counter(), time.process_time()
        result = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus), result


def median_time(fn, repeat: int) -> tuple[float, object]:
    """Median wall time of ``repeat`` calls of ``fn()`` (seconds) and the last result."""
    wall, _, result = median_times(fn, repeat)
    return wall, result


def numpy_floor(raw: bytes) -> np.ndarray:
    """Only the numbers: ``np.loadtxt`` of the lines after ``Frame Time:`` (no checks, no rotations)."""
    start = raw.index(b"\n", raw.index(b"Frame Time:")) + 1
    return np.loadtxt(raw[start:].split(b"\n"), dtype=np.float64, comments=None, ndmin=2)


def run(repeat: int, with_bvh: bool, out_dir: Path) -> dict:
    import bvhio

    from keyfill.io import bvh as kbvh

    path = concatenated_bvh(min_bytes=20_000_000)
    size = path.stat().st_size
    raw = path.read_bytes()  # also warms the page cache
    rows: dict[str, dict] = {}

    def row(name, seconds, cpu, nbytes, **extra):
        rows[name] = {"seconds": seconds, "cpu_seconds": cpu, "mb_per_s": nbytes / 1e6 / seconds, **extra}

    t, c, motion = median_times(lambda: kbvh.read(path), repeat)
    row("keyfill read", t, c, size)
    t, c, values = median_times(lambda: numpy_floor(raw), repeat)
    if values.shape != (motion.num_frames, motion.skeleton.num_channels):
        raise AssertionError(f"numpy floor parsed {values.shape}")
    row("numpy loadtxt (floor)", t, c, size)
    t, c, container = median_times(lambda: bvhio.readAsBvh(str(path)), repeat)
    if len(container.Root.Keyframes) != motion.num_frames:
        raise AssertionError("bvhio read another number of frames")
    row("bvhio readAsBvh", t, c, size)
    try:
        import bvh as bvh_pkg
    except ImportError:
        with_bvh = False
        print("bench_bvh_io: the 'bvh' package is not installed; its row is left out", file=sys.stderr)
    if with_bvh:

        def bvh_read():
            mocap = bvh_pkg.Bvh(path.read_text())
            return np.asarray(mocap.frames, dtype=np.float64)

        t, c, frames = median_times(bvh_read, repeat)
        if frames.shape != values.shape:
            raise AssertionError(f"bvh parsed {frames.shape}")
        row("bvh Bvh() + floats", t, c, size)

    out = out_dir / "keyfill_written.bvh"
    t, c, _ = median_times(lambda: kbvh.write(motion, out), repeat)
    row("keyfill write", t, c, out.stat().st_size, bytes=out.stat().st_size)
    out_bvhio = out_dir / "bvhio_written.bvh"
    t, c, _ = median_times(lambda: bvhio.writeBvh(str(out_bvhio), container), repeat)
    row("bvhio writeBvh", t, c, out_bvhio.stat().st_size, bytes=out_bvhio.stat().st_size)

    read = rows["keyfill read"]
    for r in rows.values():
        r["x_keyfill_read"] = r["seconds"] / read["seconds"]
    return {
        "file": str(path.relative_to(ROOT)),
        "bytes": size,
        "frames": motion.num_frames,
        "joints": motion.num_joints,
        "channels": motion.skeleton.num_channels,
        "repeat": repeat,
        "rows": rows,
    }


def goals(figures: dict) -> list[dict]:
    """The three goals of issue 2, judged by wall time."""
    rows = figures["rows"]
    read, write = rows["keyfill read"]["mb_per_s"], rows["keyfill write"]["mb_per_s"]
    ratio = rows["bvhio readAsBvh"]["x_keyfill_read"]
    return [results.goal(2, f"BVH read at least {READ_GOAL_MBS:g} MB/s", f"{read:.1f} MB/s", read >= READ_GOAL_MBS),
            results.goal(2, f"BVH read at least {BVHIO_GOAL_RATIO:g}x as fast as bvhio", f"{ratio:.1f}x",
                         ratio >= BVHIO_GOAL_RATIO),
            results.goal(2, f"BVH write at least {WRITE_GOAL_MBS:g} MB/s", f"{write:.1f} MB/s",
                         write >= WRITE_GOAL_MBS)]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per measurement; the median is reported (default 5)")
    parser.add_argument("--no-bvh", action="store_true", help="skip the slow 'bvh' package")
    parser.add_argument("--json", action="store_true", help="print the record as JSON on stdout")
    results.add_option(parser)
    args = parser.parse_args(argv)
    bench = results.Run()
    try:
        BENCH_DIR.mkdir(parents=True, exist_ok=True)
        figures = run(args.repeat, not args.no_bvh, BENCH_DIR)
    except Skipped as e:
        print(f"bench_bvh_io: skipped: {e}", file=sys.stderr)
        return 0
    record = bench.record("bvh_io", figures, goals(figures), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(f"{figures['file']}: {figures['bytes'] / 1e6:.1f} MB, {figures['frames']} frames, "
          f"{figures['joints']} joints, {figures['channels']} channels; median of {args.repeat}")
    print(f"{'':24s} {'seconds':>8s} {'cpu s':>7s} {'MB/s':>7s} {'x keyfill read':>15s}")
    for name, r in figures["rows"].items():
        print(f"{name:24s} {r['seconds']:8.3f} {r['cpu_seconds']:7.3f} {r['mb_per_s']:7.1f} {r['x_keyfill_read']:15.2f}")
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
