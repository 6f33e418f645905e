"""Write examples/lamp/truth.usda and keys.usda from one simulated 3-hop sequence.

truth.usda is the dense sequence (87 frames, keys recorded), byte for byte
the file ``keyfill simulate --seed 0`` writes for its first accepted run;
keys.usda holds only its 9 key poses (a sparse USD file: samples at the keys
only), the input of ``keyfill complete``.

    .venv/bin/python examples/lamp/make_example.py    (or: make -C examples lamp)
"""

from __future__ import annotations

from pathlib import Path

from keyfill import io
from keyfill.cli.simulate import DEFAULT_ITERATIONS
from keyfill.sim.runner import Job, run_job

HERE = Path(__file__).parent
SEED = 0


def main() -> None:
    job = Job(seed=SEED, iterations=DEFAULT_ITERATIONS)
    run = 0
    while not (out := run_job(job, run)).accepted:
        run += 1
    io.save(out.motion, HERE / "truth.usda")
    io.save(out.motion, HERE / "keys.usda", sparse=True)
    print(f"wrote {HERE / 'truth.usda'} and {HERE / 'keys.usda'}: {out.record['id']} of seed {SEED}, "
          f"{out.motion.num_frames} frames, keys {out.motion.keys.to_list()}")


if __name__ == "__main__":
    main()
