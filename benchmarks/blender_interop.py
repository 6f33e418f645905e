"""Blender interoperability: the worst world-position deviation per fixture and format.

For each shared BVH fixture, keyfill writes it as BVH, USDA and USDC; Blender
(the ``bpy`` wheel in ``.venv-blender``) imports each file and reports every
bone head per frame (``tests/interop/blender_world_positions.py``); this
script prints the largest distance to keyfill's forward kinematics, in file
units and relative to the skeleton's rest height (the issue's bound: 1e-4).

    .venv/bin/python benchmarks/blender_interop.py            # all shared fixtures
    .venv/bin/python benchmarks/blender_interop.py a.bvh b.bvh

Needs: ``python3.11 -m venv .venv-blender && .venv-blender/bin/pip install bpy``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "interop"))

from blender_check import blender_deviation, blender_missing  # noqa: E402

from keyfill import io  # noqa: E402

FIXTURES = ROOT.parent / "shared" / "data" / "bvh_fixtures"
SUFFIXES = (".bvh", ".usda", ".usdc")
BOUND = 1e-4


def main(argv: list[str]) -> int:
    why = blender_missing()
    if why:
        print(f"blender_interop: {why}", file=sys.stderr)
        return 1
    files = [Path(a) for a in argv] or sorted(FIXTURES.glob("*.bvh"))
    if not files:
        print(f"blender_interop: no fixtures (looked in {FIXTURES})", file=sys.stderr)
        return 1
    print(f"{'file':40s} {'format':6s} {'frames':>6s} {'joints':>6s} {'worst (units)':>14s} {'/ height':>9s}  ok")
    failed = 0
    blender_version = "?"
    for path in files:
        motion = io.load(path)
        for suffix in SUFFIXES:
            with tempfile.TemporaryDirectory() as tmp:
                per_frame, height, result = blender_deviation(motion, Path(tmp), suffix)
            blender_version = result["blender"]
            worst = float(per_frame.max())
            ok = worst < BOUND * height
            failed += not ok
            print(
                f"{path.name:40s} {suffix[1:]:6s} {motion.num_frames:6d} {motion.num_joints:6d} "
                f"{worst:14.3g} {worst / height:9.2g}  {'yes' if ok else 'NO'}"
            )
    print(f"Blender {blender_version}; bound {BOUND:g} of the skeleton's rest height; {failed} over the bound")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
