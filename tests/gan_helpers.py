"""Shared helpers of the gan tests: a tiny synthetic corpus, a tiny config and a minimal driver of a training task."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from keyfill.learn.corpus import load_corpus
from keyfill.learn.gan.config import GanConfig

TINY_WIDTHS = {"encoder": [8] * 6, "decoder": [16] * 13, "discriminator": [8] * 6, "path": [8] * 8}


def tiny_config(**changes) -> GanConfig:
    """A config small enough to train for a few steps in a second or two."""
    base = {
        "preset": "custom", "widths": {k: list(v) for k, v in TINY_WIDTHS.items()}, "sequence_frames": 256,
        "max_gap": 120, "real_frames": 128, "batch_size": 2, "crops_per_sequence": 2, "path_batch": 4,
        "steps_per_epoch": 4, "noise_dim": 4, "lr_path": 3e-4, "lr_generator": 1e-3, "lr_discriminator": 1e-3,
        "val_fraction": 0.2, "val_sequences": 2,
    }
    base.update(changes)
    return GanConfig(**base)


def synthetic_corpus(folder: Path, clips_per_style: int = 3, seed: int = 0):
    """A corpus of seeded synthetic walks (:mod:`tests.synthetic_corpus`) of 130-200 frames."""
    from synthetic_corpus import write_corpus

    write_corpus(folder, clips_per_style=clips_per_style, frames=(130, 200), seed=seed)
    return load_corpus([folder], cache=False)


def fit(task, output, seed: int = 0, checkpoint=None, resume: bool = False):
    """Train ``task`` with keyfill's one training loop; returns its :class:`~keyfill.learn.training.Outcome`."""
    from keyfill.learn.training import train

    return train(task, output, seed=seed, checkpoint=checkpoint, resume=resume)


def built(task, seed: int = 0):
    """The networks the loop will build for ``seed`` (it seeds torch's global generator so), in training mode."""
    import torch

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        nets = task.build(torch.Generator().manual_seed(seed))
    for net in nets.values():
        net.train()
    return nets


def world(m):
    """World joint positions ``(T, J, 3)`` of a :class:`~keyfill.motion.Motion`."""
    from keyfill.kinematics import fk

    return fk(m.rotations, m.positions, m.skeleton.parents)[1]


def mean_of(log, name, part=slice(None)):
    return float(np.mean([entry[name] for entry in log[part]]))
