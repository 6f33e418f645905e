"""A batch re-run with nothing changed: how long ``keyfill complete IN/ -o OUT/`` takes when all 1,000 outputs are done.

The script writes ``--files`` tiny BVH files (a 3-joint chain, 9 frames, each file its own angles) into a
temporary folder, runs ``keyfill complete IN/ -o OUT/ --method cubic --key-every 4 --json`` once as a new process
(every output done), then ``--repeat`` more times unchanged (every output skipped: the output folder's record,
docs/batch.md, says each was made from the same input bytes by the same recipe). The time is the wall time of
the whole command as a new process (start-up, planning, hashing every input, reading the record), median of
the re-runs; ``batch_s`` is the part inside the batch run (the summary's ``seconds``). Goal (issue 32): under
1 s for 1,000 done outputs. Recorded in ``benchmarks/results/batch_rerun.json`` (``results.py``; not with
``--no-record``)::

    .venv/bin/python benchmarks/bench_batch_rerun.py              # --files 1000 --repeat 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import results

ROOT = Path(__file__).resolve().parents[1]

BVH = """HIERARCHY
ROOT hips
{{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT knee
\t{{
\t\tOFFSET 0 -10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT foot
\t\t{{
\t\t\tOFFSET 0 -10 0
\t\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\t\tEnd Site
\t\t\t{{
\t\t\t\tOFFSET 0 0 3
\t\t\t}}
\t\t}}
\t}}
}}
MOTION
Frames: {frames}
Frame Time: 0.0333333
{lines}
"""


def write_files(folder: Path, count: int, frames: int = 9) -> None:
    folder.mkdir(parents=True)
    for i in range(count):
        lines = []
        for f in range(frames):
            a = (i % 90) + 2.0 * f
            lines.append(" ".join(f"{v:.4f}" for v in (0.5 * f, 0, 0, a, 0.5 * a, 0, -a, 0, 0, 0.3 * a, 0, 0)))
        (folder / f"clip{i:04d}.bvh").write_text(BVH.format(frames=frames, lines="\n".join(lines)))


def complete(src: Path, out: Path) -> tuple[float, dict]:
    cmd = [sys.executable, "-m", "keyfill", "complete", str(src), "-o", str(out), "--method", "cubic",
           "--key-every", "4", "--json", "--workers", "1"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"keyfill complete failed ({proc.returncode}): {proc.stderr.strip()[-2000:]}")
    return seconds, json.loads(proc.stdout)


def measure(count: int, repeat: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "in", Path(tmp) / "out"
        write_files(src, count)
        first_s, first = complete(src, out)
        if first["done"] != count:
            raise SystemExit(f"first run: {first['done']} of {count} done")
        print(f"first run: {count} files done in {first_s:.2f} s", flush=True)
        runs, batch = [], []
        for _ in range(repeat):
            seconds, summary = complete(src, out)
            if summary["skipped"] != count:
                raise SystemExit(f"re-run: {summary['skipped']} of {count} skipped")
            runs.append(seconds)
            batch.append(summary["seconds"])
            print(f"re-run: {count} skipped in {seconds:.3f} s (batch {summary['seconds']:.3f} s)", flush=True)
        record_bytes = (out / ".keyfill-outputs.json").stat().st_size
    return {"files": count, "repeat": repeat, "first_run_s": first_s, "rerun_s": statistics.median(runs),
            "rerun_runs_s": runs, "batch_s": statistics.median(batch), "record_bytes": record_bytes}


def goals(f: dict) -> list[dict]:
    return [results.goal(32, f"a batch re-run with nothing changed under 1 s for {f['files']:,} done outputs",
                         f"{f['rerun_s']:.2f} s as a new process ({f['batch_s']:.2f} s in the batch run; the first "
                         f"run {f['first_run_s']:.1f} s)",
                         f["rerun_s"] < 1.0)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=1000, help="input files (default 1000)")
    ap.add_argument("--repeat", type=int, default=3, help="unchanged re-runs, median (default 3)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    figures = measure(args.files, args.repeat)
    record = bench.record("batch_rerun", figures, goals(figures), write=not args.no_record)
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
