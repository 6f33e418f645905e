"""Read a BVH file with pymotion and print every joint's world position per frame.

Runs in Blender's venv (``.venv-blender``, numpy 1.26, where ``make test-interop`` installs upc-pymotion too),
so it imports nothing from keyfill::

    .venv-blender/bin/python tests/interop/pymotion_world_positions.py walk.bvh --out walk.json

Output (JSON): ``{"pymotion": version, "names": [...], "positions": [[[x, y, z] per joint] per frame]}`` in the
file's units and axes: pymotion's own parse (``BVH.load``: Euler angles to quaternions, position channels to
local positions) through pymotion's quaternion product and rotation of vectors, joint by joint (its
``skeleton_np.fk`` takes one root only; keyfill's edge layouts have two).
"""

from __future__ import annotations

import argparse
import json
from importlib.metadata import version

import numpy as np
from pymotion.io.bvh import BVH
from pymotion.rotations import quat


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    bvh = BVH()
    bvh.load(args.path)
    rotations, positions, parents, _offsets, _ends, _end_parents = bvh.get_data()
    turn, world = np.empty_like(rotations), np.empty_like(positions)
    for j, p in enumerate(parents):  # a BVH lists every parent before its children
        if p is None or p == j:  # pymotion's roots: the first is its own parent, a second has None
            turn[:, j], world[:, j] = rotations[:, j], positions[:, j]
        else:
            turn[:, j] = quat.mul(turn[:, p], rotations[:, j])
            world[:, j] = world[:, p] + quat.mul_vec(turn[:, p], positions[:, j])
    with open(args.out, "w") as f:
        json.dump({"pymotion": version("upc-pymotion"), "names": [str(n) for n in bvh.data["names"]],
                   "positions": world.tolist()}, f)


if __name__ == "__main__":
    main()
