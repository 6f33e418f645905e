"""Motion DNA data (numpy): the bank of representative poses, and how many poses a sequence gets (Appendix D).

A Motion DNA is a set of representative poses (:mod:`keyfill.learn.representative`:
root-free, in metres here), which the generator's DNA encoder turns into the
style vector joined to every latent step (section 3.5.1).

* :class:`DnaBank`: the representative poses of a set of clips, one per second of
  each clip (at least one), and the clip each came from. Training draws from the
  bank of its training clips; a model folder keeps that bank, so ``complete``
  without a DNA file draws its poses from it by the seed.
* :func:`key_dna`: the default DNA of a model trained with its windows' own DNA
  (``GanConfig.dna_source`` ``"own"``): the keys' own poses, since a DNA drawn
  from another clip would steer the in-betweens towards that clip's motion.
* :func:`dna_count`: Appendix D's number of poses for a key layout: one per 3 s
  of each gap between keys (``floor(gap / 3 s)`` summed; at least one).
* :func:`draw_dna`: ``count`` poses of one random clip of a bank (the stand-in
  for the paper's "motion class": a clip is one kind of motion), or of a given
  clip (an in-clip window's own, ``GanConfig.dna_source`` ``"own"``); drawn
  without repetition while the clip has enough, with repetition beyond.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.representative import pick_frames, root_free_poses, rotation_change


@dataclass(frozen=True, eq=False)
class DnaBank:
    """Representative poses of clips.

    Attributes:
        poses: ``(P, J - 1, 3)`` float32, root-free, metres.
        clips: ``(P,)`` int64, the clip (an index into the clips the bank was built from) of each pose.
    """

    poses: np.ndarray
    clips: np.ndarray

    def __len__(self) -> int:
        return len(self.poses)


def build_bank(corpus, clips, per_second: float = 1.0) -> DnaBank:
    """The :class:`DnaBank` of ``clips`` (indices) of a :class:`~keyfill.learn.corpus.Corpus`.

    Each clip of ``F`` frames gives its ``max(1, round(per_second * F / fps))``
    representative frames.
    """
    s = corpus.skeleton
    off = s.offsets * s.meters_per_unit
    poses, owner = [], []
    for n, i in enumerate(int(c) for c in clips):
        q = corpus.clip(i)[0]
        frames = pick_frames(rotation_change(q), max(1, round(per_second * len(q) / corpus.fps)))
        poses.append(root_free_poses(q[frames], off, s.parents).astype(np.float32))
        owner.append(np.full(len(frames), n, dtype=np.int64))
    if not poses:
        return DnaBank(np.zeros((0, s.num_joints - 1, 3), np.float32), np.zeros(0, np.int64))
    return DnaBank(np.concatenate(poses), np.concatenate(owner))


def dna_count(key_frames, fps: float, seconds: float = 3.0) -> int:
    """Appendix D: one representative pose per ``seconds`` of every gap between the ``key_frames``, at least one."""
    gaps = np.diff(np.asarray(key_frames, dtype=np.int64))
    return max(1, int(np.sum(gaps // max(round(seconds * fps), 1))))


def key_dna(key_quats: np.ndarray, offsets: np.ndarray, parents, count: int) -> np.ndarray:
    """``([B,] P, J - 1, 3)`` float32: root-free poses of keys ``key_quats ([B,] K, J, 4)`` (local rotations; ``offsets``
    in metres), the ``P = min(count, K)`` most representative of them (:func:`~keyfill.learn.representative.pick_frames`
    over the keys in order), per window when batched."""
    q = np.asarray(key_quats, dtype=np.float64)
    if q.ndim == 4:
        return np.stack([key_dna(w, offsets, parents, count) for w in q])
    picked = pick_frames(rotation_change(q), count)
    return root_free_poses(q[picked], offsets, parents).astype(np.float32)


def draw_dna(bank: DnaBank, rng: np.random.Generator, count: int, clip: int | None = None) -> np.ndarray:
    """``(count, J - 1, 3)`` poses of one random clip of ``bank``, or of clip ``clip`` (see the module docstring)."""
    if len(bank) == 0:
        raise DataError("the Motion DNA bank holds no poses")
    if clip is None:
        owners = np.unique(bank.clips)
        clip = owners[int(rng.integers(len(owners)))]
    rows = np.flatnonzero(bank.clips == clip)
    if len(rows) == 0:
        raise DataError(f"the Motion DNA bank holds no pose of clip {clip}")
    pick = rng.choice(rows, size=count, replace=len(rows) < count)
    return bank.poses[pick]


def pad_dna(sets) -> tuple[np.ndarray, np.ndarray]:
    """``(poses (B, P, J - 1, 3) float32, valid (B, P) bool)``: sets of poses of different sizes, padded with zeros."""
    P = max(len(s) for s in sets)
    shape = sets[0].shape[1:]
    poses = np.zeros((len(sets), P, *shape), np.float32)
    valid = np.zeros((len(sets), P), bool)
    for b, s in enumerate(sets):
        poses[b, : len(s)] = s
        valid[b, : len(s)] = True
    return poses, valid
