"""Write the human keys of ``make demo``: key poses of one Bandai-Namco dataset-2 clip, keys only.

The clip is ``dataset-2_walk_normal_001.bvh`` (the ``normal`` style, which the
shipped human models never saw in training). Two sparse USD files (samples at
the keys only, ``keys`` recorded):

* ``keys.usda``: frames 0, 68, 136, 204 and 272 (one every 2.3 s at 30 fps),
  long gaps for the gan;
* ``keys_15.usda``: frames 0, 15, ..., 90 (one every 0.5 s), gaps the
  transformer was trained on (it fills at most 63 frames between two keys).

Licence: CC BY-NC 4.0, as the clip (see README.md).

    .venv/bin/python examples/human/make_example.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from keyfill import io
from keyfill.learn.corpus import locate
from keyfill.motion import Keys

HERE = Path(__file__).parent
CLIP = "dataset-2_walk_normal_001.bvh"
FILES = {"keys.usda": (0, 68, 136, 204, 272), "keys_15.usda": tuple(range(0, 91, 15))}


def main() -> None:
    motion = io.load(locate("bandai2") / CLIP)
    for name, keys in FILES.items():
        clip = motion.frames(slice(0, keys[-1] + 1))  # the keyed frames' range, nothing after the last key
        io.save(clip.replace(keys=Keys(np.array(keys))), HERE / name, sparse=True)
        print(f"wrote {HERE / name}: frames {', '.join(map(str, keys))} of {CLIP}")


if __name__ == "__main__":
    main()
