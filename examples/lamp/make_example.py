"""Write examples/lamp/truth.usda and keys.usda from one simulated 3-hop sequence.

truth.usda is the dense sequence (87 frames, keys recorded); keys.usda holds
only its 9 key poses (a sparse USD file: samples at the keys only), the
input of ``keyfill complete``. Deterministic: the same keyfill version gives
the same bytes.

    .venv/bin/python examples/lamp/make_example.py    (or: make -C examples lamp)
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from keyfill import io
from keyfill.cli.simulate import DEFAULT_ITERATIONS
from keyfill.sim.dataset import read_dataset
from keyfill.sim.runner import simulate

HERE = Path(__file__).parent
SEED = 0


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        simulate(Path(tmp) / "hops", 1, seed=SEED, iterations=DEFAULT_ITERATIONS, workers=1)
        seq = read_dataset(Path(tmp) / "hops")[0]
    io.save(seq.motion, HERE / "truth.usda")
    io.save(seq.motion, HERE / "keys.usda", sparse=True)
    print(f"wrote {HERE / 'truth.usda'} and {HERE / 'keys.usda'}: {seq.id} of seed {SEED}, "
          f"{seq.motion.num_frames} frames, keys {seq.motion.keys.to_list()}")


if __name__ == "__main__":
    main()
