"""Reading and writing a 10,000-frame 22-joint motion as glTF (.glb, .gltf) against USD (.usdc, .usda) and BVH.

The motion is the Bandai-Namco dataset-1 walk fixture (``../shared/data/bvh_fixtures``, 22 joints with
6 channels each) tiled to 10,000 frames; without it the script says ``skipped`` and exits 0. Each format:
``keyfill.io.save`` then ``keyfill.io.load`` of the file, medians of ``--repeat`` runs in this one process
(after one untimed warm-up), and the file's size. Goal (issue 28): a ``.glb`` is read and written at least as
fast as the same motion in ``.usdc``. Recorded in ``benchmarks/results/formats.json`` (``results.py``; not with
``--no-record``): per format ``write_s``, ``read_s``, ``bytes``::

    .venv/bin/python benchmarks/bench_formats.py              # --repeat 5
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import results
from timing import timed_ms

from keyfill import io
from keyfill.motion import Motion

FIXTURE = Path(__file__).resolve().parents[2] / "shared" / "data" / "bvh_fixtures" / "dataset-1_walk_normal_002.bvh"
FRAMES = 10_000
SUFFIXES = (".glb", ".gltf", ".usdc", ".usda", ".bvh")


def motion() -> Motion:
    """The fixture tiled to :data:`FRAMES` frames."""
    clip = io.load(FIXTURE)
    reps = -(-FRAMES // clip.num_frames)
    return Motion(clip.skeleton, clip.fps, np.concatenate([clip.rotations] * reps)[:FRAMES],
                  np.concatenate([clip.positions] * reps)[:FRAMES])


def measure(m: Motion, repeat: int) -> dict:
    """``{suffix: {"write_s", "read_s", "bytes"}}``."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in SUFFIXES:
            path = Path(tmp) / f"walk{suffix}"
            write = timed_ms(lambda path=path: io.save(m, path), repeat, warmup=1)["median"] / 1e3
            read = timed_ms(lambda path=path: io.load(path), repeat, warmup=1)["median"] / 1e3
            size = sum(p.stat().st_size for p in Path(tmp).glob(f"walk{suffix}*")) + (
                (Path(tmp) / "walk.bin").stat().st_size if suffix == ".gltf" else 0)
            out[suffix] = {"write_s": write, "read_s": read, "bytes": size}
            print(f"{suffix:6s} write {write:.3f} s  read {read:.3f} s  {size / 1e6:.1f} MB", flush=True)
    return out


def goals(f: dict) -> list[dict]:
    glb, usdc = f["formats"][".glb"], f["formats"][".usdc"]
    return [results.goal(28, f"a {FRAMES:,}-frame 22-joint .glb read and written at least as fast as .usdc",
                         f"write {glb['write_s']:.2f} vs {usdc['write_s']:.2f} s, read {glb['read_s']:.2f} vs "
                         f"{usdc['read_s']:.2f} s", glb["write_s"] <= usdc["write_s"] and glb["read_s"] <= usdc["read_s"])]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per format (default 5)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    if not FIXTURE.is_file():
        print(f"skipped: no {FIXTURE}")
        return 0
    m = motion()
    figures = {"frames": FRAMES, "joints": m.num_joints, "repeat": args.repeat, "formats": measure(m, args.repeat)}
    record = bench.record("formats", figures, goals(figures), write=not args.no_record)
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
