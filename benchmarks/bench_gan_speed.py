"""Inference speed of a gan model on this CPU, 512 to 4,096 frames (issue 12: docs/gan.md, docs/benchmarks.md).

The paper (Zhou et al. 2020, Table 3) fills 2,048 frames in 0.188 s on a Titan
Xp GPU; keyfill's goal on the 2-core development VM with the ``cpu`` preset: at
most 0.2 s. Measured here, each the median of ``--repeat`` calls in one process:

* ``complete``: :func:`keyfill.learn.gan.model.complete_motion` and the shared
  exact-key correction, with the model loaded: what ``keyfill complete --method
  gan`` spends per motion (key poses, dense input, both networks, RC-FK,
  interpolated leaves, snapping the keys);
* ``load``: reading the model folder (once per process; ``keyfill batch`` and the
  library keep it).

The motion is a held-out Bandai-Namco clip (``--clip``) repeated to ``N``
frames, with keys every ``--gap`` frames and on the last frame (only key frames
are read, so the content does not change the time). Threads: 1 and 2.

The run is recorded in ``benchmarks/results/gan_speed-<model folder>.json`` (``results.py``; not
with ``--no-record``): ``model``, ``gap``, ``repeat`` and ``rows``, one per thread count and length
with ``keys``, ``complete_ms`` and ``load_ms`` (each ``median`` and ``best``).

    .venv/bin/python benchmarks/bench_gan_speed.py data/models/bandai2-gan --json
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import results
import torch
from timing import timed_ms

from keyfill import io
from keyfill.errors import DataError
from keyfill.learn.corpus import bvh_files, locate
from keyfill.learn.exact_keys import snap_to_keys
from keyfill.learn.gan.model import complete_motion, load_model
from keyfill.motion import Keys

GOAL_FRAMES, GOAL_MS = 2048, 200.0


def goals(rows: list[dict]) -> list[dict]:
    """Issue 12's goal: 2,048 frames in at most 0.2 s on one thread, the model loaded."""
    ms = next((r["complete_ms"]["median"] for r in rows if r["threads"] == 1 and r["frames"] == GOAL_FRAMES), None)
    if ms is None:
        return []
    return [results.goal(12, f"gan inference of {GOAL_FRAMES:,} frames at most {GOAL_MS / 1000:g} s (one thread, "
                             "model loaded)", f"{ms:.1f} ms", ms <= GOAL_MS)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="a full gan model folder")
    ap.add_argument("--clip", default=None, help="BVH file on the model's skeleton (default: a Bandai-2 normal clip)")
    ap.add_argument("--frames", default="512,1024,2048,4096")
    ap.add_argument("--gap", type=int, default=300, help="frames between keys")
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        clip = args.clip or str(bvh_files([locate("bandai2")], "*_walk_normal_*")[0])
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    source = io.load(clip)
    rows = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        load = timed_ms(lambda: load_model(args.model), max(3, args.repeat // 4), warmup=1)
        model = load_model(args.model)
        for n in (int(f) for f in args.frames.split(",")):
            motion = source.frames(np.arange(n) % source.num_frames)
            keys = Keys(np.unique(np.r_[np.arange(0, n, args.gap), n - 1]))

            def run(model=model, motion=motion, keys=keys):
                filled, _ = complete_motion(model, motion, keys, seed=0)
                snap_to_keys(filled, motion, keys)

            rows.append({"threads": threads, "frames": n, "keys": len(keys),
                         "complete_ms": timed_ms(run, args.repeat, warmup=2), "load_ms": load})
    figures = {"model": args.model, "gap": args.gap, "repeat": args.repeat, "rows": rows}
    record = bench.record(f"gan_speed-{Path(args.model).name}", figures, goals(rows), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(results.summary(record))
    print("threads  frames  keys  complete ms (best)  load ms")
    for r in rows:
        c = r["complete_ms"]
        print(f"{r['threads']:>7} {r['frames']:>7} {r['keys']:>5} {c['median']:>11.1f} ({c['best']:.1f}) "
              f"{r['load_ms']['median']:>8.1f}")
    results.print_goals(record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
