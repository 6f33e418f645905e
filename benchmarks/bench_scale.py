"""Every command on long takes: CPU time and peak memory at 1k, 10k, 100k and 1M frames (issue 44).

The input is Bandai dataset-1's clips concatenated (``bench_bvh_io.concatenated_bvh``: 22 joints, 30 fps)
and cycled to each length (a clip's end joins the next clip's start, as in a long capture session); the
other formats are made from it by ``keyfill convert`` before the timed runs. Each row is one command run
as a child process (``os.wait4``: user + system CPU seconds and the peak resident set size), the median of
``--repeat`` runs below 100k frames and one run from 100k frames on:

* ``complete --method M --key-every 30`` for cubic, linear, cubic with ``--feet lock``, the shipped
  transformer and gan (and match, the motion library, with ``--methods``);
* ``convert A B`` for every pair of formats among ``--formats`` (default bvh, usda, usdc, glb, gltf);
* ``info`` of each format.

Figures per row: ``cpu_seconds`` and ``peak_mib`` per frame count; ``exponent``: the least-squares slope
of log CPU seconds against log frames over the counts of at least 10k frames (below, the fixed start-up
hides the per-frame cost); ``decade_exponents``: the slope between each count and the next; ``memory``:
the peak beyond the fixed amount (the row's peak at the smallest count) over the motion's own arrays
(float64 rotations ``(F, J, 4)`` and positions ``(F, J, 3)``: 56 bytes per joint and frame), at the
largest count. Goals (issue 44): every exponent at most 1.1; that memory ratio at most 2.5.

The start-up goals are timed on their own: ``complete`` of a 30-frame human BVH (keys every 15) as a new
process with cubic (goal 0.2 s) and the transformer (0.3 s), medians of ``--repeat`` wall seconds after a
warm-up. The log-log plot of CPU seconds against frames goes to ``docs/img/scale.png``. The run is
recorded in ``benchmarks/results/scale.json`` (``results.py``; not with ``--no-record``).

    .venv/bin/python benchmarks/bench_scale.py                              # 1k..1M, every row (about an hour)
    .venv/bin/python benchmarks/bench_scale.py --frames 1000,10000,100000 --no-record   # a quick look
    .venv/bin/python benchmarks/bench_scale.py --methods transformer,gan --formats bvh --no-convert --merge

``--merge`` measures only the rows asked for and puts them into the existing record in place of its own
(each row names the ``commit`` it was measured at; the record's ``command`` lists the runs merged).
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import results
from bench_bvh_io import Skipped, _split_clip, concatenated_bvh
from bench_complete import keyfill_command, learned_startup

ROOT = Path(__file__).resolve().parents[1]
PLOT = ROOT / "docs" / "img" / "scale.png"
EXPONENT_GOAL = 1.1
MEMORY_GOAL = 2.5
STARTUP_GOALS = {"cubic": 0.2, "transformer": 0.3}
#: the frames of real clips cycled into every input (beyond the corpus's length they repeat)
SOURCE_FRAMES = 100_000
KEY_EVERY = 30
METHODS = ("cubic", "linear", "cubic --feet lock", "transformer", "gan")
FORMATS = ("bvh", "usda", "usdc", "glb", "gltf")
#: below this many frames a row is the median of --repeat runs; from it on, one run
SINGLE_RUN_FROM = 100_000
BYTES_PER_JOINT_FRAME = 8 * (4 + 3)


def long_bvh(path: Path, frames: int) -> int:
    """Write a BVH of ``frames`` frames: the corpus's first :data:`SOURCE_FRAMES` cycled; returns its joints."""
    try:
        source = concatenated_bvh(frames=SOURCE_FRAMES)
    except Skipped:
        source = concatenated_bvh(frames=10_000)
    head, frame_time, lines = _split_clip(source.read_bytes())
    with open(path, "wb") as f:
        f.write(head + b"MOTION\nFrames: %d\nFrame Time: %s\n" % (frames, frame_time))
        left = frames
        while left:
            part = lines[: min(left, len(lines))]
            f.write(b"\n".join(part) + b"\n")
            left -= len(part)
    return head.count(b"JOINT") + head.count(b"ROOT")


