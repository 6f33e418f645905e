"""Peak memory and time of ``keyfill convert`` on a large BVH file (issue 15: at most 4x the file size
plus a fixed overhead).

Writes a BVH of about ``--mb`` megabytes (the CMU skeleton of tests/data, 31 joints and 62 channels,
a random walk of angles printed with 6 decimals, 120 fps), then runs ``python -m keyfill convert
big.bvh big.usda`` (and ``big.bvh big2.bvh``) ``--repeat`` times as child processes and reports the
median of their peak resident set size (``wait4``'s ``ru_maxrss``) and wall time, next to the peak
of converting a one-frame file (the fixed overhead: Python, numpy, USD). The run is recorded in
``benchmarks/results/convert_memory.json`` (``results.py``; not with ``--no-record``): ``file_mb``
(MiB), ``frames``, ``overhead_mb``, ``repeat``, ``keyfill`` (the checkout run) and ``outputs``, per
format ``peak_mb``, ``peak_over_file``, ``peak_minus_overhead_over_file``, ``seconds``, ``output_mb``.

    python benchmarks/bench_convert_memory.py --mb 150 --repeat 3
    python benchmarks/bench_convert_memory.py --mb 150 --keyfill /path/to/older/checkout   # before/after
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import results

GOAL_RATIO = 4.0
ROOT = Path(__file__).resolve().parent.parent
CMU = ROOT / "tests" / "data" / "cmu_02_03_cgspeed_first4frames.bvh"


def write_big_bvh(path: Path, megabytes: float, seed: int = 0) -> int:
    """A BVH of about ``megabytes`` MB on the CMU skeleton; returns its frame count."""
    text = CMU.read_text().replace("\r\n", "\n")
    header = text.split("MOTION")[0]
    channels = len(text.split("MOTION")[1].strip().split("\n")[2].split())
    rng = np.random.default_rng(seed)
    sample = (rng.uniform(-180, 180, size=(1000, channels)))
    line_bytes = len("\n".join(" ".join(f"{v:.6f}" for v in row) for row in sample)) / 1000 + 1
    frames = int(megabytes * 2**20 / line_bytes)
    with open(path, "w") as f:
        f.write(header + f"MOTION\nFrames: {frames}\nFrame Time: 0.0083333\n")
        state = np.zeros(channels)
        for start in range(0, frames, 5000):
            n = min(5000, frames - start)
            walk = state + np.cumsum(rng.normal(scale=0.3, size=(n, channels)), axis=0)
            state = walk[-1]
            walk = (walk + 180) % 360 - 180
            f.write("\n".join(" ".join(f"{v:.6f}" for v in row) for row in walk) + "\n")
    return frames


def run_child(cmd: list[str], env: dict, cwd: Path) -> tuple[float, float, int]:
    """(peak RSS in MB, wall seconds, exit code) of one child process (run in ``cwd``, so that
    ``python -m keyfill`` finds the checkout on PYTHONPATH, not one in the current folder)."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=cwd)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {err}")
    return usage.ru_maxrss / 1024, seconds, proc.returncode


def measure(megabytes: float, repeat: int, keyfill: Path, formats: list[str]) -> dict:
    """The figures of the module docstring: a generated BVH converted by ``keyfill``'s checkout."""
    env = {**os.environ, "PYTHONPATH": str(keyfill.resolve()), "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory(prefix="keyfill-bench-") as tmp:
        tmp = Path(tmp)
        big = tmp / "big.bvh"
        frames = write_big_bvh(big, megabytes)
        size_mb = big.stat().st_size / 2**20
        small = tmp / "small.bvh"
        small.write_text(CMU.read_text())
        base = [run_child([sys.executable, "-m", "keyfill", "convert", str(small), str(tmp / "s.usda")], env, tmp)[0]
                for _ in range(repeat)]
        overhead = statistics.median(base)
        outputs = {}
        for fmt in formats:
            out = tmp / f"out.{fmt}"
            runs = [run_child([sys.executable, "-m", "keyfill", "convert", str(big), str(out)], env, tmp)
                    for _ in range(repeat)]
            peak = statistics.median(r[0] for r in runs)
            outputs[fmt] = {
                "peak_mb": round(peak, 1),
                "peak_over_file": round(peak / size_mb, 2),
                "peak_minus_overhead_over_file": round((peak - overhead) / size_mb, 2),
                "seconds": round(statistics.median(r[1] for r in runs), 1),
                "output_mb": round(out.stat().st_size / 2**20, 1),
            }
    return {"file_mb": round(size_mb, 1), "frames": frames, "overhead_mb": round(overhead, 1), "repeat": repeat,
            "keyfill": results.repo_path(str(keyfill)), "outputs": outputs}


def goals(figures: dict) -> list[dict]:
    """Issue 15's goal, for USD output: the peak beyond the fixed overhead at most 4x the file."""
    usd = figures["outputs"].get("usda")
    if usd is None:
        return []
    ratio = usd["peak_minus_overhead_over_file"]
    return [results.goal(15, f"`keyfill convert` of a {figures['file_mb']:.0f} MiB BVH to USD: peak memory at most "
                             f"{GOAL_RATIO:g}x the file plus a fixed overhead",
                         f"{usd['peak_mb']:,.0f} MiB: {ratio:.1f}x the file beyond the {figures['overhead_mb']} MiB "
                         f"overhead ({usd['peak_over_file']:.1f}x all included)", ratio <= GOAL_RATIO)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mb", type=float, default=150.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keyfill", type=Path, default=ROOT, help="the checkout whose keyfill to run")
    ap.add_argument("--to", default="usda,bvh", help="output formats to time (usda, bvh)")
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args()
    bench = results.Run()
    figures = measure(args.mb, args.repeat, args.keyfill, args.to.split(","))
    record = bench.record("convert_memory", figures, goals(figures), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return
    print(f"convert of a {figures['file_mb']} MiB BVH ({figures['frames']} frames); fixed overhead (a 4-frame file) "
          f"{figures['overhead_mb']} MiB; medians of {args.repeat}; {results.summary(record)}")
    for fmt, r in figures["outputs"].items():
        print(f"  -> .{fmt}: peak {r['peak_mb']} MiB = {r['peak_over_file']}x the file "
              f"({r['peak_minus_overhead_over_file']}x beyond the overhead), {r['seconds']} s, output {r['output_mb']} MiB")
    results.print_goals(record)


if __name__ == "__main__":
    main()
