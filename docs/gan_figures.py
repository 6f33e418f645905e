"""Make the gan pictures of docs/gan.md with keyfill's CLI: a long completion through sparse keys, two seeds, two DNAs.

The keys are real poses of held-out Bandai-Namco dataset-2 clips (the ``normal``
style, which the models never saw), strung into one journey: for each clip in
``--clips``, its first and last frames are keys, as far apart as in the clip
(so the displacement between them is real), and the next clip starts
``--transition`` frames later where the previous one ended, turned to face on.
The key file is sparse USD (samples at the keys only); the clips are CC BY-NC
4.0 (Bandai Namco Research Motion Dataset), so the pictures are too.

Writes to ``--out`` (docs/img):

* ``gan_long_trail.png``: the whole completion from above, seeds 1 and 2
  overlaid: the hips' path (a dot per frame) through the 14 keys;
* ``gan_long_strip.png``: a filmstrip of ``--window`` (frames; the camera
  frames what it shows, so a window keeps the figures large), seeds 1 and 2
  overlaid, side view;
* ``gan_long.gif``: the same window as an animation (every ``--gif-step``-th
  frame, at twice the speed);
* ``gan_dna.png`` (like the paper's Fig. 12): the window completed with the
  Motion DNA of two other held-out clips (``--dna``), overlaid.

    .venv/bin/python docs/gan_figures.py --model data/models/bandai2-gan
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from keyfill import io
from keyfill import rotations as R
from keyfill.learn.corpus import locate
from keyfill.learn.windows import axis_vector, facing_rotation
from keyfill.motion import Keys

HERE = Path(__file__).parent
KEYFILL = str(Path(sys.executable).parent / "keyfill")
CLIPS = ("walk_normal_001", "wave-both-hands_normal_002", "run_normal_001", "raise-up-left-hand_normal_001",
         "walk-turn-left_normal_003", "wave-right-hand_normal_001", "walk_normal_004")


def keyfill(*args) -> None:
    subprocess.run([KEYFILL, "-q", *map(str, args)], check=True)


def journey(folder: Path, names, transition: int):
    """The keys-only motion of the module docstring: ``(motion, key frames)``."""
    clips = [io.load(folder / f"dataset-2_{n}.bvh") for n in names]
    first = clips[0]
    skel, up = first.skeleton, first.skeleton.up_axis
    hips = skel.children(0)[0]  # joint_Root is static at the origin: the hips carry the world transform
    frames, rots, poss = [], [], []
    forward = axis_vector("+Y")  # the hips' forward axis in Bandai-Namco's rig (docs/transformer.md)
    t, at, facing = 0, None, None
    for clip in clips:
        q, p = clip.rotations.copy(), clip.positions.copy()
        if at is not None:  # turn the clip about the up axis to the heading the previous one ended with
            spin = R.quat_mul(facing, R.quat_conjugate(facing_rotation(q[0, hips], forward, up)))
            q[:, hips] = R.quat_mul(spin, q[:, hips])
            p[:, hips] = R.quat_rotate(spin, p[:, hips] - p[0, hips]) + at * [1, 0, 1] + p[0, hips] * [0, 1, 0]
        else:
            p[:, hips] = p[:, hips] - p[0, hips] * [1, 0, 1]
        for f in (0, clip.num_frames - 1):
            frames.append(t + f)
            rots.append(q[f])
            poss.append(p[f])
        t += clip.num_frames - 1 + transition
        at, facing = p[-1, hips], facing_rotation(q[-1, hips], forward, up)
    frames = np.array(frames)
    n = frames[-1] + 1
    index = np.searchsorted(frames, np.arange(n), side="right") - 1  # frames between keys hold the last key
    motion = first.replace(rotations=np.array(rots)[index], positions=np.array(poss)[index], keys=Keys(frames))
    return motion, frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True, help="a gan model folder with Motion DNA")
    ap.add_argument("--clips", default=",".join(CLIPS), help="held-out clips whose first and last frames are keys")
    ap.add_argument("--transition", type=int, default=90, help="frames between one clip's last key and the next's")
    ap.add_argument("--dna", default="run_normal_002,wave-both-hands_normal_001",
                    help="two held-out clips whose Motion DNA restyles the same keys")
    ap.add_argument("--window", default="560:900", help="frames A:B of the filmstrips and the GIF")
    ap.add_argument("--gif-step", type=int, default=2)
    ap.add_argument("--out", type=Path, default=HERE / "img")
    args = ap.parse_args()
    folder = locate("bandai2")
    motion, frames = journey(folder, args.clips.split(","), args.transition)
    print(f"{len(frames)} keys over {motion.num_frames} frames ({motion.num_frames / motion.fps:.0f} s), "
          f"largest gap {int(np.diff(frames).max())} frames")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        keys = tmp / "keys.usda"
        io.save(motion, keys, sparse=True)
        seeds = []
        for seed in (1, 2):
            seeds.append(tmp / f"seed{seed}.usda")
            keyfill("complete", keys, "-o", seeds[-1], "--method", "gan", "--model", args.model, "--seed", seed)
        labels = "seed 1,seed 2"
        keyfill("preview", *seeds, "--labels", labels, "--view", "top", "--trail", "Hips",
                "-o", args.out / "gan_long_trail.png")
        keyfill("preview", *seeds, "--labels", labels, "--view", "side", "--frames", args.window,
                "-o", args.out / "gan_long_strip.png")
        keyfill("preview", *seeds, "--labels", labels, "--view", "3d", "--frames", args.window, "--step",
                args.gif_step, "--fps", motion.fps / args.gif_step * 2, "--size", "480x300",
                "-o", args.out / "gan_long.gif")
        styled = []
        for name in args.dna.split(","):
            styled.append(tmp / f"{name}.usda")
            keyfill("complete", keys, "-o", styled[-1], "--method", "gan", "--model", args.model,
                    "--dna", folder / f"dataset-2_{name}.bvh", "--seed", 1)
        keyfill("preview", *styled, "--labels", args.dna.replace("_normal", ""), "--view", "side",
                "--frames", args.window, "-o", args.out / "gan_dna.png")


if __name__ == "__main__":
    main()