def child(cmd: list[str]) -> tuple[float, float]:
    """(CPU seconds, peak MiB) of one run of ``cmd`` as a child process; a failure stops the benchmark."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = proc.stderr.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {err.strip()}")
    return usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def measure_row(cmd_for, counts: list[int], repeat: int) -> dict:
    """One row: ``cmd_for(frames)`` run at every count (median of ``repeat`` below :data:`SINGLE_RUN_FROM`)."""
    cpu, peak = {}, {}
    for n in counts:
        runs = [child(cmd_for(n)) for _ in range(repeat if n < SINGLE_RUN_FROM else 1)]
        cpu[n] = statistics.median(r[0] for r in runs)
        peak[n] = statistics.median(r[1] for r in runs)
        print(f"  {n:>9,} frames: {cpu[n]:8.2f} s CPU, {peak[n]:7.0f} MiB", file=sys.stderr, flush=True)
    return {"cpu_seconds": {str(n): round(cpu[n], 3) for n in counts},
            "peak_mib": {str(n): round(peak[n], 1) for n in counts}}


def fitted(row: dict, joints: int) -> dict:
    """``row`` with its ``exponent``, ``decade_exponents`` and ``memory`` ratio (see the module docstring)."""
    counts = sorted(int(n) for n in row["cpu_seconds"])
    cpu = np.array([row["cpu_seconds"][str(n)] for n in counts])
    big = [i for i, n in enumerate(counts) if n >= 10_000]
    if len(big) >= 2:
        x, y = np.log(np.array(counts)[big]), np.log(cpu[big])
        row["exponent"] = round(float(np.polyfit(x, y, 1)[0]), 3)
    row["decade_exponents"] = {f"{a}-{b}": round(float(np.log(cpu[i + 1] / cpu[i]) / np.log(b / a)), 3)
                               for i, (a, b) in enumerate(itertools.pairwise(counts))}
    fixed, top = row["peak_mib"][str(counts[0])], counts[-1]
    own = top * joints * BYTES_PER_JOINT_FRAME / 2**20
    row["fixed_mib"] = fixed
    row["motion_mib"] = round(own, 1)
    row["memory"] = round((row["peak_mib"][str(top)] - fixed) / own, 2)
    return row


def measure(counts: list[int], repeat: int, methods: list[str], formats: list[str], tmp: Path,
            convert: bool = True, info: bool = True) -> dict:
    """The figures of the module docstring (``convert``, ``info``: with those rows)."""
    kf = keyfill_command()
    joints = 0
    for n in counts:
        joints = long_bvh(tmp / f"{n}.bvh", n)
        for fmt in formats:
            if fmt != "bvh":
                subprocess.run(kf + ["convert", str(tmp / f"{n}.bvh"), str(tmp / f"{n}.{fmt}")], check=True)
    rows = {}
    head = results.commit()[0]

    def add(name, cmd_for):
        print(name, file=sys.stderr, flush=True)
        rows[name] = {**fitted(measure_row(cmd_for, counts, repeat), joints), "commit": head}

    for method in methods:
        words = method.split()
        add(f"complete {method}", lambda n, w=words: kf + ["complete", str(tmp / f"{n}.bvh"), "-o",
                                                           str(tmp / f"out_{n}.bvh"), "--method", *w,
                                                           "--key-every", str(KEY_EVERY), "--force"])
    for a, b in itertools.permutations(formats, 2) if convert else ():
        add(f"convert {a} to {b}", lambda n, a=a, b=b: kf + ["convert", str(tmp / f"{n}.{a}"),
                                                             str(tmp / f"conv_{n}.{b}"), "--force"])
    for fmt in formats if info else ():
        add(f"info {fmt}", lambda n, f=fmt: kf + ["info", str(tmp / f"{n}.{f}")])
    return {"frames": counts, "joints": joints, "key_every": KEY_EVERY, "repeat": repeat, "rows": rows,
            "startup": startup(max(repeat, 5), tmp) if methods else None}


def startup(repeat: int, tmp: Path) -> dict | None:
    """``bench_complete.learned_startup``'s medians (cubic, the shipped transformer and gan on the 30-frame
    human file, new processes), with ``repeat``; None without the file."""
    figures = learned_startup(repeat, tmp)
    return None if figures is None else {**figures, "repeat": repeat}


def plot(figures: dict, path: Path) -> None:
    """The log-log plot of CPU seconds against frames, one line per row (convert rows in grey)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5), dpi=100)
    for name, row in figures["rows"].items():
        counts = sorted(int(n) for n in row["cpu_seconds"])
        cpu = [row["cpu_seconds"][str(n)] for n in counts]
        grey = not name.startswith("complete")
        ax.loglog(counts, cpu, marker="o", ms=3, lw=0.8 if grey else 1.6, color="0.7" if grey else None,
                  label=None if grey else name)
    counts = figures["frames"]
    ref = [counts[0], counts[-1]]
    ax.loglog(ref, [0.5 * n / ref[0] for n in ref], "k--", lw=0.8, label="linear (slope 1)")
    ax.set_xlabel("frames (22 joints)")
    ax.set_ylabel("CPU seconds (user + system)")
    ax.set_title("keyfill on long takes (grey: convert and info, every format)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


def merged(figures: dict) -> dict:
    """The existing record's figures with the rows (and the start-up, when measured) of ``figures`` in place
    of its own; the frame counts must be the same."""
    old = results.read_records().get("scale")
    if old is None or old["figures"]["frames"] != figures["frames"]:
        raise SystemExit("bench_scale: --merge needs a record of the same frame counts in benchmarks/results/")
    out = dict(old["figures"], rows={**old["figures"]["rows"], **figures["rows"]})
    out["merged"] = [*old["figures"].get("merged", [old["command"]]), results.command_line(sys.argv)]
    if figures.get("startup"):
        out["startup"] = figures["startup"]
    return out


def goals(figures: dict) -> list[dict]:
    """Issue 44's goals: every row's exponent and memory ratio, and the two start-up times."""
    rows = figures["rows"]
    worst = max(rows, key=lambda r: rows[r].get("exponent", 0.0))
    heavy = max(rows, key=lambda r: rows[r]["memory"])
    top = f"{max(figures['frames']):,}"
    out = [results.goal(44, f"every command linear in frames: fitted exponent at most {EXPONENT_GOAL} (10k to {top})",
                        f"largest {rows[worst].get('exponent')} ({worst})",
                        all(r.get("exponent", 0.0) <= EXPONENT_GOAL for r in rows.values())),
           results.goal(44, f"peak memory at most {MEMORY_GOAL}x the motion's arrays plus a fixed amount ({top} frames)",
                        f"largest {rows[heavy]['memory']}x ({heavy})",
                        all(r["memory"] <= MEMORY_GOAL for r in rows.values()))]
    for method, limit in STARTUP_GOALS.items():
        s = (figures.get("startup") or {}).get("seconds", {}).get(method)
        if s is not None:
            out.append(results.goal(44, f"`complete` of a small BVH with {method} in at most {limit} s",
                                    f"{s:.3f} s", s <= limit))
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", default="1000,10000,100000,1000000", help="frame counts, comma-separated")
    ap.add_argument("--repeat", type=int, default=3, help="runs per row below 100k frames (the median)")
    ap.add_argument("--methods", default=",".join(METHODS), help="complete's methods (with their options)")
    ap.add_argument("--formats", default=",".join(FORMATS), help="formats for convert and info")
    ap.add_argument("--no-convert", action="store_true", help="measure no convert rows")
    ap.add_argument("--no-info", action="store_true", help="measure no info rows")
    ap.add_argument("--merge", action="store_true", help="put the rows measured into the existing record")
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    counts = sorted(int(n) for n in args.frames.split(","))
    with tempfile.TemporaryDirectory(prefix="keyfill-scale-") as tmp:
        try:
            figures = measure(counts, args.repeat, [m for m in args.methods.split(",") if m],
                              args.formats.split(","), Path(tmp), not args.no_convert, not args.no_info)
        except Skipped as e:
            print(f"bench_scale: skipped: {e}", file=sys.stderr)
            return 0
    if args.merge:
        figures = merged(figures)
    if not args.no_record:
        plot(figures, PLOT)
        figures["plot"] = results.repo_path(str(PLOT))
    record = bench.record("scale", figures, goals(figures), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(results.summary(record))
    for name, row in figures["rows"].items():
        print(f"{name:32s} exponent {row.get('exponent')}  memory {row['memory']}x  "
              f"{row['cpu_seconds']}  {row['peak_mib']}")
    results.print_goals(record)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
