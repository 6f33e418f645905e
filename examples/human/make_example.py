"""Write examples/human/keys.usda: five key poses of one Bandai-Namco dataset-2 clip, keys only.

The clip is ``dataset-2_walk_normal_001.bvh`` (the ``normal`` style, which the
shipped human models never saw in training); its frames 0, 68, 136, 204 and
272 are the keys (one every 2.3 s at 30 fps). The file is sparse USD (samples
at the keys only, ``keys`` recorded), the input of ``make demo``'s human
in-betweening. Licence: CC BY-NC 4.0, as the clip (see README.md).

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
KEYS = (0, 68, 136, 204, 272)


def main() -> None:
    motion = io.load(locate("bandai2") / CLIP)
    io.save(motion.replace(keys=Keys(np.array(KEYS))), HERE / "keys.usda", sparse=True)
    print(f"wrote {HERE / 'keys.usda'}: frames {', '.join(map(str, KEYS))} of {CLIP}")


if __name__ == "__main__":
    main()
