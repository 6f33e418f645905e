"""Blender interoperability: the worst world-position deviation per fixture and format.

For each shared BVH fixture, keyfill writes it as BVH, USDA and USDC; Blender
(the ``bpy`` wheel in ``.venv-blender``) imports each file and reports every
bone head per frame (``tests/interop/blender_world_positions.py``); this
script prints the largest distance to keyfill's forward kinematics, in file
units and relative to the skeleton's rest height (the issue's bound: 1e-4).

    .venv/bin/python benchmarks/blender_interop.py            # all shared fixtures
    .venv/bin/python benchmarks/blender_interop.py a.bvh b.bvh

Needs: ``python3.11 -m venv .venv-blender && .venv-blender/bin/pip install bpy``. The run is
recorded in ``benchmarks/results/blender_interop.json`` (``results.py``; not with ``--no-record``):
``blender`` (its version), ``bound`` and ``rows``, one per file and format with ``frames``,
``joints``, ``worst`` (file units) and ``relative`` (over the rest height).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import results

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "interop"))

from blender_check import blender_deviation, blender_missing

from keyfill import io

FIXTURES = ROOT.parent / "shared" / "data" / "bvh_fixtures"
SUFFIXES = (".bvh", ".usda", ".usdc")
BOUND = 1e-4


def goals(rows: list[dict]) -> list[dict]:
    """Issue 2's goal: every file and format within the bound."""
    worst = max(r["relative"] for r in rows)
    return [results.goal(2, f"Blender imports keyfill's BVH and USD with the same world positions ({BOUND:g} of the "
                            "height)", f"worst {worst:.1e} of the height", worst < BOUND)]


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="*", type=Path, help="BVH files (default: the shared fixtures)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    why = blender_missing()
    if why:
        print(f"blender_interop: {why}", file=sys.stderr)
        return 1
    files = args.files or sorted(FIXTURES.glob("*.bvh"))
    if not files:
        print(f"blender_interop: no fixtures (looked in {FIXTURES})", file=sys.stderr)
        return 1
    print(f"{'file':40s} {'format':6s} {'frames':>6s} {'joints':>6s} {'worst (units)':>14s} {'/ height':>9s}  ok")
    failed = 0
    blender_version = "?"
    rows = []
    for path in files:
        motion = io.load(path)
        for suffix in SUFFIXES:
            with tempfile.TemporaryDirectory() as tmp:
                per_frame, height, result = blender_deviation(motion, Path(tmp), suffix)
            blender_version = result["blender"]
            worst = float(per_frame.max())
            ok = worst < BOUND * height
            failed += not ok
            rows.append({"file": path.name, "format": suffix[1:], "frames": motion.num_frames,
                         "joints": motion.num_joints, "worst": worst, "relative": worst / height})
            print(
                f"{path.name:40s} {suffix[1:]:6s} {motion.num_frames:6d} {motion.num_joints:6d} "
                f"{worst:14.3g} {worst / height:9.2g}  {'yes' if ok else 'NO'}"
            )
    print(f"Blender {blender_version}; bound {BOUND:g} of the skeleton's rest height; {failed} over the bound")
    bench.record("blender_interop", {"blender": blender_version, "bound": BOUND, "rows": rows}, goals(rows),
                 write=not args.no_record)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
